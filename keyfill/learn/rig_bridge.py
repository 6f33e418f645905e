"""The shipped human models on any humanoid rig and frame rate: retarget the keys in, complete, retarget back.

A human model knows one skeleton and one frame rate. :func:`complete_on_model_rig` lets it complete a motion
of any humanoid rig (:mod:`keyfill.characters.humanoid`) at any frame rate:

1. the key frames are retargeted onto the model's skeleton (:func:`keyfill.characters.retarget.retarget`);
2. the keys are placed on the model's frame grid: each gap of ``g`` frames at the motion's rate becomes
   ``max(1, round(g * model_fps / fps))`` model frames, so every key lands on a model frame (a time warp of
   at most half a model frame per gap);
3. the model completes those keys (through :func:`keyfill.learn.registry.complete`, so the method, model,
   runtime and seed options apply unchanged);
4. the result is retargeted back onto the motion's skeleton and resampled at the motion's own frames
   (slerp of rotations, lerp of translations, within each gap's time warp);
5. joints the model has no role for (fingers, eyes, twist bones, extra helper joints) take the C1 cubic
   spline through the motion's own keys, and so do translations other than the hips';
6. the keys are made exact on the motion's own channels (:func:`keyfill.learn.exact_keys.snap_to_keys`).

The output keeps the motion's skeleton, channel layout, Euler orders, frame rate and frame count. Partial keys
keep their kind; a model joint is keyed where the motion's joint of its role is.

Steps 4 and 5 are made a block of the motion's frames at a time (:func:`resampled`, :func:`keyfill.interpolate.cubic_span`) into
the result's arrays, and step 6 corrects them in place: a long take costs the motion's arrays, the model's
completion of it (on the model's skeleton) and the result's, not copies of each step (issue 44).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from keyfill import interpolate
from keyfill import rotations as R
from keyfill.characters.retarget import Rig, make_rig, retarget
from keyfill.errors import DataError, ModelError
from keyfill.learn.corpus import model_hierarchy
from keyfill.learn.windows import SignChain
from keyfill.motion import Keys, Motion, Skeleton


@dataclass(frozen=True, eq=False)
class Served:
    """What a human model serves: its ``skeleton`` (as its config records it), its ``fps`` and whether its
    corpus ``folded`` a static top joint into the hips."""

    skeleton: Skeleton
    fps: float
    folded: bool


def fits(served: Served, motion: Motion, frame: int) -> bool:
    """``motion`` is on the model's own skeleton (as the model checks it, :func:`keyfill.learn.corpus.model_hierarchy`:
    the same joints and parents, bones within 1 % at ``frame``): no retargeting needed."""
    try:
        model_hierarchy(served.skeleton, served.folded, motion.skeleton, motion.rotations[frame: frame + 1],
                        motion.positions[frame: frame + 1])
    except ModelError:
        return False
    return True


_RIGS: dict[str, Rig] = {}  # what make_rig found, by the skeleton's and rig map's JSON


def _rig(skeleton: Skeleton, rig_map: dict | None = None, label: str = "the skeleton") -> Rig:
    """:func:`make_rig` of ``skeleton``, once per skeleton (all it reads: hierarchy, offsets, channels, up axis
    and end sites), rig map and process: finding the roles and standing the reference T-pose take about 15 ms
    for a 65-joint rig, as long as the bridge's other work. The rig holds ``skeleton`` itself."""
    import json

    key = json.dumps([skeleton.to_json(), [[int(j), np.asarray(o, dtype=float).tolist()] for j, o in skeleton.end_sites],
                      rig_map], sort_keys=True)
    if key not in _RIGS:
        if len(_RIGS) >= 16:
            _RIGS.pop(next(iter(_RIGS)))
        _RIGS[key] = make_rig(skeleton, rig_map=rig_map, label=label)
    return replace(_RIGS[key], skeleton=skeleton)


def rigs(motion: Motion, model: Served, rig_map: dict | None, frame: int, hint: str,
         what: str = "the motion") -> tuple[Rig, Rig]:
    """``(the motion's rig, the model's rig)``. When either skeleton is no humanoid, the model's own error
    for another skeleton (``what`` has another skeleton ..., ending with ``hint``), followed by why the motion
    cannot be retargeted.

    Each rig is computed once per skeleton, rig map and process."""
    try:
        return _rig(motion.skeleton, rig_map), _rig(model.skeleton, label="the model's skeleton")
    except DataError as e:
        try:
            model_hierarchy(model.skeleton, model.folded, motion.skeleton, motion.rotations[frame: frame + 1],
                            motion.positions[frame: frame + 1], what=what, hint=hint)
        except ModelError as mismatch:
            raise ModelError(f"{mismatch}; nor can it be retargeted: {e}", params=e.params) from None
        raise


