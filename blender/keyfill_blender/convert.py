"""Pose bones <-> keyfill's Motion: Blender's rest-pose and axis conventions, converted once, here.

Blender poses a bone ``b`` by its *basis* (``pose_bone.matrix_basis``: the ``location`` ``t_b`` and the
rotation ``Q_b`` of its F-curves) on top of its rest matrix ``L_b = bone.matrix_local`` (rotation ``R_b``,
head ``h_b``, armature space). With the default bone settings (inherit rotation, local location) the pose
matrix in armature space is ``P_b = P_p L_p^-1 L_b B_b`` (``p`` the parent; ``P_b = L_b B_b`` for a root),
and the armature object's ``matrix_world`` (rotation ``W``, uniform scale ``c``, translation ``w``) places
it in the scene, which is Z-up and in metres.

keyfill's joint frames are world-aligned at rest (identity rotations, BVH's convention), Y-up, in file
units (``meters_per_unit``: 0.01 by default, centimetres, as the Bandai-Namco BVH files and the shipped
human models). Let ``K`` turn Blender's Z-up scene into Y-up, ``(x, y, z) -> (x, z, -y)`` (the inverse of
Blender's BVH import with ``axis_forward="-Z", axis_up="Y"``), ``g = c / meters_per_unit`` and, per bone,
``A_b = K W R_b``. Then, for every frame, the keyfill joint of bone ``b`` has

* local rotation ``q_b = A_b Q_b A_b^-1`` (a conjugation: the parent's rest cancels out);
* local translation ``x_b = o_b + g A_b t_b`` with the rest offset ``o_b = g K W (h_b - h_p)``, or for a
  root ``o_b = g K W h_b + K w / meters_per_unit`` (the object's placement goes into the root);

and back, ``Q_b = A_b^-1 q_b A_b`` and ``t_b = A_b^-1 (x_b - o_b) / g``. A connected bone ignores its
location in Blender, so its translation is its rest offset. Quaternions are (w, x, y, z) in both programs.
Blender's Euler rotation mode ``"XYZ"`` is the matrix ``Rz Ry Rx``: keyfill's (and BVH's) intrinsic order
``ZYX``, the mode's letters reversed.

A rotation is two quaternions, ``q`` and ``-q``, and keyfill's learned methods are not indifferent to which
one they get (the transformer's result moves by up to 3 % of the height when one joint's sign at the first key
flips: docs/blender.md). So the Motion gets the sign keyfill's own BVH reader would give the same rotations
written as Blender's BVH exporter writes them (rotate mode *Native*): each bone's Euler angles in its
:func:`bvh_order` (of the two Euler solutions, the one the exporter picks on its first frame), read back as the
product of the three axis quaternions (:func:`bvh_hemisphere`). The executable fallback writes exactly those
angles, so both backends and ``keyfill complete`` on Blender's export see the same quaternions.

This module needs numpy and the armature's rest data only (no keyfill import: :func:`to_motion` and
:func:`from_motion` import it, and the executable fallback of :mod:`.backend` uses the arrays directly);
``tests/test_blender_addon.py`` checks it against keyfill's own BVH reader (world positions to 1e-5 of the
height) and round trips.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Blender's Z-up scene -> keyfill's Y-up frame: (x, y, z) -> (x, z, -y)
Z_UP_TO_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
#: the Euler modes of a pose bone (the others: QUATERNION, AXIS_ANGLE)
EULER_MODES = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")
#: the channels a keyfill joint gets: translations where a bone moves, rotations in its :func:`bvh_order`
POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")
#: the keyfill Euler order of a bone without one (Blender's BVH exporter writes quaternion bones as XYZ)
DEFAULT_ORDER = "XYZ"


class ConversionError(ValueError):
    """An armature the conversion cannot represent (the message says which bone and why)."""


@dataclass(frozen=True)
class Rig:
    """An armature's rest data as the conversion needs it, bones parents-first.

    Attributes:
        names: ``J`` bone names.
        parents: ``(J,)`` parent index (-1 for roots).
        axes: ``(J, 3, 3)`` ``A_b``, each bone's rest frame in keyfill's world axes.
        offsets: ``(J, 3)`` rest offsets in keyfill units.
        scale: ``g``, keyfill units per armature unit.
        connected: ``(J,)`` bones whose location Blender ignores.
        meters_per_unit: the unit of the keyfill side.
        heads, tails: ``(J, 3)`` rest head and tail in armature space (for pictures and edit targets).
    """

    names: tuple[str, ...]
    parents: np.ndarray
    axes: np.ndarray
    offsets: np.ndarray
    scale: float
    connected: np.ndarray
    meters_per_unit: float
    heads: np.ndarray
    tails: np.ndarray

    @property
    def num_bones(self) -> int:
        return len(self.names)


def _order(bones) -> list:
    """Bones parents first (depth first from each root, in Blender's order)."""
    out, seen = [], set()

    def visit(b):
        out.append(b)
        seen.add(b.name)
        for c in b.children:
            visit(c)

    for b in bones:
        if b.parent is None:
            visit(b)
    if len(out) != len(bones):  # cannot happen for a valid armature
        raise ConversionError("the armature's bones do not form a hierarchy")
    return out


def _matrix(m) -> np.ndarray:
    return np.array([[m[i][j] for j in range(len(m[0]))] for i in range(len(m))], dtype=np.float64)


def object_transform(matrix_world) -> tuple[np.ndarray, float, np.ndarray]:
    """``(W (3, 3) rotation, c uniform scale, w (3,) translation)`` of an armature object's matrix_world."""
    m = _matrix(matrix_world)
    lin, w = m[:3, :3], m[:3, 3]
    norms = np.linalg.norm(lin, axis=0)
    c = float(norms.mean())
    if c <= 0 or np.ptp(norms) > 1e-6 * c or np.linalg.det(lin) <= 0:
        raise ConversionError("the armature object is scaled unevenly or mirrored; apply its scale first "
                              "(Object > Apply > Scale)")
    return lin / c, c, w


def rig_from_armature(obj, meters_per_unit: float = 0.01) -> Rig:
    """The :class:`Rig` of armature object ``obj`` (its rest pose and ``matrix_world``)."""
    if not meters_per_unit > 0:
        raise ConversionError(f"meters_per_unit must be positive, not {meters_per_unit!r}")
    bones = _order(list(obj.data.bones))
    for b in bones:
        if not b.use_inherit_rotation or not b.use_local_location or b.inherit_scale not in ("FULL", "NONE_LEGACY"):
            raise ConversionError(f"bone {b.name!r}: keyfill needs bones that inherit rotation and use local "
                                  "location (Bone Properties > Relations)")
    W, c, w = object_transform(obj.matrix_world)
    KW = Z_UP_TO_Y_UP @ W
    g = c / meters_per_unit
    index = {b.name: i for i, b in enumerate(bones)}
    parents = np.array([index[b.parent.name] if b.parent else -1 for b in bones], dtype=np.int64)
    rest = np.stack([_matrix(b.matrix_local) for b in bones])
    heads = rest[:, :3, 3]
    axes = KW @ rest[:, :3, :3]
    offsets = np.empty((len(bones), 3))
    for j, p in enumerate(parents):
        offsets[j] = g * KW @ (heads[j] - heads[p]) if p >= 0 else g * KW @ heads[j] + Z_UP_TO_Y_UP @ w / meters_per_unit
    tails = np.array([list(b.tail_local) for b in bones], dtype=np.float64)
    connected = np.array([bool(b.use_connect and b.parent) for b in bones])
    return Rig(tuple(b.name for b in bones), parents, axes, offsets, g, connected, float(meters_per_unit), heads,
               tails)


# --- quaternion arithmetic (w, x, y, z), vectorised ---------------------------------------------------------

def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of ``(..., 4)`` quaternions."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw], axis=-1)


def quat_conj(q: np.ndarray) -> np.ndarray:
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_from_matrix(m: np.ndarray) -> np.ndarray:
    """``(..., 3, 3)`` rotation matrices -> ``(..., 4)`` unit quaternions with ``w >= 0``."""
    m = np.asarray(m, dtype=np.float64)
    tr = np.trace(m, axis1=-2, axis2=-1)
    cand = np.stack([
        np.stack([1 + tr, m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]], -1),
        np.stack([m[..., 2, 1] - m[..., 1, 2], 1 + 2 * m[..., 0, 0] - tr, m[..., 0, 1] + m[..., 1, 0],
                  m[..., 0, 2] + m[..., 2, 0]], -1),
        np.stack([m[..., 0, 2] - m[..., 2, 0], m[..., 0, 1] + m[..., 1, 0], 1 + 2 * m[..., 1, 1] - tr,
                  m[..., 1, 2] + m[..., 2, 1]], -1),
        np.stack([m[..., 1, 0] - m[..., 0, 1], m[..., 0, 2] + m[..., 2, 0], m[..., 1, 2] + m[..., 2, 1],
                  1 + 2 * m[..., 2, 2] - tr], -1),
    ], -2)  # (..., 4, 4): row i is 4 q q_i, best conditioned where |q_i| is largest
    diag = np.stack([1 + tr, 1 + 2 * m[..., 0, 0] - tr, 1 + 2 * m[..., 1, 1] - tr, 1 + 2 * m[..., 2, 2] - tr], -1)
    best = np.argmax(diag, axis=-1)
    q = np.take_along_axis(cand, best[..., None, None], axis=-2)[..., 0, :]
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return q * np.where(q[..., :1] < 0, -1.0, 1.0)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def euler_to_quat(angles: np.ndarray, mode: str) -> np.ndarray:
    """Blender Euler ``angles (..., 3)`` (x, y, z, radians) of rotation mode ``mode`` -> quaternions."""
    half = 0.5 * np.asarray(angles, dtype=np.float64)
    out = None
    for axis in mode:  # "XYZ": Rz Ry Rx, so X is applied first (rightmost)
        i = "XYZ".index(axis)
        q = np.zeros(half.shape[:-1] + (4,))
        q[..., 0] = np.cos(half[..., i])
        q[..., 1 + i] = np.sin(half[..., i])
        out = q if out is None else quat_mul(q, out)
    return out


