"""Retargeting between humanoid rigs: reference T-poses and world-space rotation transfer.

A :class:`Rig` is a skeleton with its humanoid roles (:mod:`keyfill.characters.humanoid`) and a
*reference pose*: local rotations that stand the rig in a canonical T-pose, whatever its rest pose is
(Mixamo and CMU rest in a T-pose already, other rigs in an A-pose, and the Bandai-Namco rig's zero pose has
every bone along its joint's local X axis, the body lying down). In the canonical T-pose, in the rig's own
world axes with ``up`` its up axis, ``left`` = +X and ``forward`` = ``left x up`` (+Z for a Y-up rig):

* the hips and the top of the spine are turned as whole frames: the spine's top (the neck) straight up,
  and the right-to-left thigh (hips) or clavicle (spine top) vector along ``left``;
* every other mapped bone, from the top down, by the smallest rotation that points it (its joint to the
  next mapped joint of its chain, or to its one child or end site) along its canonical direction: spine,
  neck and head up; a left arm's clavicle, upper arm, forearm and hand along ``left`` (a right one along
  ``-left``); thigh and shin down; foot and toe forward;
* unmapped joints (fingers, twist bones, a CMU ``LHipJoint``) keep their rest rotation.

:func:`retarget` then transfers each mapped joint's world rotation as the usual tools (Unreal, VRM,
Rokoko, NVIDIA's poselib) do: ``delta = Q_src W_src^-1``, ``Q_tgt = delta W_tgt`` (``W``: world rotations
of the reference pose), back to local rotations from the top down. Spine and neck chains of different
lengths are matched by their place along the chain (the tops match exactly, the joints between get the
rotations between, slerped). The hips' world position is scaled by the ratio of the rigs' hip heights
(which converts units too) and turned from one up axis to the other. Bone directions of mapped joints
match the source exactly; a bone's twist about its own axis is the rig's own (it only shows in the
orientation of hands, feet and head, and in unmapped children).

Quaternions are ``(w, x, y, z)`` (:mod:`keyfill.rotations`); positions in each rig's own units.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from keyfill import rotations as R
from keyfill.characters.humanoid import SIDES, RoleMap, map_roles
from keyfill.errors import DataError
from keyfill.kinematics import fk
from keyfill.motion import Motion, Skeleton

_AXES = {"X": 0, "Y": 1, "Z": 2}
#: canonical bone directions of the limbs, as (coefficient of left, of up, of forward); a right limb's
#: ``left`` coefficient is negated
_LIMB_DIRECTIONS = {"clavicle": (1, 0, 0), "upper_arm": (1, 0, 0), "forearm": (1, 0, 0), "hand": (1, 0, 0),
                    "thigh": (0, -1, 0), "shin": (0, -1, 0), "foot": (0, 0, 1), "toe": (0, 0, 1)}
#: the limb chains, in order from the body out (the next role is where a bone points)
_CHAINS = (("clavicle", "upper_arm", "forearm", "hand"), ("thigh", "shin", "foot", "toe"))


def canonical_axes(up_axis: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(left, up, forward)`` unit vectors of the canonical T-pose for a rig with ``up_axis`` "Y" or "Z"."""
    up = np.zeros(3)
    up[_AXES[up_axis]] = 1.0
    left = np.array([1.0, 0.0, 0.0])
    return left, up, np.cross(left, up)


