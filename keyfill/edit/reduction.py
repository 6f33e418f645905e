"""The paper's reduction (section 3.3): which controls an edit optimises, its variables, its samples.

1. *Controls*. ``C`` starts as the controls that move the point (``C_s``)
   minus locked ones. Each pin or contact with controls ``C_j`` is then
   (1) ignored when ``C`` and ``C_j`` are disjoint, (2) dropped with
   ``C := C - C_j`` when ``C_j`` is inside ``C_s`` (those controls stay as
   they are, so the point cannot move), or (3) kept with ``C := C + C_j``.
2. *Variables* of a move edit (:class:`TangentVariables`). Only the tangents
   of ``C`` at the two keys of the segment are variables: ``(X, Y)`` of the
   out tangent at the first key and of the in tangent at the second, 4 per
   control. A *unified* key keeps its two slopes equal: the tangent on the
   other side follows, scaled by the ratio of the widths, so the
   neighbouring segment changes too and is included wherever constraints
   are sampled.
3. *Sampling*. Each kept pin or contact is sampled at the frames strictly
   inside the segments that the variables change (at most ``4 |C_j|``
   evenly spaced times per segment), plus the edit's hold frames. A
   constraint with no frame there holds nothing: it is dropped and the
   reduction runs again without it, so that its controls do not join ``C``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from keyfill.edit.edits import Contact, Manipulation
from keyfill.edit.rig import Point
from keyfill.edit.session import Session, WorkingCurves
from keyfill.errors import InfeasibleError


@dataclass(eq=False)
class Constraint:
    """A pin, contact or hold as the QP sees it.

    Attributes:
        kind: ``"pin"``, ``"contact"`` or ``"hold"``.
        start, end: the time range it holds in (frames).
        controls: its controls that the edit optimises (``C_j``).
        times: ``(T,)`` its sample times (frames).
        target_pos: ``(T, 3)`` where the point must be; ``target_rot`` ``(T, 3, 3)``
            its orientation (None: position only).
        allow: per sample, the input's own distance from the target (contacts);
            ``allow_rows`` the same per QP row (coordinate).
    """

    name: str
    kind: str
    point: Point
    start: float
    end: float
    controls: frozenset
    contact: Contact | None = None
    times: np.ndarray = None
    target_pos: np.ndarray = None
    target_rot: np.ndarray | None = None
    allow: np.ndarray | float = 0.0
    allow_rows: np.ndarray | float = 0.0


def reduce(session: Session, edit, point: Point, pins, contacts) -> tuple[list[int], list[Constraint]]:
    """Step 1: the optimised controls ``C`` (sorted, never empty) and the constraints kept.

    Raises :class:`InfeasibleError` naming ``edit`` when no control can move ``point``.
    """
    rig = session.work.rig
    fixed = set(session.ef.locked)  # locked controls, and those a pin or contact of case 2 fixes
    Cs = rig.controls_of(point) - fixed
    C = set(Cs)
    kept = []
    cands = [Constraint(session.pin_name(p), "pin", p, -np.inf, np.inf, frozenset()) for p in pins]
    cands += [Constraint(session.contact_name(c), "contact", c.point, c.start, c.end, frozenset(), c) for c in contacts]
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
            f"{session.edit_label(edit)}: nothing can move the point: every control that moves it is locked or "
            "fixed by a pin"
        )
    for con in kept:  # a later case 2 may have fixed some of a kept constraint's controls
        con.controls = con.controls - fixed
    return sorted(C), [con for con in kept if con.controls & C]


class TangentVariables:
    """Step 2: the variables of a move edit on segment ``s`` (keys ``a = s`` and ``b = s + 1``).

    ``theta (4 |C|,)``: per control of ``C``, the (width, height) of the out
    tangent at ``a`` then of the in tangent at ``b``.

    Attributes:
        C: the optimised controls (sorted); ``Carr`` the same as an array.
        unified_a, unified_b: ``(|C|,)`` the key stays unified (its other
            tangent follows); false where the edit breaks the tangents, where
            the key is broken, or where a width is zero (only this side can change).
        ratio_a, ratio_b: ``(|C|,)`` width of the other tangent over this one's.
        prev_seg, next_seg: ``(|C|,)`` the segment before (after) changes too.
    """

    def __init__(self, work: WorkingCurves, s: int, C: list[int], break_tangents: bool):
        self.s, self.a, self.b = s, s, s + 1
        self.C, self.Carr = C, np.array(C)
        a, b, Carr = self.a, self.b, self.Carr
        n = len(C)
        wa, wb = work.out_tan[a, Carr, 0], work.in_tan[b, Carr, 0]
        self.unified_a = ~work.broken[a, Carr] & (wa > 0) & (work.in_tan[a, Carr, 0] > 0) & (not break_tangents)
        self.unified_b = ~work.broken[b, Carr] & (wb > 0) & (work.out_tan[b, Carr, 0] > 0) & (not break_tangents)
        ua, ub = self.unified_a, self.unified_b
        self.ratio_a, self.ratio_b = np.zeros(n), np.zeros(n)
        self.ratio_a[ua] = work.in_tan[a, Carr[ua], 0] / wa[ua]
        self.ratio_b[ub] = work.out_tan[b, Carr[ub], 0] / wb[ub]
        self.prev_seg = ua & (s >= 1)
        self.next_seg = ub & (s + 1 <= len(work.times) - 2)

    @property
    def size(self) -> int:
        return 4 * len(self.C)

    def segments(self, i: int) -> set[int]:
        """The segments that the variables of the ``i``-th control of ``C`` change."""
        s = self.s
        return {s} | ({s - 1} if self.prev_seg[i] else set()) | ({s + 1} if self.next_seg[i] else set())

    def changed_range(self, work: WorkingCurves) -> tuple[float, float]:
        """First and last key time of the segments that change (frames)."""
        lo_seg = self.s - 1 if self.prev_seg.any() else self.s
        hi_seg = self.s + 1 if self.next_seg.any() else self.s
        return float(work.times[lo_seg]), float(work.times[hi_seg + 1])

    def mark_broken(self, work: WorkingCurves) -> None:
        """Record in ``work`` which keys of ``C`` are broken from now on."""
        work.broken[self.a, self.Carr[~self.unified_a]] = True
        work.broken[self.b, self.Carr[~self.unified_b]] = True

    def theta(self, work: WorkingCurves) -> np.ndarray:
        """The variables ``(4 |C|,)`` as the working curves hold them now."""
        a, b, Carr = self.a, self.b, self.Carr
        th = np.empty(self.size)
        th[0::4], th[1::4] = work.out_tan[a, Carr, 0], work.out_tan[a, Carr, 1]
        th[2::4], th[3::4] = work.in_tan[b, Carr, 0], work.in_tan[b, Carr, 1]
        return th

    def apply(self, work: WorkingCurves, th: np.ndarray) -> None:
        """Write variables ``th (4 |C|,)`` into ``work``; unified keys' other tangents follow."""
        a, b, Carr = self.a, self.b, self.Carr
        ua, ub = self.unified_a, self.unified_b
        out_a = np.stack([th[0::4], th[1::4]], -1)
        in_b = np.stack([th[2::4], th[3::4]], -1)
        work.out_tan[a, Carr] = out_a
        work.in_tan[b, Carr] = in_b
        if ua.any():
            work.in_tan[a, Carr[ua]] = self.ratio_a[ua, None] * out_a[ua]
        if ub.any():
            work.out_tan[b, Carr[ub]] = self.ratio_b[ub, None] * in_b[ub]

    def broken_pairs(self, work: WorkingCurves) -> tuple[np.ndarray, np.ndarray]:
        """Variables of broken keys in E_b ``(m,)`` and the tangent across their key ``(m,)``."""
        a, b, Carr, K = self.a, self.b, self.Carr, len(work.times)
        i = np.arange(len(Carr))
        sel_a = i[~self.unified_a] if a >= 1 else i[:0]
        sel_b = i[~self.unified_b] if b <= K - 2 else i[:0]
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


