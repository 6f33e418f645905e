"""Bounds of the variables: tangents of a move edit (Eqs. 7-9) and key values of a pose (Eq. 13).

* Widths (Eq. 7): inside ``[m, 1 - m]`` of the segment (``m`` =
  ``Settings.width_margin``, 1 %) so time stays strictly increasing along it;
  at a unified key the tangent across the key follows, so its own segment
  bounds the width too.
* Heights (Eqs. 8-9), only for controls with limits: the 4/3 rule of
  Appendix A. With ``phi = 4/3 (low - min(v0, v1))`` and ``psi = 4/3 (high -
  max(v0, v1))`` on a segment from value ``v0`` to ``v1``, an out height in
  ``[phi, psi]`` and an in height in ``[-psi, -phi]`` keep the curve inside
  the limits at every time, not only at samples.
"""

from __future__ import annotations

import numpy as np

from keyfill.edit.reduction import TangentVariables
from keyfill.edit.session import Session


def tangent_bounds(session: Session, var: TangentVariables):
    """Absolute bounds ``(lb, ub)``, each ``(4 |C|,)``, of a move edit's variables, and the names of the bounds.

    The third item is a function returning, per variable, what its bound stands for
    (``"timing bounds of ..."``, ``"limit on ..."`` or None); it is only called when an edit fails.
    """
    work, m = session.work, session.settings.width_margin
    times, vals = work.times, work.values
    s, Carr = var.s, var.Carr
    ratio_a, ratio_b, prev_seg, next_seg = var.ratio_a, var.ratio_b, var.prev_seg, var.next_seg
    nC = len(Carr)
    seg = np.diff(times)
    lb = np.empty(4 * nC)
    ub = np.empty(4 * nC)
    lo, hi = session.low[Carr], session.high[Carr]

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
            lambda: [f"timing bounds of {session.name(c)}" if k % 2 == 0 else None for c in Carr for k in range(4)],
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

    def names():
        out = []
        for i, c in enumerate(Carr):
            limited = np.isfinite(lo[i]) or np.isfinite(hi[i])
            ylabel = f"limit on {session.name(c)}" if limited else None
            out += [f"timing bounds of {session.name(c)}", ylabel, f"timing bounds of {session.name(c)}", ylabel]
        return out

    return lb, ub, names


def value_bounds(session: Session, k: int, Carr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bounds ``(low, high)``, each ``(len(Carr),)``, of Eq. 13 on the values of controls ``Carr`` at key ``k``.

    The limits, narrowed so that the 4/3 rule still holds for the (fixed)
    tangents on both sides of the key; never narrower than the values already are.
    """
    work = session.work
    K = len(work.times)
    lo, hi = session.low[Carr].copy(), session.high[Carr].copy()
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
