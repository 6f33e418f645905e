"""Trained lamp models: load a folder, complete lamp motions (``keyfill complete --method arnn``).

No torch at import: :func:`load` and :meth:`LampModel.predict` import it when
they run, and the ONNX path (:mod:`keyfill.learn.arnn.onnx`) shares
:func:`complete_lamp_many` without it.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from keyfill.errors import DataError, ModelError, UsageError
from keyfill.learn import installed_models
from keyfill.learn.lamp_data import NUM_VARIABLES, LampSequence, Normalizer, origin, wrap_angles

if TYPE_CHECKING:
    from keyfill.learn.arnn.network import Completer

#: the ``kind`` of a lamp model folder (:mod:`keyfill.learn.modelfile`)
KIND = "arnn"
#: the model that ``keyfill complete --method arnn`` uses for lamp files without --model (trained on keyfill's
#: own simulated hops, so MIT and inside keyfill: keyfill/learn/models/lamp-arnn)
DEFAULT_MODEL = installed_models.shipped("lamp-arnn")


class LampModel:
    """A trained network with its normalisation statistics and config."""

    def __init__(self, net: Completer, normalizer: Normalizer, config: dict, path: str = ""):
        self.net = net.eval()
        self.normalizer = normalizer
        self.config = config
        self.path = path

    @property
    def arch(self) -> str:
        return self.net.arch

    def predict(self, sequences: list[LampSequence]) -> list[np.ndarray]:
        """Complete each sequence from its keys: a list of ``(T, 6)`` arrays (m, rad), first to last key.

        Only the key frames of each sequence's ``values`` are read.
        """
        import torch

        from keyfill.learn.arnn.features import make_batch
        from keyfill.learn.arnn.network import run

        batch = make_batch(sequences, self.normalizer)
        with torch.inference_mode():
            pred = run(self.net, batch.frames, batch.is_key)
        out = []
        for b, s in enumerate(sequences):
            n = int(batch.lengths[b])
            z = np.concatenate([batch.frames[b, :1].numpy(), pred[b, : n - 1].numpy()]).astype(np.float64)
            out.append(self.normalizer.decode(z, origin(s.values[s.keys[0]])))
        return out


def model_config(net: Completer, normalizer: Normalizer, sizes: dict, training: dict) -> dict:
    """The ``config.json`` content of a lamp model (see :mod:`keyfill.learn.modelfile`)."""
    from keyfill.characters.lamp import VARIABLE_NAMES, lamp_skeleton
    from keyfill.learn.arnn.network import num_weights

    return {
        "arch": net.arch,
        "sizes": sizes,
        "variables": list(VARIABLE_NAMES),
        "normalizer": normalizer.to_json(),
        "skeleton": lamp_skeleton().to_json(hierarchy_only=True),
        "weights": num_weights(net),
        "training": training,
    }


def load(path: str | Path, device: str = "cpu") -> LampModel:
    """Read a lamp model folder; :class:`ModelError` for anything that is not an intact ARNN-family model.

    The lamp networks run on the CPU (``device`` must be ``"cpu"``).
    """
    if device != "cpu":
        raise UsageError("the lamp networks run on the CPU (device cpu)", params="device")
    from keyfill.learn.arnn.network import build
    from keyfill.learn.modelfile import build_for_loading, load_model, load_state

    tensors, config = load_model(path, kind=KIND)
    try:
        arch = config["arch"]
        sizes = dict(config.get("sizes", {}))
        normalizer = Normalizer.from_json(config["normalizer"])
        net = build_for_loading(lambda: build(arch, **sizes))
    except (KeyError, TypeError, ValueError, UsageError) as e:
        raise ModelError(f"{path}: damaged ARNN model config ({e})") from None
    load_state(net, tensors, path)
    return LampModel(net, normalizer, config, str(path))


def complete(motion, keys, options):
    """``keyfill complete --method arnn``: fill a lamp motion's frames between ``keys`` with a trained model.

    Key angles are read within ``[-pi, pi)`` (:func:`~keyfill.learn.arnn.features.wrap_angles`).
    Frames before the first and after the last key hold the frames there. With
    ``options.exact_keys`` the small residual at the keys is removed by
    :func:`keyfill.learn.exact_keys.snap_to_keys` and its size reported.
    """
    result = complete_many([(motion, keys)], options)[0]
    if isinstance(result, Exception):
        raise result
    return result


def complete_many(jobs, options):
    """:func:`complete` for many ``(motion, keys)``: the model is loaded once and runs them as one batch.

    Returns a :class:`~keyfill.learn.completion.Completion` or the
    :class:`~keyfill.errors.KeyfillError` of each job. One job's result
    depends on the jobs batched with it only in float32 rounding (about 1e-7).
    """
    from keyfill.learn.modelfile import load_cached

    path = DEFAULT_MODEL if options.model is None else Path(options.model)
    return complete_lamp_many(jobs, options, lambda: load_cached(load, path), DEFAULT_MODEL.name)


def complete_lamp_many(jobs, options, get_model, builtin_name: str):
    """Complete lamp motions ``[(motion, keys), ...]`` with a lamp model: what ``complete --method arnn``
    does around the network, for any runtime (torch or onnxruntime) and without torch.

    Args:
        options: :class:`~keyfill.learn.completion.CompleteOptions` (``model`` None: the built-in model).
        get_model: ``() -> model`` with ``predict(sequences)``, ``config`` and ``arch`` (called once, if needed).
        builtin_name: the built-in model's name, for the report.

    Returns, per job, a :class:`~keyfill.learn.completion.Completion` or the
    :class:`~keyfill.errors.KeyfillError` that stopped it. All jobs that reach
    the network go through one ``predict`` call (one batch).
    """
    from keyfill.characters.lamp import from_variables, is_lamp, to_variables
    from keyfill.errors import KeyfillError
    from keyfill.learn.completion import Completion
    from keyfill.learn.exact_keys import snap_to_keys
    from keyfill.learn.modelfile import check_skeleton

    results: list = [None] * len(jobs)
    model = None
    ready = []
    for i, (motion, keys) in enumerate(jobs):
        try:
            if options.model is None and not is_lamp(motion.skeleton):
                raise UsageError(
                    f"the built-in ARNN model serves the hopping lamp (joints base, leg, neck, head); this motion has "
                    f"joints {', '.join(motion.skeleton.names[:6])}{', ...' if motion.num_joints > 6 else ''}; "
                    f"give --model with a model trained for it"
                )
            if model is None:
                model = get_model()
            check_skeleton(model.config, motion.skeleton, model.path)
            k = keys.frames
            try:
                key_values = wrap_angles(to_variables(motion.frames(k)))  # only the key frames are read
            except DataError as e:
                raise DataError(f"the ARNN completes lamp motions only: {e}") from None
            values = np.zeros((motion.num_frames, key_values.shape[1]))
            values[k] = key_values
            ready.append((i, motion, keys, key_values, LampSequence(values, k)))
        except KeyfillError as e:
            results[i] = e
    with np.errstate(over="ignore", invalid="ignore"):  # a damaged network's overflow is reported below
        spans = model.predict([r[-1] for r in ready]) if ready else []
    for (i, motion, keys, key_values, _), span in zip(ready, spans):
        if not np.isfinite(span).all():
            results[i] = ModelError(f"{model.path or builtin_name}: the network's output is not finite "
                                    "(are its weights damaged?)")
            continue
        k = keys.frames
        out = np.empty((motion.num_frames, NUM_VARIABLES))
        out[k[0]: k[-1] + 1] = span
        out[: k[0]] = span[0]  # hold; the exact-keys correction then moves them with their key
        out[k[-1] + 1:] = span[-1]
        positions = motion.positions.copy()
        positions[:, 0, :2] = out[:, :2]
        pred = motion.replace(rotations=from_variables(out, motion.fps).rotations, positions=positions, keys=keys)
        residual = np.abs(wrap_angles(span[k - k[0]] - key_values)).max(axis=0)  # angles modulo a turn
        residual = {"position_m": float(residual[:2].max()), "angle_rad": float(residual[2:].max())}
        label = f"built-in {builtin_name}" if options.model is None else str(options.model)
        info = {"model": label, "arch": model.arch, "exact_keys": bool(options.exact_keys)}
        if options.exact_keys:
            pred, _ = snap_to_keys(pred, motion, keys)
            info["key_residual_removed"] = residual
        else:
            info["key_residual_left"] = residual
        results[i] = Completion(pred, info)
    return results
