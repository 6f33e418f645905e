"""Move edits: drag a point at a time between two keys by changing only that segment's tangents.

Key times and values never change and no key is added. The variables and
samples come from the paper's reduction (:mod:`keyfill.edit.reduction`), the
bounds from :mod:`keyfill.edit.bounds`; this module evaluates the edit at
all its times and linearises it for :mod:`keyfill.edit.iteration`, with the
Jacobians of :mod:`keyfill.edit.rig` times the analytic ``dc/dtheta`` of the
Bezier form (:func:`tangent_derivatives`).

Pins keep the input's trajectories. A contact holds its point on the
straight path between its positions at the two keys (still when they agree;
up to 1 % of the character's size apart is accepted for captured feet) and
never further from it than the input already was.
"""

from __future__ import annotations

import time as _time

import numpy as np

from keyfill import rotations as R
from keyfill.curves import SegmentEval, evaluate_segments
from keyfill.edit.bounds import tangent_bounds
from keyfill.edit.checks import check_constraints
from keyfill.edit.edits import Manipulation
from keyfill.edit.iteration import Linear, Problem, solve
from keyfill.edit.reduction import Constraint, TangentVariables, move_variables
from keyfill.edit.session import EditReport, Session, rotvec


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


def move(session: Session, edit: Manipulation) -> EditReport:
    """Apply one move edit to the session's working curves; the report says how it went."""
    t_start, cpu_start = _time.perf_counter(), _time.thread_time()
    work, settings = session.work, session.settings
    pins = list(session.ef.pins) + list(edit.pins)
    contacts = list(session.ef.contacts) + list(edit.contacts)
    var, samples = move_variables(session, edit, pins, contacts)
    model = _MoveModel(session, edit, var, samples)
    lb, ub, bound_names = tangent_bounds(session, var)
    pair_vars, pair_other = var.broken_pairs(work)
    timing = settings.timing_stiffness
    a, b = float(work.times[var.a]), float(work.times[var.b])
    problem = Problem(
        theta0=var.theta(work),
        linear0=model.linear0,
        relinearize=model.relinearize,
        apply=lambda th: var.apply(work, th),
        lower=lb,
        upper=ub,
        stiffness=np.outer(session.stiffness[var.Carr], [timing, 1.0, timing, 1.0]).reshape(-1),
        bound_names=bound_names,
        constraint_names=[con.name for con in samples],
        distance_now=lambda: session.distance_now(edit.point, edit.time, model.target_pos, model.target_rot),
        pair_vars=pair_vars,
        pair_other=pair_other,
    )
    stuck = (
        f"no constraint is active, so the tangents between the keys at frames {a:g} and "
        f"{b:g} cannot take the point any closer (move the target, add a key, or unlock controls)"
    )
    solution = solve(problem, session, session.edit_label(edit), stuck)
    report = EditReport(
        edit=edit.index,
        kind="move",
        time=float(edit.time),
        segment=(a, b),
        joint=session.sk.names[edit.point.joint],
        reached=solution.reached,
        iterations=solution.iterations,
        distance=solution.distance,
        optimised_controls=len(var.C),
        optimised_tangents=2 * len(var.C),
        constraints=[con.name for con in samples],
        solve_ms=(_time.perf_counter() - t_start) * 1e3,
        solve_cpu_ms=(_time.thread_time() - cpu_start) * 1e3,
    )
    check_constraints(session, report, pins, contacts, *var.changed_range(work))
    return report


