"""Rotation maths: quaternions, rotation vectors, matrices and Euler angles.

Conventions (used everywhere in keyfill):

* Quaternions are ``(w, x, y, z)``, unit length, Hamilton product. ``q`` and
  ``-q`` are the same rotation; functions that compare rotations account for it.
* A quaternion rotates a column vector: ``v' = q v q*``, i.e. matrices are
  ``v' = R @ v`` and composition ``quat_mul(a, b)`` applies ``b`` first, then ``a``.
* Euler orders are three upper-case letters (``"ZXY"``) and always mean
  *intrinsic* rotations applied in that order, as in BVH ``CHANNELS`` lines:
  angles ``(a, b, c)`` in order ``"ZXY"`` give ``R = Rz(a) @ Rx(b) @ Ry(c)``.
  The extrinsic reading of the same matrix is the reversed order. Angles are
  radians; degrees appear only in BVH text.
* Rotation vectors are ``axis * angle`` (radians).

All functions take arrays with any leading batch shape, ``(..., 4)`` for
quaternions, ``(..., 3)`` for vectors and angles, ``(..., 3, 3)`` for matrices.
They accept numpy arrays or torch tensors and return the same kind: the torch
path is differentiable and is the "torch twin" that training code uses (tests
check that both agree). Functions named ``*_np`` are numpy only.
"""

from __future__ import annotations

import itertools

import numpy as np

EULER_ORDERS: tuple[str, ...] = tuple("".join(p) for p in itertools.permutations("XYZ"))
_AXIS = {"X": 0, "Y": 1, "Z": 2}


def _xp(x):
    """The array namespace of ``x``: ``torch`` for tensors, else ``numpy``."""
    if type(x).__module__.startswith("torch"):
        import torch

        return torch
    return np


def check_order(order: str) -> str:
    """Return ``order`` upper-cased if it names one of the six Euler orders."""
    up = order.upper()
    if up not in EULER_ORDERS:
        raise ValueError(f"unknown Euler order {order!r}; expected one of {', '.join(EULER_ORDERS)}")
    return up


# --- quaternions -------------------------------------------------------------


def quat_identity(shape=(), like=None):
    """Identity quaternions of batch ``shape``: ``(*shape, 4)`` float64 (or like ``like``)."""
    xp = np if like is None else _xp(like)
    if xp is np:
        q = np.zeros((*shape, 4))
    else:
        q = xp.zeros((*shape, 4), dtype=like.dtype, device=like.device)
    q[..., 0] = 1
    return q


def quat_normalize(q):
    """Unit quaternions ``(..., 4)``."""
    xp = _xp(q)
    return q / xp.sqrt(xp.sum(q * q, axis=-1, keepdims=True))


def quat_conjugate(q):
    """Conjugate ``(w, -x, -y, -z)``; the inverse of a unit quaternion."""
    xp = _xp(q)
    return xp.concatenate([q[..., :1], -q[..., 1:]], axis=-1)


def quat_mul(a, b):
    """Hamilton product ``a * b`` (rotation ``b`` first, then ``a``); broadcasts."""
    xp = _xp(a)
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return xp.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def _cross(a, b):
    xp = _xp(a)
    return xp.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        axis=-1,
    )


def quat_rotate(q, v):
    """Rotate vectors ``v (..., 3)`` by unit quaternions ``q (..., 4)``; broadcasts."""
    w = q[..., :1]
    u = q[..., 1:]
    t = 2 * _cross(u, v)
    return v + w * t + _cross(u, t)


def quat_to_rotvec(q):
    """Rotation vectors ``(..., 3)`` (axis * angle, angle in [0, pi]) of unit quaternions."""
    xp = _xp(q)
    q = xp.where(q[..., :1] < 0, -q, q)  # angle in [0, pi]
    v = q[..., 1:]
    w = q[..., :1]
    s2 = xp.sum(v * v, axis=-1, keepdims=True)
    # angle / s -> 2 / w as s -> 0. Both branches stay finite (no sqrt of 0),
    # so torch gradients are finite at the identity too.
    small = s2 < 1e-16
    s = xp.sqrt(xp.where(small, 1 + 0 * s2, s2))
    scale = xp.where(small, 2 / w, 2 * xp.arctan2(s, w) / s)
    return v * scale


