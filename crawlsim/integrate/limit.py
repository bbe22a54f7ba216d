"""The periodic limit directly: a safeguarded semismooth Newton method on the period map.

With piecewise-linear offsets the period map P : w(t0) -> w(t0 + T) of a polyhedral sweeping
process is piecewise affine and nonexpansive (docs/model.md §4), for catch-up stepping (a
composition of projections) and for the exact integrator (a composition of affine pieces);
with smooth offsets it is piecewise smooth. Near a start w whose period visits the active sets
A_1, ..., A_K (`crawlsim.integrate.stepping.PeriodRecord.visited`), its Jacobian is the product of their
projectors,

    J = P_{A_K} ... P_{A_1},   P_A = I - R_A B_A,   R_A = M^{-1} B_A^T G_A^{-1},

(a step on A is w -> P_A w + R_A c_A, and P_A P_A = P_A). For the exact flow the same product
holds at events where a friction limit is reached (entries) or released (exits), but not where
one is reached while another is released: the time of such a swap moves with the start, and
its factor is the saltation `Saltation` (from ``PeriodRecord.transitions``; without it Newton
converges only linearly, sometimes slower than plain iteration). So a fixed point of P solves the
semismooth equation F(w) = P(w) - w = 0, and Newton's step solves (J - I) d = -F. The fixed
points may form a family (Theorem th:speed: every periodic solution has the same derivative),
so J - I may be singular: the step is the least-squares solution of minimal norm, in the metric
M. Once the period visits the active sets of the limit, the affine map is exact and one step
lands on a fixed point (to roundoff).

The safeguard: a Newton candidate is accepted only if its own Poincare step |P(w) - w| is
smaller. A full step that is not lands on another piece of P, whose Jacobian its period gives;
the Newton step from there is tried next, then the full step shortened (`ATTEMPTS`). If none is
accepted, the solver takes plain iterations w <- P(w), 1, 2, 4, ... after the first, second,
third ... failed attempt, before it tries Newton again. It starts with ``plain``
plain periods, so gaits that are periodic after a period or two (finite-time convergence) pay
nothing extra. The limit is *verified* by the last plain period of the solver, from the accepted
point: its Poincare step is at the tolerance (roundoff by default), and v0 and the limit period
are taken from that period.

The Jacobian at the limit also gives a contraction rate: the largest modulus of its eigenvalues
other than those equal to 1 (the directions of the family of periodic solutions), the local
rate of the plain iteration near the limit. The limit often lies on a kink of P (the acute
angle: the edge map is the identity beyond the fixed point; a crawler that sticks in its limit
period: every nearby state is periodic), where the Jacobian of the limit period itself is the
piece on the far side. The rate is therefore read from the Jacobian of the last accepted Newton
step, the piece through which the iterates approach (the limit period's own when no Newton step
was taken).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from crawlsim import interrupts
from crawlsim.integrate.stepping import PeriodRecord, PeriodStepper
from crawlsim.kernel.jit import kernel
from crawlsim.model.process import SweepingProcess
from crawlsim.projection.chain_polyhedron import ChainPolyhedron
from crawlsim.projection.kkt import ActiveSet, Dependent, Polyhedron

#: Plain periods before the first Newton step.
PLAIN_PERIODS = 2
#: Eigenvalues of J within this distance of 1 belong to the family of periodic solutions.
UNIT_EIGENVALUE = 1e-8
#: What each period simulated by the solver was (`LimitSolution.kinds`): a plain iteration
#: from the previous accepted point, an accepted Newton candidate, or a rejected one.
PLAIN, NEWTON, REJECTED = 0, 1, -1
#: Up to this many state variables J is formed densely (and its contraction rate reported);
#: beyond, the Newton step is solved matrix-free (LSMR with products by J and J^T, O(K N) each).
DENSE_JACOBIAN = 400
#: For a crawler chain, whose products are compiled (`PackedJacobian`), the Newton step is
#: matrix-free beyond this many: measured on the bench-scale waves after 3 exact periods, the
#: dense step costs 0.5-0.9 times LSMR's at n = 10-50, 1.3-1.4 times at n = 100, 4.7-11 at
#: n = 200 and 18-200 at n = 400 (the steps agreeing to 5e-13 relative).
DENSE_CHAIN_JACOBIAN = 100
#: A Newton step that leaves more than this fraction of the residual is kept but counts as a
#: failure of the model for the back-off (a random 11-block gait: 176 Newton steps of a few per
#: cent each, where 25 plain periods converge).
SUFFICIENT_DECREASE = 0.5
#: The candidates of one Newton attempt, tried in turn until one decreases the residual: the
#: full step; the Newton step from the full step's candidate with the Jacobian of its own
#: period ("through": the full step crossed a kink of P, and the fixed point may lie on the
#: piece beyond, where this step is exact; a random 10-block gait of rate 0.975: 43 periods ->
#: 9); and the step shortened to a quarter.
ATTEMPTS: tuple[tuple[Literal["step", "through"], float], ...] = (("step", 1.0), ("through", 1.0), ("step", 0.25))


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
    kinds: np.ndarray  # int8, what each of those periods was: PLAIN, NEWTON or REJECTED
    jacobian_rate: float | None  # subdominant spectral radius of J at the limit


@dataclass(frozen=True, eq=False)
class Saltation:
    """The Jacobian factor of an event of the exact flow whose time depends on the start: row
    i enters the active set while others leave (a swap A -> A', A not in A').

    Before the event the flow runs on A with velocity v_b = R_A c_A'(u), after it on A' with
    v_a = R_A' c_A''(u); a perturbation delta (in null B_A) moves the time at which row i is
    hit by d u = -<b_i, delta> / (<b_i, v_b> - c_i'(u)), and so the state after the event by
    S delta = delta + (v_b - v_a) d u: S = I - (v_b - v_a) b_i^T / (<b_i, v_b> - c_i'). For an
    entry alone (A in A') S delta = P_A' delta, and an exit alone (A' in A) leaves delta alone,
    so only swaps need S; catch-up has no such factor (its step times are fixed).
    """

    row: int
    jump: np.ndarray  # v_b - v_a
    rate: float  # <b_i, v_b> - c_i'(u)


#: A factor of the period map's Jacobian: the projector of an active set, or a saltation.
Factor = ActiveSet | Saltation


def factors(process: SweepingProcess, record: PeriodRecord) -> list[Factor]:
    """The Jacobian of the period map from ``record``'s start, as the factors applied in turn:
    the projectors P_A of the visited sets (`crawlsim.projection.kkt.ActiveSet`), and, for event-driven
    integrators (``record.transitions``), the `Saltation` of every hit that swaps the set.

    Only a hit (a gap reaching zero) happens at a time that moves with the start; the other
    decisions (the start, an edge of c(t), a release, the projection at a jump of c and the
    flow's set just after it) happen at fixed times and contribute their projector alone.
    Where several rows are hit at once (blocks of one cluster that start to slip together),
    the event's time is that of any of them; the row with the largest rate defines it."""
    if not record.transitions:
        return list(record.visited)
    poly, pieces = process.polyhedron, process.offset_pieces
    assert pieces is not None, "event-driven integrators need the closed form of c(t)"
    out: list[Factor] = []
    before = poly.empty
    for u, piece, A, cause, hit in record.transitions:
        if cause == "jump":  # the projection at a jump of c: a catch-up step
            if A.size:
                out.append(A)
            before = A
            continue
        old, new = set(before.index.tolist()), set(A.index.tolist())
        entering = new - old
        if cause == "hit" and not old <= new:
            dc = pieces.evaluate(u, order=1, piece=piece)[0]
            v_b, v_a = _velocity(poly, before, dc), _velocity(poly, A, dc)
            rates = poly.apply(v_b)[hit] - dc[hit]
            k = int(np.argmax(np.abs(rates)))
            if abs(rates[k]) > 1e-12 * max(float(np.max(np.abs(dc))), 1e-300):
                out.append(Saltation(int(hit[k]), v_b - v_a, float(rates[k])))
        if entering:
            out.append(A)  # entries: P_A' (after S, a no-op but for roundoff)
        before = A
    return out


def _velocity(poly: Polyhedron, A: ActiveSet, dc: np.ndarray) -> np.ndarray:
    """R_A c_A': the velocity of the exact flow on the faces A (zero off every face)."""
    if not A.size:
        return np.zeros(poly.n)
    lam = np.zeros(poly.m)
    lam[A.index] = A.solve(dc[A.index])
    return poly.respond(lam)


def _row_vector(poly: Polyhedron, i: int, n: int) -> np.ndarray:
    """b_i as a vector of R^n: B^T e_i = M (M^{-1} B^T e_i)."""
    e = np.zeros(poly.m)
    e[i] = 1.0
    return poly.metric_times(poly.respond(e)).reshape(n)


def jacobian(poly: Polyhedron, visited: Sequence[Factor]) -> np.ndarray:
    """J, the product of the factors ``visited`` (active sets, `Saltation`), as a dense (n, n)
    matrix, O(K n N) for a crawler."""
    return apply_jacobian(poly, visited, np.eye(poly.n)).T


def apply_jacobian(poly: Polyhedron, visited: Sequence[Factor], V: np.ndarray) -> np.ndarray:
    """J v for the rows v of V (k, n): each factor in turn."""
    X = np.array(V, dtype=float)
    for A in visited:
        if isinstance(A, Saltation):
            X = X - np.multiply.outer(poly.apply(X)[..., A.row] / A.rate, A.jump)
            continue
        lam = np.zeros(X.shape[:-1] + (poly.m,))
        lam[..., A.index] = A.solve(poly.apply(X)[..., A.index])
        X = X - poly.respond(lam)
    return X


def apply_jacobian_transpose(poly: Polyhedron, visited: Sequence[Factor], V: np.ndarray) -> np.ndarray:
    """J^T v for the rows v of V: P_A^T = I - B_A^T G_A^{-1} B_A M^{-1} and
    S^T = I - b_i (v_b - v_a)^T / rate, in reverse order."""
    X = np.array(V, dtype=float)
    for A in reversed(visited):
        if isinstance(A, Saltation):
            b = _row_vector(poly, A.row, poly.n)
            X = X - np.multiply.outer(X @ A.jump / A.rate, b)
            continue
        lam = np.zeros(X.shape[:-1] + (poly.m,))
        lam[..., A.index] = A.solve(poly.apply(poly.metric_solve(X))[..., A.index])
        X = X - poly.metric_times(poly.respond(lam))  # B^T lambda = M (M^{-1} B^T lambda)
    return X


@dataclass(frozen=True, eq=False)
class PackedJacobian:
    """The factors of J for a crawler chain packed into arrays once, for the compiled products
    of `crawlsim.kernel.jacobian` (O(K N) each, one compiled call instead of K Python solves)."""

    stiffness: np.ndarray
    kinds: np.ndarray  # int8 (K,): PROJECTOR or SALTATION
    starts: np.ndarray  # (K + 1,): projector p's saturated blocks are blocks[starts[p]:starts[p + 1]]
    blocks: np.ndarray  # sorted saturated blocks of every projector
    D: np.ndarray  # LDL^T of each projector's L_JJ, like ``blocks`` (D: reciprocal pivots)
    l: np.ndarray
    slot: np.ndarray  # (K,): saltation p is row slot[p] of rows, rates, jumps
    rows: np.ndarray
    rates: np.ndarray
    jumps: np.ndarray  # (S, n): v_b - v_a of each saltation

    def apply(self, v: np.ndarray) -> np.ndarray:
        """J v (`apply_jacobian` for one vector)."""
        x = np.array(v, dtype=float)
        kernel().jacobian.apply(
            self.stiffness,
            self.kinds,
            self.starts,
            self.blocks,
            self.D,
            self.l,
            self.slot,
            self.rows,
            self.rates,
            self.jumps,
            x,
        )
        return x

    def apply_transpose(self, v: np.ndarray) -> np.ndarray:
        """J^T v (`apply_jacobian_transpose` for one vector)."""
        x = np.array(v, dtype=float)
        kernel().jacobian.apply_transpose(
            self.stiffness,
            self.kinds,
            self.starts,
            self.blocks,
            self.D,
            self.l,
            self.slot,
            self.rows,
            self.rates,
            self.jumps,
            x,
        )
        return x


def packed_jacobian(poly: Polyhedron, visited: Sequence[Factor]) -> PackedJacobian | None:
    """The factors ``visited`` packed for the compiled products, for a crawler chain
    (`crawlsim.projection.chain_polyhedron.ChainPolyhedron`: a projector depends on its saturated
    blocks alone); None for another polyhedron.

    Neighbouring projectors of nested sets are merged (`_merged`): P_A is the M-orthogonal
    projector onto null B_A (M P_A = M - B_A^T G_A^{-1} B_A is symmetric), and for J(A) within
    J(A') null B_A' lies in null B_A, so P_A' P_A = P_A P_A' = P_A'. The product is the same
    to roundoff; an entry followed by its exit costs one projector instead of two (the
    1000-block segments wave: 128 factors -> 17, their blocks 57725 -> 7385)."""
    if not isinstance(poly, ChainPolyhedron):
        return None
    from crawlsim.kernel.jacobian import PROJECTOR, SALTATION

    kept = _merged(poly.blocks, visited)
    kinds = np.array([SALTATION if isinstance(A, Saltation) else PROJECTOR for A in kept], dtype=np.int8)
    sets = [A for A in kept if not isinstance(A, Saltation)]
    sizes = np.zeros(len(kept), dtype=np.int64)
    sizes[kinds == PROJECTOR] = [len(J) for J in sets]
    starts = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    blocks = np.concatenate(sets).astype(np.int64) if sets else np.zeros(0, dtype=np.int64)
    salts = [A for A in kept if isinstance(A, Saltation)]
    slot = np.cumsum(kinds == SALTATION).astype(np.int64) - 1
    D, l = np.empty(len(blocks)), np.empty(len(blocks))
    kernel().jacobian.pack(poly.stiffness, kinds, starts, blocks, D, l)
    return PackedJacobian(
        poly.stiffness,
        kinds,
        starts,
        blocks,
        D,
        l,
        slot,
        np.array([A.row for A in salts], dtype=np.int64),
        np.array([A.rate for A in salts], dtype=float),
        np.array([A.jump for A in salts], dtype=float).reshape(len(salts), poly.n),
    )


def _merged(N: int, visited: Sequence[Factor]) -> list[np.ndarray | Saltation]:
    """The factors in turn, each projector as its sorted saturated blocks, with every projector
    next to one of a superset (no saltation between) dropped (`packed_jacobian`)."""
    out: list[np.ndarray | Saltation] = []
    for A in visited:
        if isinstance(A, Saltation):
            out.append(A)
            continue
        J = np.unique(A.index % N)
        while out and isinstance(out[-1], np.ndarray):
            if np.isin(J, out[-1]).all():  # P_A P_last = P_last
                break
            if not np.isin(out[-1], J).all():
                out.append(J)
                break
            out.pop()  # P_A P_last = P_A, and so on back
        else:
            out.append(J)
    return out


def subdominant_rate(J: np.ndarray) -> float:
    """The largest |eigenvalue| of J below 1 (eigenvalues at 1: the family of fixed points)."""
    moduli = np.abs(np.linalg.eigvals(J))
    below = moduli[moduli < 1.0 - UNIT_EIGENVALUE]
    return float(np.max(below)) if below.size else 0.0


def newton_step(poly: Polyhedron, visited: Sequence[Factor], F: np.ndarray) -> np.ndarray:
    """The minimal-norm least-squares solution of (J - I) d = -F in the metric M: dense
    ``lstsq`` up to `DENSE_JACOBIAN` state variables, matrix-free LSMR beyond (for a crawler
    chain beyond `DENSE_CHAIN_JACOBIAN`, with the compiled products of `PackedJacobian`)."""
    global _formed
    n = len(F)
    rhs = -poly.metric_root(F)
    if n <= DENSE_JACOBIAN and (n <= DENSE_CHAIN_JACOBIAN or not isinstance(poly, ChainPolyhedron)):
        J = jacobian(poly, visited)
        _formed = (poly, visited, J)
        A = poly.metric_root((J - np.eye(n)).T).T  # L^T (J - I)
        d: np.ndarray
        d, *_ = np.linalg.lstsq(A, rhs, rcond=None)
        return d
    from scipy.sparse.linalg import LinearOperator, lsmr

    packed = packed_jacobian(poly, visited)
    if packed is not None:
        forward, backward = packed.apply, packed.apply_transpose
    else:

        def forward(v: np.ndarray) -> np.ndarray:
            return apply_jacobian(poly, visited, v)

        def backward(v: np.ndarray) -> np.ndarray:
            return apply_jacobian_transpose(poly, visited, v)

    def matvec(x: np.ndarray) -> np.ndarray:
        x = np.ravel(x)
        return poly.metric_root(forward(x) - x)

    def rmatvec(y: np.ndarray) -> np.ndarray:
        y = poly.metric_root_transpose(np.ravel(y))
        out: np.ndarray = backward(y) - y
        return out

    op = LinearOperator((n, n), matvec=matvec, rmatvec=rmatvec, dtype=float)
    d_lsmr: np.ndarray = lsmr(op, rhs, atol=1e-15, btol=1e-15, maxiter=20 * n)[0]
    return d_lsmr


#: The dense Jacobian `newton_step` formed last, with its polyhedron and factors (the list
#: itself, kept): the solver's contraction rate reads it when that step was the last accepted.
_formed: tuple[Polyhedron, Sequence[Factor], np.ndarray] | None = None


def _formed_jacobian(poly: Polyhedron, visited: Sequence[Factor]) -> np.ndarray:
    """J of ``visited``: the one `newton_step` formed for this very list, else formed now."""
    formed = _formed
    if formed is not None and formed[0] is poly and formed[1] is visited:
        return formed[2]
    return jacobian(poly, visited)


def relative_step(process: SweepingProcess, w_start: np.ndarray, w_end: np.ndarray) -> float:
    """The relative Poincare step of `crawlsim.analysis.run.poincare_step`."""
    step = float(np.linalg.norm(w_end - w_start))
    return step / max(float(np.linalg.norm(w_end)), process.scale)


def solve_limit(
    process: SweepingProcess,
    stepper: PeriodStepper,
    *,
    tolerance: float,
    max_periods: int,
    start: np.ndarray | None = None,
    plain: int = PLAIN_PERIODS,
    method: str = "newton",
    first: PeriodRecord | None = None,
) -> LimitSolution:
    """Find the periodic limit of ``process`` from ``start`` (default: the stepper's state)
    with ``stepper`` (a `crawlsim.integrate.stepping` integrator), simulating at most ``max_periods``
    periods; ``method="iterate"`` takes plain iterations only (the reference). The exact
    integrator starts from K(0): a ``start`` outside is projected onto it first.

    ``first``, a period already simulated (the last true iterate of a run), is the solver's
    first period from its start ``first.w[0]``, at no cost: it is neither simulated again nor
    counted in ``periods`` (its residual is the first of ``residuals``)."""
    poly = process.polyhedron
    exact = getattr(stepper, "needs_admissible_start", False)

    def period(w: np.ndarray) -> PeriodRecord:
        stepper.reset(w)
        return stepper.step_period()

    if first is not None:
        w, record, periods = np.array(first.w[0], dtype=float), first, 0
    else:
        w = np.array(stepper.w if start is None else start, dtype=float)
        if exact and start is not None:
            w = _admissible(stepper, w)
        record, periods = period(w), 1
    search = _Search([relative_step(process, w, record.w[-1])], [PLAIN], periods)
    residuals = search.residuals
    newton_steps, rate = 0, None
    approach: list[Factor] | None = None  # the active sets of the last accepted Newton step's Jacobian
    rejected = wait = 0  # candidates rejected so far; plain periods before the next one
    used_newton = False
    while residuals[-1] > tolerance and search.periods < max_periods:
        interrupts.check()  # a Ctrl-C noted in lstsq, LSMR or a period: stop the search here
        if method == "newton" and search.periods >= plain and wait == 0:
            current = residuals[-1]
            found = _newton(process, stepper, period, w, record, search, max_periods)
            if found is not None:
                w, record, approach = found
                newton_steps += 1
                used_newton = True
                if residuals[-1] <= SUFFICIENT_DECREASE * current:
                    continue
            # back off: 1, 2, 4, ... plain periods before the next candidate, so that a
            # solver whose candidates keep failing costs at most 2 log2 more periods than plain
            # iteration; a step kept for a small decrease (the model is off here) counts too
            wait = 2**rejected
            rejected += 1
            if found is not None:
                continue
            if search.periods >= max_periods:
                break
        wait = max(wait - 1, 0)
        w = record.w[-1].copy()  # plain iteration
        record = period(w)
        search.periods += 1
        residuals.append(relative_step(process, w, record.w[-1]))
        search.kinds.append(PLAIN)
    periods, kinds = search.periods, search.kinds
    converged = residuals[-1] <= tolerance
    if converged and method == "newton" and poly.n <= DENSE_JACOBIAN:
        rate = subdominant_rate(
            jacobian(poly, factors(process, record)) if approach is None else _formed_jacobian(poly, approach)
        )
    return LimitSolution(
        converged,
        w,
        record,
        "newton" if used_newton else "iterate",
        newton_steps,
        periods,
        np.array(residuals),
        np.array(kinds, dtype=np.int8),
        rate,
    )


@dataclass
class _Search:
    """The periodic-limit solver's history: the residual and kind of every period, and their
    number."""

    residuals: list[float]
    kinds: list[int]
    periods: int


def _newton(
    process: SweepingProcess,
    stepper: PeriodStepper,
    period: Callable[[np.ndarray], PeriodRecord],
    w: np.ndarray,
    record: PeriodRecord,
    search: _Search,
    max_periods: int,
) -> tuple[np.ndarray, PeriodRecord, list[Factor]] | None:
    """One Newton step from w (its period ``record``): the candidates of `ATTEMPTS` in turn,
    each one period; (candidate, its period, the model's factors) of the first that lowers
    the residual, or None. The affine model holds on the map's current piece only."""
    poly = process.polyhedron
    base = factors(process, record)
    d = newton_step(poly, base, record.w[-1] - w)
    current = search.residuals[-1]
    beyond = None  # the full step's candidate and its period
    for how, scale in ATTEMPTS:
        if how == "through":
            if beyond is None:
                continue
            model = factors(process, beyond[1])
            candidate = beyond[0] + newton_step(poly, model, beyond[1].w[-1] - beyond[0])
        else:
            model, candidate = base, w + scale * d
        if getattr(stepper, "needs_admissible_start", False):
            candidate = _admissible(stepper, candidate)
        trial = period(candidate)
        search.periods += 1
        r = relative_step(process, candidate, trial.w[-1])
        search.residuals.append(r)
        if r < current:
            search.kinds.append(NEWTON)
            return candidate, trial, model
        search.kinds.append(REJECTED)
        if how == "step" and scale == 1.0:
            beyond = candidate, trial
        if search.periods >= max_periods:
            break
    return None


def _admissible(stepper: PeriodStepper, w: np.ndarray) -> np.ndarray:
    """The exact integrator starts from a point of K(0): project the candidate onto it."""
    c0 = stepper.process.offsets[0]
    try:
        proj = stepper.projector.project(w, c0, time=None)
        # a long step is certified to the roundoff of its own large multipliers; once more from
        # its point, the residual is the point's alone, as the exact period certifies it
        proj = stepper.projector.project(proj.point, c0, time=None, warm=proj.active)
    except Dependent:  # pragma: no cover - the projector handles dependence itself
        return w
    return proj.point
