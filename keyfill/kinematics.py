"""Forward kinematics over any leading batch shape (numpy or torch), and analytic two-bone IK (numpy).

Joint ``j``'s world transform is its parent's world transform composed with
its local transform (translation ``positions[..., j, :]`` in the parent's
frame, then rotation ``rotations[..., j, :]``). Parents come before children
(``parents[j] < j``), roots have parent ``-1``. See :mod:`keyfill.rotations`
for the quaternion conventions.

:func:`two_bone_ik` solves a hip-knee-ankle chain in closed form (foot locking,
:mod:`keyfill.characters.feet`); it works on world positions and returns world
rotation deltas.
"""

from __future__ import annotations

import numpy as np

from keyfill import rotations as R
from keyfill.rotations import _xp, quat_mul, quat_rotate


def fk(rotations, positions, parents):
    """World rotations and positions of every joint.

    Args:
        rotations: ``(..., J, 4)`` local unit quaternions.
        positions: ``(..., J, 3)`` local translations (in the file's units).
        parents: ``(J,)`` parent index per joint, ``-1`` for roots, ``parents[j] < j``.

    Returns:
        ``(world_rotations (..., J, 4), world_positions (..., J, 3))``, the same
        array kind as the inputs (torch tensors keep their autograd graph).
    """
    parents = [int(p) for p in np.asarray(parents)]
    if _xp(rotations) is np:
        return _fk_by_depth(np.asarray(rotations), np.asarray(positions), parents)
    import torch

    world_rot, world_pos = [], []
    for j, p in enumerate(parents):
        r, t = rotations[..., j, :], positions[..., j, :]
        if p < 0:
            world_rot.append(r)
            world_pos.append(t)
        else:
            world_rot.append(quat_mul(world_rot[p], r))
            world_pos.append(world_pos[p] + quat_rotate(world_rot[p], t))
    return torch.stack(world_rot, dim=-2), torch.stack(world_pos, dim=-2)


def _fk_by_depth(rotations: np.ndarray, positions: np.ndarray, parents: list[int]):
    """:func:`fk` for numpy arrays: all joints of one depth in the tree at once.

    Each joint gets exactly the products it gets joint by joint (the torch path), so the
    result is the same to the bit; there are as many steps as the tree is deep, not one per joint.
    """
    par = np.asarray(parents)
    depth = np.zeros(len(par), dtype=np.int64)
    for j, p in enumerate(parents):
        depth[j] = 0 if p < 0 else depth[p] + 1
    lead = np.broadcast_shapes(rotations.shape[:-2], positions.shape[:-2])
    pos_dtype = positions.dtype if depth.max() == 0 else np.result_type(rotations, positions)
    world_rot = np.empty(lead + (len(par), 4), dtype=rotations.dtype)
    world_pos = np.empty(lead + (len(par), 3), dtype=pos_dtype)
    roots = np.flatnonzero(depth == 0)
    world_rot[..., roots, :], world_pos[..., roots, :] = rotations[..., roots, :], positions[..., roots, :]
    for d in range(1, int(depth.max()) + 1):
        js = np.flatnonzero(depth == d)
        parent_rot = world_rot[..., par[js], :]
        world_rot[..., js, :] = quat_mul(parent_rot, rotations[..., js, :])
        world_pos[..., js, :] = world_pos[..., par[js], :] + quat_rotate(parent_rot, positions[..., js, :])
    return world_rot, world_pos


