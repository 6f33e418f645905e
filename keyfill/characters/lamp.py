"""The hopping lamp ("Luxo") as an ordinary keyfill :class:`~keyfill.motion.Motion`.

The lamp is planar: it moves in the X-Y plane (Y up, meters) and every joint
rotates about Z. It has four rigid links in a chain and six animation
variables (Zhang & van de Panne 2018, Figure 3)::

    joint  parent  BVH channels                    animation variables
    base   -       Xposition Yposition Zrotation   base_x, base_y, base_angle
    leg    base    Zrotation                       leg_angle   (base-leg hinge)
    neck   leg     Zrotation                       neck_angle  (leg-neck hinge)
    head   neck    Zrotation                       head_angle  (neck-head hinge)

At zero angles the lamp stands straight up: the base lies flat with the
middle of its bottom face at the base joint, the leg hinge sits on top of the
base and the leg, neck and head each point along +Y. A positive angle turns a
link counter-clockwise seen from +Z (its tip moves towards -X). ``base_y`` is
the height of the middle of the base's bottom face above the ground.

This module only describes the skeleton and converts between a ``Motion`` and
its ``(F, 6)`` animation variables; the physics lives in
:mod:`keyfill.sim.physics` and uses the same dimensions (:data:`DIMENSIONS`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from keyfill.errors import DataError
from keyfill.motion import Keys, Motion, Skeleton


@dataclass(frozen=True)
class Variable:
    """One animation variable (avar) of the lamp."""

    name: str
    unit: str
    description: str


#: The six animation variables in the order of :func:`to_variables` columns.
VARIABLES: tuple[Variable, ...] = (
    Variable("base_x", "m", "horizontal position of the base (middle of its bottom face)"),
    Variable("base_y", "m", "height of the base (middle of its bottom face) above the ground"),
    Variable("base_angle", "rad", "orientation of the base about Z (counter-clockwise positive)"),
    Variable("leg_angle", "rad", "base-leg hinge angle"),
    Variable("neck_angle", "rad", "leg-neck hinge angle"),
    Variable("head_angle", "rad", "neck-head hinge angle"),
)
VARIABLE_NAMES: tuple[str, ...] = tuple(v.name for v in VARIABLES)

JOINTS: tuple[str, ...] = ("base", "leg", "neck", "head")
PARENTS: tuple[int, ...] = (-1, 0, 1, 2)
CHANNELS: tuple[tuple[str, ...], ...] = (
    ("Xposition", "Yposition", "Zrotation"),
    ("Zrotation",),
    ("Zrotation",),
    ("Zrotation",),
)


@dataclass(frozen=True)
class Dimensions:
    """Sizes (m) and masses (kg) of the four links.

    Each link is a box. ``*_length`` runs along the link's own +Y axis (the
    base's along X), ``*_width`` across it in the plane of motion, ``depth``
    out of the plane (it only matters for the inertia of the base).
    """

    base_length: float = 0.26
    base_height: float = 0.04
    base_depth: float = 0.12
    base_mass: float = 1.00
    leg_length: float = 0.22
    leg_width: float = 0.025
    leg_mass: float = 0.12
    neck_length: float = 0.22
    neck_width: float = 0.025
    neck_mass: float = 0.12
    head_length: float = 0.12
    head_width: float = 0.10
    head_mass: float = 0.25
    depth: float = 0.03


#: The lamp that ``keyfill simulate`` builds.
DIMENSIONS = Dimensions()


def lamp_skeleton(dims: Dimensions = DIMENSIONS) -> Skeleton:
    """The 4-joint planar lamp skeleton (meters, Y up; one End Site at the head's tip)."""
    offsets = np.array(
        [
            [0.0, 0.0, 0.0],
            [0.0, dims.base_height, 0.0],
            [0.0, dims.leg_length, 0.0],
            [0.0, dims.neck_length, 0.0],
        ]
    )
    return Skeleton(
        names=JOINTS,
        parents=np.array(PARENTS),
        offsets=offsets,
        channels=CHANNELS,
        end_sites=((3, np.array([0.0, dims.head_length, 0.0])),),
        meters_per_unit=1.0,
        up_axis="Y",
    )


def is_lamp(skeleton: Skeleton) -> bool:
    """True when ``skeleton`` has the lamp's joints, hierarchy and channel layout (:data:`CHANNELS`, or its
    :meth:`~keyfill.motion.Skeleton.full_layout`, which BVH outputs for Blender have).

    Link lengths may differ from :data:`DIMENSIONS` (a lamp of another size is
    still a lamp); the variables do not depend on them.
    """
    return (
        skeleton.names == JOINTS
        and tuple(int(p) for p in skeleton.parents) == PARENTS
        and skeleton.channels in (CHANNELS, skeleton.replace(channels=CHANNELS).full_layout().channels)
        and skeleton.up_axis == "Y"
    )


def _z_quat(angle: np.ndarray) -> np.ndarray:
    """Quaternions ``(..., 4)`` of rotations by ``angle`` (radians) about Z."""
    half = 0.5 * np.asarray(angle, dtype=np.float64)
    q = np.zeros(half.shape + (4,))
    q[..., 0] = np.cos(half)
    q[..., 3] = np.sin(half)
    return q


def to_variables(motion: Motion) -> np.ndarray:
    """The lamp's animation variables ``(F, 6)`` in :data:`VARIABLES` order (m, rad).

    Angles are unwrapped over time, so a base that turns a full circle gives a
    continuous curve. Raises :class:`DataError` when the motion is not a lamp
    or a joint rotates about an axis other than Z.
    """
    sk = motion.skeleton
    if not is_lamp(sk):
        raise DataError(
            f"not a lamp skeleton: expected joints {', '.join(JOINTS)} in a chain with channels "
            f"'Xposition Yposition Zrotation' / 'Zrotation'; got {', '.join(sk.names)}"
        )
    q = motion.rotations
    off_axis = np.abs(q[..., 1:3]).max(axis=-1)
    if q.shape[0] and off_axis.max() > 1e-6:
        f, j = np.unravel_index(int(np.argmax(off_axis)), off_axis.shape)
        raise DataError(f"joint {sk.names[j]!r} rotates out of the lamp's plane at frame {f}")
    angles = 2.0 * np.arctan2(q[..., 3], q[..., 0])
    angles = (angles + np.pi) % (2 * np.pi) - np.pi
    if q.shape[0]:
        angles = np.unwrap(angles, axis=0)
    out = np.empty((motion.num_frames, 6))
    out[:, 0] = motion.positions[:, 0, 0]
    out[:, 1] = motion.positions[:, 0, 1]
    out[:, 2:] = angles
    return out


def from_variables(
    values: np.ndarray, fps: float, keys: Keys | None = None, dims: Dimensions = DIMENSIONS
) -> Motion:
    """A lamp :class:`Motion` from animation variables ``values (F, 6)`` (m, rad)."""
    values = np.asarray(values, dtype=np.float64)
    if values.ndim != 2 or values.shape[1] != len(VARIABLES):
        raise DataError(f"lamp variables must be (frames, {len(VARIABLES)}), got {values.shape}")
    sk = lamp_skeleton(dims)
    F = values.shape[0]
    positions = np.broadcast_to(sk.offsets, (F, 4, 3)).copy()
    positions[:, 0, 0] = values[:, 0]
    positions[:, 0, 1] = values[:, 1]
    rotations = _z_quat(values[:, 2:])
    return Motion(sk, fps, rotations, positions, keys=keys)
