"""The guard: per gap, how familiar the keys and the output are to what a model or library knows.

A learned human method knows the poses of its corpus (a model folder's pose index, written by ``keyfill
train`` or ``keyfill library index``) or of its library (``match``). For every gap between two keys,
:func:`scores` measures the distance of the two keys' poses and of the output's poses in the gap to the
nearest known pose, in the corpus's spreads (:class:`keyfill.learn.library.index.PoseIndex`), and takes the
largest. A gap above the index's threshold is *unfamiliar*: a motion the model never saw (a person sitting
down, lying, climbing), where its in-betweens are guesses. :func:`fall_back` fills such gaps with the cubic
spline through the same keys.

The threshold (:data:`THRESHOLD`, in spreads) is calibrated on held-out clips (docs/match.md, "The guard"):
on held-out styles of the actions a corpus holds it changes few gaps, on actions it lacks most.
"""

from __future__ import annotations

from itertools import pairwise

import numpy as np

from keyfill import interpolate
from keyfill.learn.library.features import Frames, describe
from keyfill.learn.library.index import PoseIndex
from keyfill.motion import Keys, Motion

#: a gap whose largest distance to the known poses exceeds this many spreads is unfamiliar
THRESHOLD = 12.0
#: every how many frames of a gap the output's poses are scored
OUTPUT_STEP = 3
MODES = ("fallback", "warn", "off")


def scores(index: PoseIndex, frames: Frames, motion: Motion, keys: Keys, output: Motion) -> np.ndarray:
    """``(K - 1,)`` familiarity score of every gap (the module docstring): ``motion``'s keys and ``output``'s
    frames between them, both on the index's skeleton."""
    k = keys.frames
    inner = np.concatenate([np.arange(a + 1, b, OUTPUT_STEP) for a, b in pairwise(k)] or [np.zeros(0, int)])
    feats_k = describe(motion.frames(k).world_positions(), frames)[0]
    score_k = index.familiarity(feats_k)
    out = np.maximum(score_k[:-1], score_k[1:])
    if len(inner):
        score_i = index.familiarity(describe(output.frames(inner).world_positions(), frames)[0])
        gap_of = np.searchsorted(k, inner, side="right") - 1
        np.maximum.at(out, gap_of, score_i)
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


def fall_back(output: Motion, motion: Motion, keys: Keys, unfamiliar: np.ndarray) -> Motion:
    """``output`` with the frames strictly inside every unfamiliar gap (``unfamiliar (K - 1,)`` bool) taken
    from the cubic spline through ``motion``'s keys; keys and every other frame unchanged."""
    if not unfamiliar.any():
        return output
    spline = interpolate.cubic(motion, keys)
    rot, pos = np.array(output.rotations), np.array(output.positions)
    k = keys.frames
    for g in np.flatnonzero(unfamiliar):
        a, b = int(k[g]) + 1, int(k[g + 1])
        rot[a:b], pos[a:b] = spline.rotations[a:b], spline.positions[a:b]
    return output.replace(rotations=rot, positions=pos)
