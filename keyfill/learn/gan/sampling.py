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

**In-clip windows** (:func:`clip_window`, the second recipe's
``GanConfig.in_clip_fraction`` of the steps) are ``window_frames`` long and lie
in one clip, so every frame's ground truth is known: either keys every
``min_key_every`` to ``max_key_every`` frames (each gap drawn anew) over a
crop of the clip, or the whole clip when it is shorter than the window (keys
every 30-60 frames, as users key), or, a quarter of the time, the LaFAN1
layout: 10 context frames, a gap of 5-45 and the target key. The frames after
the layout hold its last key, as the padding at inference does.

**A base** (``GanConfig.base``, the third recipe): the pool holds the clips' rotations too, each key's
rotations are turned with its pose (:func:`~keyfill.learn.gan.spline_base.turned_rotations`), and a
sequence or window also carries ``base``, the RC-FK values of the interpolation through its keys, and
``spline_root``, the interpolation of its key roots (:mod:`keyfill.learn.gan.spline_base`). With base
``"match"`` every in-clip window is a row of the pool's matched set (:attr:`ClipPool.matched`): its crop and
keys, and as ``base`` and ``spline_root`` the RC-FK values and root of match's in-between
(:mod:`keyfill.learn.gan.matched_base`).

**Real sequences for the discriminator** (:func:`real_crops`) are random crops
of ``real_frames`` frames of single clips (clips shorter than that are not
used), each turned to a random heading; with content groups in the pool
(:meth:`~keyfill.learn.gan.poses.ClipPool.draw`) every content is drawn as often. The fake sequences the discriminator
sees are crops of the same length from the generated sequences, at starts
drawn by :func:`crop_starts`, so both kinds have the same length and borders.

**Partial keys** (:func:`partial_coords`, for ``GanConfig.partial_keys``): a
share of the sequences key only part of each pose, the same part at every key,
in equal shares: the root's position (a path of spots, section 5.1), one half
of the body with the root (5.2; :func:`body_halves`), or every joint's
position in one of the three view planes XY, XZ, YZ (5.3; the sequences are at
random headings, so a plane is a camera at a random azimuth). With ``sketch_stretch``, half the 2-D-keyed
sequences are given a stick figure with stretched bones (:func:`sketch_poses`) and carry ``key_truth``,
the true key positions for the key losses.

**Motion DNA** (a ``bank``): a sequence's DNA is drawn from one random clip of the bank; an in-clip
window's from its own clip with ``dna_source`` ``"own"``.

**Path predictor batches** (:func:`clip_batch`) are whole clips (crops of at
most ``max_frames`` for long ones), turned to random headings and padded at
the end by repeating the last frame; ``lengths`` tells the loss where each
ends.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from keyfill.errors import DataError
from keyfill.learn.gan.dna import dna_count, draw_dna
from keyfill.learn.gan.features import centre_keys, dense_input, nearest_key, sparse_input
from keyfill.learn.gan.matched_base import matched_arrays
from keyfill.learn.gan.poses import ClipPool, turn
from keyfill.learn.gan.spline_base import spline_root, spline_values, turned_rotations


@dataclass(frozen=True)
class KeyLayout:
    """Keys of one training sequence.

    Attributes:
        frames: ``(K,)`` increasing key frames, ``frames[0] = 0``, ``frames[-1] = N - 1``.
        poses: ``(K, J, 3)`` metres: row 0 the root (re-centred on the keys' mean
            ground position), rows 1.. root-relative joint positions.
        clips: ``(K,)`` the clip each key came from (for tests and statistics).
        quats: ``(K, J, 4)`` the keys' local rotations, turned as their poses (a pool with rotations), or None.
    """

    frames: np.ndarray
    poses: np.ndarray
    clips: np.ndarray
    quats: np.ndarray | None = None


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
    frames_out, poses, clips, quats = [0], [], [c], []

    def pose_in_clip(c, f):
        pose = turn(pool.relative[c][f].astype(np.float64), heading, pool.up_axis)
        pose[0] = turn(pool.root[c][f], heading, pool.up_axis) + shift
        if pool.quats:
            quats.append(turned_rotations(pool.quats[c][f], heading, pool.up_axis))
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
    return KeyLayout(np.array(frames_out, dtype=np.int64), poses_arr, np.array(clips, dtype=np.int64),
                     np.array(quats) if quats else None)


def key_roots(num_frames: int, key_frames, key_poses) -> np.ndarray:
    """``(T, 3)`` float32: each frame's nearest key root (the targets of the root loss, Eq. 10; the dense input's
    root channels hold them only with ``root_input="centred"``)."""
    return np.asarray(key_poses, dtype=np.float32)[nearest_key(num_frames, key_frames)[0], 0]