def on_model_skeleton(motion: Motion, model: Served, rig_map: dict | None = None, hint: str = "",
                      what: str = "the motion") -> Motion:
    """``motion`` as it is when the model serves its skeleton, else retargeted onto the model's skeleton (every
    frame, at the motion's own rate): how a Motion DNA clip of any humanoid reaches a model."""
    if fits(model, motion, 0):
        return motion
    source, target = rigs(motion, model, rig_map, 0, hint, what)
    return retarget(motion.replace(keys=None), source, target)


def model_frames(keys: np.ndarray, fps: float, model_fps: float) -> np.ndarray:
    """``(K,)`` model frames of ``keys (K,)`` given at ``fps``: the first key at 0, each gap of ``g`` frames
    ``max(1, round(g * model_fps / fps))`` model frames long."""
    gaps = np.maximum(1, np.rint(np.diff(keys) * (model_fps / fps)).astype(np.int64))
    return np.concatenate([[0], np.cumsum(gaps)]).astype(np.int64)


def _held(poses_rot: np.ndarray, poses_pos: np.ndarray, frames: np.ndarray, count: int):
    """``count`` frames holding each of the ``K`` poses from its frame in ``frames`` on."""
    src = np.searchsorted(frames, np.arange(count), side="right") - 1
    return poses_rot[src], poses_pos[src]


def model_times(model_keys: np.ndarray, keys: np.ndarray, num_frames: int) -> np.ndarray:
    """``(F,)`` the model frame (fractional) of each frame ``0 .. num_frames-1`` of a motion whose keys ``keys (K,)``
    are at ``model_keys (K,)`` on the model's grid: each gap's frames map linearly onto its model frames;
    frames before the first key and after the last map onto it."""
    t = np.clip(np.arange(num_frames), keys[0], keys[-1])
    s, u = interpolate.segment_coordinates(num_frames, keys)
    return model_keys[s] + np.where(t >= keys[-1], 1.0, u) * (model_keys[s + 1] - model_keys[s])


def resampled(filled: Motion, times: np.ndarray, back: tuple[Rig, Rig] | None = None):
    """``filled`` (a motion on the model's grid) at the model times ``times (F,)`` (:func:`model_times`): slerp of
    rotations, lerp of translations between the two model frames around each time
    (:func:`keyfill.interpolate.at_times`), with ``back`` = ``(model's rig, motion's rig)`` retargeted onto the
    motion's rig first (:func:`keyfill.characters.retarget.retarget`, whose signs are continuous along the whole of
    ``filled``).

    Yields ``(a, b, rotations (b - a, J, 4), positions (b - a, J, 3))`` for the frames ``a .. b-1`` of ``times``,
    :data:`keyfill.interpolate.BLOCK` frames at a time: memory is a block's, of ``filled``'s frames and ours.
    ``times`` must not decrease.
    """
    M = filled.num_frames
    prev = None  # (first model frame, model frames retargeted and signed as the whole take's) of the last block
    for a in range(0, len(times), interpolate.BLOCK):
        b = min(len(times), a + interpolate.BLOCK)
        t = times[a:b]
        hi = min(int(np.floor(t[-1])) + 1, M - 1)
        # from the last block's last model frame on (every frame counts for the signs), or from the first
        first = 0 if prev is None else min(int(np.floor(t[0])), prev[0] + len(prev[1]) - 1)
        part = filled.replace(rotations=filled.rotations[first: hi + 1], positions=filled.positions[first: hi + 1])
        rot = part.rotations
        if back is not None:
            part = retarget(part, *back)
            rot = part.rotations
            if prev is not None:  # the part's first frame is one the last block signed: continue its signs
                seen = prev[1][first - prev[0]]
                rot *= np.where(np.sum(seen * rot[0], axis=-1) < 0, -1.0, 1.0)[:, None]
        prev = (first, rot)
        yield (a, b, *interpolate.at_times(rot, part.positions, t - first))


def _model_keys(keys: Keys, frames: np.ndarray, source: Rig, target: Rig) -> Keys:
    """``keys`` on the model's grid (``frames``) and skeleton: a model joint is keyed where the motion's joint
    of its role is (any of a chain's joints, for the spine and neck)."""
    if keys.mask is None:
        return Keys(frames, given=keys.given)
    mask = np.zeros((len(frames), target.skeleton.num_joints), dtype=bool)
    for role, j in target.roles.limbs.items():
        if role in source.roles.limbs:
            mask[:, j] = keys.mask[:, source.roles.limbs[role]]
    for name, chain in target.chains().items():
        keyed = keys.mask[:, source.chains()[name]].any(axis=1)
        mask[:, chain] = keyed[:, None]
    return Keys(frames, mask=mask, given=keys.given)


