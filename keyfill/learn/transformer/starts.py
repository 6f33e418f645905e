"""Matched starts for training the transformer (issue 46): windows of real clips with the frames between their
keys matched from a motion library, as ``--method match`` fills them.

With keys every 20-60 frames the transformer can start from match's in-between instead of its pre-fill
(:func:`keyfill.learn.transformer.model.complete_motions`' ``starts``). To learn that correction it trains on
windows whose frames between the keys are such a match (``matched_starts`` in the training settings,
:mod:`keyfill.learn.transformer.task`). A window's own clip must not be in the library it is matched from (the
search would find the clip itself): ``benchmarks/transformer_starts.py`` matches the clips of each fold
(:func:`match_windows`) against a library of the other fold's clips.

A start set is one ``.npz`` file, read without pickles. For each key spacing ``s`` (frames between keys, of
:data:`SPACINGS`), windows of ``T = s * ((window - 1) // s) + 1`` frames keyed at ``0, s, 2s, ...``:

* ``truth_q_<s> (W, T, J, 4)`` float32: the clip's local rotations in the model's hierarchy
  (:func:`keyfill.learn.windows.model_take`, signs continuous), ``truth_r_<s> (W, T, 3)``: its root positions
  (skeleton units);
* ``start_q_<s>``, ``start_r_<s>``: the same of match's in-between (seed 0, feet free), equal to the truth at
  the keys.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from keyfill.errors import DataError, UsageError
from keyfill.learn.transformer.features import apply_transform, canonical_transform, frame_kinds
from keyfill.motion import Keys, Skeleton

#: the key spacings (frames) a start set holds windows of
SPACINGS = (20, 30, 40, 60)


def layout(spacing: int, window: int) -> np.ndarray:
    """``(K,)`` the key frames of a window of at most ``window`` frames keyed every ``spacing`` frames."""
    if not 2 <= spacing <= window - 1:
        raise UsageError(f"a key spacing of {spacing} frames does not fit a {window}-frame window")
    return np.arange(0, (window - 1) // spacing * spacing + 1, spacing)


def match_windows(matcher, files: list[Path], model_skeleton: Skeleton, folded: bool, window: int, offset: int,
                  spacings=SPACINGS, progress: Callable[[int, int], None] | None = None) -> dict[str, np.ndarray]:
    """The arrays of a start set (see the module) for windows cut every ``offset`` frames from the clips
    ``files`` (on the library's skeleton and frame rate) and matched by ``matcher`` (a
    :class:`keyfill.learn.library.matcher.Matcher` of a library that holds none of them)."""
    from keyfill import io
    from keyfill.learn.windows import model_take

    out: dict[str, list] = {f"{p}_{s}": [] for s in spacings for p in ("truth_q", "truth_r", "start_q", "start_r")}
    for n, f in enumerate(files):
        motion = io.load(f).replace(keys=None)
        if abs(motion.fps - matcher.library.fps) > 1e-6:
            raise DataError(f"{f}: {motion.fps:g} fps, the library {matcher.library.fps:g}")
        for s in spacings:
            keys = layout(s, window)
            T = int(keys[-1]) + 1
            for a in range(0, motion.num_frames - T + 1, offset):
                truth = motion.frames(slice(a, a + T))
                filled, _ = matcher.fill(truth, Keys(keys), seed=0)
                for name, m in (("truth", truth), ("start", filled)):
                    q, p, _ = model_take(model_skeleton, folded, m, np.arange(T), slerped=np.arange(0),
                                         continuous=True)
                    out[f"{name}_q_{s}"].append(q.astype(np.float32))
                    out[f"{name}_r_{s}"].append(p[:, 0].astype(np.float32))
        if progress is not None:
            progress(n + 1, len(files))
    J = model_skeleton.num_joints
    arrays = {}
    for s in spacings:
        T = int(layout(s, window)[-1]) + 1
        for name, shape in (("q", (T, J, 4)), ("r", (T, 3))):
            for kind in ("truth", "start"):
                rows = out[f"{kind}_{name}_{s}"]
                arrays[f"{kind}_{name}_{s}"] = np.stack(rows) if rows else np.zeros((0,) + shape, np.float32)
    return arrays


def make_batch(model, truth_q: np.ndarray, truth_r: np.ndarray, start_q: np.ndarray,
                     start_r: np.ndarray, keys: np.ndarray):
    """:func:`keyfill.learn.transformer.task.make_batch`'s tensors for windows started from a match:
    ``truth_* (B, T, ...)`` and ``start_*`` in the canonical frame of the keys, each joint in the hemisphere
    w >= 0 at the first key (as :meth:`CompletionModel.complete_windows` reads them); the input is the start's
    features, the target the truth's."""
    import torch

    q, r = truth_q.astype(np.float64), truth_r.astype(np.float64)
    sq, sr = start_q.astype(np.float64), start_r.astype(np.float64)
    turn, shift = canonical_transform(q, r, keys, model.config.facing_axis, model.skeleton.up_axis)
    q, r = apply_transform(q, r, turn, shift)
    sq, sr = apply_transform(sq, sr, turn, shift)
    sign = np.where(q[:, keys[:1], :, :1] < 0, -1.0, 1.0)
    q, sq = q * sign, sq * sign
    dev = model.device

    def t(a):
        return torch.as_tensor(a, dtype=torch.float32, device=dev)

    gq, gr = t(q), t(r)
    T = q.shape[1]
    kinds = torch.as_tensor(frame_kinds(T, keys), device=dev).expand(len(q), T)
    return model.features.encode(t(sq), t(sr)), model.features.encode(gq, gr), gq, gr, kinds


