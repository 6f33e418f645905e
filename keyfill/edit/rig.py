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

from keyfill.edit.curves import Control
from keyfill.motion import Skeleton

_AXIS = {"X": 0, "Y": 1, "Z": 2}


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
    """World frames of some joints at ``T`` times.

    ``rot[j]``: ``(T, 3, 3)`` world rotation matrices; ``pos[j]``: ``(T, 3)``
    world positions; ``axis[c]``: ``(T, 3)`` world axis of control ``c``
    (see the module docstring); dicts keyed by joint / control index.
    """

    rot: dict
    pos: dict
    axis: dict


def _axis_matrices_for(angles: np.ndarray, axes) -> np.ndarray:
    """``(T, n, 3, 3)`` rotations by ``angles (T, n)`` radians about coordinate ``axes (n,)``."""
    T, n = angles.shape
    c, s = np.cos(angles), np.sin(angles)
    m = np.zeros((T, n, 3, 3))
    k = np.arange(n)
    ax = np.asarray(axes, dtype=np.int64)
    i, j = (ax + 1) % 3, (ax + 2) % 3
    m[:, k, ax, ax] = 1.0
    m[:, k, i, i] = c
    m[:, k, j, j] = c
    m[:, k, i, j] = -s
    m[:, k, j, i] = s
    return m


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

    def frames(self, values: np.ndarray, joints: list[int]) -> Frames:
        """World frames of ``joints`` (closed under parents, parents first) for values ``(T, C)``."""
        T = values.shape[0]
        offsets = self.skeleton.offsets
        ident = np.broadcast_to(np.eye(3), (T, 3, 3))
        # all elementary rotations of the joints' Euler angles at once: (T, n, 3, 3)
        rc = [c for a in joints for _, c in self.rot_controls[a]]
        elem = _axis_matrices_for(values[:, rc], [self.controls[c].axis for c in rc])
        k = 0
        rot, pos, axis = {}, {}, {}
        for a in joints:
            p = self.parents[a]
            wp = rot[p] if p >= 0 else ident
            t = offsets[a]
            if self.trans_controls[a]:
                t = np.broadcast_to(t, (T, 3)).copy()
                for ax, c in self.trans_controls[a]:
                    t[:, ax] = values[:, c]
                    axis[c] = wp[..., :, ax]
                step = (wp @ t[..., None])[..., 0] if p >= 0 else t
            else:
                step = wp @ t if p >= 0 else np.broadcast_to(t, (T, 3))
            pos[a] = pos[p] + step if p >= 0 else np.array(step)
            w = wp
            for slot, c in self.rot_controls[a]:
                axis[c] = w[..., :, self.order_axes[a][slot]]
                w = elem[:, k] if w is ident else w @ elem[:, k]
                k += 1
            rot[a] = w
        return Frames(rot, pos, axis)

    def state(self, frames: Frames, point: Point, rows=None) -> tuple[np.ndarray, np.ndarray]:
        """``(position (T, 3), rotation matrices (T, 3, 3))`` of ``point`` (at ``rows`` of ``frames`` only)."""
        rot = frames.rot[point.joint]
        pos = frames.pos[point.joint]
        if rows is not None:
            rot, pos = rot[rows], pos[rows]
        if np.any(point.offset):
            pos = pos + rot @ point.offset
        return pos, rot

    def jacobian(self, frames: Frames, point: Point, position: np.ndarray, controls, rows=None) -> np.ndarray:
        """``ds/dc``: ``(T, 3 or 6, n)`` for ``controls (n,)`` at the point's ``position (T, 3)``.

        ``rows``: use only these rows (times) of ``frames``; ``position`` then
        holds just those rows. Columns of controls that do not move the point
        are zero.
        """
        T = position.shape[0]
        sel = slice(None) if rows is None else rows
        out = np.zeros((T, point.state_size, len(controls)))
        moving = self.controls_of(point)
        cols = [k for k, c in enumerate(controls) if c in moving]
        if not cols:
            return out
        ctl = [self.controls[controls[k]] for k in cols]
        v = np.stack([frames.axis[controls[k]][sel] for k in cols], axis=-1)  # (T, 3, m)
        is_rot = np.array([c.is_rotation for c in ctl])
        lever = position[:, :, None] - np.stack([frames.pos[c.joint][sel] for c in ctl], axis=-1)
        cross = v[:, [1, 2, 0]] * lever[:, [2, 0, 1]] - v[:, [2, 0, 1]] * lever[:, [1, 2, 0]]
        out[:, :3, cols] = np.where(is_rot, cross, v)
        if point.orientation:
            out[:, 3:, cols] = np.where(is_rot, v, 0.0)
        return out
