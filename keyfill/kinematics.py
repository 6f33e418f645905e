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
    xp = _xp(rotations)
    parents = [int(p) for p in np.asarray(parents)]
    world_rot, world_pos = [], []
    for j, p in enumerate(parents):
        r, t = rotations[..., j, :], positions[..., j, :]
        if p < 0:
            world_rot.append(r)
            world_pos.append(t)
        else:
            world_rot.append(quat_mul(world_rot[p], r))
            world_pos.append(world_pos[p] + quat_rotate(world_rot[p], t))
    return xp.stack(world_rot, axis=-2), xp.stack(world_pos, axis=-2)