def mapped_joints(rig: Rig) -> np.ndarray:
    """``(J,)`` bool: the joints of ``rig`` that play a role."""
    out = np.zeros(rig.skeleton.num_joints, dtype=bool)
    out[[j for chain in rig.chains().values() for j in chain]] = True
    out[list(rig.roles.limbs.values())] = True
    return out


def served(model_path) -> Served:
    """What the model folder ``model_path`` serves, from its config (no weights are read); a model that
    records no frame rate is taken to be at 30 fps (the Bandai-Namco corpora's)."""
    from keyfill.learn.modelfile import read_config

    config = read_config(model_path)
    try:
        return Served(Skeleton.from_json(config["skeleton"]), float(config.get("fps", 30.0)),
                      bool(config.get("folded_root", False)))
    except (KeyError, TypeError, ValueError, DataError) as e:
        raise ModelError(f"{model_path}: damaged model config ({e})") from None


def needed(served: Served, motion: Motion, keys: Keys) -> bool:
    """Whether ``motion`` needs the bridge: another skeleton or another frame rate than the model's."""
    return abs(motion.fps - served.fps) > 1e-9 * served.fps or not fits(served, motion, int(keys.frames[0]))


def complete_on_model_rig(motion: Motion, keys: Keys, complete, model: Served, options, hint: str = ""):
    """Complete ``motion`` between ``keys`` with a model that serves ``model`` (the module docstring).

    Args:
        complete: ``(model_motion, model_keys) -> Completion`` on the model's skeleton and frame rate.
        options: the :class:`~keyfill.learn.completion.CompleteOptions`; ``rig_map`` (a TOML file of role ->
            joint name(s)) overrides the automatic role mapping of ``motion``'s skeleton, ``exact_keys`` makes
            the keys exact on the motion's own channels.
        hint: ends the error for a motion that is neither on the model's skeleton nor a humanoid (how to train
            a model for it).

    Returns a :class:`~keyfill.learn.completion.Completion`.
    """
    from keyfill.characters.humanoid import read_rig_map
    from keyfill.learn.completion import Completion
    from keyfill.learn.exact_keys import snap_to_keys

    k = keys.frames
    same = fits(model, motion, int(k[0]))
    model_fps = model.fps
    if not same:
        rig_map = read_rig_map(options.rig_map) if options.rig_map is not None else None
        source, target = rigs(motion, model, rig_map, int(k[0]), hint)
    frames = model_frames(k, motion.fps, model_fps)
    posed = motion.replace(keys=None).frames(k)
    if not same:
        posed = retarget(posed, source, target)
    rot, pos = _held(posed.rotations, posed.positions, frames, int(frames[-1]) + 1)
    model_motion = Motion(posed.skeleton, model_fps, rot, pos)
    if same:
        model_keys = Keys(frames, mask=keys.mask, given=keys.given)
    else:
        model_keys = _model_keys(keys, frames, source, target)
    done = complete(model_motion, model_keys)
    del model_motion, rot, pos  # the completion read its keys
    # back on the motion's rig and frames, a block of frames at a time into the result's arrays: joints without
    # a role, and translations but the hips', from the cubic spline through the motion's own keys
    rotations, positions = np.empty(motion.rotations.shape), np.empty(motion.positions.shape)
    signs = SignChain()
    keep = None if same else ~mapped_joints(source)
    spline_keys = None if same else R.quat_continuous_np(motion.rotations[k], axis=0)  # as the whole spline's
    times = model_times(frames, k, motion.num_frames)
    for a, b, rot, pos in resampled(done.motion.replace(keys=None), times, None if same else (target, source)):
        if not same:
            spline_rot, spline_pos = interpolate.cubic_span(motion, k, spline_keys, a, b)
            rot = np.where(keep[None, :, None], spline_rot, rot)
            spline_pos[:, source.roles.hips] = pos[:, source.roles.hips]
            pos = spline_pos
        signs(rot)
        rotations[a:b], positions[a:b] = rot, pos
    result = motion.replace(rotations=rotations, positions=positions, keys=keys)
    inner = {key: v for key, v in done.info.items() if key not in ("method", "keys", "frames")}
    info = {**inner, "model_fps": float(model_fps), "model_keys": frames.tolist(), "exact_keys": bool(options.exact_keys)}
    if not same:
        info["rig"] = source.roles.to_json()
    if options.exact_keys:
        result, report = snap_to_keys(result, motion, keys, in_place=True)  # result: ours
        info.update(report)
    return Completion(result, info)


