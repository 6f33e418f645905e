"""Pose features of a motion library: what matching compares, and where a pose stands and faces.

Every frame of a humanoid motion is described in its own *ground frame*: the hips' point on the ground
(the hips' world position with the up coordinate dropped) and the *heading*, the angle about the up axis of
the direction the pelvis faces (perpendicular to the line from the right thigh to the left thigh, on the
ground). A frame's pose feature is the world position of every joint, relative to that ground point and
turned so that the heading is zero, in meters: two frames whose features agree are the same body pose
wherever and whichever way the character stands (heights above the ground are kept). The joints above the
hips (Bandai's static ``joint_Root``) carry no pose: their features are zero.

Shapes: ``J`` joints; features ``(..., J * 3)`` meters; ground points ``(..., 2)`` meters (the two ground
axes: ``x, z`` for Y-up, ``x, y`` for Z-up); headings ``(...)`` radians, counter-clockwise seen from above.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from keyfill import rotations as R
from keyfill.characters.retarget import Rig
from keyfill.kinematics import fk

_UP = {"Y": 1, "Z": 2}


@dataclass(frozen=True)
class Frames:
    """The joints and axes that pose features need, from a humanoid :class:`~keyfill.characters.retarget.Rig`.

    Attributes:
        hips: joint index of the hips (the joint whose world transform places a pose).
        thighs: ``(left, right)`` joint indices of the thighs (they give the heading).
        feet: ``(left, right)`` joint indices of the feet.
        ancestors: joints above the hips, root first (their world transform is undone when poses are stored).
        up: index of the up axis (1 for Y-up, 2 for Z-up).
        meters_per_unit: size of a skeleton unit in meters.
    """

    hips: int
    thighs: tuple[int, int]
    feet: tuple[int, int]
    ancestors: tuple[int, ...]
    up: int
    meters_per_unit: float

    @classmethod
    def of(cls, rig: Rig) -> Frames:
        sk = rig.skeleton
        chain, j = [], int(sk.parents[rig.roles.hips])
        while j >= 0:
            chain.append(j)
            j = int(sk.parents[j])
        limbs = rig.roles.limbs
        return cls(int(rig.roles.hips), (int(limbs["thigh_l"]), int(limbs["thigh_r"])),
                   (int(limbs["foot_l"]), int(limbs["foot_r"])), tuple(reversed(chain)), _UP[sk.up_axis], float(sk.meters_per_unit))

    @property
    def ground_axes(self) -> tuple[int, int]:
        """The two horizontal axes, in the order that makes a counter-clockwise heading about ``up``."""
        return (2, 0) if self.up == 1 else (0, 1)

    def up_vector(self) -> np.ndarray:
        v = np.zeros(3)
        v[self.up] = 1.0
        return v


def heading(world: np.ndarray, frames: Frames) -> np.ndarray:
    """Headings ``(...)`` (radians) of world joint positions ``world (..., J, 3)``: the angle on the ground of
    the direction the pelvis faces, ``(left thigh - right thigh) x up``, measured from the first ground axis
    towards the second (so that a turn by ``a`` about up adds ``a`` to it)."""
    a, b = frames.ground_axes
    across = world[..., frames.thighs[0], :] - world[..., frames.thighs[1], :]
    forward = np.cross(across, frames.up_vector())
    return np.arctan2(forward[..., b], forward[..., a])


def yaw(angle: np.ndarray, frames: Frames) -> np.ndarray:
    """Quaternions ``(..., 4)`` of turns by ``angle (...)`` radians about the up axis."""
    return R.quat_from_rotvec(np.asarray(angle, dtype=np.float64)[..., None] * frames.up_vector())


def ground_point(world: np.ndarray, frames: Frames) -> np.ndarray:
    """``(..., 2)`` the hips' point on the ground (meters) of world positions ``(..., J, 3)`` in units."""
    a, b = frames.ground_axes
    hips = world[..., frames.hips, :]
    return np.stack([hips[..., a], hips[..., b]], axis=-1) * frames.meters_per_unit


def to_ground(vectors2: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Ground vectors ``(..., 2)`` expressed in frames turned by ``angle (...)``: turned by ``-angle``."""
    c, s = np.cos(angle), np.sin(angle)
    x, y = vectors2[..., 0], vectors2[..., 1]
    return np.stack([c * x + s * y, -s * x + c * y], axis=-1)


def describe(world: np.ndarray, frames: Frames) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(features (..., J*3) m, ground points (..., 2) m, headings (...) rad)`` of world joint positions
    ``world (..., J, 3)`` in skeleton units (see the module docstring)."""
    world = np.asarray(world, dtype=np.float64)
    h = heading(world, frames)
    g = ground_point(world, frames)
    a, b = frames.ground_axes
    rel = world * frames.meters_per_unit
    rel[..., a] -= g[..., None, 0]
    rel[..., b] -= g[..., None, 1]
    turned = R.quat_rotate(yaw(-h, frames)[..., None, :], rel)
    turned[..., list(frames.ancestors), :] = 0.0  # the joints above the hips say where, not how, one stands
    return turned.reshape(turned.shape[:-2] + (-1,)), g, h


def pose_world(rotations: np.ndarray, hips: np.ndarray, skeleton, frames: Frames) -> np.ndarray:
    """World joint positions ``(..., J, 3)`` of poses stored as a library stores them: ``rotations (..., J, 4)``
    local, but the hips' entry its *world* rotation (the joints above it at rest), and ``hips (..., 3)`` the
    hips' world position; every other joint at its rest offset."""
    rot = np.array(rotations, dtype=np.float64)
    rot[..., list(frames.ancestors), :] = (1.0, 0.0, 0.0, 0.0)
    pos = np.broadcast_to(skeleton.offsets, rot.shape[:-1] + (3,)).copy()
    pos[..., frames.hips, :] = hips
    for j in frames.ancestors:
        pos[..., j, :] = 0.0
    return fk(rot, pos, skeleton.parents)[1]


def chain_world(rotations: np.ndarray, positions: np.ndarray, chain: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """``(world rotation (..., 4), world position (..., 3))`` of the last joint of ``chain`` (a root first,
    each joint the parent of the next) for local poses ``rotations (..., J, 4)``, ``positions (..., J, 3)``."""
    q = rotations[..., chain[0], :]
    p = positions[..., chain[0], :]
    for j in chain[1:]:
        p = p + R.quat_rotate(q, positions[..., j, :])
        q = R.quat_mul(q, rotations[..., j, :])
    return q, p


def hips_world(rotations: np.ndarray, positions: np.ndarray, skeleton, frames: Frames) -> tuple[np.ndarray,
                                                                                                np.ndarray]:
    """``(world rotation (..., 4), world position (..., 3))`` of the hips of local poses ``rotations
    (..., J, 4)``, ``positions (..., J, 3)``."""
    return chain_world(rotations, positions, list(frames.ancestors) + [frames.hips])