def body_halves(skeleton) -> list[np.ndarray]:
    """The two halves of a body, ``(J,)`` bool each, or ``[]`` when the skeleton does not branch into both.

    From the root down the chain of single children to the first joint with several
    children (the pelvis); that chain belongs to both halves; the child subtrees whose
    rest positions lie above that joint on average make the upper half, the others
    the lower.
    """
    J = skeleton.num_joints
    up = 1 if skeleton.up_axis == "Y" else 2
    rest = skeleton.rest_world_positions()
    b = 0
    while len(skeleton.children(b)) == 1:
        b = skeleton.children(b)[0]
    chain = np.zeros(J, dtype=bool)
    j = b
    while j >= 0:
        chain[j] = True
        j = int(skeleton.parents[j])
    upper, lower = chain.copy(), chain.copy()
    for c in skeleton.children(b):
        sub = np.zeros(J, dtype=bool)
        sub[c] = True
        for k in range(c + 1, J):
            sub[k] = sub[k] or (skeleton.parents[k] >= 0 and sub[skeleton.parents[k]])
        (upper if rest[sub, up].mean() > rest[b, up] else lower)[sub] = True
    halves = [upper, lower]
    return halves if all((h & ~chain).any() for h in halves) else []


def partial_coords(rng: np.random.Generator, num_keys: int, num_joints: int, halves, fraction: float) -> np.ndarray:
    """``(K, J, 3)`` bool: the coordinates the keys of one sequence give (see the module docstring)."""
    coords = np.ones((num_keys, num_joints, 3), dtype=bool)
    if rng.random() >= fraction:
        return coords
    modes = ["root", "plane"] + (["half"] if halves else [])
    mode = modes[int(rng.integers(len(modes)))]
    if mode == "root":
        coords[:, 1:] = False
    elif mode == "half":
        coords[:, ~halves[int(rng.integers(len(halves)))]] = False
    else:
        coords[..., int(rng.integers(3))] = False  # the axis the view plane leaves out
    return coords


#: the share of 2-D-keyed training sequences whose keys come from a stretched stick figure (``sketch_stretch``)
SKETCH_SHARE = 0.5


def sketch_poses(rng: np.random.Generator, poses: np.ndarray, parents, stretch: float) -> np.ndarray:
    """Key poses ``(K, J, 3)`` (row 0 the root's position, rows 1.. root-relative, metres) as a casually drawn
    stick figure: every bone of every key scaled by ``exp(U(-stretch, stretch))``, from the root outwards (the
    root's position is kept; section 5.3's augmented 2-D poses)."""
    poses = np.asarray(poses, dtype=np.float64)
    rel = poses.copy()
    rel[:, 0] = 0.0
    scale = np.exp(rng.uniform(-stretch, stretch, size=poses.shape[:2]))
    out = rel.copy()
    for j in range(1, poses.shape[1]):
        p = int(parents[j])
        out[:, j] = out[:, p] + scale[:, j, None] * (rel[:, j] - rel[:, p])
    out[:, 0] = poses[:, 0]
    return out


def _partial_input(rng: np.random.Generator, pool: ClipPool, cfg, num_frames: int, key_frames, poses,
                   coords) -> dict:
    """``dense`` (the sparse format) of partial keys ``poses (K, J, 3)`` given where ``coords (K, J, 3)`` says, and
    with ``cfg.sketch_stretch`` also ``key_truth (3 J, N)``: the true key positions where ``dense`` holds a
    stretched sketch (:func:`sketch_poses`; for :data:`SKETCH_SHARE` of the 2-D-keyed sequences), which the
    key losses then take."""
    shown = poses
    plane = (~coords).all(axis=(0, 1)).any()  # one axis given by no joint: keys in a view plane
    if cfg.sketch_stretch and plane and rng.random() < SKETCH_SHARE:
        shown = sketch_poses(rng, poses, pool.parents, cfg.sketch_stretch)
    out = {"dense": sparse_input(num_frames, key_frames, shown, coords)}
    if cfg.sketch_stretch:
        J = poses.shape[1]
        out["key_truth"] = out["dense"][: 3 * J] if shown is poses else \
            sparse_input(num_frames, key_frames, poses, coords)[: 3 * J]
    return out


def _spline_arrays(ranges, base: str, num_frames: int, key_frames, key_quats, key_roots) -> dict:
    """``base (6 + 3 D, N)`` and ``spline_root (N, 3)``: the interpolation ``base`` (``GanConfig.base``) of the keys."""
    return {"base": spline_values(ranges, num_frames, key_frames, key_quats, base),
            "spline_root": spline_root(num_frames, key_frames, key_roots, base).astype(np.float32)}


