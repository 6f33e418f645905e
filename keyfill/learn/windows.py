"""Windows of clips: facing and the canonical frame, global poses, a window as a :class:`Motion`, a take.

Shared by the LaFAN1 protocol (:mod:`keyfill.learn.protocols.lafan1`), which turns
each test window to face +X at its last context frame, and by the learned
methods, which see windows in such a canonical frame. Quaternions are
``(w, x, y, z)``; positions are in the units of the motion (cm for Bandai).

A learned method completes a take of any length window by window into one pair of arrays: :func:`model_take`
makes them (the keys' interpolation in the model's hierarchy), the windows overwrite their frames, and
:func:`file_take` turns them back into the file's hierarchy. Both work :data:`keyfill.interpolate.BLOCK`
frames at a time, so a long take costs the result's arrays (56 bytes per joint and frame) and a block's.
"""

from __future__ import annotations

import math

import numpy as np

from keyfill import rotations as R
from keyfill.errors import UsageError
from keyfill.interpolate import BLOCK, segment_coordinates
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


def model_take(model_skeleton: Skeleton, folded: bool, motion: Motion, key_frames: np.ndarray,
               slerped: np.ndarray | None = None, continuous: bool = False, hint: str = ""):
    """A take's starting arrays in a model's hierarchy, read from ``motion``'s key frames.

    Every frame of ``motion`` (``F`` frames, ``J`` joints): translations lerped between the keys
    ``key_frames (K,)``, rotations of the joints ``slerped`` (``(U,)`` indices; None: every joint) slerped
    (:func:`keyfill.interpolate.linear`'s values), the other rotations ``motion``'s own (for a method that
    overwrites them), key frames ``motion``'s; frames outside the keys hold the end keys. Then in the model's
    hierarchy (:func:`keyfill.learn.corpus.model_hierarchy`, checked at the first key: the top joint folded
    into the hips when ``folded``; its error ends with ``hint``) and, with ``continuous``, rotation signs
    continuous along time (:func:`keyfill.rotations.quat_continuous_np` of the whole take, a block at a time).

    Returns:
        ``(quats (F, J, 4), positions (F, J, 3), top)``, float64: ``top`` is the file's top joint's
        ``(rotations (F, 4), positions (F, 3))`` before folding (for :func:`file_take`), None unless ``folded``.
    """
    from keyfill.learn.corpus import fold_root, model_hierarchy

    k = np.asarray(key_frames, dtype=np.int64)
    k0 = int(k[0])
    model_hierarchy(model_skeleton, folded, motion.skeleton, motion.rotations[k0: k0 + 1],
                    motion.positions[k0: k0 + 1], hint=hint)  # the check, before any work
    F, J = motion.num_frames, motion.num_joints
    s, u = segment_coordinates(F, k)
    kq, kp = motion.rotations[k], motion.positions[k]
    joints = np.arange(J) if slerped is None else np.asarray(slerped, dtype=np.int64)
    kq = kq[:, joints]
    quats, positions = np.empty((F, J, 4)), np.empty((F, J, 3))
    top = (np.empty((F, 4)), np.empty((F, 3))) if folded else None
    signs = SignChain() if continuous else None
    for a in range(0, F, BLOCK):
        b = min(F, a + BLOCK)
        ss, uu = s[a:b], u[a:b]
        p0 = kp[ss]
        p = p0 + uu[:, None, None] * (kp[ss + 1] - p0)
        r = motion.rotations[a:b].copy() if slerped is not None else np.empty((b - a, J, 4))
        if len(joints):
            r[:, joints] = R.quat_slerp(kq[ss], kq[ss + 1], np.broadcast_to(uu[:, None], (b - a, len(joints))))
        at = k[(k >= a) & (k < b)]
        r[at - a], p[at - a] = motion.rotations[at], motion.positions[at]
        if folded:
            top[0][a:b], top[1][a:b] = r[:, 0], p[:, 0]
            r, p = fold_root(r, p, motion.skeleton.parents)
        if signs is not None:
            signs(r)
        quats[a:b], positions[a:b] = r, p
    return quats, positions, top


class SignChain:
    """:func:`keyfill.rotations.quat_continuous_np` along time (axis 0) of a take given a block of frames at a
    time, in order: calling it with each block's quaternions ``(n, ..., 4)`` flips their signs in place as the
    whole take's would be (the same sign changes counted from the take's first frame)."""

    def __init__(self):
        self.flips = None  # (...,) int: sign changes from the first frame to the last one seen
        self.last = None  # (1, ..., 4): the last frame seen, before its flip

    def __call__(self, q: np.ndarray) -> None:
        if not len(q):
            return
        before = q[:-1] if self.last is None else np.concatenate([self.last, q[:-1]])
        first = 1 if self.last is None else 0
        self.last = q[-1:].copy()
        changes = np.cumsum(np.sum(q[first:] * before, axis=-1) < 0, axis=0)
        if self.flips is not None:
            changes += self.flips
        if len(changes):
            self.flips = changes[-1]
            q[first:][changes % 2 == 1] *= -1


def file_take(quats: np.ndarray, positions: np.ndarray, top, skeleton: Skeleton) -> None:
    """:func:`model_take`'s arrays back in the file's hierarchy, in place: with ``top`` (a folded take) the
    hips get their own transform again under the file's top joint, and every rotation is normalised.

    Args:
        quats: ``(F, J, 4)`` local rotations in the model's hierarchy (the top joint carrying the hips').
        positions: ``(F, J, 3)`` local translations, the same.
        top: the file's top joint's ``(rotations (F, 4), positions (F, 3))``, or None (nothing was folded).
        skeleton: the file's skeleton.
    """
    c = skeleton.children(0)[0] if top is not None else None
    for a in range(0, len(quats), BLOCK):
        b = min(len(quats), a + BLOCK)
        q = quats[a:b]
        if top is not None:
            top_q, top_p = top[0][a:b], top[1][a:b]
            inv = R.quat_conjugate(top_q)
            q[:, c] = R.quat_mul(inv, q[:, 0])
            positions[a:b, c] = R.quat_rotate(inv, positions[a:b, 0] - top_p)
            q[:, 0], positions[a:b, 0] = top_q, top_p
        q /= np.sqrt(np.sum(q * q, axis=-1, keepdims=True))  # R.quat_normalize, in place
