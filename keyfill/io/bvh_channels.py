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

#: a BVH output's channel layout: ``source``: each joint's own channels (lossless from a BVH), ``full``: the
#: layout every reader takes (:meth:`Skeleton.full_layout`), ``auto``: ``source`` where that is already full or
#: the source was a BVH file
LAYOUTS = ("auto", "source", "full")


def output_layout(motion: Motion, layout: str, from_bvh: bool) -> Motion:
    """``motion`` with the channel layout a BVH output of ``layout`` (:data:`LAYOUTS`) writes (itself when that
    is its own); ``from_bvh``: the motion came from a BVH file (whose layout ``auto`` keeps). The full layout
    gives position channels to the joints that move away from their OFFSET too."""
    if layout not in LAYOUTS:
        raise ValueError(f"unknown BVH layout {layout!r}; expected one of {', '.join(LAYOUTS)}")
    sk = motion.skeleton
    if layout == "source" or (layout == "auto" and from_bvh):
        return motion
    scale = max(1.0, float(np.abs(sk.offsets).max(initial=0.0)))
    translating = [j for j in range(sk.num_joints) if motion.num_frames
                   and np.abs(motion.positions[:, j] - sk.offsets[j]).max() > 1e-6 * scale]
    full = sk.full_layout(translating)
    return motion if full.channels == sk.channels else motion.replace(skeleton=full)


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

    Angles come from :meth:`Motion.euler_blocks` (continuous curves, a block of
    frames at a time: the only full-size array made is the result). Raises
    :class:`DataError` when the motion does something the channels cannot hold
    (a rotation about an axis without a channel, a translation of a joint
    without position channels).
    """
    sk = motion.skeleton
    F = motion.num_frames
    orders = sk.euler_orders
    scale = max(1.0, float(np.abs(sk.offsets).max(initial=0.0)))
    # per column: (joint, position axis) or (joint, index of the angle in the joint's Euler order)
    columns: list[tuple[int, bool, int]] = []
    for j, chans in enumerate(sk.channels):
        pos_axes = [c[0] for c in chans if c in POSITION_CHANNELS]
        fixed = [i for i in range(3) if "XYZ"[i] not in pos_axes]
        if F and fixed:
            dev = np.abs(motion.positions[:, j, fixed] - sk.offsets[j, fixed]).max(axis=1)
            if dev.max() > 1e-6 * scale:
                raise DataError(
                    f"joint {sk.names[j]!r} moves away from its OFFSET at frame {int(np.argmax(dev))} but has no "
                    f"position channel for that axis ({' '.join(chans) or 'no channels'})"
                )
        for c in chans:
            if c in POSITION_CHANNELS:
                columns.append((j, True, "XYZ".index(c[0])))
            else:
                columns.append((j, False, orders[j].index(c[0])))
    values = np.empty((F, len(columns)))
    for i, (j, is_position, axis) in enumerate(columns):
        if is_position:
            values[:, i] = motion.positions[:, j, axis]
    angle_columns = [(i, j, axis) for i, (j, is_position, axis) in enumerate(columns) if not is_position]
    if angle_columns:
        cols, js, axes = (np.array(x) for x in zip(*angle_columns))
        for start, angles in motion.euler_blocks():
            values[start : start + len(angles), cols] = np.rad2deg(angles[:, js, axes])
    return values
