"""The quadratic programs of tangent-space editing, solved through qpsolvers.

:func:`assemble` builds Eq. 10 of Ciccone et al. 2019 (and Eq. 13, its static
case, with the same pieces) as ``min 1/2 x'Px + q'x`` subject to
``Gx <= h`` and ``lb <= x <= ub``:

* ``w_m E_m``: ``w_m |r_m - J_m x|^2``, the manipulated state reaching its target;
* ``w_d E_d``: ``w_d |D x|^2`` with ``D`` the per-variable stiffness;
* ``w_b E_b``: ``w_b |theta + x - pair|^2`` for tangents of broken keys,
  pulling each toward the tangent on the other side of its key;
* the hard constraints of Eq. 6 as the band of Eq. 11:
  ``-eps <= r_c - J_c x <= eps``;
* the bounds (Eqs. 7-9, or ``u <= c <= v`` in Eq. 13);
* ``P + lambda I`` (``lambda = 1e-6``) so that ``P`` is full rank.

:func:`solve` runs any backend qpsolvers has installed (DAQP by default)
and returns the solution with its multipliers, which name the constraints
that block an infeasible edit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from keyfill.errors import UsageError

DEFAULT_SOLVER = "daqp"


@dataclass(frozen=True)
class Weights:
    """Energy weights of Eq. 10 and the regulariser of section 3.3 (the paper's values)."""

    manipulation: float = 100.0
    stiffness: float = 1.0
    broken: float = 1.0
    regularization: float = 1e-6


@dataclass
class Program:
    """A QP ``min 1/2 x'Px + q'x, Gx <= h, lb <= x <= ub`` (``G`` may have no rows)."""

    P: np.ndarray
    q: np.ndarray
    G: np.ndarray
    h: np.ndarray
    lb: np.ndarray
    ub: np.ndarray


@dataclass
class Result:
    """``x`` (None when the solver found no solution) and the multipliers.

    ``z``: one per row of ``G`` (>= 0); ``z_box``: one per variable (negative
    at a lower bound, positive at an upper bound).
    """

    x: np.ndarray | None
    z: np.ndarray
    z_box: np.ndarray


def assemble(
    Jm: np.ndarray,
    rm: np.ndarray,
    stiffness: np.ndarray,
    lb: np.ndarray,
    ub: np.ndarray,
    Jc: np.ndarray | None = None,
    rc: np.ndarray | None = None,
    band: float | np.ndarray = 0.0,
    pair_vars: np.ndarray | None = None,
    pair_gap: np.ndarray | None = None,
    weights: Weights = Weights(),
) -> Program:
    """Build the program of Eq. 10 (see the module docstring).

    Args:
        Jm: ``(m, n)`` Jacobian of the manipulated state; ``rm (m,)`` its residual ``s' - s``.
        stiffness: ``(n,)`` the diagonal of ``D``.
        lb, ub: ``(n,)`` bounds on the step ``x``.
        Jc, rc: ``(k, n)`` and ``(k,)`` hard constraints ``J_c x ~= r_c`` within ``band``
            (a number or one per row).
        pair_vars: indices of variables in ``E_b``; ``pair_gap`` their ``theta - pair``.
    """
    n = Jm.shape[1]
    wm, wd, wb = weights.manipulation, weights.stiffness, weights.broken
    P = 2.0 * wm * (Jm.T @ Jm)
    q = -2.0 * wm * (Jm.T @ rm)
    P[np.diag_indices(n)] += 2.0 * wd * stiffness**2 + weights.regularization
    if pair_vars is not None and len(pair_vars):
        P[pair_vars, pair_vars] += 2.0 * wb
        q[pair_vars] += 2.0 * wb * pair_gap
    if Jc is not None and len(Jc):
        G = np.concatenate([Jc, -Jc])
        h = np.concatenate([rc + band, band - rc])
    else:
        G = np.zeros((0, n))
        h = np.zeros(0)
    return Program(P, q, G, h, lb, ub)


def check_solver(name: str) -> str:
    """``name`` if qpsolvers has that backend installed, else a :class:`UsageError` listing them."""
    import qpsolvers

    if name not in qpsolvers.available_solvers:
        raise UsageError(
            f"QP solver {name!r} is not installed; available: {', '.join(sorted(qpsolvers.available_solvers))}"
        )
    return name


def solve(program: Program, solver: str = DEFAULT_SOLVER, **options) -> Result:
    """Solve ``program`` with the qpsolvers backend ``solver`` (``options`` go to the backend)."""
    import qpsolvers

    n = len(program.q)
    has_rows = program.G.shape[0] > 0
    problem = qpsolvers.Problem(
        program.P,
        program.q,
        program.G if has_rows else None,
        program.h if has_rows else None,
        None,
        None,
        program.lb,
        program.ub,
    )
    sol = qpsolvers.solve_problem(problem, solver=solver, **options)
    ok = sol.found and sol.x is not None and np.all(np.isfinite(sol.x))
    z = np.asarray(sol.z, dtype=np.float64) if has_rows and sol.z is not None else np.zeros(program.G.shape[0])
    z_box = np.asarray(sol.z_box, dtype=np.float64) if sol.z_box is not None else np.zeros(n)
    return Result(np.asarray(sol.x, dtype=np.float64) if ok else None, z, z_box)
