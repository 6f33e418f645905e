"""Dense checks of the constraints, before the edits (contacts) and after each one (the report).

The QPs see pins and contacts only at samples; these checks look at every
frame of the time range an edit changed (limits at
:data:`LIMIT_SAMPLES_PER_FRAME` times per frame) and fill the report's worst
values.
"""

from __future__ import annotations

import numpy as np

from keyfill.curves import evaluate_segments
from keyfill.edit.session import EditReport, Session, rotvec
from keyfill.errors import DataError

#: samples per frame of the dense limit check
LIMIT_SAMPLES_PER_FRAME = 10


def check_contacts(session: Session, contacts) -> None:
    """A contact's point must be (nearly) at the same place at its two keys: keys never move.

    Captured feet glide a little while planted, so up to ``contact_slide``
    (a fraction of the character's size) is accepted; the contact then
    holds the point on the straight line between its key positions.
    Raises :class:`DataError` naming the first contact that slides further.
    """
    limit = max(session.kappa, session.settings.contact_slide * session.scale)
    for c in contacts:
        ends = session.work.states([c.point], [c.start, c.end])[0][0]
        gap = float(np.linalg.norm(ends[1] - ends[0]))
        if gap > limit:
            raise DataError(
                f"{session.contact_name(c)}: the point is {gap:.4g} apart at the two keys, more than a contact "
                f"may slide ({limit:.3g}); keys never move, so pick keys where it stands still "
                "(or move it there with keyfill pose first)"
            )


def limits_margin(session: Session, lo_t: float, hi_t: float) -> tuple[float | None, str | None]:
    """Worst ``min(c - low, high - c)`` over limited controls between frames ``lo_t`` and ``hi_t``.

    Degrees for rotations, file units for translations; ``(None, None)`` without limits.
    """
    if not session.ef.limits:
        return None, None
    work = session.work
    n = max(round((hi_t - lo_t) * LIMIT_SAMPLES_PER_FRAME), 1)
    t = np.linspace(lo_t, hi_t, n + 1)
    cols = np.array(sorted(session.ef.limits))
    vals = evaluate_segments(work.arrays(), t, work.segment(t), cols).value
    margin = np.minimum(vals - session.low[cols], session.high[cols] - vals)  # (T, n)
    unit = np.array([np.degrees(1.0) if work.curves.controls[c].is_rotation else 1.0 for c in cols])
    margin = margin * unit
    i = int(np.argmin(margin.min(axis=0)))
    return float(margin[:, i].min()), session.name(cols[i])


def _frames_in(session: Session, lo_t: float, hi_t: float) -> np.ndarray:
    """The whole frames of the curves between times ``lo_t`` and ``hi_t``."""
    last = session.work.curves.num_frames - 1
    return np.arange(max(np.ceil(lo_t), 0), min(np.floor(hi_t), last) + 1, dtype=np.float64)


def check_constraints(session: Session, report: EditReport, pins, contacts, lo_t, hi_t) -> None:
    """Dense checks at every frame of the changed time range (the report's worst values).

    Pins are measured against the input's trajectories, contacts against
    their still position.
    """
    work = session.work
    frames = _frames_in(session, lo_t, hi_t)
    if pins and len(frames):
        old = work.states(pins, frames, session.original)
        new = work.states(pins, frames)
        worst = 0.0
        for p, (op, orot), (np_, nrot) in zip(pins, old, new):
            d = np.linalg.norm(np_ - op, axis=-1)
            if p.orientation:
                d = np.hypot(d, session.scale * np.linalg.norm(rotvec(orot, nrot), axis=-1))
            worst = max(worst, float(d.max()))
        report.worst_pin_violation = worst
    touched = [c for c in contacts if c.start < hi_t and c.end > lo_t]
    if touched:
        worst = 0.0
        for c in touched:
            f = frames[(frames >= c.start) & (frames <= c.end)]
            if len(f):
                target = session.contact_target(c, f)
                now = np.linalg.norm(work.states([c.point], f)[0][0] - target, axis=-1)
                given = np.linalg.norm(work.states([c.point], f, session.original)[0][0] - target, axis=-1)
                worst = max(worst, float(np.maximum(now - given, 0.0).max()))
        report.worst_contact_violation = worst
    report.worst_limit_margin, report.worst_limit_control = limits_margin(session, lo_t, hi_t)
