"""Forward kinematics over any leading batch shape (numpy or torch).

Joint ``j``'s world transform is its parent's world transform composed with
its local transform (translation ``positions[..., j, :]`` in the parent's
frame, then rotation ``rotations[..., j, :]``). Parents come before children
(``parents[j] < j``), roots have parent ``-1``. See :mod:`keyfill.rotations`
for the quaternion conventions.
"""

from __future__ import annotations

import numpy as np

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
