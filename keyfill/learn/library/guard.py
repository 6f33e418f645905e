"""The guard: per gap, how familiar the keys and the output are to what a model or library knows.

A learned human method knows the poses of its corpus (a model folder's pose index, written by ``keyfill
train`` or ``keyfill library index``) or of its library (``match``). For every gap between two keys,
:func:`scores` measures the distance of the two keys' poses and of the output's poses in the gap to the
nearest known pose, in the corpus's spreads (:class:`keyfill.learn.library.index.PoseIndex`), and takes the
largest. A gap above the index's threshold is *unfamiliar*: a motion the model never saw (a person sitting
down, lying, climbing), where its in-betweens are guesses. :func:`fall_back` fills such gaps with the cubic
spline through the same keys.

The threshold (:data:`keyfill.learn.library.index.THRESHOLD`, in spreads) is calibrated on held-out clips (docs/match.md, "The guard"):
on held-out styles of the actions a corpus holds it changes few gaps, on actions it lacks most.
"""

from __future__ import annotations

from itertools import pairwise
from pathlib import Path

import numpy as np

from keyfill import interpolate
from keyfill import rotations as R
from keyfill.learn.library.features import Frames, describe
from keyfill.learn.library.index import PoseIndex, index_step, subsampled
from keyfill.motion import Keys, Motion

#: every how many frames of a gap the output's poses are scored
OUTPUT_STEP = 3
#: poses scored at a time (memory: a chunk's features and candidates, about 14 MB, not a long take's)
CHUNK = 4096
MODES = ("fallback", "warn", "off")


def scores(index: PoseIndex, frames: Frames, motion: Motion, keys: Keys, output: Motion) -> np.ndarray:
    """``(K - 1,)`` familiarity score of every gap (the module docstring): ``motion``'s keys and ``output``'s
    frames between them, both on the index's skeleton."""
    k = keys.frames
    inner = np.concatenate([np.arange(a + 1, b, OUTPUT_STEP) for a, b in pairwise(k)] or [np.zeros(0, int)])
    score_k = familiarity(index, frames, motion, k)
    out = np.maximum(score_k[:-1], score_k[1:])
    if len(inner):
        score_i = familiarity(index, frames, output, inner)
        gap_of = np.searchsorted(k, inner, side="right") - 1
        np.maximum.at(out, gap_of, score_i)
    return out


def familiarity(index: PoseIndex, frames: Frames, motion: Motion, rows: np.ndarray) -> np.ndarray:
    """``(N,)`` :meth:`PoseIndex.familiarity` of ``motion``'s frames ``rows (N,)``, :data:`CHUNK` at a time."""
    out = np.empty(len(rows))
    for a in range(0, len(rows), CHUNK):
        part = rows[a: a + CHUNK]
        out[a: a + CHUNK] = index.familiarity(describe(motion.frames(part).world_positions(), frames)[0])
    return out


def report(index: PoseIndex, mode: str, keys: Keys, gap_scores: np.ndarray) -> dict:
    """The JSON-ready guard block of a completion's info (docs/json.md)."""
    k = keys.frames
    unfamiliar = gap_scores > index.threshold
    return {"mode": mode, "index": index.name, "threshold": index.threshold,
            "unfamiliar": int(unfamiliar.sum()), "gaps_scored": len(gap_scores),
            "filled_by_cubic": int(unfamiliar.sum()) if mode == "fallback" else 0,
            "gaps": [{"keys": [int(a), int(b)], "score": round(float(s), 3), "unfamiliar": bool(u)}
                     for a, b, s, u in zip(k[:-1], k[1:], gap_scores, unfamiliar)]}


def fall_back(output: Motion, motion: Motion, keys: Keys, unfamiliar: np.ndarray, in_place: bool = False) -> Motion:
    """``output`` with the frames strictly inside every unfamiliar gap (``unfamiliar (K - 1,)`` bool) taken
    from the cubic spline through ``motion``'s keys; keys and every other frame unchanged. With ``in_place``
    the spline is written into ``output``'s own arrays (for a caller that owns them: a long take needs no copy)."""
    if not unfamiliar.any():
        return output
    rot, pos = (output.rotations, output.positions) if in_place else (np.array(output.rotations),
                                                                       np.array(output.positions))
    k = keys.frames
    signs = R.quat_continuous_np(motion.rotations[k], axis=0)  # the keys as the whole spline sees them
    for g in np.flatnonzero(unfamiliar):
        a, b = int(k[g]) + 1, int(k[g + 1])
        if a < b:  # the gap's piece of the spline, from the keys around it alone
            rot[a:b], pos[a:b] = interpolate.cubic_span(motion, k, signs, a, b)
    return output.replace(rotations=rot, positions=pos)


def corpus_pose_index(corpus, name: str) -> PoseIndex:
    """The pose index of a training corpus (:class:`keyfill.learn.corpus.Corpus`; :func:`subsampled`). A
    :class:`~keyfill.errors.DataError` when its skeleton is no humanoid."""
    from keyfill.kinematics import fk
    from keyfill.learn.library.features import describe
    from keyfill.learn.library.store import frames_of

    sk = corpus.skeleton
    frames = frames_of(sk)
    rows = np.arange(0, len(corpus.quats), index_step(len(corpus.quats)))
    pos = np.broadcast_to(sk.offsets, (len(rows),) + sk.offsets.shape).copy()
    pos[:, 0] = corpus.root[rows]
    feats = describe(fk(np.asarray(corpus.quats[rows]), pos, sk.parents)[1], frames)[0]
    return subsampled(feats, np.searchsorted(corpus.starts, rows, side="right") - 1, name)


def model_pose_index(model, clips, include=(), exclude=()) -> dict:
    """Write the pose index of ``clips`` (the clips a model was trained on) into the model folder ``model``:
    ``{"path", "poses", "spread_m"}``. Clips of other humanoid rigs are retargeted onto the model's skeleton."""
    from keyfill.learn.library.store import clip_files, frames_of, served_by
    from keyfill.learn.rig_bridge import on_model_skeleton, served

    model_skeleton = served(model).skeleton
    frames = frames_of(model_skeleton)
    target = served_by(model_skeleton, 30.0)
    feats, clip_of = [], []
    from keyfill import io
    from keyfill.learn.library.features import describe

    for c, f in enumerate(clip_files(clips, include, exclude)):
        motion = on_model_skeleton(io.load(f).replace(keys=None), target, what=f.name)
        feats.append(describe(motion.world_positions(), frames)[0].astype(np.float32))
        clip_of.append(np.full(len(feats[-1]), c, dtype=np.int32))
    index = subsampled(np.concatenate(feats), np.concatenate(clip_of), Path(model).name)
    return {"path": index.save(model), "poses": len(index.features), "spread_m": index.spread}


def write_corpus_index(corpus, folder) -> None:
    """Beside a human model's weights (``folder``), the pose index of its training corpus; nothing for a corpus
    that is no clips of a humanoid (the lamp's, or None)."""
    from keyfill.errors import DataError

    if corpus is None or not hasattr(corpus, "quats"):
        return
    try:
        corpus_pose_index(corpus, folder.name).save(folder)
    except DataError:
        return
