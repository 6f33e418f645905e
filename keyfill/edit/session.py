"""What the edits of one file share while they are applied.

* :class:`Settings`: the solver's settings (the paper's values where it gives them);
* :class:`EditReport`: what one edit did (the ``--json`` record);
* :class:`WorkingCurves`: mutable copies of the curves' key arrays, and the
  states of points on them;
* :class:`Session`: the working curves and the input, the edit file's
  tolerances, limits and stiffness, and how messages name things.

Lengths are in the curves file's units; ``epsilon`` (the band of pins and
contacts) and ``tolerance`` (how close a target must be reached, ``kappa``)
default to 1e-4 and 1e-3 times the character's size (the extent of its rest
pose).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from keyfill import rotations as R
from keyfill.curves import CurveArrays, Curves, evaluate_segments
from keyfill.edit import qp as QP
from keyfill.edit.edits import Contact, EditFile, Manipulation
from keyfill.edit.rig import Point, Rig
from keyfill.errors import InfeasibleError
from keyfill.kinematics import fk


@dataclass(frozen=True)
class Settings:
    """Solver settings (the paper's values where it gives them).

    Attributes:
        weights: the weights of Eq. 10 and the regulariser lambda.
        patience: iterations without improvement before an edit is rejected.
        max_iterations: hard cap on QP solves per edit.
        width_margin: fraction of a segment kept free at both ends of the
            width bounds of Eq. 7.
        band: the QP's band (Eq. 11) as a fraction of epsilon; the result
            is accepted when the true (non-linear) violation is within epsilon.
        timing_stiffness: stiffness of the widths (X, frames) relative to the
            heights (Y) in D of Eq. 4. Widths move the curve non-linearly (through
            the time cubic) and change timing, which timing edits (Eq. 12) own;
            10 makes move edits reshape first and converge in fewer iterations.
        epsilon_scale, tolerance_scale: defaults relative to the character size.
        contact_slide: how far (relative to the character size) a contact's
            point may be apart at its two keys; it then glides straight between them.
    """

    weights: QP.Weights = field(default_factory=QP.Weights)
    patience: int = 5
    max_iterations: int = 50
    width_margin: float = 0.01
    band: float = 0.25
    timing_stiffness: float = 10.0
    epsilon_scale: float = 1e-4
    tolerance_scale: float = 1e-3
    contact_slide: float = 0.01


@functools.lru_cache(maxsize=64)
def character_size(skeleton) -> float:
    """The largest extent of the rest pose (joints and End Sites), in file units."""
    rest = skeleton.rest_world_positions()
    pts = [rest]
    ident = R.quat_identity((skeleton.num_joints,))
    world_rot = fk(ident, skeleton.offsets, skeleton.parents)[0]
    for j, off in skeleton.end_sites:
        pts.append((rest[j] + R.quat_rotate(world_rot[j], off))[None])
    size = float(np.ptp(np.concatenate(pts), axis=0).max())
    return size if size > 0 else 1.0


@dataclass
class EditReport:
    """What one edit did (the ``--json`` record).

    ``time`` and ``segment`` are in frames; ``distance`` and the pin and
    contact violations in file units; ``worst_limit_margin`` in degrees for
    rotations (file units for translations); times of the solve in ms.
    """

    edit: int
    kind: str
    time: float
    segment: tuple[float, float]
    joint: str | None = None
    reached: bool = True
    iterations: int = 0
    distance: float | None = None
    optimised_controls: int = 0
    optimised_tangents: int = 0
    constraints: list[str] = field(default_factory=list)
    worst_pin_violation: float | None = None
    worst_contact_violation: float | None = None
    worst_limit_margin: float | None = None
    worst_limit_control: str | None = None
    solve_ms: float = 0.0
    solve_cpu_ms: float = 0.0

    def as_dict(self) -> dict:
        return dict(self.__dict__)


@functools.lru_cache(maxsize=16)
def _rig(skeleton, controls) -> Rig:
    """One :class:`Rig` (and its caches) per skeleton and control set, across edits and files."""
    return Rig(skeleton, controls)


class WorkingCurves:
    """Mutable copies of the key arrays of ``curves`` while edits are applied.

    ``values (K, C)``, ``in_tan``/``out_tan (K, C, 2)`` and ``broken (K, C)``
    change; ``times (K,)`` never do.
    """

    def __init__(self, curves: Curves):
        self.curves = curves
        self.rig = _rig(curves.skeleton, curves.controls)
        self.times = curves.times
        self.values = curves.values.copy()
        self.in_tan = curves.in_tan.copy()
        self.out_tan = curves.out_tan.copy()
        self.broken = curves.broken.copy()

    def arrays(self) -> CurveArrays:
        return CurveArrays(self.times, self.values, self.in_tan, self.out_tan)

    def snapshot(self) -> CurveArrays:
        return CurveArrays(self.times, self.values.copy(), self.in_tan.copy(), self.out_tan.copy())

    def result(self) -> Curves:
        return self.curves.replace(values=self.values, in_tan=self.in_tan, out_tan=self.out_tan, broken=self.broken)

    def segment(self, t) -> np.ndarray:
        """Segment index (keys ``s``, ``s+1``) of each time, clipped to ``[0, K-2]``."""
        return np.minimum(np.maximum(np.searchsorted(self.times, t, side="right") - 1, 0), len(self.times) - 2)

    def states(self, points, times, arrays: CurveArrays | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
        """``(positions (T, 3), rotations (T, 3, 3))`` of each point at ``times (T,)`` (frames).

        ``arrays``: other key arrays to evaluate (the input's), by default the working ones.
        """
        times = np.asarray(times, dtype=np.float64)
        joints = self.rig.joints_for(points)
        cols = self.rig.controls_on(joints)
        values = np.zeros((len(times), len(self.curves.controls)))
        if len(cols):
            ev = evaluate_segments(arrays or self.arrays(), times, self.segment(times), cols)
            values[:, cols] = ev.value
        frames = self.rig.frames(values, joints)
        return [self.rig.state(frames, p) for p in points]


def rotvec(target: np.ndarray, current: np.ndarray) -> np.ndarray:
    """World rotation vectors ``(..., 3)`` (radians) taking ``current`` to ``target`` (matrices ``(..., 3, 3)``)."""
    rel = target @ np.swapaxes(current, -1, -2)
    return R.quat_to_rotvec(R.quat_from_matrix(rel))


class Session:
    """The state the edits of one edit file share, edit after edit.

    Attributes:
        work: the working curves (what the edits change).
        original: the input's key arrays; pins keep the input's trajectories.
        eps, kappa: the constraint band and the reach tolerance (file units).
        scale: the character's size; it weighs orientations (radians) against
            lengths and scales the QP.
        stiffness: ``(C,)`` the diagonal of D (Eq. 4).
        low, high: ``(C,)`` limits of each control (``-inf``/``inf`` when none).
    """

    def __init__(self, curves: Curves, ef: EditFile, solver: str, best_effort: bool, settings: Settings):
        self.work = WorkingCurves(curves)
        self.original = self.work.snapshot()
        self.ef = ef
        self.sk = curves.skeleton
        self.solver = QP.check_solver(solver)
        self.best_effort = best_effort
        self.settings = settings
        size = character_size(self.sk)
        self.scale = size
        self.eps = ef.epsilon if ef.epsilon is not None else settings.epsilon_scale * size
        self.kappa = ef.tolerance if ef.tolerance is not None else settings.tolerance_scale * size
        C = curves.num_controls
        self.stiffness = ef.stiffness if ef.stiffness is not None else np.ones(C)
        self.low = np.full(C, -np.inf)
        self.high = np.full(C, np.inf)
        for c, (lo, hi) in ef.limits.items():
            self.low[c], self.high[c] = lo, hi

    # --- names in messages and reports -------------------------------------

    def name(self, c: int) -> str:
        return self.work.curves.controls[c].name(self.sk)

    def pin_name(self, p: Point) -> str:
        return f"pin {p.label(self.sk)}"

    def contact_name(self, c: Contact) -> str:
        return f"contact {c.point.label(self.sk)} frames {c.start:g}-{c.end:g}"

    def edit_label(self, edit: Manipulation) -> str:
        where = "key" if self.work.curves.key_index(edit.time) is not None else "frame"
        return f"edit {edit.index} ({edit.point.label(self.sk)} at {where} {edit.time:g})"

    def infeasible(self, what: str, distance: float, blocking: list[str], extra: str) -> InfeasibleError:
        """The error of an edit that stops ``distance`` from its target; ``blocking`` names the culprits."""
        if blocking:
            shown = blocking[:6] + ([f"and {len(blocking) - 6} more"] if len(blocking) > 6 else [])
            why = "conflicting constraints: " + ", ".join(shown)
        else:
            why = extra
        return InfeasibleError(
            f"{what} cannot reach its target: it stops {distance:.4g} away (tolerance {self.kappa:.3g}); {why}"
        )

    # --- where points are ----------------------------------------------------

    def contact_target(self, contact: Contact, times: np.ndarray) -> np.ndarray:
        """``(T, 3)``: where a contact holds its point at ``times``, straight between its two keys."""
        ends = self.work.states([contact.point], [contact.start, contact.end])[0][0]
        u = ((times - contact.start) / (contact.end - contact.start))[:, None]
        return ends[0] + u * (ends[1] - ends[0])

    def distance_now(self, point, t, target_pos, target_rot) -> float:
        """How far ``point`` is from its target at time ``t`` on the working curves (file units)."""
        pos, rot = self.work.states([point], [t])[0]
        d2 = float(np.sum((target_pos - pos[0]) ** 2))
        if target_rot is not None:
            d2 += float(np.sum((self.scale * rotvec(target_rot, rot[0])) ** 2))
        return float(np.sqrt(d2))
