"""BVH channel values <-> a pose: degrees in each joint's Euler order and the file's position channels.

:func:`channels_to_pose` reads them (intrinsic Euler angles in channel order; a position channel replaces the
OFFSET's component on its axis), :func:`pose_to_channels` writes them (continuous Euler curves of
:meth:`keyfill.motion.Motion.euler_angles`). Used by :mod:`keyfill.io.bvh`, the one BVH reader and writer.
"""

from __future__ import annotations

import numpy as np

from keyfill import rotations as R
from keyfill.errors import DataError
from keyfill.motion import POSITION_CHANNELS, Motion, Skeleton


def channels_to_pose(values: np.ndarray, skeleton: Skeleton, block: int = 16384) -> tuple[np.ndarray, np.ndarray]:
    """BVH channel values ``(F, C)`` (degrees, file units) -> ``(rotations (F,J,4), positions (F,J,3))``.

    Frames are converted ``block`` at a time, so the temporaries stay small
    next to the result.
    """
    F, J = values.shape[0], skeleton.num_joints
    pos = np.empty((F, J, 3))
    rot = np.empty((F, J, 4))
    orders = skeleton.euler_orders
    groups = [(order, [j for j in range(J) if orders[j] == order]) for order in sorted(set(orders))]
    for a in range(0, max(F, 1), block):
        b = min(F, a + block)
        pos[a:b] = skeleton.offsets
        angles = np.zeros((b - a, J, 3))
        col = 0
        for j, chans in enumerate(skeleton.channels):
            for c in chans:
                axis = "XYZ".index(c[0])
                if c in POSITION_CHANNELS:
                    pos[a:b, j, axis] = values[a:b, col]
                else:
                    angles[:, j, orders[j].index(c[0])] = np.deg2rad(values[a:b, col])
                col += 1
        for order, js in groups:
            rot[a:b, js] = R.euler_to_quat(angles[:, js], order)
    return rot, pos


def pose_to_channels(motion: Motion) -> np.ndarray:
    """``(F, C)`` BVH channel values (degrees, file units) of ``motion`` in its skeleton's layout.

    Angles come from :meth:`Motion.euler_angles` (continuous curves). Raises
    :class:`DataError` when the motion does something the channels cannot hold
    (a rotation about an axis without a channel, a translation of a joint
    without position channels).
    """
    sk = motion.skeleton
    F = motion.num_frames
    orders = sk.euler_orders
    degrees = np.rad2deg(motion.euler_angles())
    scale = max(1.0, float(np.abs(sk.offsets).max(initial=0.0)))
    columns = []
    for j, chans in enumerate(sk.channels):
        pos_axes = [c[0] for c in chans if c in POSITION_CHANNELS]
        fixed = [i for i in range(3) if "XYZ"[i] not in pos_axes]
        if F and fixed:
            dev = np.abs(motion.positions[:, j, fixed] - sk.offsets[j, fixed])
            if dev.max() > 1e-6 * scale:
                f = int(np.argmax(dev.max(axis=1)))
                raise DataError(
                    f"joint {sk.names[j]!r} moves away from its OFFSET at frame {f} but has no position "
                    f"channel for that axis ({' '.join(chans) or 'no channels'})"
                )
        for c in chans:
            if c in POSITION_CHANNELS:
                columns.append(motion.positions[:, j, "XYZ".index(c[0])])
            else:
                columns.append(degrees[:, j, orders[j].index(c[0])])
    if not columns:
        return np.zeros((F, 0))
    return np.stack(columns, axis=1)
