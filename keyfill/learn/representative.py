"""Representative frames of a motion (Zhou et al. 2020, section 3.5.1): the poses a Motion DNA is made of.

The representative frames of a motion are the frames whose joint rotations
change most from their neighbours: for every frame, :func:`rotation_change`
sums over the joints below the root the rotation angle (radians) to the
previous and to the next frame (half each; the first and last frame have one
neighbour, counted in full). :func:`pick_frames` takes the local maxima of that
curve, largest first (so one sharp gesture gives one frame, not its
neighbours), then, if more frames are asked for than there are maxima, the
remaining frames by size.

A representative *pose* is the pose without root rotation
(:func:`root_free_poses`): the joints' positions relative to the root, in the
root's own axes, so every pose faces the same way and a turn of the whole
body changes nothing (the paper's ``Lambda(S_i)``). Files with a static top
joint above the hips (Bandai-Namco's ``joint_Root``) are folded first, as the
corpus does, so the hips are the root whose rotation is removed.

Shapes: quaternions ``(F, J, 4)`` (w, x, y, z), poses ``(N, J - 1, 3)`` in the
units of the offsets given (file units for :func:`representative_poses`).
"""

from __future__ import annotations

import numpy as np

from keyfill import rotations as R
from keyfill.errors import UsageError
from keyfill.kinematics import fk
from keyfill.motion import Motion


def rotation_change(quats: np.ndarray) -> np.ndarray:
    """``(F,)`` radians: per frame, the summed rotation angle of joints 1.. to the neighbouring frames."""
    q = np.asarray(quats, dtype=np.float64)[:, 1:]
    F = len(q)
    if F < 2:
        return np.zeros(F)
    step = R.quat_angle(q[1:], q[:-1]).sum(axis=-1)  # (F - 1,): frame f to f + 1
    out = np.zeros(F)
    out[1:] += step
    out[:-1] += step
    out[1:-1] /= 2
    return out


def pick_frames(change: np.ndarray, count: int) -> np.ndarray:
    """``(min(count, F),)`` increasing frames: the local maxima of ``change (F,)`` largest first, then the rest."""
    change = np.asarray(change, dtype=np.float64)
    F = len(change)
    if count < 1:
        raise UsageError(f"the number of representative frames must be at least 1, got {count}")
    left = np.concatenate([[-np.inf], change[:-1]])
    right = np.concatenate([change[1:], [-np.inf]])
    peak = (change >= left) & (change > right)
    order = np.lexsort((np.arange(F), -change, ~peak))  # peaks first, each group by size, ties by frame
    return np.sort(order[: min(count, F)])


def root_free_poses(quats: np.ndarray, offsets: np.ndarray, parents) -> np.ndarray:
    """``(..., J - 1, 3)``: joints 1.. relative to the root in the root's axes (forward kinematics with the
    root's rotation and position taken away); units of ``offsets (J, 3)``."""
    q = np.array(quats, dtype=np.float64)
    q[..., 0, :] = (1.0, 0.0, 0.0, 0.0)
    off = np.array(offsets, dtype=np.float64)
    off[0] = 0.0
    return fk(q, np.broadcast_to(off, q.shape[:-1] + (3,)), parents)[1][..., 1:, :]


def _folded(motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """``(quats, positions)`` of ``motion``, the static top joint folded into its child when there is one."""
    from keyfill.learn.corpus import fold_root, top_joint_is_static

    if top_joint_is_static(motion):
        return fold_root(motion.rotations, motion.positions, motion.skeleton.parents)
    return motion.rotations, motion.positions


def representative_frames(motion: Motion, count: int) -> np.ndarray:
    """The ``count`` representative frames of ``motion`` (fewer when it is shorter), increasing."""
    return pick_frames(rotation_change(_folded(motion)[0]), count)


def representative_poses(motion: Motion, frames) -> np.ndarray:
    """``(N, J - 1, 3)`` file units: the root-free poses of ``motion`` at ``frames`` (after folding a static top joint).

    A frame outside the motion is a :class:`UsageError`.
    """
    frames = np.asarray(frames, dtype=np.int64).reshape(-1)
    bad = frames[(frames < 0) | (frames >= motion.num_frames)]
    if len(bad):
        raise UsageError(f"frame {int(bad[0])} is outside the motion (frames 0-{motion.num_frames - 1})")
    q, p = _folded(motion)
    return root_free_poses(q[frames], p[frames[0] if len(frames) else 0], motion.skeleton.parents)
