"""Following a BVH file's own numbers: a motion's channel values take the Euler angles (and positions) of the
BVH file it came from wherever they hold the same rotation (for :mod:`keyfill.io.bvh`'s writer).

A completion written next to its input keeps ``-177.333`` where the input says ``-177.333`` (not ``182.667``,
the same rotation): :func:`follow` takes the input's values chunk by chunk, as :mod:`keyfill.io.bvh` streams them.
"""

from __future__ import annotations

import numpy as np

from keyfill import rotations as R
from keyfill.io.bvh_channels import channels_to_pose
from keyfill.motion import POSITION_CHANNELS, Motion, Skeleton

#: a frame's rotation is "unchanged" from the template's when they differ by less than this (radians)
SAME_ROTATION_RAD = 1e-9


def follow(values: np.ndarray, motion: Motion, skeleton: Skeleton, chunks) -> np.ndarray:
    """``values`` (``(F, C)`` channels of ``motion``, :func:`keyfill.io.bvh_channels.pose_to_channels`; changed
    in place and returned) with the numbers of a BVH file (its ``skeleton`` and its channel values as
    ``chunks`` of ``(first row, (n, C))``, in order: e.g. the input ``motion`` was completed from) where they
    can be kept.

    At each frame where a joint's rotation is unchanged from the file's (within :data:`SAME_ROTATION_RAD`;
    only the keys are compared when ``motion`` records keys, as a completion does), its rotation channels take
    the file's own values (``-177.333`` stays ``-177.333``, not ``182.667``), and so do position channels equal
    to within 1e-12 of the file's scale. The frames after such a frame, up to the next one, are shifted by the
    whole turns per channel that put them next to it (the frames before the first, next to the first): still
    continuous, and unwrapped towards their neighbours. A file of another channel layout changes nothing. The
    chunks are taken one at a time (:class:`_Follower`); chunks that stop part way leave the frames after
    them as they were: every frame still holds its own rotation.
    """
    if skeleton.names != motion.skeleton.names or skeleton.channels != motion.skeleton.channels or not len(values):
        return values
    follower = _Follower(values, motion)
    for row, tvalues in chunks:
        if row >= len(values):
            break
        follower.chunk(row, tvalues[: len(values) - row])
    return values


class _Follower:
    """:func:`follow`'s work on one chunk of the template's rows at a time (in order), changing
    ``values`` in place; per joint it carries the whole turns of its last frame that held the template's
    rotation to the chunks after it."""

    def __init__(self, values: np.ndarray, motion: Motion):
        sk = motion.skeleton
        self.values, self.motion, self.skeleton = values, motion, sk
        self.scale = max(1.0, float(np.abs(sk.offsets).max(initial=0.0)))
        self.joints = []  # per joint: (j, rotation columns, position columns)
        col = 0
        for j, chans in enumerate(sk.channels):
            cols = np.arange(col, col + len(chans))
            col += len(chans)
            self.joints.append((j, cols[[c not in POSITION_CHANNELS for c in chans]],
                                cols[[c in POSITION_CHANNELS for c in chans]]))
        self.turns: dict[int, np.ndarray] = {}  # joint -> (r,) degrees: the turns of its last anchor so far

    def chunk(self, r0: int, t: np.ndarray) -> None:
        """Follow the template's rows ``r0 .. r0 + len(t) - 1`` (``t``: their ``(n, C)`` channel values)."""
        values, motion, r1 = self.values, self.motion, r0 + len(t)
        keys = motion.keys
        # the frames that may hold the template's rotations: a completion's keys, else every frame
        maybe = np.arange(r0, r1) if keys is None else keys.frames[(keys.frames >= r0) & (keys.frames < r1)]
        same = np.zeros((0, self.skeleton.num_joints), dtype=bool)
        if len(maybe):
            trot, _ = channels_to_pose(t[maybe - r0], self.skeleton)
            same = R.quat_angle(motion.rotations[maybe], trot) < SAME_ROTATION_RAD  # (k, J)
        frames = np.arange(r0, r1)
        for j, rot, pos in self.joints:
            if len(pos):
                close = np.abs(values[r0:r1, pos] - t[:, pos]) <= 1e-12 * self.scale
                values[r0:r1, pos] = np.where(close, t[:, pos], values[r0:r1, pos])
            if not len(rot):
                continue
            anchors = maybe[same[:, j]]
            v = values[r0:r1, rot]
            if not len(anchors):
                if j in self.turns:
                    values[r0:r1, rot] = v + self.turns[j]
                continue  # else: no anchor yet; these frames take the first anchor's turns when it comes
            turns = 360.0 * np.round((t[anchors - r0][:, rot] - v[anchors - r0]) / 360.0)  # (A, r)
            segment = np.searchsorted(anchors, frames, side="right") - 1
            shift = turns[np.maximum(segment, 0)]
            if j in self.turns:
                shift[segment < 0] = self.turns[j]
            elif r0:  # the frames before this joint's first anchor, in earlier chunks
                values[:r0, rot] += turns[0]
            v = v + shift
            v[anchors - r0] = t[anchors - r0][:, rot]
            values[r0:r1, rot] = v
            self.turns[j] = turns[-1]