def sample_times(work: WorkingCurves, segs, start: float, end: float, n_max: int) -> np.ndarray:
    """Frames strictly inside each segment of ``segs`` (within [start, end]); at most ``n_max`` per segment."""
    times = work.times
    last = work.curves.num_frames - 1
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


def move_variables(session: Session, edit: Manipulation, pins, contacts) -> tuple[TangentVariables, list[Constraint]]:
    """Steps 1-3 for a move edit: its variables and its sampled constraints (holds last).

    A kept pin or contact with no frame inside the segments that change
    (a contact on another segment, with ``break_tangents`` or a broken key)
    holds nothing, yet case 3 added its controls to ``C``: such constraints
    are dropped and the reduction runs again without them, until every kept
    constraint has samples. Marks the keys whose tangents the edit breaks in
    the working curves.
    """
    work, point = session.work, edit.point
    s = int(work.segment(edit.time))
    while True:
        C, kept = reduce(session, edit, point, pins, contacts)
        var = TangentVariables(work, s, C, edit.break_tangents)
        position = {c: i for i, c in enumerate(C)}
        for con in kept:
            inter = [position[c] for c in con.controls if c in position]
            segs = sorted(set().union(*(var.segments(i) for i in inter))) if inter else []
            con.times = sample_times(work, segs, con.start, con.end, 4 * len(inter))
        unsampled = [con for con in kept if not len(con.times)]
        if not unsampled:
            break
        pins = [p for p in pins if not any(con.kind == "pin" and con.point is p for con in unsampled)]
        contacts = [c for c in contacts if not any(con.contact is c for con in unsampled)]
    var.mark_broken(work)
    for h in edit.holds:
        name = f"hold {point.label(session.sk)} at frame {h:g}"
        kept.append(Constraint(name, "hold", point, h, h, frozenset(C), times=np.array([h])))
    return var, kept