def training_sequence(pool: ClipPool, rng: np.random.Generator, cfg, halves=(), bank=None, ranges=None) -> dict:
    """One generator training sequence of ``cfg.sequence_frames`` (``N``) frames as arrays.

    The keys span the first ``N - tail`` frames, ``tail`` drawn from 0 to 63: the
    last frames hold the last key, as the padding to a multiple of 64 frames does
    at inference. Returns ``dense (6 J, N)`` (the sparse format with partial keys
    for a ``cfg.partial_keys`` config, :func:`partial_coords`), ``key_mask (N,)``
    bool, ``key_root (N, 3)`` (:func:`key_roots`), and with a Motion DNA ``bank`` its ``dna (P, J - 1, 3)``
    poses, as many as :func:`~keyfill.learn.gan.dna.dna_count` says for the keys (Appendix D). With the
    driven joints' ``ranges`` (a base, ``cfg.base``; the pool has rotations) also ``base (6 + 3 D, N)`` and
    ``spline_root (N, 3)`` (:mod:`keyfill.learn.gan.spline_base`).
    """
    N = cfg.sequence_frames
    tail = int(rng.integers(0, 64))
    lay = sample_keys(pool, rng, N - tail, cfg.min_gap, cfg.max_gap, cfg.short_gap_seconds, cfg.jump_speed)
    key_mask = np.zeros(N, dtype=bool)
    key_mask[lay.frames] = True
    out = {"key_mask": key_mask, "key_root": key_roots(N, lay.frames, lay.poses)}
    if cfg.partial_keys:
        coords = partial_coords(rng, len(lay.frames), lay.poses.shape[1], halves, cfg.partial_fraction)
        poses, _ = centre_keys(lay.poses, pool.up_axis, coords)
        out.update(_partial_input(rng, pool, cfg, N, lay.frames, poses, coords))
    else:
        out["dense"] = dense_input(N, lay.frames, lay.poses, cfg.mask_scale, cfg.root_input, pool.up_axis)
    if ranges is not None:
        out.update(_spline_arrays(ranges, cfg.base, N, lay.frames, lay.quats, lay.poses[:, 0]))
    if bank is not None:
        out["dna"] = draw_dna(bank, rng, dna_count(lay.frames, pool.fps, cfg.dna_seconds))
    return out


def real_crops(pool: ClipPool, rng: np.random.Generator, count: int, frames: int) -> np.ndarray:
    """``(count, frames, J, 3)`` float32 root-relative positions: random crops of clips, random headings."""
    usable = np.flatnonzero(pool.lengths >= frames)
    if len(usable) == 0:
        raise DataError(f"no clip has the {frames} frames a real sequence for the discriminator needs "
                        f"(the longest has {int(pool.lengths.max(initial=0))}); lower real_frames")
    out = []
    for _ in range(count):
        c = pool.draw(rng, usable) if pool.groups is not None else int(rng.choice(usable))
        s = int(rng.integers(pool.lengths[c] - frames + 1))
        out.append(turn(pool.relative[c][s : s + frames], rng.uniform(-np.pi, np.pi), pool.up_axis))
    return np.array(out, dtype=np.float32)


#: LaFAN1's layout (Harvey et al. 2020): context frames before the gap, and the gap's range
LAFAN_CONTEXT, LAFAN_GAPS = 10, (5, 45)
#: the share of in-clip windows with the LaFAN1 layout
LAFAN_SHARE = 0.25


def _window_keys(rng: np.random.Generator, length: int, min_every: int, max_every: int) -> np.ndarray:
    """Keys at 0 and ``length - 1`` with gaps drawn from ``[min_every, max_every]`` between (the last cut short)."""
    frames = [0]
    while frames[-1] < length - 1:
        frames.append(min(frames[-1] + int(rng.integers(min_every, max_every + 1)), length - 1))
    return np.array(frames, dtype=np.int64)