def quat_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation ``(..., 4)`` turning direction ``a (..., 3)`` onto direction ``b (..., 3)``.

    Opposite directions turn half a turn about an axis perpendicular to ``a``.
    """
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    w = 1.0 + np.sum(a * b, axis=-1, keepdims=True)
    axis = np.cross(a, b)
    opposite = w[..., 0] < 1e-9
    if np.any(opposite):  # any perpendicular axis
        other = np.where(np.abs(a[..., :1]) < 0.9, np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))
        perp = np.cross(a, other)
        axis = np.where(opposite[..., None], perp / np.linalg.norm(perp, axis=-1, keepdims=True), axis)
        w = np.where(opposite[..., None], 0.0, w)
    return R.quat_normalize(np.concatenate([w, axis], axis=-1))


def frame_rotation(primary: np.ndarray, secondary: np.ndarray, to_primary: np.ndarray,
                   to_secondary: np.ndarray) -> np.ndarray:
    """The rotation ``(4,)`` turning ``primary (3,)`` onto ``to_primary`` and the part of ``secondary``
    perpendicular to ``primary`` onto ``to_secondary`` (perpendicular to ``to_primary``)."""
    def basis(p, s):
        p = p / np.linalg.norm(p)
        s = s - p * np.dot(s, p)
        n = np.linalg.norm(s)
        if n < 1e-9:
            raise DataError("the rig's body axes are parallel (its hips or shoulders have no width)")
        s = s / n
        return np.stack([p, s, np.cross(p, s)], axis=1)  # columns

    return R.quat_normalize(R.quat_from_matrix(basis(to_primary, to_secondary) @ basis(primary, secondary).T))


@dataclass(frozen=True, eq=False)
class Rig:
    """A humanoid skeleton ready for retargeting.

    Attributes:
        skeleton: the joints.
        roles: which joint plays each role.
        reference: ``(J, 4)`` local rotations of the reference T-pose.
        world: ``(J, 4)`` world rotations of the reference T-pose.
        hip_height: height of the hips above the lowest foot or toe joint in the reference pose (skeleton units).
    """

    skeleton: Skeleton
    roles: RoleMap
    reference: np.ndarray
    world: np.ndarray
    hip_height: float

    def chains(self) -> dict[str, list[int]]:
        """The joint chains that are matched by their place along them: ``spine`` (hips first, then the spine
        joints) and ``neck`` (the neck joints, then the head)."""
        return {"spine": [self.roles.hips, *self.roles.spine], "neck": [*self.roles.neck, self.roles.head]}


def make_rig(skeleton: Skeleton, roles: RoleMap | None = None, rig_map: dict | None = None,
             label: str = "the skeleton") -> Rig:
    """The :class:`Rig` of ``skeleton``: its roles (found with :func:`map_roles` unless given; ``label`` names
    the skeleton in its errors) and its reference T-pose (see the module docstring)."""
    roles = roles if roles is not None else map_roles(skeleton, rig_map, label=label)
    reference = reference_pose(skeleton, roles)
    world, pos = fk(reference, skeleton.offsets, skeleton.parents)
    up = _AXES[skeleton.up_axis]
    feet = [roles.limbs[f"{r}_{s}"] for s in SIDES for r in ("foot", "toe") if f"{r}_{s}" in roles.limbs]
    hip_height = float(pos[roles.hips, up] - pos[feet, up].min())
    if not hip_height > 0:
        raise DataError("the rig's hips are not above its feet in the reference pose")
    return Rig(skeleton, roles, reference, world, hip_height)


def _rest_positions(skeleton: Skeleton) -> np.ndarray:
    """``(J, 3)`` joint positions with every rotation at identity: in each joint's frame of that pose, the
    vector to a descendant is the difference of these."""
    return fk(np.tile([1.0, 0.0, 0.0, 0.0], (skeleton.num_joints, 1)), skeleton.offsets, skeleton.parents)[1]


def _pointing(skeleton: Skeleton, roles: RoleMap, rest: np.ndarray) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """joint -> (its bone in its rest frame, the canonical world direction) for every swung bone."""
    left, up, forward = canonical_axes(skeleton.up_axis)
    out = {}
    chain = [roles.hips, *roles.spine, *roles.neck, roles.head]
    for i, a in enumerate(chain[1:-1], start=1):
        bone = _bone_to(rest, a, chain[i + 1:])
        if bone is not None:
            out[a] = (bone, up)
    for side in SIDES:
        sign = 1.0 if side == "l" else -1.0
        for limb in _CHAINS:
            present = [r for r in limb if f"{r}_{side}" in roles.limbs]
            for i, role in enumerate(present):
                j = roles.limbs[f"{role}_{side}"]
                c = _LIMB_DIRECTIONS[role]
                direction = sign * c[0] * left + c[1] * up + c[2] * forward
                further = [roles.limbs[f"{r}_{side}"] for r in present[i + 1:]]
                bone = _bone_to(rest, j, further) if further else _leaf_bone(skeleton, j, rest)
                if bone is not None:
                    out[j] = (bone, direction)
    bone = _leaf_bone(skeleton, roles.head, rest)
    if bone is not None:
        out[roles.head] = (bone, up)
    return out


def _bone_to(rest: np.ndarray, j: int, further: list[int]) -> np.ndarray | None:
    """The bone from ``j`` to the first of the joints ``further`` down its chain that is not at ``j``
    (helper joints of zero length, such as CMU's ``Neck``, share their parent's place)."""
    for k in further:
        bone = rest[k] - rest[j]
        if np.linalg.norm(bone) > 1e-9:
            return bone
    return None


def _leaf_bone(skeleton: Skeleton, j: int, rest: np.ndarray) -> np.ndarray | None:
    """The bone of a joint at the end of a chain: to its one child or end site, the mean over several; None
    when it has none (or they are all at the joint)."""
    kids = [rest[c] - rest[j] for c in np.flatnonzero(skeleton.parents == j)]
    kids += [np.asarray(o) for k, o in skeleton.end_sites if k == j]
    if not kids:
        return None
    bone = np.mean(kids, axis=0)
    return bone if np.linalg.norm(bone) > 1e-9 else None


def reference_pose(skeleton: Skeleton, roles: RoleMap) -> np.ndarray:
    """``(J, 4)`` local rotations that stand ``skeleton`` in the canonical T-pose (the module docstring)."""
    rest = _rest_positions(skeleton)
    left, up, _ = canonical_axes(skeleton.up_axis)
    J = skeleton.num_joints
    world = np.tile([1.0, 0.0, 0.0, 0.0], (J, 1))
    local = world.copy()
    top = roles.spine[-1] if roles.spine else roles.hips
    above = [*roles.neck, roles.head]
    frames = {roles.hips: (_bone_to(rest, roles.hips, above), _side_vector(roles, rest, "thigh", "shin", "foot")),
              top: (_bone_to(rest, top, above), _side_vector(roles, rest, "clavicle", "upper_arm", "forearm", "hand"))}
    if any(primary is None for primary, _ in frames.values()):
        raise DataError("the rig's head is at its hips or spine top in the rest pose")
    pointing = _pointing(skeleton, roles, rest)
    for j in range(J):
        p = skeleton.parents[j]
        parent = world[p] if p >= 0 else np.array([1.0, 0.0, 0.0, 0.0])
        if j in frames:
            primary, secondary = frames[j]  # in the rest frame, whose world rotation is ``parent``
            turn = frame_rotation(R.quat_rotate(parent, primary), R.quat_rotate(parent, secondary), up, left)
        elif j in pointing:
            bone, direction = pointing[j]
            turn = quat_between(R.quat_rotate(parent, bone), direction)
        else:
            turn = np.array([1.0, 0.0, 0.0, 0.0])
        world[j] = R.quat_normalize(R.quat_mul(turn, parent))
        local[j] = R.quat_normalize(R.quat_mul(R.quat_conjugate(parent), world[j]))
    return local


def _side_vector(roles: RoleMap, rest: np.ndarray, *names: str) -> np.ndarray:
    """Right-to-left vector between the first of ``names`` both sides have apart (rest positions)."""
    for name in names:
        if f"{name}_l" in roles.limbs and f"{name}_r" in roles.limbs:
            side = rest[roles.limbs[f"{name}_l"]] - rest[roles.limbs[f"{name}_r"]]
            if np.linalg.norm(side) > 1e-9:
                return side
    raise DataError(f"the rig has no left and right {' or '.join(names)} apart to tell its sides")


def up_conversion(source_up: str, target_up: str) -> np.ndarray:
    """The rotation ``(4,)`` from a ``source_up`` rig's world axes to a ``target_up`` rig's (left stays +X)."""
    s, t = canonical_axes(source_up), canonical_axes(target_up)
    return frame_rotation(s[1], s[0], t[1], t[0])


def retarget(motion: Motion, source: Rig, target: Rig) -> Motion:
    """``motion`` (on ``source``'s skeleton) on ``target``'s skeleton, frame for frame (see the module docstring).

    Joints of the target that no role maps keep their reference rotation; non-root translations are the
    target's rest offsets; the frame rate and keys are the motion's.
    """
    if motion.skeleton is not source.skeleton and motion.skeleton.difference(source.skeleton) is not None:
        raise DataError("the motion is not on the source rig's skeleton")
    src_world, src_pos = fk(motion.rotations, motion.positions, motion.skeleton.parents)
    convert = up_conversion(source.skeleton.up_axis, target.skeleton.up_axis)
    # delta_j = C Q_src W_src^-1 C^-1: each mapped source joint's turn from its reference, in target axes
    delta = R.quat_mul(R.quat_mul(convert, R.quat_mul(src_world, R.quat_conjugate(source.world))),
                       R.quat_conjugate(convert))
    F, J = motion.num_frames, target.skeleton.num_joints
    tgt_delta: dict[int, np.ndarray] = {}
    for role, j in target.roles.limbs.items():
        if role in source.roles.limbs:
            tgt_delta[j] = delta[:, source.roles.limbs[role]]
    for name, chain in target.chains().items():
        tgt_delta.update(_chain_deltas(delta, source.chains()[name], chain, anchor=0 if name == "spine" else -1))
    world = np.empty((F, J, 4))
    local = np.empty((F, J, 4))
    for j in range(J):
        p = target.skeleton.parents[j]
        if j in tgt_delta:
            world[:, j] = R.quat_mul(tgt_delta[j], target.world[j])
            parent = world[:, p] if p >= 0 else np.array([1.0, 0.0, 0.0, 0.0])
            local[:, j] = R.quat_mul(R.quat_conjugate(parent), world[:, j])
        else:
            local[:, j] = target.reference[j]
            world[:, j] = R.quat_mul(world[:, p], local[:, j]) if p >= 0 else local[:, j]
    local = R.quat_continuous_np(R.quat_normalize(local), axis=0)
    positions = np.broadcast_to(target.skeleton.offsets, (F, J, 3)).copy()
    hips_world = R.quat_rotate(convert, src_pos[:, source.roles.hips]) * (target.hip_height / source.hip_height)
    h = target.roles.hips
    p = target.skeleton.parents[h]
    if p >= 0:  # above the hips (Bandai's joint_Root): the reference pose, then the hips' place inside it
        top_world, top_pos = fk(np.broadcast_to(local, (F, J, 4)), positions, target.skeleton.parents)
        hips_world = R.quat_rotate(R.quat_conjugate(top_world[:, p]), hips_world - top_pos[:, p])
    positions[:, h] = hips_world
    return Motion(target.skeleton, motion.fps, local, positions, keys=motion.keys)


def _chain_deltas(delta: np.ndarray, source_chain: list[int], target_chain: list[int],
                  anchor: int) -> dict[int, np.ndarray]:
    """Target chain joint -> its turn ``(F, 4)``: the source's at the same place along the chain (slerped
    between the two nearest source joints), so both ends match the source's ends. A chain of one joint takes
    the source joint at ``anchor`` (0: the first, -1: the last)."""
    n, m = len(source_chain) - 1, len(target_chain) - 1
    if n == 0 or m == 0:
        k = source_chain[0] if n == 0 else source_chain[anchor]
        return {j: delta[:, k] for j in target_chain}
    out = {}
    for i, j in enumerate(target_chain):
        a, u = divmod(i * n, m)  # place along the source chain: joint a, u / m of the way to a + 1
        out[j] = delta[:, source_chain[a]] if u == 0 else R.quat_slerp(
            delta[:, source_chain[a]], delta[:, source_chain[a + 1]], np.full(len(delta), u / m))
    return out