def draw_batch(rng: np.random.Generator, sets: dict, batch_size: int, mirror, model):
    """One training batch of matched-start windows from ``sets`` (:func:`load`'s): a key spacing drawn
    uniformly, ``batch_size`` of its windows drawn without replacement, half of them (truth and start alike)
    mirrored left-right with ``mirror`` (:func:`keyfill.learn.corpus.find_mirror`'s; None: none); the tensors of
    :func:`make_batch`."""
    spacing = sorted(sets)[int(rng.integers(len(sets)))]
    tq, tr, sq, sr = sets[spacing]
    idx = np.sort(rng.choice(len(tq), min(batch_size, len(tq)), replace=False))
    tq, tr, sq, sr = (a[idx].astype(np.float64) for a in (tq, tr, sq, sr))
    if mirror is not None:
        flip = rng.random(len(idx)) < 0.5
        tq[flip], tr[flip] = mirror(tq[flip], tr[flip])
        sq[flip], sr[flip] = mirror(sq[flip], sr[flip])
    return make_batch(model, tq, tr, sq, sr, layout(spacing, tq.shape[1]))


def save(arrays: dict[str, np.ndarray], path: str | os.PathLike) -> None:
    """Write a start set (uncompressed ``.npz``)."""
    np.savez(path, **arrays)


def load(path: str | os.PathLike, joints: int) -> dict[int, tuple[np.ndarray, ...]]:
    """A start set as ``{spacing: (truth_q, truth_r, start_q, start_r)}`` (float32, see the module); a
    :class:`UsageError` naming the setting ``matched_starts`` when the file is not one for ``joints`` joints."""
    from keyfill.files import read_arrays

    what = f"training setting 'matched_starts' {path}"
    files = read_arrays(path, what, "a start set")
    sets = {}
    for key in files:
        if not key.startswith("truth_q_"):
            continue
        s = int(key.rsplit("_", 1)[1])
        parts = tuple(files.get(f"{p}_{s}") for p in ("truth_q", "truth_r", "start_q", "start_r"))
        W = len(parts[0])
        ok = all(a is not None and a.dtype == np.float32 and len(a) == W for a in parts)
        ok = ok and parts[0].shape[2:] == (joints, 4) and parts[2].shape == parts[0].shape
        ok = ok and parts[1].shape == parts[0].shape[:2] + (3,) and parts[3].shape == parts[1].shape
        if not ok:
            raise UsageError(f"{what}: spacing {s} is not {joints} joints' windows")
        if W:
            sets[s] = parts
    if not sets:
        raise UsageError(f"{what}: no window")
    return sets
