"""Tangent-space optimisation (Ciccone, Oztireli & Sumner 2019): edits of Bezier curves.

:func:`edit_tangents` applies the edits of an edit file in order. A *move*
edit drags a point of the skeleton at a time between two keys toward a
target by changing only the tangents of that segment (key times and values
never change, no key is added):

1. *Reduction* (section 3.3). ``C`` starts as the controls that move the
   point (``C_s``) minus locked ones. Each pin or contact with controls
   ``C_j`` is then (1) ignored when ``C`` and ``C_j`` are disjoint, (2)
   dropped with ``C := C - C_j`` when ``C_j`` is inside ``C_s`` (those
   controls stay as they are, so the point cannot move), or (3) kept with
   ``C := C + C_j``. Only the tangents of ``C`` at the two keys of the
   segment are variables: ``(X, Y)`` of the out tangent at the first key and
   of the in tangent at the second, 4 per control. A *unified* key keeps
   its two slopes equal: the tangent on the other side follows, scaled by
   the ratio of the widths, so the neighbouring segment changes too and is
   included wherever constraints are sampled.
2. *Sampling*. Each kept pin or contact is sampled at the frames strictly
   inside the segments that the variables change (at most ``4 |C_j|``
   evenly spaced times per segment), plus the edit's hold frames.
3. *The QP of Eq. 10* (:mod:`keyfill.edit.qp`) with the Jacobians of
   :mod:`keyfill.edit.rig` times the analytic ``dc/dtheta`` of the Bezier
   form: at a time in the segment with Bezier parameter ``l``, ``dc/dY_out =
   3 l (1-l)^2``, ``dc/dY_in = -3 l^2 (1-l)`` and ``dc/dX = -c'(t) dc/dY``
   (the width moves the curve along time). Bounds: Eq. 7 on widths (with a
   1 % margin so timing stays strictly increasing), Eqs. 8-9 on heights for
   controls with limits (the 4/3 rule of Appendix A: limits then hold at
   every time, not only at samples).
4. *Iteration* (section 3.3): re-linearise and solve again until the point
   is within ``tolerance`` of its target with every kept constraint within
   ``epsilon``; after 5 iterations without improvement the edit is rejected
   (:class:`~keyfill.errors.InfeasibleError`, naming the constraints whose
   multipliers block it) unless ``best_effort``. A step whose constraints
   break by more than the linear model allows is *mended* (a QP that holds
   the moved point and restores them, from the step's end), steps that make
   things worse are halved, and a trust radius limits how far one step aims.

Pins keep the input's trajectories. A contact holds its point on the
straight path between its positions at the two keys (still when they agree;
up to 1 % of the character's size apart is accepted for captured feet) and
never further from it than the input already was.

A *timing* edit applies Eq. 12 (with the tangent's slope kept, so unified
keys stay unified). :func:`pose` is the static case of Eq. 13: it changes
the values at one key (the tangents stay) with pins held at that key.

Defaults: ``epsilon = 1e-4`` and ``tolerance = 1e-3`` times the character's
size (the extent of its rest pose), in the file's units.
"""

from __future__ import annotations

import functools
import time as _time
from dataclasses import dataclass, field

import numpy as np

from keyfill import rotations as R
from keyfill.curves import CurveArrays, Curves, SegmentEval, evaluate_segments
from keyfill.edit import qp as QP
from keyfill.edit.edits import Contact, EditFile, Manipulation, TimingEdit
from keyfill.edit.rig import Point, Rig
from keyfill.errors import DataError, InfeasibleError
from keyfill.kinematics import fk

#: samples per frame of the dense limit check
LIMIT_SAMPLES_PER_FRAME = 10


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
    """What one edit did (the ``--json`` record)."""

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


# --- working state -----------------------------------------------------------


@functools.lru_cache(maxsize=16)
def _rig(skeleton, controls) -> Rig:
    """One :class:`Rig` (and its caches) per skeleton and control set, across edits and files."""
    return Rig(skeleton, controls)


