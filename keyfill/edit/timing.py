"""Timing edits (Eq. 12 of Ciccone et al. 2019): widen or narrow the frame spacing around a time.

On the segment around the edit's time, the out tangent at its first key
widens by ``amount * u`` and the in tangent at its last key by ``amount *
(1 - u)`` (``u`` where the time lies in the segment, 0 to 1), for every
control (or those that move the edit's joint) that is not locked. Each
tangent keeps its slope, so unified keys stay unified and key velocities do
not change; widths stay within Eq. 7 (with the 1 % margin) and the change
shrinks where a height would leave the limits' bounds (Eqs. 8-9).
"""

from __future__ import annotations

import time as _time

import numpy as np

from keyfill.edit.checks import limits_margin
from keyfill.edit.edits import TimingEdit
from keyfill.edit.rig import Point
from keyfill.edit.session import EditReport, Session


def timing(session: Session, edit: TimingEdit) -> EditReport:
    """Apply one timing edit to the session's working curves; the report counts the tangents rescaled."""
    t_start, cpu_start = _time.perf_counter(), _time.thread_time()
    work, m = session.work, session.settings.width_margin
    times = work.times
    s = int(work.segment(edit.time))
    a, b = s, s + 1
    dt = times[b] - times[a]
    u = (edit.time - times[a]) / dt
    if edit.joint is not None:
        cols = sorted(work.rig.controls_of(Point(edit.joint)) - session.ef.locked)
    else:
        cols = sorted(set(range(work.curves.num_controls)) - session.ef.locked)
    changed = 0
    for c in cols:
        phi = 4.0 / 3.0 * (session.low[c] - min(work.values[a, c], work.values[b, c]))
        psi = 4.0 / 3.0 * (session.high[c] - max(work.values[a, c], work.values[b, c]))
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
        joint=session.sk.names[edit.joint] if edit.joint is not None else None,
        optimised_controls=len(cols),
        optimised_tangents=changed,
        solve_ms=(_time.perf_counter() - t_start) * 1e3,
        solve_cpu_ms=(_time.thread_time() - cpu_start) * 1e3,
    )
    report.worst_limit_margin, report.worst_limit_control = limits_margin(session, float(times[a]), float(times[b]))
    return report