def quat_from_rotvec(r):
    """Unit quaternions ``(..., 4)`` from rotation vectors ``(..., 3)``."""
    xp = _xp(r)
    theta2 = xp.sum(r * r, axis=-1, keepdims=True)
    small = theta2 < 1e-12
    theta = xp.sqrt(xp.where(small, 1 + 0 * theta2, theta2))
    half = 0.5 * theta
    # sin(theta/2)/theta, with its series near zero.
    k = xp.where(small, 0.5 - theta2 / 48, xp.sin(half) / theta)
    w = xp.where(small, 1 - theta2 / 8, xp.cos(half))
    return xp.concatenate([w, r * k], axis=-1)


def quat_angle(a, b):
    """Angle in radians ``(...)`` of the rotation between ``a`` and ``b`` (sign-agnostic)."""
    xp = _xp(a)
    d = quat_mul(quat_conjugate(a), b)
    s = xp.sqrt(xp.sum(d[..., 1:] ** 2, axis=-1))
    return 2 * xp.arctan2(s, xp.abs(d[..., 0]))


def quat_slerp(q0, q1, t):
    """Shortest-path spherical interpolation; ``t`` broadcasts against ``q0[..., 0]``.

    Exact at ``t = 0`` (returns ``q0``) and ``t = 1`` (returns ``q1`` up to sign). The weights of the two
    ends in one pass, ``sin((1 - t) theta) / sin(theta)`` and ``sin(t theta) / sin(theta)``, with the angle
    ``theta`` between the 4-vectors as ``2 atan2(|q0 - q1|, |q0 + q1|)`` (accurate at every angle, unlike
    ``acos`` of the dot product near 0), and linear weights below 1e-9 rad, where they agree to rounding.
    """
    xp = _xp(q0)
    t = t[..., None] if hasattr(t, "shape") and t.shape != () else t
    q1 = xp.where(xp.sum(q0 * q1, axis=-1, keepdims=True) < 0, -q1, q1)  # the shorter way round
    d, s = q0 - q1, q0 + q1
    theta = 2 * xp.arctan2(xp.sqrt(xp.sum(d * d, axis=-1, keepdims=True)), xp.sqrt(xp.sum(s * s, axis=-1, keepdims=True)))
    sin = xp.sin(theta)
    small = sin < 1e-9
    safe = xp.where(small, 1.0, sin)
    a = xp.where(small, 1 - t, xp.sin((1 - t) * theta) / safe)
    b = xp.where(small, t, xp.sin(t * theta) / safe)
    return quat_normalize(a * q0 + b * q1)


def quat_continuous_np(q: np.ndarray, axis: int = 0) -> np.ndarray:
    """Flip signs along ``axis`` so that consecutive quaternions have a positive dot product."""
    q = np.moveaxis(np.asarray(q, dtype=np.float64), axis, 0).copy()
    if len(q) > 1:
        dots = np.sum(q[1:] * q[:-1], axis=-1)
        flips = np.cumsum(dots < 0, axis=0) % 2 == 1
        q[1:][flips] *= -1
    return np.moveaxis(q, 0, axis)


def quat_continuous_between(q: np.ndarray, anchors) -> np.ndarray:
    """Quaternions ``(T, ..., 4)`` with signs made continuous along axis 0 (as :func:`quat_continuous_np`)
    between the ``anchors`` (increasing frame indices), which keep their signs: every other frame continues
    the chain from the last anchor before it (frames before the first anchor, from frame 0)."""
    q = np.array(q, dtype=np.float64, copy=True)
    if len(q) < 2:
        return q
    first = np.zeros((1, *q.shape[1:-1]), dtype=np.int64)
    c = np.concatenate([first, np.cumsum(np.sum(q[1:] * q[:-1], axis=-1) < 0, axis=0)])  # (T, ...) sign changes
    a = np.asarray(anchors, dtype=np.int64)
    last = np.searchsorted(a, np.arange(len(q)), side="right") - 1  # the last anchor at or before each frame
    base = np.where((last >= 0).reshape(-1, *[1] * (c.ndim - 1)), c[a[np.maximum(last, 0)]], 0)
    q[(c - base) % 2 == 1] *= -1
    return q


