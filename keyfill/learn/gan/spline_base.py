"""The interpolation under the generator (``GanConfig.base``, the third recipe of issue 31).

The paper's generator makes every frame's pose from the keys' positions alone. With a base
(``"spline"``: keyfill's cubic spline, :func:`keyfill.interpolate.cubic_arrays`; ``"linear"``: the
LaFAN1 protocol's interpolation, slerp and lerp) it makes a *correction* to that interpolation instead
(the delta-interpolator reading of in-betweening, Oreshkin et al. 2022, there over linear
interpolation): its output is added to

* :func:`spline_values`: the RC-FK values of the interpolation through the keys' local rotations:
  the root's 6D vector, and each driven joint's
  Euler angles (:func:`~keyfill.learn.gan.ranges.range_angles`) clipped into its range and taken
  back through the inverse of the range map (:func:`range_unmap`, to
  ``|v| <= LIMIT``), so a zero network output gives the spline, inside the ranges;

and the root's path is :func:`spline_root`, the same interpolation of the key roots (the path
predictor is not used: through keys every 15-90 frames the cubic spline's hips are about 1 cm from
the real path, the predictor's 10-50 cm after 2 s). A fresh generator of this recipe (zero output
layer) therefore starts as the interpolation, and training moves it only where that pays.

Shapes: ``T`` frames, ``K`` keys, ``J`` joints, ``D`` driven joints; rotations are unit
quaternions ``(w, x, y, z)``, positions metres.
"""

from __future__ import annotations

import numpy as np

from keyfill import rotations as R
from keyfill.learn.gan.ranges import JointRanges, range_angles

#: the largest pre-``tanh`` value of a spline angle at its range's end (``tanh(3)`` = 0.995: the network's
#: correction still has 1 % of the full slope there, where the inverse of ``tanh`` would be infinite)
LIMIT = 3.0


def matrix_to_rotation_6d(m):
    """6D vectors ``(..., 6)`` of rotation matrices ``(..., 3, 3)``: the first two columns (numpy; the inverse of
    :func:`keyfill.learn.gan.rcfk.rotation_6d_to_matrix` on rotations)."""
    return np.concatenate([m[..., :, 0], m[..., :, 1]], axis=-1)


def range_unmap(u, lo, hi, limit: float = 4.0):
    """The inverse of :func:`keyfill.learn.gan.rcfk.range_map` (numpy), clipped to ``|v| <= limit``; 0 where the
    range is empty."""
    w = np.asarray(hi) - np.asarray(lo)
    t = np.where(w > 0, 2 * (np.asarray(u) - lo) / np.where(w > 0, w, 1) - 1, 0.0)
    return np.arctanh(np.clip(t, -np.tanh(limit), np.tanh(limit)))


def heading_quat(angle: float, up_axis: str = "Y") -> np.ndarray:
    """``(4,)`` the rotation :func:`keyfill.learn.gan.poses.turn` applies: ``angle`` radians about the up axis."""
    axis = np.array([0.0, 1.0, 0.0]) if up_axis == "Y" else np.array([0.0, 0.0, 1.0])
    return R.quat_from_rotvec(axis * angle)


def turned_rotations(quats: np.ndarray, angle: float, up_axis: str = "Y") -> np.ndarray:
    """``quats (..., J, 4)`` local rotations (float64) of a pose turned by ``angle`` radians about the up axis, as
    :func:`~keyfill.learn.gan.poses.turn` turns its positions: the root's rotation is turned, the others are local."""
    out = np.array(quats, dtype=np.float64, copy=True)
    out[..., 0, :] = R.quat_mul(heading_quat(angle, up_axis), out[..., 0, :])
    return out


def _curves(base: str, num_frames: int, key_frames, key_rotations=None, key_positions=None):
    """``(rotations (T, N, 4), positions (T, 3))`` of ``base`` through the keys (identity / zero where not given):
    :func:`keyfill.interpolate.cubic_windows` or :func:`~keyfill.interpolate.linear_windows` on one window."""
    from keyfill.interpolate import cubic_windows, linear_windows

    k = np.asarray(key_frames, dtype=np.int64)
    rot = np.zeros((num_frames, 1, 4)) if key_rotations is None else np.zeros((num_frames, *key_rotations.shape[1:]))
    rot[..., 0] = 1.0
    pos = np.zeros((num_frames, 3))
    if key_rotations is not None:
        rot[k] = key_rotations
    if key_positions is not None:
        pos[k] = key_positions
    q, p = (cubic_windows if base == "spline" else linear_windows)(None, rot[None], pos[None], k)
    return q[0], p[0]


def spline_values(ranges: JointRanges, num_frames: int, key_frames, key_quats: np.ndarray,
                  base: str = "spline") -> np.ndarray:
    """``(6 + 3 D, T)`` float32: the RC-FK values of the ``base`` interpolation (``"spline"`` or ``"linear"``)
    through ``key_quats (K, J, 4)`` (local rotations, root first) at ``key_frames (K,)`` (increasing, within
    ``[0, T)``); frames after the last key hold it."""
    q, _ = _curves(base, num_frames, key_frames, key_rotations=np.asarray(key_quats, dtype=np.float64))
    return track_values(ranges, q)


def track_values(ranges: JointRanges, quats: np.ndarray) -> np.ndarray:
    """``(6 + 3 D, T)`` float32: the RC-FK values of the local rotations ``quats (T, J, 4)`` (root first): the
    root's 6D vector and each driven joint's range angles clipped into its range, through :func:`range_unmap`
    (a track the generator corrects: an interpolation, :func:`spline_values`, or a matched motion,
    :mod:`keyfill.learn.gan.matched_base`)."""
    q = np.asarray(quats, dtype=np.float64)
    six = matrix_to_rotation_6d(R.quat_to_matrix(q[:, 0]))  # (T, 6)
    ang = np.clip(range_angles(ranges, q), ranges.lo, ranges.hi)  # (T, D, 3)
    v = range_unmap(ang, ranges.lo, ranges.hi, LIMIT).reshape(len(q), -1)
    return np.concatenate([six, v], axis=1).T.astype(np.float32)


def spline_root(num_frames: int, key_frames, key_roots: np.ndarray, base: str = "spline") -> np.ndarray:
    """``(T, 3)`` float64: the ``base`` interpolation through ``key_roots (K, 3)`` at ``key_frames``; the last key
    held after it."""
    return _curves(base, num_frames, key_frames, key_positions=np.asarray(key_roots, dtype=np.float64))[1]
