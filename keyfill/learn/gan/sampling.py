"""Training data of both stages: key layouts for long sequences, real crops, whole clips (section 3.7, Appendix C).

All randomness comes from the ``numpy.random.Generator`` passed in.

**Generator sequences** (:func:`sample_keys`) are ``N`` frames long with keys at
frame 0 and ``N - 1`` and gaps drawn uniformly from ``[min_gap, max_gap]``
(the last gap cut to fit). Walking from the first key to the last (Appendix C):

* a gap of at most ``short_gap_seconds`` takes the next key from the same clip,
  ``gap`` frames further on, keeping the clip's placement: both keys and the
  root displacement between them are real. When the clip ends sooner, the gap
  is cut to what the clip holds; when the key sits on the clip's last frame,
  the gap is redrawn longer than the short limit and becomes a jump (below),
  or, near the end of the sequence where no longer gap fits, a short jump;
* a longer gap jumps to another clip with probability ``gap / max_gap`` (and
  always when the clip ends sooner): the next key is a random frame of a random
  other clip, turned to a random heading, its root placed a random distance
  ``U(0, 1) * jump_speed * gap / fps`` from the previous key's root in a random
  ground direction (so probability and distance both grow with the gap), its
  height its own. Otherwise it stays in the clip as a short gap does.

Bandai-Namco clips last about 5 s, so a 1,024-frame sequence gets its keys from
several clips.

**Real sequences for the discriminator** (:func:`real_crops`) are random crops
of ``real_frames`` frames of single clips (clips shorter than that are not
used), each turned to a random heading. The fake sequences the discriminator
sees are crops of the same length from the generated sequences, at starts
drawn by :func:`crop_starts`, so both kinds have the same length and borders.

**Path predictor batches** (:func:`clip_batch`) are whole clips (crops of at
most ``max_frames`` for long ones), turned to random headings and padded at
the end by repeating the last frame; ``lengths`` tells the loss where each
ends.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from keyfill.errors import DataError
from keyfill.learn.gan.dense import centre_keys
from keyfill.learn.gan.poses import ClipPool, turn


@dataclass(frozen=True)
class KeyLayout:
    """Keys of one training sequence.

    Attributes:
        frames: ``(K,)`` increasing key frames, ``frames[0] = 0``, ``frames[-1] = N - 1``.
        poses: ``(K, J, 3)`` metres: row 0 the root (re-centred on the keys' mean
            ground position), rows 1.. root-relative joint positions.
        clips: ``(K,)`` the clip each key came from (for tests and statistics).
    """

    frames: np.ndarray
    poses: np.ndarray
    clips: np.ndarray


def _ground_mask(up_axis: str) -> np.ndarray:
    m = np.ones(3, dtype=bool)
    m[1 if up_axis == "Y" else 2] = False
    return m


def sample_keys(pool: ClipPool, rng: np.random.Generator, frames: int, min_gap: int, max_gap: int,
                short_gap_seconds: float = 3.0, jump_speed: float = 1.5) -> KeyLayout:
    """One :class:`KeyLayout` of a ``frames``-frame sequence (see the module docstring)."""
    lengths = pool.lengths
    if len(pool) == 0:
        raise DataError("no clips to sample keys from")
    short = max(round(short_gap_seconds * pool.fps), 0)
    ground = _ground_mask(pool.up_axis)

    c = int(rng.integers(len(pool)))
    f = int(rng.integers(lengths[c]))
    heading = float(rng.uniform(-np.pi, np.pi))
    # the clip's placement: world root = turn(root) + shift (shift is zero on the up axis)
    shift = -turn(pool.root[c][f], heading, pool.up_axis) * ground
    t = 0
    frames_out, poses, clips = [0], [], [c]

    def pose_in_clip(c, f):
        pose = turn(pool.relative[c][f].astype(np.float64), heading, pool.up_axis)
        pose[0] = turn(pool.root[c][f], heading, pool.up_axis) + shift
        return pose

    poses.append(pose_in_clip(c, f))
    while t < frames - 1:
        g = min(int(rng.integers(min_gap, max_gap + 1)), frames - 1 - t)
        left = int(lengths[c]) - 1 - f  # frames the clip still holds after f
        jump = False
        if g <= short:
            if g > left:
                if left >= min_gap:
                    g = left
                else:
                    jump = True
                    lo = min(short + 1, frames - 1 - t)
                    g = int(rng.integers(lo, max(min(max_gap, frames - 1 - t), lo) + 1))
        else:
            jump = g > left or rng.random() < g / max_gap
        if jump:
            others = np.flatnonzero(np.arange(len(pool)) != c) if len(pool) > 1 else np.arange(len(pool))
            c = int(rng.choice(others))
            f = int(rng.integers(lengths[c]))
            heading = float(rng.uniform(-np.pi, np.pi))
            dist = rng.uniform() * jump_speed * g / pool.fps
            ang = rng.uniform(-np.pi, np.pi)
            step = turn(np.array([0.0, 0.0, 1.0]) if pool.up_axis == "Y" else np.array([0.0, 1.0, 0.0]), ang,
                        pool.up_axis) * dist
            prev_root = poses[-1][0]
            anchor = prev_root * ground + step
            shift = (anchor - turn(pool.root[c][f], heading, pool.up_axis)) * ground
        else:
            f += g
        t += g
        frames_out.append(t)
        poses.append(pose_in_clip(c, f))
        clips.append(c)
    poses_arr, _ = centre_keys(np.array(poses), pool.up_axis)
    return KeyLayout(np.array(frames_out, dtype=np.int64), poses_arr, np.array(clips, dtype=np.int64))


def real_crops(pool: ClipPool, rng: np.random.Generator, count: int, frames: int) -> np.ndarray:
    """``(count, frames, J, 3)`` float32 root-relative positions: random crops of clips, random headings."""
    usable = np.flatnonzero(pool.lengths >= frames)
    if len(usable) == 0:
        raise DataError(f"no clip has the {frames} frames a real sequence for the discriminator needs "
                        f"(the longest has {int(pool.lengths.max(initial=0))}); lower real_frames")
    out = []
    for _ in range(count):
        c = int(rng.choice(usable))
        s = int(rng.integers(pool.lengths[c] - frames + 1))
        out.append(turn(pool.relative[c][s : s + frames], rng.uniform(-np.pi, np.pi), pool.up_axis))
    return np.array(out, dtype=np.float32)


def crop_starts(rng: np.random.Generator, rows: int, crops: int, frames: int, length: int) -> np.ndarray:
    """``(rows, crops)`` start frames of crops of ``length`` frames from sequences of ``frames`` frames."""
    return rng.integers(0, frames - length + 1, size=(rows, crops))


def clip_batch(pool: ClipPool, rng: np.random.Generator, count: int, max_frames: int, min_frames: int = 2):
    """``(relative (B, T, J, 3) float32, root (B, T, 3) float32, lengths (B,))`` of ``count`` random whole clips.

    Each clip is turned to a random heading and its root path starts at the
    ground origin; clips longer than ``max_frames`` are cropped at random;
    rows are padded to the longest by repeating their last frame.
    """
    usable = np.flatnonzero(pool.lengths >= min_frames)
    if len(usable) == 0:
        raise DataError(f"no clip has at least {min_frames} frames")
    rels, roots = [], []
    ground = _ground_mask(pool.up_axis)
    for _ in range(count):
        c = int(rng.choice(usable))
        n = int(pool.lengths[c])
        s = int(rng.integers(n - max_frames + 1)) if n > max_frames else 0
        e = min(n, s + max_frames)
        h = rng.uniform(-np.pi, np.pi)
        root = turn(pool.root[c][s:e], h, pool.up_axis)
        root = root - root[0] * ground
        rels.append(turn(pool.relative[c][s:e], h, pool.up_axis))
        roots.append(root)
    lengths = np.array([len(r) for r in roots], dtype=np.int64)
    T = int(lengths.max())
    rel = np.stack([np.concatenate([r, np.repeat(r[-1:], T - len(r), 0)]) for r in rels]).astype(np.float32)
    root = np.stack([np.concatenate([r, np.repeat(r[-1:], T - len(r), 0)]) for r in roots]).astype(np.float32)
    return rel, root, lengths