def _quat_matrix_entry(q, r: int, c: int):
    """Entry ``(r, c)`` of the rotation matrices of unit quaternions ``(..., 4)``."""
    w, v = q[..., 0], (q[..., 1], q[..., 2], q[..., 3])
    if r == c:
        a, b = (i for i in range(3) if i != r)
        return 1 - 2 * (v[a] * v[a] + v[b] * v[b])
    sign = -1 if (c - r) % 3 == 1 else 1  # e.g. m01 = 2 (xy - wz), m10 = 2 (xy + wz)
    return 2 * (v[r] * v[c] + sign * w * v[3 - r - c])


def quat_to_matrix(q):
    """Rotation matrices ``(..., 3, 3)`` of unit quaternions ``(..., 4)``."""
    xp = _xp(q)
    rows = [xp.stack([_quat_matrix_entry(q, r, c) for c in range(3)], axis=-1) for r in range(3)]
    return xp.stack(rows, axis=-2)


def quat_from_matrix(m):
    """Unit quaternions ``(..., 4)`` with ``w >= 0`` from rotation matrices ``(..., 3, 3)``.

    Uses the best-conditioned of the four classic formulas per matrix, so it is
    accurate for every rotation, including 180-degree turns.
    """
    xp = _xp(m)
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    m01, m02, m10 = m[..., 0, 1], m[..., 0, 2], m[..., 1, 0]
    m12, m20, m21 = m[..., 1, 2], m[..., 2, 0], m[..., 2, 1]
    cands = xp.stack(
        [
            xp.stack([1 + m00 + m11 + m22, m21 - m12, m02 - m20, m10 - m01], axis=-1),
            xp.stack([m21 - m12, 1 + m00 - m11 - m22, m01 + m10, m02 + m20], axis=-1),
            xp.stack([m02 - m20, m01 + m10, 1 - m00 + m11 - m22, m12 + m21], axis=-1),
            xp.stack([m10 - m01, m02 + m20, m12 + m21, 1 - m00 - m11 + m22], axis=-1),
        ],
        axis=-2,
    )  # (..., 4 candidates, 4); candidate i has component i = 4 * q_i^2
    diag = xp.stack([cands[..., i, i] for i in range(4)], axis=-1)
    best = xp.argmax(diag, axis=-1)
    if xp is np:
        q = np.take_along_axis(cands, best[..., None, None], axis=-2)[..., 0, :]
    else:
        idx = best[..., None, None].expand(*best.shape, 1, 4)
        q = xp.gather(cands, -2, idx)[..., 0, :]
    q = quat_normalize(q)
    return xp.where(q[..., :1] < 0, -q, q)


# --- Euler angles ------------------------------------------------------------


def euler_to_quat(angles, order: str):
    """Unit quaternions ``(..., 4)`` from intrinsic Euler angles ``(..., 3)`` (radians).

    The product ``q_i(a) q_j(b) q_k(c)`` of the three axis rotations, written
    out: the orders are permutations of XYZ, so ``i, j, k`` are distinct.
    """
    xp = _xp(angles)
    i, j, k = (_AXIS[c] for c in check_order(order))
    s = 1 if (j - i) % 3 == 1 else -1  # e_i x e_j = s e_k
    half = 0.5 * angles
    cos, sin = xp.cos(half), xp.sin(half)
    ca, cb, cc = cos[..., 0], cos[..., 1], cos[..., 2]
    sa, sb, sc = sin[..., 0], sin[..., 1], sin[..., 2]
    # p = q_i(a) q_j(b), by axis
    pw, pi, pj, pk = ca * cb, sa * cb, ca * sb, s * sa * sb
    # p q_k(c)
    v = [None, None, None]
    v[i] = pi * cc + s * pj * sc
    v[j] = pj * cc - s * pi * sc
    v[k] = pk * cc + pw * sc
    return xp.stack([pw * cc - pk * sc, *v], axis=-1)