def keyfill_order(mode: str) -> str:
    """keyfill's intrinsic Euler order (its channel order) of Blender rotation mode ``mode``."""
    return mode[::-1]


def bvh_order(mode: str) -> str:
    """The keyfill Euler order (BVH channel order) Blender's BVH exporter writes a bone of rotation mode ``mode``
    in with rotate mode *Native*: the mode's own letters (it decomposes in the reversed mode, so the channels
    ``X Y Z`` of mode ``XYZ`` mean ``Rx Ry Rz``), ``XYZ`` for quaternion and axis-angle bones."""
    return mode if mode in EULER_MODES else DEFAULT_ORDER


def euler_angles(q: np.ndarray, order: str) -> np.ndarray:
    """Intrinsic Euler angles ``(..., 3)`` (radians, in ``order``'s slots: ``R = R_o0(a) R_o1(b) R_o2(c)``) of
    quaternions ``(..., 4)``; of the two solutions, the one with the smaller sum of absolute angles (the one
    Blender's ``to_euler`` picks against a zero Euler, as its BVH exporter does on its first frame), the
    middle angle in [-90, 90] degrees on a tie."""
    m = quat_to_matrix(np.asarray(q, dtype=np.float64))
    i, j, k = ("XYZ".index(c) for c in order)
    s = 1.0 if (j - i) % 3 == 1 else -1.0  # e_i x e_j = s e_k

    def e(r, c):
        return m[..., r, c]

    sb = np.clip(s * e(i, k), -1.0, 1.0)
    cb = np.hypot(e(i, i), e(i, j))
    first = np.stack([np.arctan2(-s * e(j, k), e(k, k)), np.arctan2(sb, cb), np.arctan2(-s * e(i, j), e(i, i))], -1)
    second = np.stack([np.arctan2(s * e(j, k), -e(k, k)), np.arctan2(sb, -cb), np.arctan2(s * e(i, j), -e(i, i))],
                      -1)
    pick = np.abs(second).sum(axis=-1) < np.abs(first).sum(axis=-1)
    return np.where(pick[..., None], second, first)


