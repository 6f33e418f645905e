"""The QP iteration shared by move edits and key poses (section 3.3 of Ciccone et al. 2019).

A :class:`Problem` is an edit linearised at its variables: tangents for a
move edit, key values for a pose. :func:`solve` solves the QP of
:mod:`keyfill.edit.qp`, re-linearises and repeats until the point is within
``kappa`` of its target with every kept constraint within ``epsilon``;
after ``patience`` iterations without improvement the edit is rejected
(:class:`~keyfill.errors.InfeasibleError`, naming the constraints whose
multipliers block it) unless the session is best effort. A step whose
constraints break by more than the linear model allows is *mended* (a QP
that holds the moved point and restores them, from the step's end), steps
that make things worse are halved, and a trust radius limits how far one
step aims.

Lengths enter the QP in units of a hundredth of the character's size, so
the weights of Eq. 10 act the same on a lamp in metres and a human in
centimetres.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from keyfill.edit import qp as QP
from keyfill.edit.session import Session


@dataclass
class Linear:
    """The problem at the current variables: residuals now, Jacobians on demand.

    Attributes:
        distance: how far the moved point is from its target (file units).
        violation: the worst constraint error beyond what the input itself has.
        rm: ``(3,)`` or ``(6,)`` the moved point's residual (orientation rows times the character size).
        rc: ``(R,)`` the constraints' residuals, one row per coordinate and sample.
        rows: ``(constraint name, number of its rows in rc)``, in order.
        jacobians: ``() -> (Jm (len(rm), n), Jc (R, n))``, the rows of ``rm``
            and ``rc`` differentiated by the variables; only called when
            another QP is needed (an edit that converges does not pay for its
            last Jacobian).
        allow: per row of ``rc``: the error the input itself has there.
    """

    distance: float
    violation: float
    rm: np.ndarray
    rc: np.ndarray
    rows: list
    jacobians: Callable[[], tuple[np.ndarray, np.ndarray]]
    allow: np.ndarray | float = 0.0


@dataclass
class Problem:
    """One edit as the iteration sees it: ``n`` variables, their bounds and the linearisation.

    Attributes:
        theta0: ``(n,)`` the variables now (tangent widths and heights, or key values).
        linear0: the problem at ``theta0``.
        relinearize: applies variables ``(n,)`` to the working curves and linearises there.
        apply: applies variables ``(n,)`` to the working curves (the result).
        lower, upper: ``(n,)`` absolute bounds of the variables.
        stiffness: ``(n,)`` the diagonal of D (Eq. 4).
        bound_names: ``() -> n`` names (or None) of what each bound stands for,
            asked only when an edit fails.
        constraint_names: the kept constraints, named when the QP itself fails.
        distance_now: how far the point is from its target on the working
            curves, for a failed edit that kept its input.
        pair_vars, pair_other: ``(m,)`` variables of broken keys in E_b and the
            tangent across their key (empty for poses).
    """

    theta0: np.ndarray
    linear0: Linear
    relinearize: Callable[[np.ndarray], Linear]
    apply: Callable[[np.ndarray], None]
    lower: np.ndarray
    upper: np.ndarray
    stiffness: np.ndarray
    bound_names: Callable[[], list]
    constraint_names: list[str]
    distance_now: Callable[[], float]
    pair_vars: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    pair_other: np.ndarray = field(default_factory=lambda: np.zeros(0))


class Solution(NamedTuple):
    """What :func:`solve` did: target ``reached``, QPs solved, the final ``distance`` (file units)."""

    reached: bool
    iterations: int
    distance: float


class _Outcome(NamedTuple):
    best: np.ndarray | None  # the variables closest to the target whose constraints hold within eps
    distance: float  # their distance (inf when none)
    iterations: int
    reached: bool
    last_linear: Linear
    last_qp: tuple | None  # (Linear, QP.Result) of the last QP solved


def solve(problem: Problem, session: Session, what: str, stuck: str) -> Solution:
    """Iterate, then apply the best variables found (the input's when none kept the constraints).

    Raises :class:`~keyfill.errors.InfeasibleError` when the target is not
    reached, unless the session is best effort; the message names ``what``
    (the edit) and the constraints in the way, or says ``stuck`` when none is.
    """
    out = _iterate(problem, session)
    if not out.reached:
        blocking = _diagnose(out.last_qp, problem.bound_names(), problem.constraint_names)
        distance = out.distance if np.isfinite(out.distance) else out.last_linear.distance
        err = session.infeasible(what, distance, blocking, stuck)
        if not session.best_effort:
            raise err
    problem.apply(out.best if out.best is not None else problem.theta0)
    distance = out.distance if out.best is not None else problem.distance_now()
    return Solution(bool(out.reached), out.iterations, float(distance))


def _iterate(problem: Problem, session: Session) -> _Outcome:
    """Solve, re-linearise, repeat (section 3.3), from ``problem.theta0``."""
    settings, eps, kappa = session.settings, session.eps, session.kappa
    lb, ub, relinearize = problem.lower, problem.upper, problem.relinearize
    theta0 = problem.theta0
    theta = np.minimum(np.maximum(theta0, lb), ub)  # tangents the limits forbid are brought inside first
    lin = problem.linear0 if np.array_equal(theta, theta0) else relinearize(theta)
    best_theta, best_d = (theta.copy(), lin.distance) if lin.violation <= eps else (None, np.inf)
    count = [0]  # QPs solved
    last = [None]
    band = settings.band * eps
    k = 100.0 / session.scale

    def step(at, lin_at, aim):
        """The QP step from ``at``: toward the target by ``aim`` (0: mend the constraints only)."""
        Jm, Jc = lin_at.jacobians()
        rm = lin_at.rm * (aim / lin_at.distance) if lin_at.distance > aim else lin_at.rm
        mending = aim == 0.0
        if mending:  # the smallest change that restores the constraints, holding the point (no E_b pull)
            rm = 0.0 * rm
        pv = problem.pair_vars if not mending else problem.pair_vars[:0]
        gap = at[pv] - problem.pair_other[: len(pv)] if len(pv) else None
        program = QP.assemble(
            k * Jm, k * rm, problem.stiffness, lb - at, ub - at, k * Jc, k * lin_at.rc, k * (band + lin_at.allow),
            pv, gap, settings.weights,
        )  # fmt: skip
        res = QP.solve(program, session.solver)
        if res.x is None and lin_at.violation <= eps:
            # the band cannot be met from here: let rows keep their current error (within eps)
            slack = k * np.maximum(band + lin_at.allow, np.abs(lin_at.rc))
            program.h = np.concatenate([k * lin_at.rc + slack, slack - k * lin_at.rc])
            res = QP.solve(program, session.solver)
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
    return _Outcome(best_theta, best_d, count[0], best_d < kappa, lin, last[0])


def _merit(lin: Linear, eps: float) -> float:
    """Distance to the target plus a penalty on constraint errors beyond ``eps``."""
    return lin.distance + 5.0 * max(lin.violation - eps, 0.0)


def _diagnose(last, bound_names, constraint_names) -> list[str]:
    """Constraints whose multipliers are large in the last QP: what blocks the edit."""
    if last is None:
        return []
    lin, res = last
    if res.x is None:  # no multipliers: name the constraints and limits that were in play
        return list(constraint_names) + sorted({g for g in bound_names if g and g.startswith("limit")})
    score: dict[str, float] = {}
    k = len(lin.rc)
    z = np.abs(res.z[:k]) + np.abs(res.z[k:]) if len(res.z) == 2 * k else np.zeros(k)
    start = 0
    for name, n in lin.rows:
        score[name] = score.get(name, 0.0) + float(z[start : start + n].sum())
        start += n
    for g, zb in zip(bound_names, np.abs(res.z_box)):
        if g:
            score[g] = score.get(g, 0.0) + float(zb)
    top = max(score.values(), default=0.0)
    if top <= 1e-9:
        return []
    return [name for name, s in sorted(score.items(), key=lambda kv: -kv[1]) if s >= 0.05 * top]
