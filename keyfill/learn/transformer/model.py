"""The motion-completion transformer (Duan et al. 2021, "Single-Shot Motion Completion with Transformer").

Every missing frame is predicted in one forward pass (section 3 of the paper):

1. Frames are *key* (given), *unknown* (to fill) or *ignored* (padding; no
   loss): :func:`frame_kinds`. Unknown frames are pre-filled (``prefill``): by
   LERP of the root and SLERP of the local rotations between the nearest keys
   (``"interpolation"``, :func:`keyfill.learn.protocols.lafan1.interpolation`), or by
   keyfill's C1 cubic spline through the keys (``"cubic"``,
   :func:`keyfill.learn.protocols.lafan1.cubic`), or by the interpolation plus the
   velocity of the given frames next to the gap, fading over a few frames
   (``"velocity"``, :func:`keyfill.learn.protocols.lafan1.velocity`).
2. Each frame becomes a feature vector (:class:`Features`): in ``global``
   coordinates (the paper's best variant) the normalised global positions and
   the global quaternions of all joints; in ``local`` coordinates the
   normalised root position and the local quaternions.
3. A Conv1d (kernel 3) turns the sequence into tokens; the *mixture embedding*
   (a learnable position embedding plus a learnable keyframe embedding chosen
   by the frame's kind; with ``key_distances`` also learnable embeddings of the
   frames since the last key and until the next) is added; a BERT encoder (``torch.nn.TransformerEncoder``,
   post-norm, GELU; 8 layers, d_model 256, FFN 512, 8 heads by default)
   processes all frames; a Conv1d (kernel 3) maps back to features. With
   ``residual`` (keyfill's default) that output is added to the pre-filled input,
   so the network learns a correction of the pre-fill; ``residual=False``
   is the paper's plain output.
4. Global predictions go back to local rotations by the simplest IK (each
   joint's rotation relative to its parent) and the standard bone offsets; the
   root position is the predicted one.

Windows are put in a canonical frame before they reach the network
(:func:`canonical_transform`): centred on the mean ground position of the
root over the *key* frames and turned so that the root faces +X on the anchor
key (the last key before the first unknown frame). Outputs are turned back.

Losses (Eqs. 12-15): L1 reconstruction of positions (normalised) and
quaternions over key and unknown frames, plus a kinematics loss: in global
coordinates the IK loss (bone offsets recovered from predicted global
positions and rotations against the true offsets), in local coordinates the FK
loss (global positions by forward kinematics against the truth). Optionally
(``fk_weight``, not in the paper) an FK loss on the decoded global output.

A model is a keyfill model folder of kind ``"transformer"``
(:mod:`keyfill.learn.modelfile`): ``weights.safetensors`` and a
``config.json`` holding the architecture, the skeleton it serves (joint names,
parents, offsets, channels, up axis), whether its corpus folded the top joint,
the normalisation statistics and a training summary. :func:`load`
refuses anything else without executing code from it.
"""

from __future__ import annotations

import itertools
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from keyfill import rotations as R
from keyfill.errors import KeyfillError, ModelError
from keyfill.learn import installed_models
from keyfill.learn.modelfile import torch_device
from keyfill.learn.transformer.config import ModelConfig
from keyfill.learn.transformer.features import IGNORED, Features, apply_transform, canonical_transform, frame_kinds
from keyfill.learn.windows import binomial_lowpass
from keyfill.motion import Skeleton

#: the ``kind`` of a transformer model folder (:mod:`keyfill.learn.modelfile`)
KIND = "transformer"
#: the model ``keyfill complete --method transformer`` uses without --model: Bandai-Namco's skeleton
#: (``normal`` style held out; its MODEL_CARD.md has the command, the data, the figures and the licence,
#: CC BY-NC 4.0, so it comes in the model distribution models/bandai); None when that is not installed
DEFAULT_MODEL = installed_models.shipped("bandai2-transformer")
#: ends the error for a motion of another skeleton
TRAIN_HINT = "; train a transformer on your own clips with 'keyfill train transformer CLIPS -o MODEL'"


# --- a trained model -----------------------------------------------------------------