def _euler_from_entries(entry, order: str, xp):
    """Intrinsic Euler angles ``(..., 3)`` from the matrix entries ``entry(r, c)``; see :func:`matrix_to_euler`."""
    i, j, k = (_AXIS[c] for c in check_order(order))
    s = 1.0 if (j - i) % 3 == 1 else -1.0  # even permutation of XYZ: +1
    m_ii, m_ij, m_ik = entry(i, i), entry(i, j), entry(i, k)
    cos_b = xp.sqrt(m_ii**2 + m_ij**2)
    b = xp.arctan2(s * m_ik, cos_b)
    locked = cos_b < 1e-9
    a = xp.arctan2(-s * entry(j, k), entry(k, k))
    c = xp.arctan2(-s * m_ij, m_ii)
    # Gimbal lock: only a +- c is defined; put it all in a (c = 0).
    a_locked = xp.arctan2(s * entry(k, j), entry(j, j))
    a = xp.where(locked, a_locked, a)
    c = xp.where(locked, 0 * c, c)
    return xp.stack([a, b, c], axis=-1)


def matrix_to_euler(m, order: str):
    """Intrinsic Euler angles ``(..., 3)`` in radians from rotation matrices ``(..., 3, 3)``.

    The middle angle lies in ``[-pi/2, pi/2]``, the others in ``(-pi, pi]``. At
    gimbal lock (middle angle +-pi/2) the third angle is set to zero.
    """
    return _euler_from_entries(lambda r, c: m[..., r, c], order, _xp(m))


def euler_to_matrix(angles, order: str):
    """Rotation matrices ``(..., 3, 3)`` from intrinsic Euler angles ``(..., 3)``."""
    return quat_to_matrix(euler_to_quat(angles, order))


def quat_to_euler(q, order: str):
    """Intrinsic Euler angles ``(..., 3)`` in radians of unit quaternions ``(..., 4)``.

    The same as ``matrix_to_euler(quat_to_matrix(q), order)``, computing only
    the matrix entries it needs.
    """
    return _euler_from_entries(lambda r, c: _quat_matrix_entry(q, r, c), order, _xp(q))


def euler_continuous_np(angles: np.ndarray, axis: int = 0) -> np.ndarray:
    """Make Euler angle curves continuous along ``axis`` (the time axis).

    Each frame's angles ``(a, b, c)`` may be replaced by the same rotation's other
    Euler solution ``(a + pi, pi - b, c + pi)`` and shifted by multiples of
    ``2 pi``, so that no curve jumps between consecutive frames. ``angles`` are
    radians in the ranges :func:`matrix_to_euler` returns; the rotations are
    unchanged.
    """
    x = np.moveaxis(np.asarray(angles, dtype=np.float64), axis, 0)
    if len(x) < 2:
        return np.moveaxis(x.copy(), 0, axis)
    alt = np.stack([x[..., 0] + np.pi, np.pi - x[..., 1], x[..., 2] + np.pi], axis=-1)

    def wrap(d):
        return (d + np.pi) % (2 * np.pi) - np.pi

    # A branch switch between frames shows as a half-turn jump of the first and
    # last angles. Count switches cumulatively and use the other solution on odd
    # counts; then remove whole turns.
    d_same = np.abs(wrap(np.diff(x, axis=0))).sum(axis=-1)
    d_swap = np.abs(wrap(alt[1:] - x[:-1])).sum(axis=-1)
    switch = d_swap < d_same
    odd = np.concatenate([np.zeros_like(switch[:1]), np.cumsum(switch, axis=0) % 2 == 1])
    chosen = np.where(odd[..., None], alt, x)
    chosen = np.unwrap(chosen, axis=0)
    # Start near the principal range.
    chosen = chosen - 2 * np.pi * np.round(chosen[:1] / (2 * np.pi))
    return np.moveaxis(chosen, 0, axis)