def _unit(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(v / |v|, |v|)`` over the last axis; a zero vector stays zero."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0), n[..., 0]


def _perpendicular(v: np.ndarray, *hints: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to the unit vectors ``v (..., 3)``: the part of the first hint not
    (nearly) parallel to ``v``, else of the next, else of a world axis."""
    out = np.zeros_like(v)
    done = np.zeros(v.shape[:-1], dtype=bool)
    axes = np.eye(3)[np.argmin(np.abs(v), axis=-1)]  # the world axis least parallel to v: never degenerate
    for h in (*hints, axes):
        h = np.broadcast_to(h, v.shape)
        p, n = _unit(h - v * np.sum(h * v, axis=-1, keepdims=True))
        ok = ~done & (n > 1e-9 * np.maximum(np.linalg.norm(h, axis=-1), 1e-300))
        out = np.where(ok[..., None], p, out)
        done |= ok
    return out


def two_bone_ik(a, b, c, target, pole=None, *, slack: float = 1e-9):
    """Analytic two-bone IK (a hip, a knee, an ankle): the rotations that put the ankle on ``target``.

    Args:
        a, b, c: ``(..., 3)`` world positions of the chain's root (hip), middle joint (knee) and end (ankle).
        target: ``(..., 3)`` where ``c`` should go.
        pole: ``(..., 3)`` direction the middle joint bends towards (the knee's side); only its part
            perpendicular to ``target - a`` counts. Default: the current knee's, ``b - a`` without its
            component along ``c - a``.
        slack: how far short of full extension (a fraction of ``|b-a| + |c-b|``) an unreachable target
            leaves the chain, so that the bending plane stays defined.

    Returns:
        ``(qa, qb)``, unit quaternions ``(..., 4)`` (w, x, y, z): world rotation deltas. ``qa`` turns the
        whole chain about ``a``; then ``qb`` turns the part below ``b`` about the moved knee
        ``b' = a + qa (b - a)``. So ``b' = a + qa(b - a)``, ``c' = b' + qb qa (c - b)``, and a joint with world
        rotation ``W`` gets ``qa W`` (the upper bone) or ``qb qa W`` (the lower bone).

    The maths. With bone lengths ``l1 = |b-a|``, ``l2 = |c-b|`` and ``u`` the unit vector from ``a`` to the
    target at distance ``d``, clamped to ``[|l1-l2|, l1+l2]`` shrunk by ``slack``: the knee angle follows from
    the law of cosines, ``cos(alpha) = (l1^2 + d^2 - l2^2) / (2 l1 d)`` at ``a``, and with ``k`` the unit pole
    direction perpendicular to ``u``, ``b' = a + l1 (cos(alpha) u + sin(alpha) k)`` and ``c' = a + d u``. So
    ``c' = target`` whenever ``|l1 - l2| <= |target - a| <= l1 + l2`` (otherwise the leg points straight at
    the target, as far as it can, or folded as close as it can) and the knee lies in the plane of ``a``,
    ``target`` and ``pole``. ``qa`` is the rotation that turns the old upper bone onto the new one *and*
    the old bending plane's normal ``n0 = (b-a) x (c-b)`` onto the new one ``n1 = k x u``: the bone does not
    twist about itself more than the plane's turn needs, and the knee keeps bending about its own hinge
    axis. ``qb`` is then a turn about ``n1`` alone (a hinge), by the signed angle between the lower bone
    after ``qa`` and ``c' - b'``. Rotations preserve lengths, so both bone lengths stay exact (to rounding).
    Where the old chain is straight (no plane), ``n0`` comes from the pole as ``n1`` does.

    numpy only (no torch twin: nothing trains through it).
    """
    a, b, c, t = (np.asarray(x, dtype=np.float64) for x in (a, b, c, target))
    shape = np.broadcast_shapes(a.shape, b.shape, c.shape, t.shape)
    a, b, c, t = (np.broadcast_to(x, shape) for x in (a, b, c, t))
    ab, bc = b - a, c - b
    l1, l2 = np.linalg.norm(ab, axis=-1), np.linalg.norm(bc, axis=-1)
    ac_dir, _ = _unit(c - a)
    knee_now = ab - ac_dir * np.sum(ab * ac_dir, axis=-1, keepdims=True)
    pole = knee_now if pole is None else np.broadcast_to(np.asarray(pole, dtype=np.float64), shape)
    u, dist = _unit(t - a)
    u = np.where((dist > 0)[..., None], u, ac_dir)
    reach = l1 + l2
    d = np.clip(dist, np.abs(l1 - l2) + slack * reach, reach * (1 - slack))
    k = _perpendicular(u, pole, knee_now)
    cos_a = np.clip((l1 * l1 + d * d - l2 * l2) / np.maximum(2 * l1 * d, 1e-300), -1.0, 1.0)
    sin_a = np.sqrt(1 - cos_a * cos_a)
    b_new = a + l1[..., None] * (cos_a[..., None] * u + sin_a[..., None] * k)
    c_new = a + d[..., None] * u
    # qa: frame (upper bone, bending-plane normal) old -> new
    e1_old, _ = _unit(ab)
    n0, n0_len = _unit(np.cross(ab, bc))
    straight = n0_len <= 1e-12 * np.maximum(l1 * l2, 1e-300)
    if np.any(straight):
        k_old = _perpendicular(ac_dir, pole, knee_now)
        n0 = np.where(straight[..., None], _unit(np.cross(k_old, ac_dir))[0], n0)
    n0 = _perpendicular(e1_old, n0)  # exactly perpendicular to the bone
    e1_new, _ = _unit(b_new - a)
    n1 = _perpendicular(e1_new, np.cross(k, u))
    old = np.stack([e1_old, n0, np.cross(e1_old, n0)], axis=-1)  # columns
    new = np.stack([e1_new, n1, np.cross(e1_new, n1)], axis=-1)
    qa = R.quat_normalize(R.quat_from_matrix(new @ np.swapaxes(old, -1, -2)))
    lower = R.quat_rotate(qa, bc)
    want = c_new - b_new
    angle = np.arctan2(np.sum(n1 * np.cross(lower, want), axis=-1), np.sum(lower * want, axis=-1))
    qb = R.quat_from_rotvec(n1 * angle[..., None])
    return qa, qb
