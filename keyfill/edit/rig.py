"""States of points of the skeleton and their Jacobians with respect to the controls.

A :class:`Point` is a joint plus a local offset (in the joint's frame); its
*state* at a time is its world position and, optionally, its world
orientation. :class:`Rig` computes states from control values (the curves
evaluated at some times) by forward kinematics over just the joints that
matter, and the analytic Jacobian ``ds/dc`` of Eq. 2 of Ciccone et al. 2019:

* translation control along the parent-frame axis ``v`` (in world):
  ``ds_P/dc = v``, ``ds_O/dc = 0``;
* rotation control, the Euler angle about axis ``v`` (in world, after the
  parent's rotation and the joint's earlier Euler factors) centred on the
  joint's world position ``r``: ``ds_P/dc = v x (s_P - r)``, ``ds_O/dc = v``.

Orientation rows are angular velocities in world coordinates. Joint local
rotations follow :mod:`keyfill.rotations` (intrinsic Euler angles in each
joint's order) and the composition of :mod:`keyfill.kinematics`; the tests
check states against :func:`keyfill.kinematics.fk` of the baked motion and
Jacobians against finite differences.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from keyfill.curves import Control
from keyfill.motion import Skeleton

_AXIS = {"X": 0, "Y": 1, "Z": 2}
_EYE = np.eye(3)


@dataclass(frozen=True, eq=False)
class Point:
    """A point rigidly attached to ``joint`` at ``offset (3,)`` in the joint's frame.

    ``orientation``: the point's state includes its orientation (the joint's).
    """

    joint: int
    offset: np.ndarray = field(default_factory=lambda: np.zeros(3))
    orientation: bool = False

    def __post_init__(self):
        object.__setattr__(self, "offset", np.asarray(self.offset, dtype=np.float64).reshape(3))

    @property
    def state_size(self) -> int:
        return 6 if self.orientation else 3

    def label(self, skeleton: Skeleton) -> str:
        name = skeleton.names[self.joint]
        if np.any(self.offset):
            name += " + (" + ", ".join(f"{x:g}" for x in self.offset) + ")"
        return name


class Frames(NamedTuple):
    """World frames of a set of joints at ``T`` times.

    ``moved``: ``(T, n + 1, 3, 7)``, per joint of the set (in the set's
    order; the last slot is the world frame) its world rotation matrix
    (columns 0-2) and, in world axes, the axes of its Euler angles (columns
    3-5) and its translation (column 6); ``place``: ``(T, n, 3)`` world
    positions; ``joint_at`` / ``control_at``: where a joint's frame / a
    control's axis is (``(slot, column)``), ``-1`` when not in the set.
    """

    moved: np.ndarray
    place: np.ndarray
    joint_at: np.ndarray
    control_at: np.ndarray

    def rot(self, joint: int, rows=slice(None)) -> np.ndarray:
        return self.moved[rows, self.joint_at[joint], :, :3]

    def pos(self, joint: int, rows=slice(None)) -> np.ndarray:
        return self.place[rows, self.joint_at[joint]]

    def axes(self, controls, rows=slice(None)) -> np.ndarray:
        """World axes ``(T, 3, m)`` of ``controls``."""
        at = self.control_at[controls]
        return self.moved[rows].swapaxes(2, 3)[:, at[:, 0], at[:, 1]].swapaxes(1, 2)


def _rotation_pattern(axes: np.ndarray) -> tuple[np.ndarray, ...]:
    """Flat positions, in ``m`` Euler factors of 3x3 entries each, of the entries that are
    1, cos, cos, -sin and sin for rotations about coordinate ``axes (m,)``."""
    base = 9 * np.arange(len(axes))
    i, j = (axes + 1) % 3, (axes + 2) % 3
    return (base + 4 * axes, base + 4 * i, base + 4 * j, base + 3 * i + j, base + 3 * j + i)


def _axis_matrices(angles: np.ndarray, pattern) -> np.ndarray:
    """``(T, m, 3, 3)`` rotations by ``angles (T, m)`` radians about the axes of ``pattern``."""
    T, m = angles.shape
    one, ci, cj, sij, sji = pattern
    out = np.zeros((T, 9 * m))
    c, s = np.cos(angles), np.sin(angles)
    out[:, one] = 1.0
    out[:, ci] = c
    out[:, cj] = c
    out[:, sij] = -s
    out[:, sji] = s
    return out.reshape(T, m, 3, 3)


class _Plan(NamedTuple):
    """Index arrays of :meth:`Rig.frames` for one set of joints (computed once per set)."""

    joints: np.ndarray  # (n,) joint indices, parents first
    parents: list  # position of each joint's parent in ``joints`` (-1: root)
    offsets: np.ndarray  # (n, 3)
    t_at: tuple  # (joint position, axis) of translation controls
    t_ctl: np.ndarray  # their control indices
    r_at: tuple  # (joint position, Euler slot) of rotation controls
    r_ctl: np.ndarray
    slot_axes: np.ndarray  # (n, 3) coordinate axis of each Euler slot
    pattern: tuple  # where the elementary rotations' entries go (_rotation_pattern)
    levels: list  # (positions, parent positions) of the joints at each depth below the roots
    roots: np.ndarray  # positions of joints without a parent in the set
    first_axes: np.ndarray  # (n, 3) the unit axis of each joint's first Euler angle
    joint_at: np.ndarray  # (J,) position of each skeleton joint in the set, -1 if absent
    control_at: np.ndarray  # (C, 2) (slot in ``moved``, column) of each control's world axis


class Rig:
    """Forward kinematics and Jacobians of points, driven by control values.

    Args:
        skeleton: the skeleton.
        controls: the curves' controls (index ``c`` in value arrays is ``controls[c]``).
    """

    def __init__(self, skeleton: Skeleton, controls: tuple[Control, ...]):
        self.skeleton = skeleton
        self.controls = controls
        J = skeleton.num_joints
        self.parents = [int(p) for p in skeleton.parents]
        orders = skeleton.euler_orders
        self.order_axes = [[_AXIS[a] for a in orders[j]] for j in range(J)]
        #: per joint: [(Euler slot 0-2, control)] and [(axis, control)]
        self.rot_controls: list[list[tuple[int, int]]] = [[] for _ in range(J)]
        self.trans_controls: list[list[tuple[int, int]]] = [[] for _ in range(J)]
        for c, ctl in enumerate(controls):
            if ctl.is_rotation:
                self.rot_controls[ctl.joint].append((orders[ctl.joint].index(ctl.channel[0]), c))
            else:
                self.trans_controls[ctl.joint].append((ctl.axis, c))
        self._moving: dict = {}
        self._plans: dict = {}
        self._joint_of = np.array([c.joint for c in controls], dtype=np.int64)
        self._is_rot = np.array([c.is_rotation for c in controls], dtype=bool)
        for lst in self.rot_controls:
            lst.sort()  # Euler slot order: the order the factors compose
        self.chains = []
        for j in range(J):
            chain, a = [], j
            while a >= 0:
                chain.append(a)
                a = self.parents[a]
            self.chains.append(chain[::-1])

    def controls_of(self, point: Point) -> frozenset[int]:
        """Controls that move ``point``'s state (the set ``C_s`` of section 3.3)."""
        key = (point.joint, bool(np.any(point.offset)), point.orientation)
        if key not in self._moving:
            self._moving[key] = self._controls_of(point)
        return self._moving[key]

    def _controls_of(self, point: Point) -> frozenset[int]:
        out = set()
        for a in self.chains[point.joint]:
            out.update(c for _, c in self.trans_controls[a])
            if a != point.joint or point.orientation or np.any(point.offset):
                out.update(c for _, c in self.rot_controls[a])
        return frozenset(out)

    def joints_for(self, points) -> list[int]:
        """Joints whose frames the states of ``points`` need, parents first."""
        return sorted({a for p in points for a in self.chains[p.joint]})

    def controls_on(self, joints: list[int]) -> np.ndarray:
        """Sorted indices of the controls of ``joints`` (what :meth:`frames` reads)."""
        plan = self._plan(joints)
        return np.sort(np.concatenate([plan.r_ctl, plan.t_ctl]))

    def _plan(self, joints: list[int]) -> _Plan:
        key = tuple(joints)
        if key not in self._plans:
            where = {a: k for k, a in enumerate(joints)}
            parents = [where.get(self.parents[a], -1) for a in joints]
            depth = []
            for p in parents:
                depth.append(0 if p < 0 else depth[p] + 1)
            t_at = [(where[a], ax) for a in joints for ax, _ in self.trans_controls[a]]
            r_at = [(where[a], slot) for a in joints for slot, _ in self.rot_controls[a]]
            slot_axes = np.array([self.order_axes[a] for a in joints], dtype=np.int64).reshape(-1, 3)
            joint_at = np.full(self.skeleton.num_joints, -1, dtype=np.int64)
            joint_at[joints] = np.arange(len(joints))
            control_at = np.full((len(self.controls), 2), -1, dtype=np.int64)
            for a in joints:  # Euler axes: columns 3-5 of the joint; translations: the parent's axes
                for slot, c in self.rot_controls[a]:
                    control_at[c] = where[a], 3 + slot
                for ax, c in self.trans_controls[a]:
                    p = where.get(self.parents[a], -1)
                    control_at[c] = (p if p >= 0 else len(joints)), ax
            levels = []
            for d in range(1, max(depth, default=0) + 1):
                ks = [k for k in range(len(joints)) if depth[k] == d]
                levels.append((np.array(ks), np.array([parents[k] for k in ks])))
            self._plans[key] = _Plan(
                joints=np.array(joints, dtype=np.int64),
                parents=parents,
                offsets=self.skeleton.offsets[joints],
                t_at=tuple(np.array(x, dtype=np.int64) for x in zip(*t_at)) if t_at else (),
                t_ctl=np.array([c for a in joints for _, c in self.trans_controls[a]], dtype=np.int64),
                r_at=tuple(np.array(x, dtype=np.int64) for x in zip(*r_at)) if r_at else (),
                r_ctl=np.array([c for a in joints for _, c in self.rot_controls[a]], dtype=np.int64),
                slot_axes=slot_axes,
                pattern=_rotation_pattern(slot_axes.reshape(-1)),
                levels=levels,
                roots=np.array([k for k in range(len(joints)) if parents[k] < 0]),
                first_axes=np.eye(3)[slot_axes[:, 0]],
                joint_at=joint_at,
                control_at=control_at,
            )
        return self._plans[key]

    def frames(self, values: np.ndarray, joints: list[int]) -> Frames:
        """World frames of ``joints`` (closed under parents, parents first) for values ``(T, C)``.

        Each joint's local rotation is the product of its three Euler factors
        (all joints at once); the hierarchy is then walked one depth at a
        time with one batched matrix product per depth: the parents' world
        rotations times, side by side, the joints' local rotations, the axes
        of their Euler angles (in the parent's frame) and their translations.
        """
        plan = self._plan(joints)
        T, n = values.shape[0], len(joints)
        angles = np.zeros((T, n, 3))
        if plan.r_at:
            angles[:, plan.r_at[0], plan.r_at[1]] = values[:, plan.r_ctl]
        elem = _axis_matrices(angles.reshape(T, 3 * n), plan.pattern).reshape(T, n, 3, 3, 3)
        # per joint, in its parent's frame: [local rotation | Euler axes 0, 1, 2 | translation]
        block = np.empty((T, n, 3, 7))
        first = elem[:, :, 0]
        both = first @ elem[:, :, 1]
        np.matmul(both, elem[:, :, 2], out=block[..., :3])
        ax, ar = plan.slot_axes, np.arange(n)
        block[..., 3] = plan.first_axes
        block[..., 4] = first.swapaxes(-1, -2)[:, ar, ax[:, 1]]
        block[..., 5] = both.swapaxes(-1, -2)[:, ar, ax[:, 2]]
        block[..., 6] = plan.offsets
        if plan.t_at:
            block[:, plan.t_at[0], plan.t_at[1], 6] = values[:, plan.t_ctl]
        moved = np.empty((T, n + 1, 3, 7))  # the same in world axes; slot n: the world frame
        moved[:, n, :, :3] = _EYE
        place = np.empty((T, n, 3))
        r = plan.roots
        moved[:, r] = block[:, r]
        place[:, r] = block[:, r][..., 6]
        for ks, ps in plan.levels:
            if len(ks) == 1:  # plain indices give views: no copies along a single chain
                k, p = int(ks[0]), int(ps[0])
                np.matmul(moved[:, p, :, :3], block[:, k], out=moved[:, k])
                np.add(place[:, p], moved[:, k, :, 6], out=place[:, k])
            else:
                moved[:, ks] = moved[:, ps, :, :3] @ block[:, ks]
                place[:, ks] = place[:, ps] + moved[:, ks][..., 6]
        return Frames(moved, place, plan.joint_at, plan.control_at)

    def state(self, frames: Frames, point: Point, rows=None) -> tuple[np.ndarray, np.ndarray]:
        """``(position (T, 3), rotation matrices (T, 3, 3))`` of ``point`` (at ``rows`` of ``frames`` only)."""
        sel = slice(None) if rows is None else rows
        rot = frames.rot(point.joint, sel)
        pos = frames.pos(point.joint, sel)
        if point.offset.any():
            pos = pos + rot @ point.offset
        return pos, rot

    def jacobian(self, frames: Frames, point: Point, position: np.ndarray, controls, rows=None) -> np.ndarray:
        """``ds/dc``: ``(T, 3 or 6, n)`` for ``controls (n,)`` at the point's ``position (T, 3)``.

        ``rows``: use only these rows (times) of ``frames``; ``position`` then
        holds just those rows. Columns of controls that do not move the point
        are zero.
        """
        T = position.shape[0]
        out = np.zeros((T, point.state_size, len(controls)))
        moving = self.controls_of(point)
        cols = [k for k, c in enumerate(controls) if c in moving]
        if not cols:
            return out
        ctl = np.asarray(controls, dtype=np.int64)[cols]
        sel = slice(None) if rows is None else rows
        v = frames.axes(ctl, sel)  # (T, 3, m)
        is_rot = self._is_rot[ctl]
        lever = position[:, :, None] - frames.place[sel][:, frames.joint_at[self._joint_of[ctl]]].swapaxes(1, 2)
        cross = v[:, [1, 2, 0]] * lever[:, [2, 0, 1]] - v[:, [2, 0, 1]] * lever[:, [1, 2, 0]]
        out[:, :3, cols] = np.where(is_rot, cross, v)
        if point.orientation:
            out[:, 3:, cols] = np.where(is_rot, v, 0.0)
        return out
