"""Windows of clips: facing and the canonical frame, global poses, a window as a :class:`Motion`.

Shared by the LaFAN1 protocol (:mod:`keyfill.learn.protocols.lafan1`), which turns
each test window to face +X at its last context frame, and by the learned
methods, which see windows in such a canonical frame. Quaternions are
``(w, x, y, z)``; positions are in the units of the motion (cm for Bandai).
"""

from __future__ import annotations

import math

import numpy as np

from keyfill import rotations as R
from keyfill.errors import UsageError
from keyfill.kinematics import fk
from keyfill.motion import Motion, Skeleton

_AXES = {"X": 0, "Y": 1, "Z": 2}


def axis_vector(text: str) -> np.ndarray:
    """``"+Y"``, ``"-z"``, ``"X"`` -> a unit vector ``(3,)``."""
    t = text.strip().upper()
    sign = -1.0 if t.startswith("-") else 1.0
    name = t.lstrip("+-")
    if name not in _AXES:
        raise UsageError(f"a facing axis is X, Y or Z with an optional sign (e.g. +Y, -Z), not {text!r}")
    v = np.zeros(3)
    v[_AXES[name]] = sign
    return v


def horizontal_axes(up_axis: str) -> tuple[int, int]:
    """The two ground-plane coordinates for an up axis (``"Y"`` -> ``(0, 2)``)."""
    return (0, 2) if up_axis == "Y" else (0, 1)


def facing_rotation(root_quats: np.ndarray, facing_axis: np.ndarray, up_axis: str = "Y") -> np.ndarray:
    """The rotations about the up axis that take +X to the ground projection of the facing axis.

    ``root_quats (..., 4)`` -> ``(..., 4)`` unit quaternions (the inverse turns a
    pose to face +X), computed as the reference's ``quat_between``.
    """
    fwd = R.quat_rotate(root_quats, np.broadcast_to(facing_axis, root_quats.shape[:-1] + (3,)))
    fwd = fwd.copy()
    fwd[..., _AXES[up_axis]] = 0.0
    norm = np.linalg.norm(fwd, axis=-1, keepdims=True)
    fwd = fwd / np.where(norm > 0, norm, 1.0)
    x = np.array([1.0, 0.0, 0.0])
    q = np.concatenate([1.0 + fwd[..., :1], np.cross(np.broadcast_to(x, fwd.shape), fwd)], axis=-1)
    # Facing exactly -X: half a turn about the up axis.
    half = np.zeros(4)
    half[1 + _AXES[up_axis]] = 1.0
    q = np.where(np.linalg.norm(q, axis=-1, keepdims=True) < 1e-9, half, q)
    return R.quat_normalize(q)


def align_windows(
    quats: np.ndarray,
    root: np.ndarray,
    facing_axis: np.ndarray | str = "+Y",
    up_axis: str = "Y",
    frame: int = 9,
) -> tuple[np.ndarray, np.ndarray]:
    """Centre each window on the ground and turn it to face +X on ``frame``.

    Args:
        quats: ``(W, T, J, 4)`` local quaternions.
        root: ``(W, T, 3)`` root positions.
        facing_axis: the root's local axis that points forward (``"+Y"`` as the reference).
        up_axis: ``"Y"`` or ``"Z"``.
        frame: the frame whose facing direction is aligned (9: the LaFAN1 protocol's last context frame).

    Returns:
        New ``(quats, root)``: only the root rotation and position change.
    """
    if isinstance(facing_axis, str):
        facing_axis = axis_vector(facing_axis)
    root = np.array(root, dtype=np.float64)
    h = list(horizontal_axes(up_axis))
    root[..., h] -= root[..., h].mean(axis=1, keepdims=True)
    turn = R.quat_conjugate(facing_rotation(quats[:, frame, 0], facing_axis, up_axis))[:, None]  # (W, 1, 4)
    quats = np.array(quats, dtype=np.float64)
    quats[:, :, 0] = R.quat_mul(turn, quats[:, :, 0])
    root = R.quat_rotate(turn, root)
    return quats, root


def global_pose(quats: np.ndarray, root: np.ndarray, offsets: np.ndarray, parents) -> tuple[np.ndarray, np.ndarray]:
    """Global ``(quats (..., J, 4), positions (..., J, 3))`` from local quats, root and constant offsets."""
    pos = np.broadcast_to(offsets, root.shape[:-1] + offsets.shape).copy()
    pos[..., 0, :] = root
    return fk(quats, pos, parents)


def window_motion(skeleton: Skeleton, quats: np.ndarray, root: np.ndarray, fps: float = 30.0) -> Motion:
    """A :class:`Motion` of one window: ``quats (T, J, 4)``, ``root (T, 3)``, constant offsets."""
    pos = np.broadcast_to(skeleton.offsets, root.shape[:-1] + skeleton.offsets.shape).copy()
    pos[:, 0] = root
    return Motion(skeleton, fps, quats, pos)


def binomial_lowpass(x: np.ndarray, order: int, axis: int) -> np.ndarray:
    """``x`` filtered along ``axis`` with the binomial kernel of ``order`` (``order + 1`` taps, e.g. 4:
    ``[1, 4, 6, 4, 1] / 16``, about a Gaussian of ``sqrt(order) / 2`` frames), the ends padded by repeating
    the first and last values; ``order`` 0 or 1 returns ``x``. The numpy twin of the gan's
    :func:`keyfill.learn.gan.rcfk.binomial_lowpass` (a test holds them equal)."""
    half = order // 2
    if half == 0:
        return x
    k = np.array([math.comb(2 * half, i) for i in range(2 * half + 1)], dtype=np.float64)
    k /= k.sum()
    moved = np.moveaxis(np.asarray(x, dtype=np.float64), axis, 0)
    padded = np.concatenate([np.repeat(moved[:1], half, axis=0), moved, np.repeat(moved[-1:], half, axis=0)])
    out = sum(w * padded[i: i + len(moved)] for i, w in enumerate(k))
    return np.moveaxis(out, 0, axis)
