"""BVH channel values <-> a pose: degrees in each joint's Euler order and the file's position channels.

:func:`channels_to_pose` reads them (intrinsic Euler angles in channel order; a position channel replaces the
OFFSET's component on its axis), :func:`pose_to_channels` writes them (continuous Euler curves of
:meth:`keyfill.motion.Motion.euler_angles`). Used by :mod:`keyfill.io.bvh`, the one BVH reader and writer.
"""

from __future__ import annotations

import numpy as np

from keyfill import rotations as R
from keyfill.errors import DataError
from keyfill.motion import EULER_BLOCK, POSITION_CHANNELS, Motion, Skeleton

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
    """``(F, C)`` BVH channel values (degrees, file units) of ``motion`` in its skeleton's layout: the blocks
    of :func:`channel_blocks` in one array."""
    count, blocks = channel_blocks(motion)
    values = np.empty((motion.num_frames, count))
    for start, block in blocks():
        values[start : start + len(block)] = block
    return values


def channel_blocks(motion: Motion):
    """``(C, blocks)``: the number of BVH channels of ``motion`` and a function whose every call iterates
    ``(first frame, (b, C) values)`` (degrees, file units) over the frames, a block of
    :meth:`Motion.euler_blocks` at a time (continuous curves across blocks), so that a writer holds no
    full-size array (and may pass over the frames twice).

    Raises :class:`DataError` (at once) when the motion does something the channels cannot hold (a rotation
    about an axis without a channel, a translation of a joint without position channels).
    """
    columns = _columns(motion)
    positions = [(i, j, axis) for i, (j, is_position, axis) in enumerate(columns) if is_position]
    angle_columns = [(i, j, axis) for i, (j, is_position, axis) in enumerate(columns) if not is_position]

    def blocks():
        if not angle_columns:
            for start in range(0, motion.num_frames, EULER_BLOCK):
                rows = min(EULER_BLOCK, motion.num_frames - start)
                yield start, _with_positions(np.empty((rows, len(columns))), motion, positions, start)
            return
        cols, js, axes = (np.array(x) for x in zip(*angle_columns))
        for start, angles in motion.euler_blocks():
            block = _with_positions(np.empty((len(angles), len(columns))), motion, positions, start)
            block[:, cols] = np.rad2deg(angles[:, js, axes])
            yield start, block

    return len(columns), blocks


def _with_positions(block: np.ndarray, motion: Motion, positions, start: int) -> np.ndarray:
    """``block`` (frames ``start ..``) with its position columns ``(column, joint, axis)`` filled in."""
    for i, j, axis in positions:
        block[:, i] = motion.positions[start : start + len(block), j, axis]
    return block


def _columns(motion: Motion) -> list[tuple[int, bool, int]]:
    """Per BVH channel of ``motion``'s skeleton: ``(joint, is a position, axis)``, the axis being the position's
    (0-2 for X-Z) or the angle's index in the joint's Euler order; a :class:`DataError` when a joint moves
    along an axis it has no position channel for."""
    sk = motion.skeleton
    F = motion.num_frames
    orders = sk.euler_orders
    scale = max(1.0, float(np.abs(sk.offsets).max(initial=0.0)))
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
    return columns