def euler_product(angles: np.ndarray, order: str) -> np.ndarray:
    """The quaternion keyfill's BVH reader makes of intrinsic Euler ``angles (..., 3)`` in ``order``'s slots:
    the product of the three axis quaternions (each with ``w = cos(angle / 2)``)."""
    xyz = np.empty_like(np.asarray(angles, dtype=np.float64))
    for slot, axis in enumerate(order):
        xyz[..., "XYZ".index(axis)] = angles[..., slot]
    return euler_to_quat(xyz, order[::-1])  # Blender mode = the keyfill order reversed


def bvh_hemisphere(rotations: np.ndarray, orders) -> np.ndarray:
    """``rotations (F, J, 4)`` with each quaternion's sign as keyfill's BVH reader gives it for the Euler angles
    :func:`euler_angles` in joint ``j``'s ``orders[j]`` (see the module docstring: what Blender's BVH exporter
    writes, read by ``keyfill complete``)."""
    out = np.array(rotations, dtype=np.float64, copy=True)
    for j, order in enumerate(orders):
        ref = euler_product(euler_angles(out[:, j], order), order)
        out[:, j] *= np.where(np.sum(ref * out[:, j], axis=-1, keepdims=True) < 0, -1.0, 1.0)
    return out


# --- the conversion -------------------------------------------------------------------------------------------

def axes_quat(rig: Rig) -> np.ndarray:
    """``(J, 4)``: ``A_b`` as quaternions."""
    return quat_from_matrix(rig.axes)