@dataclass
class CompletionModel:
    """A trained transformer with everything needed to use it.

    Attributes:
        config: the architecture.
        skeleton: the skeleton it serves (names, parents, constant offsets).
        features: the feature encoding (with normalisation statistics).
        network: the torch module, or an exported graph runner that takes numpy arrays (``numpy_io``;
            :class:`keyfill.learn.transformer.onnx.GraphNetwork`).
        folded: whether its corpus folded a static top joint into the hips.
        info: training summary (epochs, data, final validation scores).
    """

    config: ModelConfig
    skeleton: Skeleton
    features: Features
    network: object
    folded: bool = False
    info: dict = field(default_factory=dict)

    def to(self, device: str) -> CompletionModel:
        if not getattr(self.network, "numpy_io", False):
            self.network.to(device)
        return self

    @property
    def device(self):
        return next(self.network.parameters()).device

    def complete_windows(self, quats: np.ndarray, root: np.ndarray, keys,
                         prefilled: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Fill windows whose key frames are ``keys`` (numpy in, numpy out).

        Args:
            quats: ``(B, T, J, 4)`` local quaternions (only key frames are read, unless ``prefilled``).
            root: ``(B, T, 3)`` root positions.
            keys: ``(K,)`` increasing frame indices shared by the windows.
            prefilled: the frames between the keys already hold where the network starts (a matched
                in-between: :func:`complete_motions`' ``starts``), in place of the model's pre-fill; with
                ``residual`` the output is that start plus the network's correction.

        Returns:
            ``(quats, root)`` of all ``T`` frames; frames outside the keys hold
            the nearest key.
        """
        keys = np.asarray(keys, dtype=np.int64)
        T = quats.shape[1]
        kinds = frame_kinds(T, keys)
        q = np.nan_to_num(np.asarray(quats, dtype=np.float64))
        r = np.nan_to_num(np.asarray(root, dtype=np.float64))
        up = self.skeleton.up_axis
        turn, shift = canonical_transform(q, r, keys, self.config.facing_axis, up)
        q, r = apply_transform(q, r, turn, shift)
        # q and -q are one rotation, but the network reads the numbers: each joint of each window is taken in
        # the hemisphere w >= 0 at the first key (its signs along the window kept), and given back in its own
        sign = np.where(q[:, keys[:1], :, :1] < 0, -1.0, 1.0)  # (B, 1, J, 1)
        q = q * sign
        if not prefilled:
            q, r = self.config.fill(q, r, keys)
        x = self.features.encode(q, r)  # numpy: many small quaternion products are cheaper than in torch
        if getattr(self.network, "numpy_io", False):
            y = self.network(x, np.broadcast_to(kinds, (len(q), T)))
        else:
            import torch

            dev = self.device
            with torch.inference_mode():
                k = torch.as_tensor(kinds, device=dev).expand(len(q), T)
                y = self.network(torch.as_tensor(x, dtype=torch.float32, device=dev), k).double().cpu().numpy()
        if self.config.output_smoothing:  # the network's correction, low-passed along time
            y = x + binomial_lowpass(y - x, self.config.output_smoothing, axis=1)
        pq, pr = self.features.decode(y)
        outside = kinds == IGNORED
        pq[:, outside], pr[:, outside] = q[:, outside], r[:, outside]
        pq, pr = apply_transform(pq * sign, pr, turn, shift, inverse=True)
        return R.quat_normalize(pq), pr

    def benchmark_method(self):
        """This model as a method of :func:`keyfill.learn.protocols.lafan1.evaluate`."""

        def method(skeleton: Skeleton, quats, root, keys):
            diff = self.skeleton.difference(skeleton, atol=1e-2 * float(np.abs(skeleton.offsets).max()))
            if diff is not None:
                raise ModelError(f"the model serves another skeleton: {diff}")
            return self.complete_windows(quats, root, keys)

        method.folded = self.folded  # the protocol should prepare clips as the model's corpus was
        return method

    # --- files ---

    def model_config(self) -> dict:
        """The ``config.json`` content of this model (see :mod:`keyfill.learn.modelfile`)."""
        s = self.skeleton
        return {
            "architecture": self.config.recorded(),
            "skeleton": s.to_json(),
            "folded_root": self.folded,
            "statistics": {"pos_mean": self.features.pos_mean.tolist(), "pos_std": self.features.pos_std.tolist()},
            "training": self.info,
        }

    def save(self, path: str | os.PathLike) -> None:
        """Write the model folder ``path`` (atomically; replaces a model already there)."""
        from keyfill.learn.modelfile import save_model

        save_model(path, KIND, self.network.state_dict(), self.model_config())


def features_for(skeleton: Skeleton, cfg: ModelConfig, pos_mean, pos_std) -> Features:
    std = np.where(np.asarray(pos_std) > 1e-6, pos_std, 1.0)
    return Features(cfg.coordinates, skeleton.parents.copy(), skeleton.offsets.copy(),
                    np.asarray(pos_mean, dtype=np.float64), np.asarray(std, dtype=np.float64))


def new_model(skeleton: Skeleton, cfg: ModelConfig, pos_mean, pos_std, folded: bool, info=None) -> CompletionModel:
    """A freshly initialised :class:`CompletionModel` (weights from torch's current generator)."""
    from keyfill.learn.transformer.network import build_network

    feat = features_for(skeleton, cfg, pos_mean, pos_std)
    return CompletionModel(cfg, skeleton, feat, build_network(feat.size, cfg), folded, dict(info or {}))


def config_parts(config: dict):
    """``(ModelConfig, Skeleton, statistics, folded, training)`` of a model's ``config.json`` content."""
    from keyfill.learn.modelfile import bounded_array

    cfg = ModelConfig(**config["architecture"])
    skel = Skeleton.from_json(config["skeleton"])
    n = (skel.num_joints * 3,)
    st = config["statistics"]
    stats = {"pos_mean": bounded_array(st["pos_mean"], "the position means", n),
             "pos_std": bounded_array(st["pos_std"], "the position deviations", n, above=0.0)}
    return cfg, skel, stats, bool(config["folded_root"]), config.get("training")


def load(path: str | os.PathLike, device: str = "cpu") -> CompletionModel:
    """Read a model folder written by :meth:`CompletionModel.save` (no code is executed)."""
    from keyfill.learn import modelfile

    dev = torch_device(device)
    tensors, config = modelfile.load_model(path, kind=KIND)
    try:
        cfg, skel, st, folded, training = config_parts(config)
        model = modelfile.build_for_loading(lambda: new_model(skel, cfg, st["pos_mean"], st["pos_std"],
                                                              folded, training))
    except (KeyError, TypeError, ValueError, KeyfillError) as e:
        raise ModelError(f"{modelfile.model_folder(path)}: damaged transformer model config ({e})") from None
    modelfile.load_state(model.network, tensors, path)
    model.network.eval()
    return model.to(dev)


# --- keyfill complete --------------------------------------------------------------


def spans(keys, max_frames: int) -> list[tuple[int, int]]:
    """Split the key range into spans ``(first key, last key)`` of at most ``max_frames`` frames.

    Consecutive spans share their boundary key. Raises a :class:`UsageError`
    when two consecutive keys are too far apart for the model.
    """
    from keyfill.errors import UsageError

    keys = [int(k) for k in keys]
    for a, b in itertools.pairwise(keys):
        if b - a + 1 > max_frames:
            raise UsageError(
                f"keys {a} and {b} are {b - a} frames apart; this model fills gaps of at most {max_frames - 2} frames"
            )
    out, start = [], 0
    while start < len(keys) - 1:
        end = start + 1
        while end + 1 < len(keys) and keys[end + 1] - keys[start] + 1 <= max_frames:
            end += 1
        out.append((keys[start], keys[end]))
        start = end
    return out


def complete_motion(model: CompletionModel, motion, keys) -> tuple[object, dict]:
    """Fill every frame of ``motion`` between its ``keys`` with ``model``.

    Reads only the key frames. Frames before the first key and after the last
    hold that key. Long key ranges are cut into spans that fit the model's
    window (:func:`spans`), each completed on its own. Returns ``(motion,
    info)``; keys are *not* yet exact (see :func:`keyfill.learn.exact_keys.snap_to_keys`).
    """
    result = complete_motions(model, [(motion, keys)], batch=False)[0]
    if isinstance(result, Exception):
        raise result
    return result


#: most windows sent through the network at once by :func:`complete_motions`
MAX_WINDOWS = 64


def complete_motions(model: CompletionModel, jobs, batch: bool = True, starts=None) -> list:
    """:func:`complete_motion` for many ``(motion, keys)``: ``(motion, info)`` or the error, per job.

    With ``batch``, windows of the same length and key layout (from any of the
    motions: clips keyed every N frames share most) go through the network
    together, up to :data:`MAX_WINDOWS` at a time; a window's result then
    depends on its batch in float32 rounding only. Without, every window is
    completed alone, in order (what one ``keyfill complete`` does).

    ``starts``: per job, None or a motion of the job's skeleton and frames (an in-between matched from a
    motion library, issue 46) whose frames between the keys the network starts from instead of the model's
    pre-fill (:meth:`CompletionModel.complete_windows`' ``prefilled``); its key frames are the job's own.
    """
    from keyfill.learn.windows import file_take, model_take
    from keyfill.motion import Keys

    results: list = [None] * len(jobs)
    prepared = {}
    for j, (motion, keys) in enumerate(jobs):
        try:
            k = np.asarray(keys.frames if isinstance(keys, Keys) else keys, dtype=np.int64)
            # the keys' interpolation (held outside them) in the model's hierarchy, signs continuous; the
            # windows' interiors are written into q and p in place (windows share no frame but keys), and
            # they become the result's arrays
            start = None if starts is None else starts[j]
            if start is None:
                q, p, top = model_take(model.skeleton, model.folded, motion, k, continuous=True, hint=TRAIN_HINT)
            else:  # every frame the start's own (no joint slerped), signs continuous along the take
                check_start(start, motion, k)
                q, p, top = model_take(model.skeleton, model.folded, start, np.arange(start.num_frames),
                                       slerped=np.arange(0), continuous=True, hint=TRAIN_HINT)
            parts = spans(k, model.config.max_frames)
            prepared[j] = (k, top, q, p, parts, start is not None)
        except KeyfillError as e:
            results[j] = e
    # windows: (job, a, b, key frames inside); spans of one motion never overlap but at their boundary keys
    windows = [(j, a, b, tuple(k[np.searchsorted(k, a): np.searchsorted(k, b, side="right")] - a))
               for j, (k, _, _, _, parts, _) in prepared.items() for a, b in parts]
    if batch:  # windows started from a match and from the pre-fill go through the network apart
        groups: dict = {}
        for w in windows:
            groups.setdefault((w[2] - w[1], w[3], prepared[w[0]][5]), []).append(w)
        runs = [g[i: i + MAX_WINDOWS] for g in groups.values() for i in range(0, len(g), MAX_WINDOWS)]
    else:
        runs = [[w] for w in windows]
    for run in runs:
        wq, wr = model.complete_windows(np.stack([prepared[j][2][a: b + 1] for j, a, b, _ in run]),
                                        np.stack([prepared[j][3][a: b + 1, 0] for j, a, b, _ in run]),
                                        np.asarray(run[0][3]), prefilled=prepared[run[0][0]][5])
        for i, (j, a, b, _) in enumerate(run):
            out_q, pos = prepared[j][2], prepared[j][3]
            out_q[a + 1: b], pos[a + 1: b, 0] = wq[i, 1:-1], wr[i, 1:-1]
    for j, (k, top, out_q, pos, parts, _) in prepared.items():
        motion = jobs[j][0]
        file_take(out_q, pos, top, motion.skeleton)
        result = motion.replace(rotations=out_q, positions=pos, keys=Keys(k))
        results[j] = (result, {"spans": len(parts), "max_frames": model.config.max_frames})
    return results


def check_start(start, motion, keys: np.ndarray) -> None:
    """A :class:`DataError` unless ``start`` can stand for ``motion`` between ``keys (K,)``: the same skeleton
    (joint names and parents) and frames, and the same poses at the keys."""
    from keyfill.errors import DataError

    sk, own = start.skeleton, motion.skeleton
    if tuple(sk.names) != tuple(own.names) or not np.array_equal(sk.parents, own.parents):
        raise DataError("the start motion is not on the motion's skeleton")
    if start.num_frames != motion.num_frames:
        raise DataError(f"the start motion has {start.num_frames} frames, the motion {motion.num_frames}")
    if not np.allclose(np.abs((start.rotations[keys] * motion.rotations[keys]).sum(-1)), 1.0, atol=1e-6):
        raise DataError("the start motion's poses at the keys are not the motion's")
    if not np.allclose(start.positions[keys], motion.positions[keys], atol=1e-6):
        raise DataError("the start motion's positions at the keys are not the motion's")


def complete(motion, keys, options):
    """``keyfill complete --method transformer``: see :func:`complete_motion`."""
    from keyfill.learn.modelfile import load_cached

    model = load_cached(load, model_path(options), options.device)
    return _complete_with(model, motion, keys, options)


def _complete_with(model: CompletionModel, motion, keys, options):
    return _finish(complete_motion(model, motion, keys), motion, keys, options)


def _finish(completed, motion, keys, options):
    """The :class:`Completion` of ``completed`` = ``(filled motion, info)`` (keys made exact if asked)."""
    from keyfill.learn.completion import Completion
    from keyfill.learn.exact_keys import snap_to_keys

    filled, info = completed
    info = {"model": str(options.model or model_path(options).name), **info, "exact_keys": bool(options.exact_keys)}
    if options.exact_keys:
        filled, report = snap_to_keys(filled, motion, keys, in_place=True)  # filled: ours
        info.update(report)
    return Completion(filled, info)


def complete_many_with(model: CompletionModel, jobs, options, extra=None) -> list:
    out = []
    for (motion, keys), done in zip(jobs, complete_motions(model, jobs, batch=True)):
        if isinstance(done, KeyfillError):
            out.append(done)
            continue
        result = _finish(done, motion, keys, options)
        result.info.update(extra or {})
        out.append(result)
    return out


def complete_many(jobs, options):
    """:func:`complete` for many ``(motion, keys)``: the model loaded once, windows of the same length and
    key layout batched (:func:`complete_motions`); a Completion or the error, per job."""
    from keyfill.learn.modelfile import load_cached

    return complete_many_with(load_cached(load, model_path(options), options.device), jobs, options)


def model_path(options, keys=None) -> Path:
    """The model folder (or graph) a completion with ``options`` uses: ``options.model`` or the shipped one
    (:func:`keyfill.learn.installed_models.missing`'s error when it is not installed)."""
    return Path(options.model) if options.model is not None else installed_models.require(DEFAULT_MODEL, KIND)
