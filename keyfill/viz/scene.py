"""What a stick figure shows, and from where: world points and bones, the camera, the ground.

Geometry: world joint positions (and End Sites) from forward kinematics,
seen by a fixed orthographic camera. A bone joins a joint to its parent unless
the joint's own translation is animated (a root-motion joint such as Bandai's
``Hips`` under a static ``joint_Root`` is not tied to its parent by a bone).
Each bone knows its limb side (names with ``Left``, ``_L``, ``L_``, ...), so
that left limbs can be drawn lighter. The hopping lamp
(:mod:`keyfill.characters.lamp`) also gets its base plate and lampshade.

Views, with the up axis from ``Skeleton.up_axis`` and the horizontal axis ``h``
the ground axis along which the motion travels farther (positive towards where
it goes, so travel runs left to right in the side view):

* ``side``: ``h`` to the right, up upwards;
* ``front``: the other ground axis to the right (the camera faces a character
  that walks along ``h``);
* ``top``: from above, ``h`` to the right;
* ``3d``: turned 35 degrees from the side view towards the front, 22 degrees from above.

The ground is a line (along one ground direction) or a grid of round spacing
under the figure. Lengths are in the motion's file units.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from keyfill.characters import lamp
from keyfill.errors import UsageError
from keyfill.motion import Motion
from keyfill.rotations import quat_rotate

VIEWS = ("side", "front", "top", "3d")
#: (azimuth, elevation) in degrees of each view, relative to the side view
_ANGLES = {"side": (0.0, 0.0), "front": (90.0, 0.0), "top": (0.0, 90.0), "3d": (35.0, 22.0)}


def limb_side(name: str) -> int:
    """-1 for a left-side joint name, +1 for right, 0 otherwise.

    Recognises ``LeftArm``, ``mixamorig:LeftHand``, ``UpperArm_L``, ``l_knee``,
    ``LHipJoint`` (CMU) and the same for right.
    """
    base = re.split(r"[:|]", name)[-1]
    low = base.lower()
    for word, side in (("left", -1), ("right", 1)):
        if word in low:
            return side
    tokens = [t for t in re.split(r"[^A-Za-z0-9]+", base) if t]
    if any(t in ("L", "l") for t in tokens) or re.match(r"L[A-Z][a-z]", base):
        return -1
    if any(t in ("R", "r") for t in tokens) or re.match(r"R[A-Z][a-z]", base):
        return 1
    return 0


@dataclass(frozen=True)
class Figure3D:
    """The drawable points of one motion.

    Attributes:
        points: ``(F, P, 3)`` world positions of the joints, then the End Sites.
        bones: ``(B, 2)`` point indices (parent end, child end).
        sides: ``(B,)`` -1/0/+1 limb side of each bone.
        used: ``(P,)`` bool, the point belongs to a bone (or is a lone joint).
    """

    points: np.ndarray
    bones: np.ndarray
    sides: np.ndarray
    used: np.ndarray


def figure_points(motion: Motion) -> Figure3D:
    """Bones and world points of ``motion`` (see the module docstring for which bones)."""
    sk = motion.skeleton
    world_rot, world_pos = motion.world()
    J = sk.num_joints
    ends = [quat_rotate(world_rot[:, j], np.broadcast_to(off, (motion.num_frames, 3))) + world_pos[:, j]
            for j, off in sk.end_sites]
    points = np.concatenate([world_pos] + [e[:, None] for e in ends], axis=1) if ends else world_pos
    scale = max(1.0, float(np.abs(sk.offsets).max(initial=0.0)))
    tiny = 1e-6 * scale
    bones, sides = [], []
    for j in range(J):
        p = int(sk.parents[j])
        if p < 0:
            continue
        animated = np.ptp(motion.positions[:, j], axis=0).max() > tiny
        if animated or np.linalg.norm(sk.offsets[j]) <= tiny:
            continue
        bones.append((p, j))
        sides.append(limb_side(sk.names[j]))
    for e, (j, off) in enumerate(sk.end_sites):
        if np.linalg.norm(off) > tiny:
            bones.append((j, J + e))
            sides.append(limb_side(sk.names[j]))
    if lamp.is_lamp(sk) and sk.end_sites and sk.end_sites[0][0] == 3:  # the head's tip
        points, extra = _lamp_outline(lamp.DIMENSIONS, world_rot, points)
        bones = [b for b in bones if b != (3, J)] + extra
        sides += [0] * (len(bones) - len(sides))
    bones_arr = np.array(bones, dtype=np.int64).reshape(-1, 2)
    used = np.zeros(points.shape[1], dtype=bool)
    used[bones_arr.reshape(-1)] = True
    if not used.any():
        used[:J] = True
    return Figure3D(points, bones_arr, np.array(sides, dtype=np.int64), used)


def _lamp_outline(dims, world_rot: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """Points and bones that make the lamp's stick figure look like the lamp.

    Adds the base plate (``dims.base_length`` along the base's own X axis
    through the base joint) and the lampshade (a triangle from the head joint
    to the head's tip, ``dims.head_width`` wide there) to ``points`` (F, 5, 3):
    the joints base, leg, neck, head and the head's End Site.
    """
    F = len(points)
    x = np.zeros((F, 3))
    x[:, 0] = 1.0
    plate = quat_rotate(world_rot[:, 0], x * dims.base_length / 2)
    shade = quat_rotate(world_rot[:, 3], x * dims.head_width / 2)
    base, tip = points[:, 0], points[:, 4]
    extra = np.stack([base - plate, base + plate, tip - shade, tip + shade], axis=1)
    P = points.shape[1]
    bones = [(P, P + 1), (3, P + 2), (3, P + 3), (P + 2, P + 3)]
    return np.concatenate([points, extra], axis=1), bones


@dataclass(frozen=True)
class Camera:
    """An orthographic camera: screen x = ``points @ right``, screen y = ``points @ up``."""

    right: np.ndarray
    up: np.ndarray

    def project(self, points: np.ndarray) -> np.ndarray:
        """``(..., 3)`` world points -> ``(..., 2)`` screen coordinates (world units)."""
        return np.stack([points @ self.right, points @ self.up], axis=-1)


def up_index(up_axis: str) -> int:
    """0, 1 or 2: the world axis that points up."""
    return "XYZ".index(up_axis)


def travel_axis(points: np.ndarray, used: np.ndarray, up_axis: str) -> np.ndarray:
    """Unit ground vector along which the figure travels farther, pointing where it goes.

    ``points`` (F, P, 3). Decided by the path of the centroid of the drawn
    points; ties go to the axis of larger overall extent, then to the first axis.
    """
    u = up_index(up_axis)
    ground = [a for a in range(3) if a != u]
    centroid = points[:, used].mean(axis=1)
    travel = np.ptp(centroid, axis=0)
    extent = np.ptp(points[:, used].reshape(-1, 3), axis=0)
    tol = 1e-6 * max(1.0, float(extent.max()))
    a, b = ground
    if abs(travel[a] - travel[b]) > tol:
        h = a if travel[a] > travel[b] else b
    elif abs(extent[a] - extent[b]) > tol:
        h = a if extent[a] > extent[b] else b
    else:
        h = a
    axis = np.zeros(3)
    axis[h] = 1.0 if centroid[-1, h] - centroid[0, h] >= -tol else -1.0
    return axis


def make_camera(view: str, h: np.ndarray, up_axis: str) -> Camera:
    """The camera of ``view`` (one of :data:`VIEWS`) around travel axis ``h``."""
    if view not in _ANGLES:
        raise UsageError(f"unknown view {view!r}; expected one of {', '.join(VIEWS)}")
    u = np.zeros(3)
    u[up_index(up_axis)] = 1.0
    d = np.cross(u, h)
    az, el = (math.radians(x) for x in _ANGLES[view])
    right = math.cos(az) * h + math.sin(az) * d
    away = np.cross(u, right)
    up = math.cos(el) * u + math.sin(el) * away
    return Camera(_clean(right), _clean(up))


def _clean(v: np.ndarray) -> np.ndarray:
    """Round away float noise such as cos(90 deg) = 6e-17 (keeps axis views exact)."""
    return np.where(np.abs(v) < 1e-12, 0.0, v)


def nice_step(span: float, count: int = 8) -> float:
    """A round grid spacing (1, 2 or 5 times a power of ten) giving about ``count`` lines over ``span``."""
    raw = max(span, 1e-12) / count
    power = 10.0 ** math.floor(math.log10(raw))
    for m in (1, 2, 5, 10):
        if m * power >= raw:
            return m * power
    return 10 * power


def ground_segments(points: np.ndarray, up_axis: str, along: np.ndarray | None) -> tuple[np.ndarray, float]:
    """3D segments ``(S, 2, 3)`` of the ground under ``points`` (N, 3), and the ground height.

    The ground is at height 0 when the lowest point is close to it, else at
    the lowest point. It is a line in the ground direction ``along`` (a unit
    vector) through the middle of the points, or a grid of round spacing when
    ``along`` is None; either reaches 15% of the motion's size beyond it.
    """
    u = up_index(up_axis)
    lo, hi = float(points[:, u].min()), float(points[:, u].max())
    height = max(hi - lo, 1e-9)
    level = 0.0 if -0.02 * height <= lo <= 0.25 * height else lo
    g = [a for a in range(3) if a != u]
    mins, maxs = points[:, g].min(axis=0), points[:, g].max(axis=0)
    span = max(float((maxs - mins).max()), height)
    margin = 0.15 * span
    if along is not None:
        center = points.mean(axis=0)
        center[u] = level
        proj = (points - center) @ along
        ends = [center + (proj.min() - margin) * along, center + (proj.max() + margin) * along]
        return np.array(ends)[None], level
    # A grid at least two thirds of the motion's size wide on both axes (a walk
    # along one axis still stands on a floor, not a strip).
    mid, half = (mins + maxs) / 2, np.maximum((maxs - mins) / 2, span / 3) + margin
    mins, maxs = mid - half, mid + half
    step = nice_step(span, 6)
    segs = []
    for k in range(2):
        for x in np.arange(math.ceil(mins[k] / step), math.floor(maxs[k] / step) + 1) * step:
            seg = np.zeros((2, 3))
            seg[:, u] = level
            seg[:, g[k]] = x
            seg[:, g[1 - k]] = (mins[1 - k], maxs[1 - k])
            segs.append(seg)
    return np.array(segs).reshape(-1, 2, 3), level


def is_planar(points: np.ndarray, used: np.ndarray) -> bool:
    """All drawn points lie in one vertical plane through a world axis (the lamp)."""
    flat = points[:, used].reshape(-1, 3)
    extent = np.ptp(flat, axis=0)
    return bool(extent.min() <= 1e-6 * max(1.0, float(extent.max())))