def to_keyfill(rig: Rig, basis_rot: np.ndarray, basis_loc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Blender basis ``(rotations (F, J, 4), locations (F, J, 3))`` -> keyfill local ``(rotations, positions)``."""
    a = axes_quat(rig)
    rot = quat_mul(quat_mul(a, basis_rot), quat_conj(a))
    loc = np.where(rig.connected[:, None], 0.0, basis_loc)
    pos = rig.offsets + rig.scale * np.einsum("jab,fjb->fja", rig.axes, loc)
    return rot / np.linalg.norm(rot, axis=-1, keepdims=True), pos


def to_blender(rig: Rig, rotations: np.ndarray, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """keyfill local ``(rotations (F, J, 4), positions (F, J, 3))`` -> Blender basis ``(rotations, locations)``;
    a connected bone's location is zero (Blender would ignore it)."""
    a = axes_quat(rig)
    rot = quat_mul(quat_mul(quat_conj(a), rotations), a)
    loc = np.einsum("jba,fjb->fja", rig.axes, positions - rig.offsets) / rig.scale
    loc = np.where(rig.connected[:, None], 0.0, loc)
    return rot / np.linalg.norm(rot, axis=-1, keepdims=True), loc


def world_positions(rig: Rig, rotations: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """``(F, J, 3)`` keyfill world positions of keyfill local ``rotations`` and ``positions`` (forward
    kinematics; for checks without keyfill)."""
    F, J = rotations.shape[:2]
    wrot = np.empty((F, J, 3, 3))
    wpos = np.empty((F, J, 3))
    local = quat_to_matrix(rotations)
    for j, p in enumerate(rig.parents):
        if p < 0:
            wrot[:, j], wpos[:, j] = local[:, j], positions[:, j]
        else:
            wrot[:, j] = wrot[:, p] @ local[:, j]
            wpos[:, j] = wpos[:, p] + np.einsum("fab,fb->fa", wrot[:, p], positions[:, j])
    return wpos


def keyfill_to_scene(rig: Rig, points: np.ndarray) -> np.ndarray:
    """keyfill world points ``(..., 3)`` -> Blender scene coordinates (metres, Z-up); the object's placement
    is in the roots' offsets already."""
    return points @ Z_UP_TO_Y_UP * rig.meters_per_unit  # K^-1 = K^T


def channels(rig: Rig, moving: np.ndarray, orders=None) -> tuple[tuple[str, ...], ...]:
    """keyfill channel lists: translations on roots and on unconnected bones that ``moving (J,)`` says move,
    rotations in each bone's ``orders[j]`` (keyfill Euler orders, :func:`bvh_order`; default XYZ)."""
    orders = _orders(rig, orders)
    return tuple((POSITION_CHANNELS if (p < 0 or (m and not c)) else ()) + tuple(f"{a}rotation" for a in o)
                 for p, m, c, o in zip(rig.parents, moving, rig.connected, orders))


def _orders(rig: Rig, orders) -> tuple[str, ...]:
    orders = (DEFAULT_ORDER,) * rig.num_bones if orders is None else tuple(orders)
    if len(orders) != rig.num_bones or any(sorted(o) != ["X", "Y", "Z"] for o in orders):
        raise ConversionError(f"need one Euler order (a permutation of XYZ) per bone, not {orders!r}")
    return orders


def to_motion(rig: Rig, basis_rot: np.ndarray, basis_loc: np.ndarray, fps: float, keys=None, moving=None,
              orders=None):
    """A keyfill :class:`~keyfill.motion.Motion` of the basis arrays (needs keyfill importable); rotations signed
    as keyfill reads them from Blender's BVH export (:func:`bvh_hemisphere` with ``orders``, :func:`bvh_order`
    of each bone's rotation mode; default XYZ)."""
    from keyfill.motion import Motion, Skeleton

    orders = _orders(rig, orders)
    rot, pos = to_keyfill(rig, basis_rot, basis_loc)
    rot = bvh_hemisphere(rot, orders)
    moving = np.ones(rig.num_bones, bool) if moving is None else np.asarray(moving, bool)
    sk = Skeleton(names=rig.names, parents=rig.parents, offsets=rig.offsets,
                  channels=channels(rig, moving, orders), meters_per_unit=rig.meters_per_unit, up_axis="Y")
    return Motion(sk, fps, rot, pos, keys=keys)


def from_motion(rig: Rig, motion) -> tuple[np.ndarray, np.ndarray]:
    """Blender basis ``(rotations, locations)`` of a keyfill Motion on ``rig``'s skeleton (joints by name)."""
    names = list(motion.skeleton.names)
    missing = [n for n in rig.names if n not in names]
    if missing:
        raise ConversionError(f"keyfill's result has no joint {missing[0]!r}")
    order = [names.index(n) for n in rig.names]
    return to_blender(rig, motion.rotations[:, order], motion.positions[:, order])
