"""The registry of in-betweening methods: the one list that ``complete``, ``evaluate`` and ``train`` read.

Each :class:`Method` names the functions that implement it as
``"module:attribute"`` strings, imported on first use, so reading the registry
(``keyfill --help``, ``keyfill info``) loads no torch. The baselines of
:mod:`keyfill.interpolate` are methods like the learned ones, so
``complete --method``, ``evaluate`` and the protocols share one vocabulary. A learned method's model
folders carry its name as their ``kind`` (:mod:`keyfill.learn.modelfile`), so a
folder is dispatched to its method by :func:`method_for_model`.

A learned method's module provides:

* ``complete(motion, keys, options) -> Completion`` (:mod:`keyfill.learn.completion`);
* ``load(path, device) -> model``: a loaded model. The protocol that scores the
  method calls the model's own hook: ``benchmark_method()`` for ``lafan1``
  (:mod:`keyfill.learn.protocols.lafan1`), ``predict(sequences)`` for ``keys``
  (:mod:`keyfill.learn.protocols.keys`);
* ``DEFAULT_MODEL``: the folder of its shipped model (inside keyfill, or in an installed model
  distribution: :mod:`keyfill.learn.installed_models`), or None.

Its training module provides ``TRAINING``, a
:class:`keyfill.learn.training.TrainingSpec` (options, help text and the task
for the one training loop). See docs/learned_methods.md, "Adding a method".
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, replace
from pathlib import Path

from keyfill.errors import DataError, KeyfillError, ModelError, UsageError
from keyfill.learn.completion import CompleteOptions, Completion
from keyfill.motion import Keys, Motion


@dataclass(frozen=True)
class Method:
    """One in-betweening method.

    Attributes:
        name: the ``--method`` name; for a learned method also the ``kind`` of its model folders.
        summary: one line for ``--help``.
        complete: ``"module:function"`` implementing ``complete(motion, keys, options) -> Completion``; for a
            baseline (``module`` None) the name of :data:`keyfill.interpolate.BASELINES` it is.
        module: the learned method's module (``load``, ``DEFAULT_MODEL``); None for splines.
        protocol: the benchmark protocol that scores its models (``"lafan1"``, ``"keys"``).
        training: the module whose ``TRAINING`` trains it (``keyfill train NAME``); None if not trainable.
        export: ``"module:function"`` writing a loaded model as an ONNX graph,
            ``export_onnx(model, folder, path)`` (``keyfill export``); None if not exportable.
        onnx: the module that completes with an exported graph and no torch:
            ``complete_graph(jobs, options, graph)`` (:mod:`keyfill.learn.onnx`).
        partial_keys: whether it accepts partial keys (:attr:`keyfill.motion.Keys.partial`); :func:`complete`
            refuses them for the others.
        dna: whether it takes a Motion DNA (``CompleteOptions.dna`` / ``dna_count``).
        aliases: other names it answers to (``interpolation``: the LaFAN1 benchmark's word for ``linear``).
        humanoid: its models serve one human skeleton and frame rate, and any humanoid rig at any frame rate
            through :mod:`keyfill.learn.rig_bridge` (the module's ``model_path(options, keys)`` names the model,
            its ``served(options, keys)``, where it has one, what the model serves). Its gaps are scored by
            the guard (:mod:`keyfill.learn.library.guard`) against the model's pose index.
        library: it takes a motion library (``CompleteOptions.library``) as its model.
        matches: its models may match from a motion library (``CompleteOptions.library``, else the one the model
            names) beside the model: a gan on a matched base (:mod:`keyfill.learn.gan.matched_base`).
        feet: its ``feet`` when the options give none (``"free"`` or ``"lock"``).
    """

    name: str
    summary: str
    complete: str
    module: str | None = None
    protocol: str | None = None
    training: str | None = None
    export: str | None = None
    onnx: str | None = None
    partial_keys: bool = False
    dna: bool = False
    aliases: tuple[str, ...] = ()
    humanoid: bool = False
    library: bool = False
    matches: bool = False
    feet: str = "free"

    @property
    def learned(self) -> bool:
        return self.module is not None

    def function(self):
        """The ``complete(motion, keys, options) -> Completion`` function."""
        if not self.learned:
            from keyfill.interpolate import BASELINES

            spline = BASELINES[self.complete][0]
            return lambda motion, keys, options: Completion(spline(motion, keys), {"exact_keys": True})
        module, attr = self.complete.split(":")
        return getattr(importlib.import_module(module), attr)

    def windows(self):
        """A baseline on windows, ``(skeleton, quats (B, T, J, 4), root (B, T, 3), keys) -> (quats, root)``."""
        if self.learned:
            raise UsageError(f"{self.name} is a learned method; its models give their own window function")
        from keyfill.interpolate import BASELINES

        return BASELINES[self.complete][1]

    def implementation(self):
        """The learned method's module."""
        if self.module is None:
            raise UsageError(f"{self.name} is not a learned method; it has no models")
        return importlib.import_module(self.module)

    def training_spec(self):
        """The :class:`~keyfill.learn.training.TrainingSpec` of ``keyfill train NAME``."""
        if self.training is None:
            raise UsageError(f"{self.name} cannot be trained")
        return importlib.import_module(self.training).TRAINING

    def default_model(self) -> Path | None:
        """The folder of this method's shipped model (:mod:`keyfill.learn.installed_models`), or None when none
        ships or its distribution is not installed."""
        path = getattr(self.implementation(), "DEFAULT_MODEL", None)
        return Path(path) if path is not None and Path(path).is_dir() else None


METHODS: dict[str, Method] = {m.name: m for m in (
    Method("linear", "lerp of translations, slerp of rotations", "linear", aliases=("interpolation",)),
    Method("cubic", "C1 cubic splines (log-map cubic for rotations)", "cubic"),
    Method("velocity", "linear, plus the velocity of given frames next to a gap, fading over 3 frames", "velocity"),
    Method("zero-velocity", "every frame holds the key before it", "zero-velocity"),
    Method("arnn", "keyframe-conditioned recurrent network for the hopping lamp (Zhang & van de Panne 2018)",
           "keyfill.learn.arnn.model:complete", module="keyfill.learn.arnn.model", protocol="keys",
           training="keyfill.learn.arnn.task", export="keyfill.learn.arnn.onnx:export_onnx",
           onnx="keyfill.learn.arnn.onnx"),
    Method("transformer", "BERT-style motion-completion transformer (Duan et al. 2021)",
           "keyfill.learn.transformer.model:complete", module="keyfill.learn.transformer.model", protocol="lafan1",
           training="keyfill.learn.transformer.task", export="keyfill.learn.transformer.onnx:export_onnx",
           onnx="keyfill.learn.transformer.onnx", humanoid=True),
    Method("gan", "generative tweening: long-term in-betweening with a convolutional GAN (Zhou et al. 2020)",
           "keyfill.learn.gan.model:complete", module="keyfill.learn.gan.model", protocol="lafan1",
           training="keyfill.learn.gan.train_command", export="keyfill.learn.gan.onnx:export_onnx",
           onnx="keyfill.learn.gan.onnx", partial_keys=True, dna=True, humanoid=True, matches=True),
    Method("match", "in-betweens matched from a library of real motion (motion matching through the keys)",
           "keyfill.learn.match.model:complete", module="keyfill.learn.match.model", protocol="lafan1",
           partial_keys=True, humanoid=True, library=True, feet="lock"),
)}


#: every other name of a method -> its name
ALIASES = {alias: m.name for m in METHODS.values() for alias in m.aliases}


def get(name: str) -> Method:
    """The method called ``name`` (or one of its aliases); a :class:`UsageError` listing the methods otherwise."""
    if name not in METHODS and name not in ALIASES:
        raise UsageError(f"unknown method {name!r}; methods are: {', '.join(METHODS)}")
    return METHODS[ALIASES.get(name, name)]


def learned() -> list[Method]:
    """The learned methods, in registry order."""
    return [m for m in METHODS.values() if m.learned]


def exportable() -> list[Method]:
    """The methods ``keyfill export`` can write as ONNX graphs."""
    return [m for m in METHODS.values() if m.export is not None]


def trainable() -> list[Method]:
    """The methods ``keyfill train`` offers."""
    return [m for m in METHODS.values() if m.training is not None]


def method_for_model(path: str | Path) -> Method:
    """The learned method whose model folder ``path`` is (by the ``kind`` in its config)."""
    from keyfill.learn.modelfile import read_config

    kind = read_config(path)["kind"]
    for m in learned():
        if m.name == kind:
            return m
    raise ModelError(f"{path}: a model of kind {kind!r}, which no method of this keyfill knows "
                     f"(known kinds: {', '.join(m.name for m in learned())})")


def kind_of(model: str | Path) -> str:
    """The method name of a model folder (the ``kind`` of its config) or of an exported ``.onnx`` graph (its
    metadata): what ``keyfill complete --model FOLDER`` runs without ``--method``."""
    from keyfill.learn.onnx import is_graph, open_graph

    return open_graph(model).kind if is_graph(model) else method_for_model(model).name


def load_model(name_or_path: str, device: str = "cpu") -> tuple[str, Method, object]:
    """``(label, method, loaded model)`` for a learned method's name (its shipped model) or a model folder."""
    if name_or_path in METHODS:
        method = METHODS[name_or_path]
        path = method.default_model()
        if path is None:
            raise _no_model(method, option=False)
        return name_or_path, method, method.implementation().load(path, device)
    if not Path(name_or_path).exists():
        raise UsageError(f"{name_or_path!r} is neither a method ({', '.join(METHODS)}) nor a model folder")
    method = method_for_model(name_or_path)
    return str(name_or_path), method, method.implementation().load(name_or_path, device)


def _no_model(m: Method, option: bool = True) -> KeyfillError:
    """The error of using ``m``'s shipped model when it has none here: the human models' distribution is not
    installed (they are CC BY-NC 4.0, apart from keyfill), or no model ships for ``m``."""
    if m.library:
        from keyfill.learn.installed_models import HOW_TO_GET

        return ModelError(f"the shipped motion library is not installed: {HOW_TO_GET}; or give library LIB, one of "
                          f"your own (build one with 'keyfill library build CLIPS -o LIB')",
                          params="library" if option else ())
    if m.humanoid:
        from keyfill.learn.installed_models import missing

        return missing(m.name, option)
    return UsageError(f"no {m.name} model ships with keyfill; give a model folder "
                      f"(train one with 'keyfill train {m.name}')")


def checked_keys(m: Method, motion: Motion, keys: Keys) -> Keys:
    """``keys`` once they are known to fit ``motion`` and ``m`` (partial keys only for methods that take them)."""
    keys = keys.check(motion.num_frames, min_keys=2)
    keys.joint_mask(motion.num_joints)  # a mask of another skeleton is a usage error
    if keys.partial and not m.partial_keys:
        accept = [n.name for n in METHODS.values() if n.partial_keys]
        raise UsageError(f"{m.name} needs whole poses at every key; partial keys (some joints, positions or "
                         f"2-D positions) are accepted by: {', '.join(accept)}")
    return keys


def checked_options(m: Method, options: CompleteOptions) -> CompleteOptions:
    """``options`` once its ``model``, ``dna`` and ``rig_map`` are known to fit ``m`` (a :class:`UsageError`
    naming them otherwise); reads no weights."""
    if (options.dna is not None or options.dna_count is not None) and not m.dna:
        raise UsageError(f"dna and dna_count apply to methods with Motion DNA "
                         f"({', '.join(n.name for n in METHODS.values() if n.dna)}), not to {m.name!r}",
                         params=("dna", "dna_count"))
    if not m.learned and options.model is not None:
        raise UsageError(f"model applies to learned methods, not to {m.name!r}", params="model")
    if options.library is not None and not (m.library or m.matches):
        raise UsageError(f"library applies to methods that match from a motion library "
                         f"({', '.join(n.name for n in METHODS.values() if n.library or n.matches)}), not to "
                         f"{m.name!r}", params="library")
    if options.model is not None and m.library:
        raise UsageError(f"{m.name} takes a motion library (library), not a model", params=("model", "library"))
    if options.guard is not None and not m.humanoid:
        raise UsageError(f"guard applies to the human methods "
                         f"({', '.join(n.name for n in METHODS.values() if n.humanoid)}), not to {m.name!r}",
                         params="guard")
    if options.rig_map is not None and not m.humanoid and options.feet != "lock":
        raise UsageError(f"rig_map applies to methods whose models serve any humanoid rig "
                         f"({', '.join(n.name for n in METHODS.values() if n.humanoid)}) and to feet lock, "
                         f"not to {m.name!r}", params="rig_map")
    from keyfill.learn.onnx import is_graph

    if options.model is not None and not is_graph(options.model):
        kind = method_for_model(options.model).name
        if kind != m.name:
            raise UsageError(f"{options.model}: a model of kind {kind!r}, not {m.name!r}; complete with method {kind}",
                             params="method")
        options = replace(options, model=str(options.model))
    return options


def complete(motion: Motion, keys: Keys, method: str = "cubic", options: CompleteOptions | None = None) -> Completion:
    """Fill the frames between ``keys`` of ``motion`` with ``method``."""
    options = options or CompleteOptions()
    m = get(method)
    keys = checked_keys(m, motion, keys)
    options = checked_options(m, options)
    if m.learned and (options.library if m.library else options.model) is None and m.default_model() is None:
        raise _no_model(m)
    graph = _graph(m, options)
    bridged = _on_model_rig(m, motion, keys, options)
    if bridged is not None:
        result = bridged
    elif graph is not None:
        result = importlib.import_module(m.onnx).complete_graph([(motion, keys)], options, graph)[0]
        if isinstance(result, KeyfillError):
            raise result
    else:
        result = m.function()(motion, keys, options)
    result = guarded(m, motion, keys, options, result)
    result = with_feet(m, result, keys, options, motion)
    result.info = reported(m, motion, keys, options, result)
    return result


def guarded(m: Method, motion: Motion, keys: Keys, options: CompleteOptions, result: Completion) -> Completion:
    """``result`` with its gaps scored by the guard (:mod:`keyfill.learn.library.guard`) against what ``m``'s
    model or library knows, and, with ``guard`` ``"fallback"`` (the default), the unfamiliar ones filled by
    the cubic spline; ``info["guard"]`` reports it (None where the model has no pose index). A completion
    through the rig bridge was scored on the model's skeleton (its inner completion only warns); the
    fallback is then made here, on the motion's own skeleton."""
    mode = options.guard or "fallback"
    if not m.humanoid or mode == "off" or keys.partial:
        return result
    import numpy as np

    from keyfill.learn.library import guard

    block = result.info.get("guard")
    if block is None and "guard" not in result.info:
        index = _pose_index(m, options, keys)
        if index is None:
            result.info["guard"] = None
            return result
        from keyfill.learn.library.store import frames_of

        frames = frames_of(model_served(m, options, keys).skeleton)
        block = guard.report(index, mode, keys, guard.scores(index, frames, motion, keys, result.motion))
    if block is None:
        return result
    block = {**block, "mode": mode, "filled_by_cubic": block["unfamiliar"] if mode == "fallback" else 0}
    result.info["guard"] = block
    if mode == "fallback" and block["unfamiliar"]:
        unfamiliar = np.array([g["unfamiliar"] for g in block["gaps"]], dtype=bool)
        return Completion(guard.fall_back(result.motion, motion, keys, unfamiliar,
                                          in_place=_own_arrays(result.motion, motion)), result.info)
    return result


def model_served(m: Method, options: CompleteOptions, keys: Keys | None = None):
    """What the model (or library) of the ``humanoid`` method ``m`` serves under ``options``
    (:class:`keyfill.learn.rig_bridge.Served`), for ``keys`` (a method may choose its model by them; None:
    the default model); reads a model's config, no weights."""
    served_by = getattr(m.implementation(), "served", None)
    if served_by is not None:
        return served_by(options, keys)
    from keyfill.learn import installed_models, rig_bridge

    path = m.implementation().model_path(options, keys) if keys is not None else options.model or m.default_model()
    return rig_bridge.served(installed_models.require(path, m.name))


def _pose_index(m: Method, options: CompleteOptions, keys: Keys):
    """The :class:`~keyfill.learn.library.index.PoseIndex` of ``m``'s model or library, or None when the model
    folder has none (an exported graph alone, a model trained before pose indexes)."""
    from keyfill.learn.library.index import library_index, load_pose_index
    from keyfill.learn.onnx import is_graph

    if is_graph(options.model):
        return None
    path = m.implementation().model_path(options, keys)
    if m.library:
        return library_index(m.implementation().load(path).library)
    return load_pose_index(path, Path(path).name)


def reported(m: Method, motion: Motion, keys: Keys, options: CompleteOptions, result: Completion) -> dict:
    """``result.info`` in the one shape of every method (docs/json.md): ``method``, ``keys``, ``frames`` (a
    count), ``model`` (an id: the model folder's or graph's name) with ``model_path``, and ``key_residual``:
    ``{"position": file units, "rotation_rad": radians, "removed": bool}``, the largest difference of the
    method's own frames at the keys from the keys, and whether exact keys removed it."""
    info = dict(result.info)
    if "key_residual" not in info:
        if "key_residual_position" in info:  # measured by snap_to_keys before it removed it
            block = {"position": info.pop("key_residual_position"),
                     "rotation_rad": info.pop("key_residual_rotation_rad"), "removed": True}
        elif "key_residual_removed" in info or "key_residual_left" in info:  # the lamp's (kept: docs/arnn.md)
            r = info.get("key_residual_removed", info.get("key_residual_left"))
            block = {"position": r["position_m"], "rotation_rad": r["angle_rad"],
                     "removed": "key_residual_removed" in info}
        else:  # a method that reports none: its frames at the keys as they are
            from keyfill.learn.exact_keys import key_residual

            measured = key_residual(result.motion, motion, keys)
            block = {"position": measured["key_residual_position"],
                     "rotation_rad": measured["key_residual_rotation_rad"], "removed": False}
        info["key_residual"] = block
    if not m.learned:
        info.update(model=None, model_path=None)
    elif "model_path" not in info:
        path = info.get("model") if info.get("model") and Path(str(info.get("model"))).exists() else None
        chosen = getattr(m.implementation(), "model_path", None)  # the model these keys use (gan: partial keys)
        path = path or (chosen(options, keys) if chosen is not None else options.model or m.default_model())
        if path is not None:
            from keyfill.learn.onnx import GRAPH

            path = Path(path).resolve()
            if path.name == GRAPH and (path.parent / "config.json").is_file():
                path = path.parent  # a model folder's own graph: the model is the folder (runtime says onnx)
        info["model_path"] = None if path is None else str(path)
        info["model"] = None if path is None else (path.stem if path.suffix.lower() == ".onnx" else path.name)
    return {"method": m.name, "keys": keys.to_list(), "frames": motion.num_frames, **info}


def with_feet(m: Method, result: Completion, keys: Keys, options: CompleteOptions, source: Motion) -> Completion:
    """``result`` with its feet locked (:func:`keyfill.characters.feet.lock_feet`) when ``options.feet`` is
    ``"lock"``, or is None and the default is; ``info`` then gives the foot skating (cm/s) before and after.
    The default is the method's (:attr:`Method.feet`): ``"free"`` for the learned methods and splines, as
    measured on held-out styles locking lowers their foot skating by 5-15 % only and can raise the gap error by
    up to 19 % (docs/feet.md); ``"lock"`` for ``match``, whose real steps it keeps planted (docs/match.md), and
    for any result built on matched real motion (``info`` has ``matched_gaps``: a gan on a matched base, whose
    skating locking lowers by 13-23 % and gap error by up to 2 %, docs/gan.md). The feet are locked in
    ``result``'s own arrays unless they may be ``source``'s (the input's) too."""
    default = "lock" if "matched_gaps" in result.info else m.feet
    if (options.feet or default) != "lock":
        return result

    from keyfill.characters.feet import lock_feet
    from keyfill.characters.humanoid import read_rig_map
    from keyfill.characters.retarget import make_rig

    rig_map = read_rig_map(options.rig_map) if options.rig_map is not None else None
    try:
        rig = make_rig(result.motion.skeleton, rig_map=rig_map)
    except DataError as e:
        raise DataError(f"feet lock needs a skeleton with legs: {e}", params=("feet",) + e.params) from None
    locked, report = lock_feet(result.motion, rig, keys, ground=options.ground,
                               in_place=_own_arrays(result.motion, source))
    cm = 100.0 * result.motion.skeleton.meters_per_unit
    before, after = report["skating_before"], report["skating_after"]
    result.info.update({"feet": "lock", "foot_skating_cm_s": {
        "before": None if before is None else before * cm, "after": None if after is None else after * cm},
        "contact_intervals": report["intervals"]})
    return Completion(locked, result.info)


def _own_arrays(out: Motion, source: Motion) -> bool:
    """Whether a completion's ``out`` shares no array with its input ``source``: a later step (the guard's
    fallback, the feet lock) may then change it in place instead of copying a long take."""
    import numpy as np

    return not any(np.may_share_memory(a, b) for a in (out.rotations, out.positions)
                   for b in (source.rotations, source.positions))


def _on_model_rig(m: Method, motion: Motion, keys: Keys, options: CompleteOptions) -> Completion | None:
    """For a ``humanoid`` method, the completion through :mod:`keyfill.learn.rig_bridge` when ``motion`` has
    another skeleton or frame rate than the model; None when the model serves it as it is."""
    from keyfill.learn.onnx import is_graph

    if not m.humanoid or is_graph(options.model):
        return None
    from keyfill.learn import rig_bridge

    model = model_served(m, options, keys)
    if not rig_bridge.needed(model, motion, keys):
        return None
    # the feet are locked once, and unfamiliar gaps filled once, on the motion's own rig
    inner = replace(options, feet="free", guard="off" if options.guard == "off" else "warn")
    return rig_bridge.complete_on_model_rig(motion, keys, lambda mm, kk: complete(mm, kk, m.name, inner),
                                            model, options, hint=getattr(m.implementation(), "TRAIN_HINT", ""))


def humanoid_fit(motion: Motion, rig_map: dict | None = None, label: str = "the skeleton"):
    """``(roles, models)``: the humanoid roles of ``motion``'s skeleton (a :class:`~keyfill.characters.humanoid.RoleMap`,
    with ``rig_map`` as :func:`~keyfill.characters.humanoid.map_roles` takes it) and how the shipped model of
    each ``humanoid`` method fits it, for ``keyfill info --rig``. Reads model configs, no weights, no torch.

    ``models``: method name -> ``{"model": folder name or None, "model_fps": float, "fits": "own skeleton" |
    "through retargeting" | "no", "reason": why not (only with "no"), "resampled": whether the motion's frame
    rate differs from the model's (its keys are then placed on the model's frames)}``.

    Raises the mapper's :class:`~keyfill.errors.DataError` (``params="rig_map"``) when the skeleton is no
    humanoid it can resolve; ``label`` names it there.
    """
    import numpy as np

    from keyfill.characters.humanoid import map_roles
    from keyfill.characters.retarget import make_rig
    from keyfill.errors import DataError
    from keyfill.learn import rig_bridge

    roles = map_roles(motion.skeleton, rig_map, label=label)
    if motion.num_frames == 0:  # the rest pose stands for the frames the file lacks
        sk = motion.skeleton
        motion = Motion(sk, motion.fps, np.tile([1.0, 0.0, 0.0, 0.0], (1, sk.num_joints, 1)), sk.offsets[None].copy())
    try:
        make_rig(motion.skeleton, roles=roles, label=label)
        own_problem = None
    except DataError as e:
        own_problem = str(e)
    models: dict[str, dict] = {}
    for m in METHODS.values():
        if not m.humanoid:
            continue
        path = m.default_model()
        if path is None:
            from keyfill.learn.installed_models import HOW_TO_GET

            models[m.name] = {"model": None, "fits": "no", "reason": f"its shipped models are not installed: {HOW_TO_GET}"}
            continue
        try:
            served = model_served(m, CompleteOptions())
        except ModelError as e:
            models[m.name] = {"model": path.name, "fits": "no", "reason": str(e)}
            continue
        entry = {"model": path.name, "model_fps": served.fps,
                 "resampled": bool(abs(motion.fps - served.fps) > 1e-9 * served.fps)}
        if rig_bridge.fits(served, motion, 0):
            entry["fits"] = "own skeleton"
        else:
            try:
                make_rig(served.skeleton, label="the model's skeleton")
                if own_problem is not None:
                    raise DataError(own_problem)
                entry["fits"] = "through retargeting"
            except DataError as e:
                entry.update(fits="no", reason=str(e))
        models[m.name] = entry
    return roles, models


def complete_many(jobs: list[tuple[Motion, Keys]], method: str = "cubic",
                  options: CompleteOptions | None = None) -> list[Completion | KeyfillError]:
    """:func:`complete` for many ``(motion, keys)`` at once: a :class:`Completion` or the error, per job.

    A method whose module has ``complete_many(jobs, options)`` (same return)
    completes the jobs together (the ARNN runs them as one batch through its
    network); the others are completed one by one. The model is loaded once.
    An error of one job (bad keys, another skeleton) is that job's result;
    an error of the method or model (a model of another kind) is raised.
    """
    options = options or CompleteOptions()
    m = get(method)
    options = checked_options(m, options)
    if m.learned and (options.library if m.library else options.model) is None and m.default_model() is None:
        raise _no_model(m)
    results: list = [None] * len(jobs)
    ready = []
    for i, (motion, keys) in enumerate(jobs):
        try:
            ready.append((i, motion, checked_keys(m, motion, keys)))
        except KeyfillError as e:
            results[i] = e
    if m.humanoid:  # motions of other rigs or frame rates go through the bridge one by one
        direct = []
        for i, motion, keys in ready:
            try:
                bridged = _on_model_rig(m, motion, keys, options)
                if bridged is not None:
                    bridged = with_feet(m, guarded(m, motion, keys, options, bridged), keys, options, motion)
                    bridged.info = reported(m, motion, keys, options, bridged)
            except KeyfillError as e:
                bridged = e
            if bridged is None:
                direct.append((i, motion, keys))
            else:
                results[i] = bridged
        ready = direct
    graph = _graph(m, options)
    many = getattr(m.implementation(), "complete_many", None) if m.learned and graph is None else None
    if graph is not None:
        outs = importlib.import_module(m.onnx).complete_graph(
            [(motion, keys) for _, motion, keys in ready], options, graph) if ready else []
    elif many is not None:
        outs = many([(motion, keys) for _, motion, keys in ready], options) if ready else []
    else:
        outs = [_one(m.function(), motion, keys, options) for _, motion, keys in ready]
    for (i, motion, keys), out in zip(ready, outs):
        if isinstance(out, Completion):
            try:
                out = with_feet(m, guarded(m, motion, keys, options, out), keys, options, motion)
            except KeyfillError as e:
                results[i] = e
                continue
            out.info = reported(m, motion, keys, options, out)
        results[i] = out
    return results


def _graph(m: Method, options: CompleteOptions):
    """The exported graph that completes for ``m`` under ``options.runtime``, or None (the torch path)."""
    from keyfill.learn.onnx import select

    return select(m, options.model, options.runtime, options.device)


def _one(function, motion, keys, options):
    try:
        return function(motion, keys, options)
    except KeyfillError as e:
        return e