class _MoveModel:
    """A move edit evaluated at every time the iteration looks at, and linearised there.

    Times ``(T,)``: the edited time (row 0), then the samples of each
    constraint (rows ``rows[i]`` for ``samples[i]``). Targets come from the
    curves as they are before the edit.
    """

    def __init__(self, session: Session, edit: Manipulation, var: TangentVariables, samples: list[Constraint]):
        work, rig = session.work, session.work.rig
        self.session, self.var, self.point, self.samples = session, var, edit.point, samples
        self.times = np.concatenate([[edit.time]] + [con.times for con in samples])
        self.rows, start = [], 1
        for con in samples:
            self.rows.append(np.arange(start, start + len(con.times)))
            start += len(con.times)
        self.seg = work.segment(self.times)
        self.joints = rig.joints_for([edit.point] + [con.point for con in samples])
        # every control the frames need, once; those not optimised stay as they are
        needed = rig.controls_on(self.joints)
        self.values = np.zeros((len(self.times), len(work.curves.controls)))
        ev_all = evaluate_segments(work.arrays(), self.times, self.seg, needed)
        self.values[:, needed] = ev_all.value
        s = var.s
        self.in_s = (self.seg == s)[:, None]
        self.in_prev = (self.seg == s - 1)[:, None] & var.prev_seg[None]
        self.in_next = (self.seg == s + 1)[:, None] & var.next_seg[None]

        ev0 = ev_all.columns(np.searchsorted(needed, var.Carr))
        frames0 = rig.frames(self.values, self.joints)
        self._set_targets(edit, frames0)
        self.linear0 = self.linearize(ev0, frames0)

    def _set_targets(self, edit: Manipulation, frames0) -> None:
        """The moved point's target and each constraint's, from the curves before the edit."""
        session, work, rig = self.session, self.session.work, self.session.work.rig
        cur_pos, _ = rig.state(frames0, self.point, np.array([0]))
        self.target_pos = edit.target if edit.target is not None else cur_pos[0] + edit.move
        self.target_rot = R.quat_to_matrix(edit.orientation) if edit.orientation is not None else None
        for con, r in zip(self.samples, self.rows):
            if con.kind == "pin":
                pos, rot = work.states([con.point], con.times, session.original)[0]
            else:
                pos, rot = rig.state(frames0, con.point, r)
            con.target_pos, con.target_rot = pos, (rot if con.point.orientation else None)
            if con.kind == "contact":
                # a captured foot wobbles around its contact: the edit may not make that worse
                con.target_pos = session.contact_target(con.contact, con.times)
                given = work.states([con.point], con.times, session.original)[0][0] - con.target_pos
                con.allow = np.linalg.norm(given, axis=-1)
                con.allow_rows = np.abs(given)

    def relinearize(self, th: np.ndarray) -> Linear:
        """Apply variables ``th (4 |C|,)`` to the working curves and linearise there."""
        work, var = self.session.work, self.var
        var.apply(work, th)
        ev = evaluate_segments(work.arrays(), self.times, self.seg, var.Carr)
        self.values[:, var.Carr] = ev.value
        return self.linearize(ev, work.rig.frames(self.values, self.joints))

    def linearize(self, ev: SegmentEval, frames) -> Linear:
        """Residuals at the current values; ``ev`` holds the optimised controls at every time."""
        rig, point, scale = self.session.work.rig, self.point, self.session.scale
        r0 = np.array([0])
        pos_m, rot_m = rig.state(frames, point, r0)
        rm = self.target_pos - pos_m[0]
        dist2 = float(rm @ rm)
        if point.orientation:
            rvec = rotvec(self.target_rot, rot_m[0]) if self.target_rot is not None else np.zeros(3)
            rm = np.concatenate([rm, scale * rvec])
            dist2 += float(scale * scale * (rvec @ rvec))
        rcs, names, viol, states, allow = [], [], 0.0, [], []
        for con, r in zip(self.samples, self.rows):
            pos, rot = rig.state(frames, con.point, r)
            res = con.target_pos - pos
            err2 = np.sum(res * res, axis=-1)
            if con.point.orientation:
                rv = scale * rotvec(con.target_rot, rot)
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
            n, C = self.var.size, self.var.C
            dc = self._dc_dtheta(ev)
            jm = rig.jacobian(frames, point, pos_m, C, r0)[0]  # (3 or 6, |C|)
            if point.orientation:
                jm = np.concatenate([jm[:3], scale * jm[3:]])
            Jm = (jm[:, :, None] * dc[0][None]).reshape(len(rm), n)
            Jcs = []
            for con, r, pos in zip(self.samples, self.rows, states):
                jc = rig.jacobian(frames, con.point, pos, C, r)
                if con.point.orientation:
                    jc = np.concatenate([jc[:, :3], scale * jc[:, 3:]], axis=1)
                Jcs.append((jc[:, :, :, None] * dc[r][:, None]).reshape(-1, n))
            return Jm, (np.concatenate(Jcs) if Jcs else np.zeros((0, n)))

        return Linear(np.sqrt(dist2), viol, rm, rc, names, jacobians, allow)

    def _dc_dtheta(self, ev: SegmentEval) -> np.ndarray:
        """``(T, |C|, 4)``: derivatives of each optimised control at each time by its 4 variables.

        The variables at key a are the out tangent of this segment and (unified)
        the in tangent of the previous one, scaled by the width ratio; likewise
        at key b with the next segment.
        """
        var = self.var
        own = tangent_derivatives(ev)
        dc = np.empty((len(self.times), len(var.C), 4))
        dc[..., :2] = np.where(
            self.in_s[..., None],
            own[..., :2],
            np.where(self.in_prev[..., None], var.ratio_a[:, None] * own[..., 2:], 0.0),
        )
        dc[..., 2:] = np.where(
            self.in_s[..., None],
            own[..., 2:],
            np.where(self.in_next[..., None], var.ratio_b[:, None] * own[..., :2], 0.0),
        )
        return dc
