"""The periodic limit directly: a safeguarded semismooth Newton method on the period map.

With piecewise-linear offsets the period map P : w(t0) -> w(t0 + T) of a polyhedral sweeping
process is piecewise affine and nonexpansive (docs/model.md §4), for catch-up stepping (a
composition of projections) and for the exact integrator (a composition of affine pieces);
with smooth offsets it is piecewise smooth. Near a start w whose period visits the active sets
A_1, ..., A_K (`crawlsim.stepping.PeriodRecord.visited`), its Jacobian is the product of their
projectors,

    J = P_{A_K} ... P_{A_1},   P_A = I - R_A B_A,   R_A = M^{-1} B_A^T G_A^{-1},

(a step on A is w -> P_A w + R_A c_A, and P_A P_A = P_A), so a fixed point of P solves the
semismooth equation F(w) = P(w) - w = 0, and Newton's step solves (J - I) d = -F. The fixed
points may form a family (Theorem th:speed: every periodic solution has the same derivative),
so J - I may be singular: the step is the least-squares solution of minimal norm, in the metric
M. Once the period visits the active sets of the limit, the affine map is exact and one step
lands on a fixed point (to roundoff).

The safeguard: a Newton candidate is accepted only if its own Poincare step |P(w) - w| is
smaller. The affine model holds on the current piece of the map only, and where J has an
eigenvalue close to 1 the full step can leave that piece by far (a random 7-block gait: |d| 50
times |F|); the step is then shortened (`BACKTRACK`), and if no fraction of it helps the solver
takes a plain iteration w <- P(w). Where the Jacobian from the visited active sets is not the
map's (no fraction of a Newton step helps), the solver tries Anderson's extrapolation
from the last accepted periods instead (a secant method that needs no Jacobian), under the same
rule, and returns to Newton once that fails. It starts with ``plain``
plain periods, so gaits that are periodic after a period or two (finite-time convergence) pay
nothing extra. The limit is *verified* by the last plain period of the solver, from the accepted
point: its Poincare step is at the tolerance (roundoff by default), and v0 and the limit period
are taken from that period.

The Jacobian at the limit also gives a contraction rate: the largest modulus of its eigenvalues
other than those equal to 1 (the directions of the family of periodic solutions), the local
rate of the plain iteration near the limit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .kkt import Dependent, Polyhedron
from .model import SweepingProcess
from .stepping import PeriodRecord

#: Plain periods before the first Newton step.
PLAIN_PERIODS = 2
#: Eigenvalues of J within this distance of 1 belong to the family of periodic solutions.
UNIT_EIGENVALUE = 1e-8
#: Up to this many state variables J is formed densely; beyond, the Newton step is solved
#: matrix-free (LSMR with products by J and J^T, O(K N) each).
DENSE_JACOBIAN = 400
#: Fractions of the Newton step tried in turn until one decreases the Poincare step.
BACKTRACK = (1.0, 0.25, 0.0625)
#: Pairs (w, P(w)) that Anderson's extrapolation combines after a failed Newton step.
ANDERSON_DEPTH = 5


@dataclass(frozen=True, eq=False)
class LimitSolution:
    """What the periodic-limit solver found."""

    converged: bool
    w: np.ndarray  # w(t0) of the limit period (the start of ``record``)
    record: PeriodRecord  # the verified period: a plain period from w
    method: str  # "newton" or "iterate"
    newton_steps: int  # accepted Newton steps
    periods: int  # periods simulated by the solver, the verifying one included
    residuals: np.ndarray  # relative Poincare step of each period simulated
    jacobian_rate: float | None  # subdominant spectral radius of J at the limit


def jacobian(poly: Polyhedron, visited) -> np.ndarray:
    """J = P_{A_K} ... P_{A_1} as a dense (n, n) matrix, O(K n N) for a crawler."""
    n = poly.n
    X = np.eye(n)  # rows: the images of the basis vectors, transformed in turn
    for A in visited:
        idx = A.index
        lam = np.zeros((n, poly.m))
        lam[:, idx] = A.solve(poly.apply(X)[:, idx])
        X = X - poly.respond(lam)
    return X.T


def apply_jacobian(poly: Polyhedron, visited, V: np.ndarray) -> np.ndarray:
    """J v for the rows v of V (k, n): each visited projector in turn."""
    X = np.array(V, dtype=float)
    for A in visited:
        lam = np.zeros(X.shape[:-1] + (poly.m,))
        lam[..., A.index] = A.solve(poly.apply(X)[..., A.index])
        X = X - poly.respond(lam)
    return X


def apply_jacobian_transpose(poly: Polyhedron, visited, V: np.ndarray) -> np.ndarray:
    """J^T v for the rows v of V: P_A^T = I - B_A^T G_A^{-1} B_A M^{-1}, in reverse order."""
    X = np.array(V, dtype=float)
    for A in reversed(visited):
        lam = np.zeros(X.shape[:-1] + (poly.m,))
        lam[..., A.index] = A.solve(poly.apply(poly.metric_solve(X))[..., A.index])
        X = X - poly.metric_times(poly.respond(lam))  # B^T lambda = M (M^{-1} B^T lambda)
    return X


def subdominant_rate(J: np.ndarray) -> float:
    """The largest |eigenvalue| of J below 1 (eigenvalues at 1: the family of fixed points)."""
    moduli = np.abs(np.linalg.eigvals(J))
    below = moduli[moduli < 1.0 - UNIT_EIGENVALUE]
    return float(np.max(below)) if below.size else 0.0


def newton_step(poly: Polyhedron, visited, F: np.ndarray) -> np.ndarray:
    """The minimal-norm least-squares solution of (J - I) d = -F in the metric M: dense
    ``lstsq`` up to `DENSE_JACOBIAN` state variables, matrix-free LSMR beyond."""
    n = len(F)
    rhs = -poly.metric_root(F)
    if n <= DENSE_JACOBIAN:
        J = jacobian(poly, visited)
        A = poly.metric_root((J - np.eye(n)).T).T  # L^T (J - I)
        d, *_ = np.linalg.lstsq(A, rhs, rcond=None)
        return d
    from scipy.sparse.linalg import LinearOperator, lsmr

    def matvec(x):
        x = np.ravel(x)
        return poly.metric_root(apply_jacobian(poly, visited, x) - x)

    def rmatvec(y):
        y = poly.metric_root_transpose(np.ravel(y))
        return apply_jacobian_transpose(poly, visited, y) - y

    op = LinearOperator((n, n), matvec=matvec, rmatvec=rmatvec, dtype=float)
    return lsmr(op, rhs, atol=1e-15, btol=1e-15, maxiter=20 * n)[0]


def relative_step(process: SweepingProcess, w_start: np.ndarray, w_end: np.ndarray) -> float:
    """The relative Poincare step of `crawlsim.analysis.poincare_step`."""
    step = float(np.linalg.norm(w_end - w_start))
    return step / max(float(np.linalg.norm(w_end)), process.scale)


def solve_limit(process: SweepingProcess, stepper, *, tolerance: float, max_periods: int,
                start: np.ndarray | None = None, plain: int = PLAIN_PERIODS,
                method: str = "newton") -> LimitSolution:
    """Find the periodic limit of ``process`` from ``start`` (default: the stepper's state)
    with ``stepper`` (a `crawlsim.stepping` integrator), simulating at most ``max_periods``
    periods; ``method="iterate"`` takes plain iterations only (the reference)."""
    poly = process.polyhedron
    exact = getattr(stepper, "needs_admissible_start", False)

    def period(w: np.ndarray) -> PeriodRecord:
        stepper.reset(w)
        return stepper.step_period()

    w = np.array(stepper.w if start is None else start, dtype=float)
    record = period(w)
    residuals = [relative_step(process, w, record.w[-1])]
    periods, newton_steps, rate = 1, 0, None
    used_newton = False
    history: list[tuple[np.ndarray, np.ndarray]] = [(w, record.w[-1])]  # (w, P(w)) accepted
    anderson = False  # the last Newton step failed: try Anderson's step instead

    def attempt(candidate: np.ndarray) -> bool:
        nonlocal w, record, periods
        if exact:
            candidate = _admissible(stepper, candidate)
        trial = period(candidate)
        periods += 1
        r = relative_step(process, candidate, trial.w[-1])
        residuals.append(r)
        if r < current:
            w, record = candidate, trial
            history.append((w, record.w[-1]))
            return True
        return False

    while residuals[-1] > tolerance and periods < max_periods:
        F = record.w[-1] - w
        current = residuals[-1]
        accepted = False
        if method == "newton" and periods >= plain:
            if anderson and len(history) > 2:
                accepted = attempt(anderson_step(history))
                anderson = accepted
            else:
                d = newton_step(poly, record.visited, F)
                # backtracking: the affine model holds on the current piece of the map only; a
                # full step that leaves it is shortened (a period per trial, as a plain step)
                for scale in BACKTRACK:
                    if periods >= max_periods:
                        break
                    if attempt(w + scale * d):
                        accepted = True
                        break
                anderson = not accepted
            if accepted:
                newton_steps += 1
                used_newton = True
                continue
            if periods >= max_periods:
                break
        w = record.w[-1].copy()  # plain iteration
        record = period(w)
        periods += 1
        residuals.append(relative_step(process, w, record.w[-1]))
        history.append((w, record.w[-1]))
    converged = residuals[-1] <= tolerance
    if converged and method == "newton" and poly.n <= DENSE_JACOBIAN:
        rate = subdominant_rate(jacobian(poly, record.visited))
    return LimitSolution(converged, w, record, "newton" if used_newton else "iterate",
                         newton_steps, periods, np.array(residuals), rate)


def anderson_step(history, depth: int = ANDERSON_DEPTH) -> np.ndarray:
    """Anderson's extrapolation (type II) from the last ``depth`` + 1 pairs (w, P(w)): the
    combination of the P(w) whose residuals F = P(w) - w combine to the least |F| (a secant
    method on F that needs no Jacobian)."""
    pairs = history[-(depth + 1):]
    W = np.array([np.ravel(w) for w, _ in pairs])
    G = np.array([np.ravel(g) for _, g in pairs])
    F = G - W
    dF, dG = np.diff(F, axis=0).T, np.diff(G, axis=0).T
    gamma = np.linalg.lstsq(dF, F[-1], rcond=None)[0]
    return (G[-1] - dG @ gamma).reshape(np.shape(pairs[-1][0]))


def _admissible(stepper, w: np.ndarray) -> np.ndarray:
    """The exact integrator starts from a point of K(0): project the candidate onto it."""
    c0 = stepper.process.offsets[0]
    try:
        proj = stepper.projector.project(w, c0, time=None)
    except Dependent:  # pragma: no cover - the projector handles dependence itself
        return w
    return proj.point
