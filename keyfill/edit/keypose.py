"""Key poses (Eq. 13, the static case): move a point at a key by changing the key's values.

The tangents stay. Pins, and contacts through the key, hold their points
where they are at the key; the value bounds of :func:`keyfill.edit.bounds.value_bounds`
keep limits holding between keys too. The variables are the values ``(|C|,)``
of the optimised controls at the key; the rig's Jacobian is the QP's.
"""

from __future__ import annotations

import time as _time

import numpy as np

from keyfill import rotations as R
from keyfill.edit.bounds import value_bounds
from keyfill.edit.checks import check_constraints, limits_margin
from keyfill.edit.edits import Manipulation
from keyfill.edit.iteration import Linear, Problem, solve
from keyfill.edit.reduction import reduce
from keyfill.edit.session import EditReport, Session, rotvec


def pose_key(session: Session, edit: Manipulation) -> EditReport:
    """Apply one pose edit (at a key) to the session's working curves; the report says how it went."""
    t_start, cpu_start = _time.perf_counter(), _time.thread_time()
    work, rig = session.work, session.work.rig
    times, K = work.times, len(work.times)
    k = work.curves.key_index(edit.time)
    point = edit.point
    pins = list(session.ef.pins) + list(edit.pins)
    # a contact through this key holds the point where it is at the key
    contacts = list(session.ef.contacts) + list(edit.contacts)
    pins += [c.point for c in contacts if c.start <= edit.time <= c.end]
    C, kept = reduce(session, edit, point, pins, [])
    Carr = np.array(C)
    n = len(C)
    T = np.array([edit.time])
    joints = rig.joints_for([point] + [con.point for con in kept])
    needed = rig.controls_on(joints)
    values = np.zeros((1, work.curves.num_controls))
    values[0, needed] = work.values[k, needed]
    cur = work.states([point], T)[0]
    target_pos = edit.target if edit.target is not None else cur[0][0] + edit.move
    target_rot = R.quat_to_matrix(edit.orientation) if edit.orientation is not None else None
    for con in kept:
        con.times = T
        pos, rot = work.states([con.point], T, session.original)[0]
        con.target_pos, con.target_rot = pos, (rot if con.point.orientation else None)
    scale = session.scale

    def apply(x_abs: np.ndarray) -> None:
        work.values[k, Carr] = x_abs

    def linearize(x_abs: np.ndarray) -> Linear:
        values[0, Carr] = x_abs
        frames = rig.frames(values, joints)
        pos, rot = rig.state(frames, point)
        rm = target_pos - pos[0]
        dist2 = float(rm @ rm)
        if point.orientation:
            rvec = rotvec(target_rot, rot[0]) if target_rot is not None else np.zeros(3)
            rm = np.concatenate([rm, scale * rvec])
            dist2 += float(scale * scale * (rvec @ rvec))
        rcs, names, viol, states = [], [], 0.0, []
        for con in kept:
            p, r = rig.state(frames, con.point)
            res = con.target_pos[0] - p[0]
            err2 = float(res @ res)
            if con.point.orientation:
                rv = scale * rotvec(con.target_rot[0], r[0])
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

        return Linear(np.sqrt(dist2), viol, rm, rc, names, jacobians)

    lb, ub = value_bounds(session, k, Carr)
    limited = [np.isfinite(session.low[c]) or np.isfinite(session.high[c]) for c in C]
    bound_names = [f"limit on {session.name(c)}" if lim else None for c, lim in zip(C, limited)]
    x0 = work.values[k, Carr].copy()
    problem = Problem(
        theta0=x0,
        linear0=linearize(x0),
        relinearize=linearize,
        apply=apply,
        lower=lb,
        upper=ub,
        stiffness=session.stiffness[Carr],
        bound_names=lambda: bound_names,
        constraint_names=[con.name for con in kept],
        distance_now=lambda: session.distance_now(point, edit.time, target_pos, target_rot),
    )
    stuck = "no constraint is active, so the controls that move the point cannot take it any closer"
    solution = solve(problem, session, session.edit_label(edit), stuck)
    report = EditReport(
        edit=edit.index,
        kind="pose",
        time=float(edit.time),
        segment=(float(times[max(k - 1, 0)]), float(times[min(k + 1, K - 1)])),
        joint=session.sk.names[point.joint],
        reached=solution.reached,
        iterations=solution.iterations,
        distance=solution.distance,
        optimised_controls=n,
        constraints=[con.name for con in kept],
        solve_ms=(_time.perf_counter() - t_start) * 1e3,
        solve_cpu_ms=(_time.thread_time() - cpu_start) * 1e3,
    )
    # pins hold at the key itself; limits over both neighbouring segments
    check_constraints(session, report, pins, [], edit.time, edit.time)
    report.worst_limit_margin, report.worst_limit_control = limits_margin(session, *report.segment)
    return report
