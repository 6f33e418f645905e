"""Place a library stretch between two keys, correct it so the keys come out exact, and join stretches.

Poses here are in the library's form (:mod:`keyfill.learn.library.store`): ``rotations (T, J, 4)`` local but
the hips' entry its world rotation, ``hips (T, 3)`` the hips' world position (skeleton units).

1. :func:`place`: a stretch (library frames ``i .. i+L``, with ``margin`` frames more on each side where its
   clip has them) is resampled onto the gap's frames (a time warp ``L / g``: slerp and lerp between the
   library's frames), turned about the up axis and moved on the ground so that its first frame stands where
   key ``A`` stands and faces where it faces (heights are kept);
2. and corrected: at each key, the difference of every joint's rotation (and of the hips' position) from the
   key is a *residual*; residual ``A`` at the gap's start goes smoothly (a smoothstep of the gap's time) into
   residual ``B`` at its end, so the stretch passes exactly through both keys; the margins keep the
   residual of their key;
3. :func:`join`: at an inner key, the frames ``h`` either side blend the left stretch (continued past the
   key) into the right one (continued before it) with a smoothstep weight, so position and velocity are
   continuous across the key, and the key itself stays exact (both stretches pass through it).
"""

from __future__ import annotations

import numpy as np

from keyfill import rotations as R
from keyfill.learn.library.features import Frames, ground_point, heading, pose_world, yaw


def smoothstep(u: np.ndarray) -> np.ndarray:
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3 - 2 * u)


def _resampled(lib, i: int, L: int, g: int, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Library-form poses of the stretch ``i .. i+L`` played over ``g`` frames, at gap times ``times``
    (0 at the first key, ``g`` at the second), clipped to the stretch's clip."""
    from keyfill.interpolate import at_times

    c = int(lib.clip_of[i])
    lo, hi = lib.clips[c].start, lib.clips[c].stop
    tau = np.clip(i + times * (L / g), lo, hi - 1)
    a, b = int(np.floor(tau.min())), int(np.ceil(tau.max())) + 1
    rot = R.quat_continuous_np(np.asarray(lib.rotations[a:b], dtype=np.float64), axis=0)
    return at_times(rot, np.asarray(lib.hips[a:b], dtype=np.float64), tau - a)


def place(lib, i: int, L: int, key_a: tuple[np.ndarray, np.ndarray], key_b: tuple[np.ndarray, np.ndarray],
          g: int, before: int, after: int) -> tuple[np.ndarray, np.ndarray]:
    """The corrected stretch ``(rotations (T, J, 4), hips (T, 3))`` for gap frames ``-before .. g + after``
    (``T = before + g + after + 1``); ``key_a``, ``key_b``: the keys' library-form poses ``((J, 4), (3,))``."""
    fr: Frames = lib.frames
    times = np.arange(-before, g + after + 1, dtype=np.float64)
    rot, hips = _resampled(lib, i, L, g, times)
    ka = before  # row of key A
    kb = before + g
    # place: the stretch's first frame where key A stands, facing where it faces
    ends = pose_world(np.stack([rot[ka], key_a[0]]), np.stack([hips[ka], key_a[1]]), lib.skeleton, fr)
    turn = heading(ends[1], fr) - heading(ends[0], fr)
    q = yaw(turn, fr)
    src_g, key_g = ground_point(ends, fr) / fr.meters_per_unit
    a, b = fr.ground_axes
    origin = np.zeros(3)
    origin[[a, b]] = src_g
    target = np.zeros(3)
    target[[a, b]] = key_g
    rot[:, fr.hips] = R.quat_mul(q, rot[:, fr.hips])
    hips = R.quat_rotate(q, hips - origin) + target
    # correct: residuals at both keys, spread with a smoothstep over the gap
    s = smoothstep(times / g)[:, None]
    res_a = R.quat_mul(key_a[0], R.quat_conjugate(rot[ka]))
    res_b = R.quat_mul(key_b[0], R.quat_conjugate(rot[kb]))
    res = R.quat_slerp(np.broadcast_to(res_a, rot.shape), np.broadcast_to(res_b, rot.shape),
                       np.broadcast_to(s, rot.shape[:2]))
    rot = R.quat_normalize(R.quat_mul(res, rot))
    hips = hips + (1 - s) * (key_a[1] - hips[ka]) + s * (key_b[1] - hips[kb])
    rot[ka], hips[ka] = key_a
    rot[kb], hips[kb] = key_b
    return rot, hips


def join(left: tuple[np.ndarray, np.ndarray], right: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray,
                                                                                              np.ndarray]:
    """Blend ``left`` into ``right`` (the same ``2h + 1`` frames around a key, the key in the middle) with a
    smoothstep weight; the middle frame is the key when both pass through it."""
    n = len(left[0])
    w = smoothstep(np.arange(n) / max(n - 1, 1))
    right_q = np.where((np.sum(left[0] * right[0], axis=-1) < 0)[..., None], -right[0], right[0])
    rot = R.quat_slerp(left[0], right_q, np.broadcast_to(w[:, None], left[0].shape[:2]))
    hips = left[1] + w[:, None] * (right[1] - left[1])
    return rot, hips