def window_layout(rng: np.random.Generator, n: int, cfg) -> tuple[int, int, np.ndarray]:
    """``(start, length, key frames from 0)`` of an in-clip window in a clip of ``n`` frames (the module
    docstring: the LaFAN1 layout a quarter of the time, else the whole clip when it fits ``cfg.window_frames``,
    else a crop of that many frames)."""
    W = cfg.window_frames
    if n >= LAFAN_CONTEXT + LAFAN_GAPS[0] + 1 and rng.random() < LAFAN_SHARE:
        gap = int(rng.integers(LAFAN_GAPS[0], min(LAFAN_GAPS[1], n - LAFAN_CONTEXT - 1) + 1))
        L = LAFAN_CONTEXT + gap + 1
        frames = np.append(np.arange(LAFAN_CONTEXT), L - 1)
    elif n <= W:
        L = n
        frames = _window_keys(rng, L, max(cfg.min_key_every, 30), max(min(cfg.max_key_every, 60), 30))
    else:
        L = W
        frames = _window_keys(rng, L, cfg.min_key_every, cfg.max_key_every)
    return int(rng.integers(n - L + 1)), L, frames


def clip_window(pool: ClipPool, rng: np.random.Generator, cfg, halves=(), bank=None, ranges=None) -> dict:
    """One in-clip training window of ``cfg.window_frames`` (``W``) frames as arrays (the module docstring).

    Returns ``dense (6 J, W)``, ``key_mask (W,)`` bool, ``valid (W,)`` bool (frames of the clip; the rest
    hold the last key), ``truth (W, J, 3)`` float32 metres (row 0 the root, re-centred as the keys are;
    rows 1.. root-relative joints, the last valid frame repeated), ``contact (W, n)`` bool (False past the
    clip), and with a Motion DNA ``bank`` its ``dna (P, J - 1, 3)`` poses. A ``cfg.partial_keys`` config
    keys part of the poses as :func:`training_sequence` does (the sparse format), and with ``ranges`` it has the
    spline arrays of :func:`training_sequence` too.
    """
    W = cfg.window_frames
    if cfg.base == "match":  # a row of the matched set: its clip, crop and keys, and match's in-between
        c = pool.draw(rng, np.flatnonzero([len(rows) > 0 for rows in pool.matched]))
        s, frames, matched_q, matched_root = pool.matched[c][int(rng.integers(len(pool.matched[c])))]
        L = len(matched_q)
    else:
        c = pool.draw(rng, np.flatnonzero(pool.lengths >= 2))
        s, L, frames = window_layout(rng, int(pool.lengths[c]), cfg)
    heading = float(rng.uniform(-np.pi, np.pi))
    rel = turn(pool.relative[c][s : s + L].astype(np.float64), heading, pool.up_axis)
    truth = rel.copy()
    truth[:, 0] = turn(pool.root[c][s : s + L], heading, pool.up_axis)
    coords = partial_coords(rng, len(frames), truth.shape[1], halves, cfg.partial_fraction) \
        if cfg.partial_keys else None
    _, shift = centre_keys(truth[frames], pool.up_axis, coords)
    truth[:, 0] -= shift
    pad = W - L
    truth = np.concatenate([truth, np.repeat(truth[-1:], pad, 0)]).astype(np.float32)
    key_mask = np.zeros(W, dtype=bool)
    key_mask[frames] = True
    n_feet = len(pool.foot_joints)
    contact = np.zeros((W, n_feet), dtype=bool)
    if n_feet:
        contact[:L] = pool.contacts[c][s : s + L]
    out = _partial_input(rng, pool, cfg, W, frames, truth[frames], coords) if coords is not None else \
        {"dense": dense_input(W, frames, truth[frames], cfg.mask_scale, cfg.root_input, pool.up_axis)}
    out.update({"key_mask": key_mask, "key_root": key_roots(W, frames, truth[frames]), "valid": np.arange(W) < L,
                "truth": truth, "contact": contact})
    if cfg.base == "match":
        out.update(matched_arrays(ranges, W, matched_q, matched_root, heading, shift, pool.up_axis))
    elif ranges is not None:
        key_quats = turned_rotations(pool.quats[c][s + frames], heading, pool.up_axis)
        out.update(_spline_arrays(ranges, cfg.base, W, frames, key_quats, truth[frames, 0]))
    if bank is not None:
        out["dna"] = draw_dna(bank, rng, dna_count(frames, pool.fps, cfg.dna_seconds),
                              c if cfg.dna_source == "own" else None)
    return out


def crop_starts(rng: np.random.Generator, rows: int, crops: int, frames, length: int) -> np.ndarray:
    """``(rows, crops)`` start frames of crops of ``length`` frames from sequences of ``frames`` frames (a number,
    or ``(rows,)`` valid frames per row: a crop then starts where it fits, at 0 when none does)."""
    if np.ndim(frames) == 0:
        return rng.integers(0, frames - length + 1, size=(rows, crops))
    high = np.maximum(np.asarray(frames) - length + 1, 1)
    return rng.integers(0, high[:, None], size=(rows, crops))


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