class _Work:
    """Mutable copies of the curves' key arrays while edits are applied."""

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
        return np.minimum(np.maximum(np.searchsorted(self.times, t, side="right") - 1, 0), len(self.times) - 2)

    def states(self, points, times, arrays: CurveArrays | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
        """``(positions (T, 3), rotations (T, 3, 3))`` of each point at ``times``."""
        times = np.asarray(times, dtype=np.float64)
        joints = self.rig.joints_for(points)
        cols = self.rig.controls_on(joints)
        values = np.zeros((len(times), len(self.curves.controls)))
        if len(cols):
            ev = evaluate_segments(arrays or self.arrays(), times, self.segment(times), cols)
            values[:, cols] = ev.value
        frames = self.rig.frames(values, joints)
        return [self.rig.state(frames, p) for p in points]


def tangent_derivatives(ev: SegmentEval) -> np.ndarray:
    """``(T, n, 4)``: derivatives of ``c(t)`` with respect to the segment's own tangents.

    Columns: width and height of the out tangent at the segment's first key,
    width and height of the in tangent at its last key. Heights enter the
    Bezier linearly (``b1``, ``-b2``); a width moves its control point in
    time, which shifts the curve by minus its slope times the same weight.
    """
    sb1 = ev.slope * ev.b1
    sb2 = ev.slope * ev.b2
    return np.stack([-sb1, ev.b1, sb2, -ev.b2], axis=-1)



def _rotvec(target: np.ndarray, current: np.ndarray) -> np.ndarray:
    """World rotation vectors ``(..., 3)`` taking ``current`` to ``target`` (rotation matrices)."""
    rel = target @ np.swapaxes(current, -1, -2)
    return R.quat_to_rotvec(R.quat_from_matrix(rel))


@dataclass(eq=False)
class _Constraint:
    """A pin, contact or hold as the QP sees it."""

    name: str
    kind: str  # "pin", "contact" or "hold"
    point: Point
    start: float
    end: float
    controls: frozenset
    contact: Contact | None = None
    times: np.ndarray = None
    target_pos: np.ndarray = None
    target_rot: np.ndarray | None = None
    allow: np.ndarray | float = 0.0  # per sample: the input's own distance from the target
    allow_rows: np.ndarray | float = 0.0  # the same per QP row (coordinate)


# --- the iteration shared by edits and poses ---------------------------------


@dataclass
class _Linear:
    """The problem at the current variables: residuals now, Jacobians on demand.

    ``jacobians()`` returns ``(Jm, Jc)``, the rows of ``rm`` and ``rc``
    differentiated by the variables; it is only called when another QP is
    needed (an edit that converges does not pay for its last Jacobian).
    """

    distance: float
    violation: float
    rm: np.ndarray
    rc: np.ndarray
    rows: list  # (constraint name, number of rows of rc)
    jacobians: object
    allow: np.ndarray | float = 0.0  # per row of rc: error the input itself has there


def _iterate(theta0, lin0, relinearize, lb, ub, stiffness, pairs, eps, kappa, solver, settings, size):
    """Solve, re-linearise, repeat (section 3.3).

    ``lin0`` is the problem at ``theta0``; ``relinearize(theta)`` applies new
    variables to the curves and linearises there. Returns ``(best theta or
    None, its distance, iterations, reached, last linearisation, last (lin,
    QP result))``; the best theta is the closest to the target among those
    whose constraints hold within ``eps``. Lengths enter the QP in units of
    a hundredth of the character's ``size``, so the weights of Eq. 10 act
    the same on a lamp in metres and a human in centimetres.
    """
    theta = np.minimum(np.maximum(theta0, lb), ub)  # tangents the limits forbid are brought inside first
    lin = lin0 if np.array_equal(theta, theta0) else relinearize(theta)
    best_theta, best_d = (theta.copy(), lin.distance) if lin.violation <= eps else (None, np.inf)
    count = [0]  # QPs solved
    last = [None]
    pair_vars, pair_other = pairs
    band = settings.band * eps
    k = 100.0 / size

    def step(at, lin_at, aim):
        """The QP step from ``at``: toward the target by ``aim`` (0: mend the constraints only)."""
        Jm, Jc = lin_at.jacobians()
        rm = lin_at.rm * (aim / lin_at.distance) if lin_at.distance > aim else lin_at.rm
        mending = aim == 0.0
        if mending:  # the smallest change that restores the constraints, holding the point (no E_b pull)
            rm = 0.0 * rm
        pv = pair_vars if not mending else pair_vars[:0]
        gap = at[pv] - pair_other[: len(pv)] if len(pv) else None
        program = QP.assemble(
            k * Jm, k * rm, stiffness, lb - at, ub - at, k * Jc, k * lin_at.rc, k * (band + lin_at.allow),
            pv, gap, settings.weights,
        )  # fmt: skip
        res = QP.solve(program, solver)
        if res.x is None and lin_at.violation <= eps:
            # the band cannot be met from here: let rows keep their current error (within eps)
            slack = k * np.maximum(band + lin_at.allow, np.abs(lin_at.rc))
            program.h = np.concatenate([k * lin_at.rc + slack, slack - k * lin_at.rc])
            res = QP.solve(program, solver)
        count[0] += 1
        last[0] = (lin_at, res)
        return res.x

    radius = np.inf  # how far toward the target one step aims (shrinks when the linear model fails)
    stall = 0
    while best_d >= kappa and count[0] < settings.max_iterations and stall < settings.patience:
        if lin.violation > eps and best_theta is not None:
            # constraints broken by the linear model's error: mend them, holding the moved point
            x = step(theta, lin, 0.0)
            if x is None:
                break
            trial = np.minimum(np.maximum(theta + x, lb), ub)
            new = relinearize(trial)
            if new.violation < lin.violation:
                theta, lin = trial, new
            else:  # cannot mend: back to the best point, aim closer
                theta, radius = best_theta.copy(), 0.25 * min(radius, lin.distance)
                lin = relinearize(theta)
                stall += 1
                continue
        else:
            aim = min(radius, lin.distance)
            x = step(theta, lin, aim)
            if x is None:
                break
            for alpha in (1.0, 0.5, 0.25, 0.125):
                trial = np.minimum(np.maximum(theta + alpha * x, lb), ub)
                new = relinearize(trial)
                if new.violation > eps and lin.violation <= eps and count[0] < settings.max_iterations:
                    # second-order correction: mend at the trial point before judging the step
                    x2 = step(trial, new, 0.0)
                    if x2 is not None:
                        fixed = np.minimum(np.maximum(trial + x2, lb), ub)
                        mended = relinearize(fixed)
                        if mended.violation < new.violation:
                            trial, new = fixed, mended
                if _merit(new, eps) < _merit(lin, eps):
                    break
            else:  # no progress: go back to the best point and aim closer
                radius = 0.25 * aim
                if best_theta is not None:
                    theta = best_theta.copy()
                lin = relinearize(theta)
                stall += 1
                continue
            theta, lin = trial, new
            if lin.violation > eps:
                radius = 0.5 * aim
            elif alpha == 1.0:
                radius = 2.0 * radius
        # "improved": closer by 1 % at least (slow creeping toward an unreachable target stalls)
        better = best_d - max(1e-3 * kappa, 0.01 * best_d) if np.isfinite(best_d) else np.inf
        if lin.violation <= eps and lin.distance < better:
            best_theta, best_d, stall = theta.copy(), lin.distance, 0
        elif lin.violation <= eps:
            stall += 1
    return best_theta, best_d, count[0], best_d < kappa, lin, last[0]


def _merit(lin: _Linear, eps: float) -> float:
    return lin.distance + 5.0 * max(lin.violation - eps, 0.0)


def _diagnose(last, var_groups, constraint_names) -> list[str]:
    """Constraints whose multipliers are large in the last QP: what blocks the edit."""
    if last is None:
        return []
    lin, res = last
    if res.x is None:  # no multipliers: name the constraints and limits that were in play
        return list(constraint_names) + sorted({g for g in var_groups if g and g.startswith("limit")})
    score: dict[str, float] = {}
    k = len(lin.rc)
    z = np.abs(res.z[:k]) + np.abs(res.z[k:]) if len(res.z) == 2 * k else np.zeros(k)
    start = 0
    for name, n in lin.rows:
        score[name] = score.get(name, 0.0) + float(z[start : start + n].sum())
        start += n
    for g, zb in zip(var_groups, np.abs(res.z_box)):
        if g:
            score[g] = score.get(g, 0.0) + float(zb)
    top = max(score.values(), default=0.0)
    if top <= 1e-9:
        return []
    return [name for name, s in sorted(score.items(), key=lambda kv: -kv[1]) if s >= 0.05 * top]


# --- edits ---------------------------------------------------------------------


class _Editor:
    def __init__(self, curves: Curves, ef: EditFile, solver: str, best_effort: bool, settings: Settings):
        self.work = _Work(curves)
        self.original = self.work.snapshot()  # pins keep the input's trajectories, edit after edit
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

    # --- shared pieces -------------------------------------------------

    def name(self, c: int) -> str:
        return self.work.curves.controls[c].name(self.sk)

    def pin_name(self, p: Point) -> str:
        return f"pin {p.label(self.sk)}"

    def contact_name(self, c: Contact) -> str:
        return f"contact {c.point.label(self.sk)} frames {c.start:g}-{c.end:g}"

    def contact_target(self, contact: Contact, times: np.ndarray) -> np.ndarray:
        ends = self.work.states([contact.point], [contact.start, contact.end])[0][0]
        u = ((times - contact.start) / (contact.end - contact.start))[:, None]
        return ends[0] + u * (ends[1] - ends[0])

    def check_contacts(self, contacts) -> None:
        """A contact's point must be (nearly) at the same place at its two keys: keys never move.

        Captured feet glide a little while planted, so up to ``contact_slide``
        (a fraction of the character's size) is accepted; the contact then
        holds the point on the straight line between its key positions.
        """
        limit = max(self.kappa, self.settings.contact_slide * self.scale)
        for c in contacts:
            ends = self.work.states([c.point], [c.start, c.end])[0][0]
            gap = float(np.linalg.norm(ends[1] - ends[0]))
            if gap > limit:
                raise DataError(
                    f"{self.contact_name(c)}: the point is {gap:.4g} apart at the two keys, more than a contact "
                    f"may slide ({limit:.3g}); keys never move, so pick keys where it stands still "
                    "(or move it there with keyfill pose first)"
                )

    def reduce(self, edit, point: Point, pins, contacts):
        """Section 3.3: the optimised controls ``C`` (never empty) and the constraints kept.

        Raises :class:`InfeasibleError` naming ``edit`` when no control can move ``point``.
        """
        rig = self.work.rig
        fixed = set(self.ef.locked)  # locked controls, and those a pin or contact of case 2 fixes
        Cs = rig.controls_of(point) - fixed
        C = set(Cs)
        kept = []
        cands = [_Constraint(self.pin_name(p), "pin", p, -np.inf, np.inf, frozenset()) for p in pins]
        cands += [
            _Constraint(self.contact_name(c), "contact", c.point, c.start, c.end, frozenset(), c) for c in contacts
        ]
        for con in cands:
            Cj = rig.controls_of(con.point) - fixed
            if not C & Cj:
                continue
            if Cj <= Cs:
                C -= Cj
                fixed |= Cj
                continue
            con.controls = Cj
            kept.append(con)
            C |= Cj
        if not C:
            raise InfeasibleError(
                f"{self.edit_label(edit)}: nothing can move the point: every control that moves it is locked or "
                "fixed by a pin"
            )
        for con in kept:  # a later case 2 may have fixed some of a kept constraint's controls
            con.controls = con.controls - fixed
        return sorted(C), [con for con in kept if con.controls & C]

    def limits_margin(self, lo_t: float, hi_t: float) -> tuple[float | None, str | None]:
        """Worst ``min(c - low, high - c)`` over limited controls, 10 samples per frame."""
        if not self.ef.limits:
            return None, None
        n = max(round((hi_t - lo_t) * LIMIT_SAMPLES_PER_FRAME), 1)
        t = np.linspace(lo_t, hi_t, n + 1)
        cols = np.array(sorted(self.ef.limits))
        vals = evaluate_segments(self.work.arrays(), t, self.work.segment(t), cols).value
        margin = np.minimum(vals - self.low[cols], self.high[cols] - vals)  # (T, n)
        unit = np.array([np.degrees(1.0) if self.work.curves.controls[c].is_rotation else 1.0 for c in cols])
        margin = margin * unit
        i = int(np.argmin(margin.min(axis=0)))
        return float(margin[:, i].min()), self.name(cols[i])

    def frames_in(self, lo_t: float, hi_t: float) -> np.ndarray:
        last = self.work.curves.num_frames - 1
        return np.arange(max(np.ceil(lo_t), 0), min(np.floor(hi_t), last) + 1, dtype=np.float64)

    def check_constraints(self, report: EditReport, pins, contacts, lo_t, hi_t) -> None:
        """Dense checks at every frame of the changed time range (the report's worst values).

        Pins are measured against the input's trajectories, contacts against
        their still position.
        """
        frames = self.frames_in(lo_t, hi_t)
        if pins and len(frames):
            old = self.work.states(pins, frames, self.original)
            new = self.work.states(pins, frames)
            worst = 0.0
            for p, (op, orot), (np_, nrot) in zip(pins, old, new):
                d = np.linalg.norm(np_ - op, axis=-1)
                if p.orientation:
                    d = np.hypot(d, self.scale * np.linalg.norm(_rotvec(orot, nrot), axis=-1))
                worst = max(worst, float(d.max()))
            report.worst_pin_violation = worst
        touched = [c for c in contacts if c.start < hi_t and c.end > lo_t]
        if touched:
            worst = 0.0
            for c in touched:
                f = frames[(frames >= c.start) & (frames <= c.end)]
                if len(f):
                    target = self.contact_target(c, f)
                    now = np.linalg.norm(self.work.states([c.point], f)[0][0] - target, axis=-1)
                    given = np.linalg.norm(self.work.states([c.point], f, self.original)[0][0] - target, axis=-1)
                    worst = max(worst, float(np.maximum(now - given, 0.0).max()))
            report.worst_contact_violation = worst
        report.worst_limit_margin, report.worst_limit_control = self.limits_margin(lo_t, hi_t)

    def infeasible(self, what: str, distance: float, blocking: list[str], extra: str) -> InfeasibleError:
        if blocking:
            shown = blocking[:6] + ([f"and {len(blocking) - 6} more"] if len(blocking) > 6 else [])
            why = "conflicting constraints: " + ", ".join(shown)
        else:
            why = extra
        return InfeasibleError(
            f"{what} cannot reach its target: it stops {distance:.4g} away (tolerance {self.kappa:.3g}); {why}"
        )

    # --- move edits ----------------------------------------------------

    def manipulate(self, edit: Manipulation) -> EditReport:
        t_start, cpu_start = _time.perf_counter(), _time.thread_time()
        work, rig, S = self.work, self.work.rig, self.settings
        times, K = work.times, len(work.times)
        s = int(work.segment(edit.time))
        a, b = s, s + 1
        point = edit.point
        pins = list(self.ef.pins) + list(edit.pins)
        contacts = list(self.ef.contacts) + list(edit.contacts)

        C, kept = self.reduce(edit, point, pins, contacts)
        Carr = np.array(C)
        nC = len(C)
        n = 4 * nC
        if edit.break_tangents:
            work.broken[a, Carr] = work.broken[b, Carr] = True
        # unified keys: the tangent on the other side follows with the ratio of the widths
        ratio_a = np.zeros(nC)
        ratio_b = np.zeros(nC)
        uni_a = ~work.broken[a, Carr]
        uni_b = ~work.broken[b, Carr]
        wa, wb = work.out_tan[a, Carr, 0], work.in_tan[b, Carr, 0]
        ok_a = uni_a & (wa > 0) & (work.in_tan[a, Carr, 0] > 0)
        ok_b = uni_b & (wb > 0) & (work.out_tan[b, Carr, 0] > 0)
        ratio_a[ok_a] = work.in_tan[a, Carr[ok_a], 0] / wa[ok_a]
        ratio_b[ok_b] = work.out_tan[b, Carr[ok_b], 0] / wb[ok_b]
        work.broken[a, Carr[uni_a & ~ok_a]] = True  # degenerate widths: only this side can change
        work.broken[b, Carr[uni_b & ~ok_b]] = True
        uni_a, uni_b = ok_a, ok_b
        prev_seg = uni_a & (s >= 1)
        next_seg = uni_b & (s + 1 <= K - 2)

        # the segments each control's variables change; constraint samples
        aff = [{s} | ({s - 1} if prev_seg[i] else set()) | ({s + 1} if next_seg[i] else set()) for i in range(nC)]
        lo_seg = s - 1 if prev_seg.any() else s
        hi_seg = s + 1 if next_seg.any() else s
        pos_in_C = {c: i for i, c in enumerate(C)}
        samples: list[_Constraint] = []
        for con in kept:
            inter = [pos_in_C[c] for c in con.controls if c in pos_in_C]
            segs = sorted(set().union(*(aff[i] for i in inter))) if inter else []
            t = self.sample_times(segs, con.start, con.end, 4 * len(inter))
            if len(t):
                con.times = t
                samples.append(con)
        for h in edit.holds:
            name = f"hold {point.label(self.sk)} at frame {h:g}"
            samples.append(_Constraint(name, "hold", point, h, h, frozenset(C), times=np.array([h])))

        # all times the iteration evaluates: the edited time, then each constraint's samples
        T_all = np.concatenate([[edit.time]] + [con.times for con in samples])
        rows, start = [], 1
        for con in samples:
            rows.append(np.arange(start, start + len(con.times)))
            start += len(con.times)
        seg_all = work.segment(T_all)
        pts = [point] + [con.point for con in samples]
        joints = rig.joints_for(pts)
        # every control the frames need, once; those not optimised stay as they are
        needed = rig.controls_on(joints)
        values = np.zeros((len(T_all), len(work.curves.controls)))
        ev_all = evaluate_segments(work.arrays(), T_all, seg_all, needed)
        values[:, needed] = ev_all.value
        in_s = (seg_all == s)[:, None]
        in_prev = (seg_all == s - 1)[:, None] & prev_seg[None]
        in_next = (seg_all == s + 1)[:, None] & next_seg[None]
        scale = self.scale

        def theta_now() -> np.ndarray:
            th = np.empty(n)
            th[0::4], th[1::4] = work.out_tan[a, Carr, 0], work.out_tan[a, Carr, 1]
            th[2::4], th[3::4] = work.in_tan[b, Carr, 0], work.in_tan[b, Carr, 1]
            return th

        def apply(th: np.ndarray) -> None:
            out_a = np.stack([th[0::4], th[1::4]], -1)
            in_b = np.stack([th[2::4], th[3::4]], -1)
            work.out_tan[a, Carr] = out_a
            work.in_tan[b, Carr] = in_b
            if uni_a.any():
                work.in_tan[a, Carr[uni_a]] = ratio_a[uni_a, None] * out_a[uni_a]
            if uni_b.any():
                work.out_tan[b, Carr[uni_b]] = ratio_b[uni_b, None] * in_b[uni_b]

        def evaluate():
            ev = evaluate_segments(work.arrays(), T_all, seg_all, Carr)
            values[:, Carr] = ev.value
            return ev, rig.frames(values, joints)

        def linearize(ev, frames) -> _Linear:
            r0 = np.array([0])
            pos_m, rot_m = rig.state(frames, point, r0)
            rm = target_pos - pos_m[0]
            dist2 = float(rm @ rm)
            if point.orientation:
                rvec = _rotvec(target_rot, rot_m[0]) if target_rot is not None else np.zeros(3)
                rm = np.concatenate([rm, scale * rvec])
                dist2 += float(scale * scale * (rvec @ rvec))
            rcs, names, viol, states, allow = [], [], 0.0, [], []
            for con, r in zip(samples, rows):
                pos, rot = rig.state(frames, con.point, r)
                res = con.target_pos - pos
                err2 = np.sum(res * res, axis=-1)
                if con.point.orientation:
                    rv = scale * _rotvec(con.target_rot, rot)
                    res = np.concatenate([res, rv], axis=-1)
                    err2 = err2 + np.sum(rv * rv, axis=-1)
                viol = max(viol, float((np.sqrt(err2) - con.allow).max()))
                rcs.append(res.reshape(-1))
                names.append((con.name, res.size))
                states.append(pos)
                allow.append(np.broadcast_to(con.allow_rows, res.shape).reshape(-1))
            rc = np.concatenate(rcs) if rcs else np.zeros(0)
            allow = np.concatenate(allow) if allow else 0.0

            def jacobians():
                # dc/dtheta per time and control: the variables at key a are the out tangent of
                # this segment and (unified) the in tangent of the previous one, scaled by the
                # width ratio; likewise at key b with the next segment
                own = tangent_derivatives(ev)
                dc = np.empty((len(T_all), nC, 4))
                dc[..., :2] = np.where(
                    in_s[..., None], own[..., :2], np.where(in_prev[..., None], ratio_a[:, None] * own[..., 2:], 0.0)
                )
                dc[..., 2:] = np.where(
                    in_s[..., None], own[..., 2:], np.where(in_next[..., None], ratio_b[:, None] * own[..., :2], 0.0)
                )
                jm = rig.jacobian(frames, point, pos_m, C, r0)[0]  # (3 or 6, nC)
                if point.orientation:
                    jm = np.concatenate([jm[:3], scale * jm[3:]])
                Jm = (jm[:, :, None] * dc[0][None]).reshape(len(rm), n)
                Jcs = []
                for con, r, pos in zip(samples, rows, states):
                    jc = rig.jacobian(frames, con.point, pos, C, r)
                    if con.point.orientation:
                        jc = np.concatenate([jc[:, :3], scale * jc[:, 3:]], axis=1)
                    Jcs.append((jc[:, :, :, None] * dc[r][:, None]).reshape(-1, n))
                return Jm, (np.concatenate(Jcs) if Jcs else np.zeros((0, n)))

            return _Linear(np.sqrt(dist2), viol, rm, rc, names, jacobians, allow)

        def relinearize(th: np.ndarray) -> _Linear:
            apply(th)
            return linearize(*evaluate())

        # targets, from the curves as they are now
        ev0 = ev_all.columns(np.searchsorted(needed, Carr))
        frames0 = rig.frames(values, joints)
        cur_pos, _ = rig.state(frames0, point, np.array([0]))
        target_pos = edit.target if edit.target is not None else cur_pos[0] + edit.move
        target_rot = R.quat_to_matrix(edit.orientation) if edit.orientation is not None else None
        for con, r in zip(samples, rows):
            if con.kind == "pin":
                pos, rot = work.states([con.point], con.times, self.original)[0]
            else:
                pos, rot = rig.state(frames0, con.point, r)
            con.target_pos, con.target_rot = pos, (rot if con.point.orientation else None)
            if con.kind == "contact":
                # a captured foot wobbles around its contact: the edit may not make that worse
                con.target_pos = self.contact_target(con.contact, con.times)
                given = work.states([con.point], con.times, self.original)[0][0] - con.target_pos
                con.allow = np.linalg.norm(given, axis=-1)
                con.allow_rows = np.abs(given)
        lin0 = linearize(ev0, frames0)

        lb, ub, groups = self.tangent_bounds(s, Carr, ratio_a, ratio_b, prev_seg, next_seg)
        pair_vars, pair_other = self.broken_pairs(a, b, Carr, uni_a, uni_b)
        theta0 = theta_now()
        stiff = np.outer(self.stiffness[Carr], [S.timing_stiffness, 1.0, S.timing_stiffness, 1.0]).reshape(-1)
        best, dist, iters, reached, lin, last = _iterate(
            theta0,
            lin0,
            relinearize,
            lb,
            ub,
            stiff,
            (pair_vars, pair_other),
            self.eps,
            self.kappa,
            self.solver,
            S,
            self.scale,
        )
        if not reached:
            blocking = _diagnose(last, groups(), [con.name for con in samples])
            err = self.infeasible(
                self.edit_label(edit),
                dist if np.isfinite(dist) else lin.distance,
                blocking,
                f"no constraint is active, so the tangents between the keys at frames {times[a]:g} and "
                f"{times[b]:g} cannot take the point any closer (move the target, add a key, or unlock controls)",
            )
            if not self.best_effort:
                raise err
        apply(best if best is not None else theta0)
        solve_ms = (_time.perf_counter() - t_start) * 1e3
        solve_cpu_ms = (_time.thread_time() - cpu_start) * 1e3
        report = EditReport(
            edit=edit.index,
            kind="move",
            time=float(edit.time),
            segment=(float(times[a]), float(times[b])),
            joint=self.sk.names[point.joint],
            reached=bool(reached),
            iterations=iters,
            distance=float(dist if best is not None else self.distance_now(point, edit.time, target_pos, target_rot)),
            optimised_controls=nC,
            optimised_tangents=2 * nC,
            constraints=[con.name for con in samples],
            solve_ms=solve_ms,
            solve_cpu_ms=solve_cpu_ms,
        )
        self.check_constraints(report, pins, contacts, float(times[lo_seg]), float(times[hi_seg + 1]))
        return report

    def edit_label(self, edit: Manipulation) -> str:
        where = "key" if self.work.curves.key_index(edit.time) is not None else "frame"
        return f"edit {edit.index} ({edit.point.label(self.sk)} at {where} {edit.time:g})"

    def distance_now(self, point, t, target_pos, target_rot) -> float:
        pos, rot = self.work.states([point], [t])[0]
        d2 = float(np.sum((target_pos - pos[0]) ** 2))
        if target_rot is not None:
            d2 += float(np.sum((self.scale * _rotvec(target_rot, rot[0])) ** 2))
        return float(np.sqrt(d2))

    def sample_times(self, segs, start, end, n_max) -> np.ndarray:
        """Frames strictly inside each segment (within [start, end]); at most ``n_max`` per segment."""
        times = self.work.times
        last = self.work.curves.num_frames - 1
        out = []
        for g in segs:
            t0, t1 = times[g], times[g + 1]
            if t1 <= start or t0 >= end:
                continue
            f = np.arange(np.floor(t0) + 1, np.ceil(t1), dtype=np.float64)
            f = f[(f > t0) & (f < t1) & (f >= start) & (f <= end) & (f <= last)]
            if len(f) > n_max:
                f = np.linspace(f[0], f[-1], n_max)
            out.append(f)
        return np.concatenate(out) if out else np.zeros(0)

    def tangent_bounds(self, s, Carr, ratio_a, ratio_b, prev_seg, next_seg):
        """Absolute bounds of the variables (Eqs. 7-9) and the group each bound belongs to."""
        work, m = self.work, self.settings.width_margin
        times, vals = work.times, work.values
        nC = len(Carr)
        seg = np.diff(times)
        lb = np.empty(4 * nC)
        ub = np.empty(4 * nC)
        lo, hi = self.low[Carr], self.high[Carr]

        def phi_psi(g):
            v0, v1 = vals[g, Carr], vals[g + 1, Carr]
            with np.errstate(invalid="ignore"):
                phi = 4.0 / 3.0 * (lo - np.minimum(v0, v1))
                psi = 4.0 / 3.0 * (hi - np.maximum(v0, v1))
            return phi, psi

        # widths: Eq. 7 on this segment, and on the neighbour for unified keys
        xa_lo, xa_hi = np.full(nC, m * seg[s]), np.full(nC, (1 - m) * seg[s])
        xb_lo, xb_hi = xa_lo.copy(), xa_hi.copy()
        if prev_seg.any():
            r = ratio_a[prev_seg]
            xa_lo[prev_seg] = np.maximum(xa_lo[prev_seg], m * seg[s - 1] / r)
            xa_hi[prev_seg] = np.minimum(xa_hi[prev_seg], (1 - m) * seg[s - 1] / r)
        if next_seg.any():
            r = ratio_b[next_seg]
            xb_lo[next_seg] = np.maximum(xb_lo[next_seg], m * seg[s + 1] / r)
            xb_hi[next_seg] = np.minimum(xb_hi[next_seg], (1 - m) * seg[s + 1] / r)
        # heights: Eqs. 8-9 (infinite without limits)
        if not (np.isfinite(lo).any() or np.isfinite(hi).any()):
            for k, (l, h) in enumerate(((xa_lo, xa_hi), (xb_lo, xb_hi))):
                lb[2 * k :: 4], ub[2 * k :: 4] = l, h
            lb[1::2], ub[1::2] = -np.inf, np.inf
            return (
                lb,
                ub,
                lambda: [f"timing bounds of {self.name(c)}" if k % 2 == 0 else None for c in Carr for k in range(4)],
            )
        phi, psi = phi_psi(s)
        ya_lo, ya_hi = phi.copy(), psi.copy()
        yb_lo, yb_hi = -psi, -phi
        if prev_seg.any():
            pphi, ppsi = phi_psi(s - 1)
            r = ratio_a[prev_seg]
            ya_lo[prev_seg] = np.maximum(ya_lo[prev_seg], -ppsi[prev_seg] / r)
            ya_hi[prev_seg] = np.minimum(ya_hi[prev_seg], -pphi[prev_seg] / r)
        if next_seg.any():
            nphi, npsi = phi_psi(s + 1)
            r = ratio_b[next_seg]
            yb_lo[next_seg] = np.maximum(yb_lo[next_seg], nphi[next_seg] / r)
            yb_hi[next_seg] = np.minimum(yb_hi[next_seg], npsi[next_seg] / r)
        for k, (l, h) in enumerate(((xa_lo, xa_hi), (ya_lo, ya_hi), (xb_lo, xb_hi), (yb_lo, yb_hi))):
            bad = l > h  # only from rounding: both sides' intervals hold the current tangent
            if bad.any():
                mid = 0.5 * (l[bad] + h[bad])
                l, h = l.copy(), h.copy()
                l[bad], h[bad] = mid, mid
            lb[k::4], ub[k::4] = l, h

        def groups():  # what each bound stands for, named only when an edit fails
            out = []
            for i, c in enumerate(Carr):
                limited = np.isfinite(lo[i]) or np.isfinite(hi[i])
                ylabel = f"limit on {self.name(c)}" if limited else None
                out += [f"timing bounds of {self.name(c)}", ylabel, f"timing bounds of {self.name(c)}", ylabel]
            return out

        return lb, ub, groups

    def broken_pairs(self, a, b, Carr, uni_a, uni_b):
        """Variables of broken keys in E_b and the tangent across their key."""
        work, K = self.work, len(self.work.times)
        i = np.arange(len(Carr))
        sel_a = i[~uni_a] if a >= 1 else i[:0]
        sel_b = i[~uni_b] if b <= K - 2 else i[:0]
        idx = np.concatenate([4 * sel_a, 4 * sel_a + 1, 4 * sel_b + 2, 4 * sel_b + 3])
        other = np.concatenate(
            [
                work.in_tan[a, Carr[sel_a], 0],
                work.in_tan[a, Carr[sel_a], 1],
                work.out_tan[b, Carr[sel_b], 0],
                work.out_tan[b, Carr[sel_b], 1],
            ]
        )
        return idx, other

    # --- timing edits (Eq. 12) -------------------------------------------

    def timing(self, edit: TimingEdit) -> EditReport:
        t_start, cpu_start = _time.perf_counter(), _time.thread_time()
        work, m = self.work, self.settings.width_margin
        times = work.times
        s = int(work.segment(edit.time))
        a, b = s, s + 1
        dt = times[b] - times[a]
        u = (edit.time - times[a]) / dt
        if edit.joint is not None:
            cols = sorted(work.rig.controls_of(Point(edit.joint)) - self.ef.locked)
        else:
            cols = sorted(set(range(work.curves.num_controls)) - self.ef.locked)
        changed = 0
        for c in cols:
            phi = 4.0 / 3.0 * (self.low[c] - min(work.values[a, c], work.values[b, c]))
            psi = 4.0 / 3.0 * (self.high[c] - max(work.values[a, c], work.values[b, c]))
            for tan, k, add, (ylo, yhi) in (
                (work.out_tan, a, edit.amount * u, (phi, psi)),
                (work.in_tan, b, edit.amount * (1 - u), (-psi, -phi)),
            ):
                x, y = tan[k, c]
                if x <= 0:
                    continue
                new_x = float(np.clip(x + add, m * dt, (1 - m) * dt))
                f = new_x / x
                # keep the slope; shrink the change if the height would leave Eqs. 8-9
                if y * f > yhi and y > 0:
                    f = max(min(f, yhi / y), min(1.0, f))
                elif y * f < ylo and y < 0:
                    f = max(min(f, ylo / y), min(1.0, f))
                if f != 1.0:
                    tan[k, c] = (x * f, y * f)
                    changed += 1
        report = EditReport(
            edit=edit.index,
            kind="timing",
            time=float(edit.time),
            segment=(float(times[a]), float(times[b])),
            joint=self.sk.names[edit.joint] if edit.joint is not None else None,
            optimised_controls=len(cols),
            optimised_tangents=changed,
            solve_ms=(_time.perf_counter() - t_start) * 1e3,
            solve_cpu_ms=(_time.thread_time() - cpu_start) * 1e3,
        )
        report.worst_limit_margin, report.worst_limit_control = self.limits_margin(float(times[a]), float(times[b]))
        return report

    # --- static posing (Eq. 13) --------------------------------------------

    def pose(self, edit: Manipulation) -> EditReport:
        t_start, cpu_start = _time.perf_counter(), _time.thread_time()
        work, rig, S = self.work, self.work.rig, self.settings
        times, K = work.times, len(work.times)
        k = work.curves.key_index(edit.time)
        point = edit.point
        pins = list(self.ef.pins) + list(edit.pins)
        # a contact through this key holds the point where it is at the key
        contacts = list(self.ef.contacts) + list(edit.contacts)
        pins += [c.point for c in contacts if c.start <= edit.time <= c.end]
        C, kept = self.reduce(edit, point, pins, [])
        Carr = np.array(C)
        n = len(C)
        T = np.array([edit.time])
        pts = [point] + [con.point for con in kept]
        joints = rig.joints_for(pts)
        needed = rig.controls_on(joints)
        values = np.zeros((1, work.curves.num_controls))
        values[0, needed] = work.values[k, needed]
        cur = work.states([point], T)[0]
        target_pos = edit.target if edit.target is not None else cur[0][0] + edit.move
        target_rot = R.quat_to_matrix(edit.orientation) if edit.orientation is not None else None
        for con in kept:
            con.times = T
            pos, rot = work.states([con.point], T, self.original)[0]
            con.target_pos, con.target_rot = pos, (rot if con.point.orientation else None)
        scale = self.scale

        def apply(x_abs: np.ndarray) -> None:
            work.values[k, Carr] = x_abs

        def linearize(x_abs: np.ndarray) -> _Linear:
            values[0, Carr] = x_abs
            frames = rig.frames(values, joints)
            pos, rot = rig.state(frames, point)
            rm = target_pos - pos[0]
            dist2 = float(rm @ rm)
            if point.orientation:
                rvec = _rotvec(target_rot, rot[0]) if target_rot is not None else np.zeros(3)
                rm = np.concatenate([rm, scale * rvec])
                dist2 += float(scale * scale * (rvec @ rvec))
            rcs, names, viol, states = [], [], 0.0, []
            for con in kept:
                p, r = rig.state(frames, con.point)
                res = con.target_pos[0] - p[0]
                err2 = float(res @ res)
                if con.point.orientation:
                    rv = scale * _rotvec(con.target_rot[0], r[0])
                    res = np.concatenate([res, rv])
                    err2 += float(rv @ rv)
                viol = max(viol, np.sqrt(err2))
                rcs.append(res)
                names.append((con.name, len(res)))
                states.append(p)
            rc = np.concatenate(rcs) if rcs else np.zeros(0)

            def jacobians():
                Jm = rig.jacobian(frames, point, pos, C)[0]
                if point.orientation:
                    Jm = np.concatenate([Jm[:3], scale * Jm[3:]])
                Jcs = []
                for con, p in zip(kept, states):
                    jc = rig.jacobian(frames, con.point, p, C)[0]
                    Jcs.append(np.concatenate([jc[:3], scale * jc[3:]]) if con.point.orientation else jc)
                return Jm, (np.concatenate(Jcs) if Jcs else np.zeros((0, n)))

            return _Linear(np.sqrt(dist2), viol, rm, rc, names, jacobians)

        lb, ub = self.value_bounds(k, Carr)
        groups = [
            f"limit on {self.name(c)}" if np.isfinite(self.low[c]) or np.isfinite(self.high[c]) else None for c in C
        ]
        x0 = work.values[k, Carr].copy()
        empty = (np.zeros(0, dtype=np.int64), np.zeros(0))
        best, dist, iters, reached, lin, last = _iterate(
            x0,
            linearize(x0),
            linearize,
            lb,
            ub,
            self.stiffness[Carr],
            empty,
            self.eps,
            self.kappa,
            self.solver,
            S,
            self.scale,
        )
        if not reached:
            blocking = _diagnose(last, groups, [con.name for con in kept])
            err = self.infeasible(
                self.edit_label(edit),
                dist if np.isfinite(dist) else lin.distance,
                blocking,
                "no constraint is active, so the controls that move the point cannot take it any closer",
            )
            if not self.best_effort:
                raise err
        apply(best if best is not None else x0)
        report = EditReport(
            edit=edit.index,
            kind="pose",
            time=float(edit.time),
            segment=(float(times[max(k - 1, 0)]), float(times[min(k + 1, K - 1)])),
            joint=self.sk.names[point.joint],
            reached=bool(reached),
            iterations=iters,
            distance=float(dist if best is not None else self.distance_now(point, edit.time, target_pos, target_rot)),
            optimised_controls=n,
            constraints=[con.name for con in kept],
            solve_ms=(_time.perf_counter() - t_start) * 1e3,
            solve_cpu_ms=(_time.thread_time() - cpu_start) * 1e3,
        )
        # pins hold at the key itself; limits over both neighbouring segments
        self.check_constraints(report, pins, [], edit.time, edit.time)
        report.worst_limit_margin, report.worst_limit_control = self.limits_margin(*report.segment)
        return report

    def value_bounds(self, k, Carr):
        """Bounds of Eq. 13 on key values, narrowed so the 4/3 rule still holds for the fixed tangents."""
        work = self.work
        K = len(work.times)
        lo, hi = self.low[Carr].copy(), self.high[Carr].copy()
        cur = work.values[k, Carr]
        low, high = lo.copy(), hi.copy()
        with np.errstate(invalid="ignore"):
            for y_out, y_in in (
                ((work.out_tan[k, Carr, 1], work.in_tan[k + 1, Carr, 1]) if k <= K - 2 else (None, None)),
                ((work.out_tan[k - 1, Carr, 1], work.in_tan[k, Carr, 1]) if k >= 1 else (None, None)),
            ):
                if y_out is None:
                    continue
                low = np.maximum(low, np.maximum(lo - 0.75 * y_out, lo + 0.75 * y_in))
                high = np.minimum(high, np.minimum(hi - 0.75 * y_out, hi + 0.75 * y_in))
        # never demand more than the curves already meet
        low = np.where(np.isfinite(low), np.minimum(low, cur), low)
        high = np.where(np.isfinite(high), np.maximum(high, cur), high)
        return low, high


# --- public API -----------------------------------------------------------------


def edit_tangents(
    curves: Curves,
    edit_file: EditFile,
    solver: str = QP.DEFAULT_SOLVER,
    best_effort: bool = False,
    settings: Settings = Settings(),
) -> tuple[Curves, list[EditReport]]:
    """Apply the edits of ``edit_file`` in order; returns the new curves and one report per edit.

    Raises :class:`InfeasibleError` for an edit that cannot reach its target
    (unless ``best_effort``: then the closest result that keeps every
    constraint is kept and its report says ``reached = False``).
    """
    ed = _Editor(curves, edit_file, solver, best_effort, settings)
    ed.check_contacts(
        list(edit_file.contacts) + [c for e in edit_file.edits if isinstance(e, Manipulation) for c in e.contacts]
    )
    reports = []
    for edit in edit_file.edits:
        reports.append(ed.timing(edit) if isinstance(edit, TimingEdit) else ed.manipulate(edit))
    return ed.work.result(), reports


def pose(
    curves: Curves,
    edit_file: EditFile,
    solver: str = QP.DEFAULT_SOLVER,
    best_effort: bool = False,
    settings: Settings = Settings(),
) -> tuple[Curves, list[EditReport]]:
    """Change key poses (Eq. 13): each edit moves its point at its key frame; tangents stay."""
    ed = _Editor(curves, edit_file, solver, best_effort, settings)
    reports = [ed.pose(edit) for edit in edit_file.edits]
    return ed.work.result(), reports
