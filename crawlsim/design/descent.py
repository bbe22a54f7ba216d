"""The gradient search of gait design (``crawlsim optimize --method gradient``): a coarse sample
of the box, then quasi-Newton runs from its best points on the exact derivatives of the
objective and the constraints (`crawlsim.sensitivity`, docs/sensitivity.md).

* **The global stage** goes through the sweep engine in batches (so ``jobs``, a Dask scheduler
  and the journal apply): the grid of `Method.sample` points per free parameter, one batch,
  while it has at most `crawlsim.design.problem.SAMPLE_GRID` points; in more dimensions, where a
  coarse sample leaves most basins of v0 unvisited, differential evolution on the run's budget
  less `Method.polish_share` (the evolution search's global stage, `Search._global`). A run of a
  Pareto front evaluates the population it is given instead (the front found so far among
  it).
* **The local runs** start from the `Method.restarts` best points of that stage by the feasibility
  rules (`crawlsim.design.problem.rank`): L-BFGS-B in the box without constraints, SLSQP with
  them (each constraint ``q >= b`` or ``q <= b`` with its exact gradient), in units of the box.
  Every step is one verified limit with the derivatives of v0, the displacement, the dissipation
  and the cost of transport per period, kept in the row's extra columns (so a rerun replays
  them from the journal). A free path with ``*`` ties every element to one value, so its
  derivative is the sum over the elements.
* **Kinks.** v0 is only piecewise smooth. Where the limit period sits on a kink, the derivative
  used is the one on the period's own pieces (one element of the generalized gradient), and a
  run ends when `Method.stall` evaluations in a row improve its best value by less than 1e-13
  relative (a line search stuck on a kink); the restarts from distinct sample points keep one
  kink from ending the search.

Points that do not run (an invalid gait, a failed run) are recorded and never chosen, as in
the evolution search: they stop the local run that met them, not the search.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from crawlsim.analysis.sensitivity import sensitivity
from crawlsim.design.optresult import BUDGET_SPENT, Evaluation, Run, Stage
from crawlsim.design.problem import QUANTITIES, SAMPLE_GRID, Constraint, Problem
from crawlsim.design.search import BudgetSpent, Search
from crawlsim.errors import CrawlsimError, InputError
from crawlsim.gait.docpaths import resolve_path
from crawlsim.status import PointStatus
from crawlsim.study.points import PointResult

#: The quantities whose derivatives a gradient evaluation keeps, in the order of its extra
#: columns (one block of n derivatives each, n the free parameters).
DERIVED = tuple(QUANTITIES)
#: Improvement below this (relative) does not reset a local run's stall count.
STALL_IMPROVEMENT = 1e-13


class _LocalEnd(Exception):
    """A local run ends (stalled, or it met a point that does not run)."""


def parameter_groups(problem: Problem) -> list[set[str]]:
    """The concrete dotted paths each free parameter sets (a ``*`` path sets several)."""
    base = problem.base
    return [
        {".".join(str(k) for k in keys) for keys in resolve_path(base.document, f.path, base.source)}
        for f in problem.free
    ]


def gradient_row(problem: Problem, groups: Sequence[set[str]], x: Sequence[float]) -> PointResult:
    """The row of point ``x`` with the derivatives of `DERIVED` with respect to the free
    parameters in its extra columns (NaN where a derivative has no value), from one
    `crawlsim.sensitivity` at the exact integrator's verified limit. A gait that is not valid,
    or a run that fails, is a row of its own (``invalid`` or ``failed``) without derivatives."""
    try:
        r = sensitivity(problem.gait(x), list(problem.paths), one_sided=False)
    except InputError as exc:
        return PointResult(0, PointStatus.INVALID, message=str(exc))
    except CrawlsimError as exc:
        return PointResult(0, PointStatus.FAILED, message=str(exc))
    extra: list[float | None] = []
    for name in DERIVED:
        for group in groups:
            total = 0.0
            for p in r.parameters:
                if p.path in group:
                    d = p.v0_on_pieces if name == "v0" else getattr(p, name).value
                    total += math.nan if d is None else float(d)
            extra.append(total)
    return PointResult(
        0,
        PointStatus.OK,
        v0=r.v0,
        v0_error_estimate=r.v0_error_estimate,
        displacement_per_period=r.displacement_per_period,
        dissipation_per_period=r.dissipation_per_period,
        cost_of_transport=r.cost_of_transport,
        integrator="exact",
        limit="newton",
        extra=tuple(extra),
    )


def derivative(row: PointResult, name: str, n: int) -> np.ndarray:
    """d(name)/dx of a gradient row (zeros where it has none: a kink of that quantity)."""
    k = DERIVED.index(name)
    values = np.array([math.nan if v is None else v for v in row.extra[k * n : (k + 1) * n]], dtype=float)
    return np.nan_to_num(values, nan=0.0)


class Descent(Search):
    """One single-objective run of the gradient search on the shared evaluator (the module
    docstring); the same bookkeeping as the evolution search (`Search`)."""

    def __init__(self, *args: Any, **kwargs: Any):
        super().__init__(*args, **kwargs)
        self.groups: list[set[str]] = []
        self._local_best = math.inf  # the local run's best energy
        self._since = 0  # its evaluations since that improved

    def solve(self) -> Run:
        problem = self.ev.problem
        self.groups = parameter_groups(problem)
        try:
            starts = self._starts(problem.dimension)
            for u0 in starts[: self.method.restarts]:
                self._local(u0)
            self.stop = f"{min(len(starts), self.method.restarts)} quasi-Newton runs converged or stalled" + (
                f" (differential evolution: {self.stop})" if self.stop else ""
            )
        except BudgetSpent:
            self.stop = f"{BUDGET_SPENT} in the quasi-Newton runs" if self.best >= 0 else BUDGET_SPENT
        return self._finished()

    def _sample(self, n: int) -> np.ndarray:
        """The coarse sample: the grid of `Method.sample` points per parameter, in the unit
        box."""
        return np.array(list(itertools.product(*[np.linspace(0.0, 1.0, self.method.sample)] * n)))

    def _starts(self, n: int) -> list[np.ndarray]:
        """The global stage, and its points that run, best first by the feasibility rules, in
        the unit box: the coarse sample as one batch (cut to what the run may spend) while its
        grid is small, else differential evolution on the run's budget less the quasi-Newton
        runs' share (`Method.polish_share`): a Latin hypercube of ``sample n`` points leaves
        most basins of a multimodal v0 unvisited in many dimensions (ten phase lags:
        scripts/optimize-gradient.py)."""
        problem = self.ev.problem
        if self.init is None and self.method.sample**n > SAMPLE_GRID:
            self._global(n)
            evaluations = self.ev.evaluations[self.start :]
        else:
            X = (
                np.asarray(self.init, dtype=float)
                if self.init is not None
                else np.array([problem.values(u) for u in self._sample(n)])
            )
            evaluations = self.evaluate(X[: max(self.left(), 1)], Stage.INITIAL)
        ranked = sorted({e.index: e for e in evaluations if self.rank(e)[0] < 2}.values(), key=self.rank)
        return [np.array([f.unit(v) for f, v in zip(problem.free, e.x)]) for e in ranked]

    def _point(self, u: np.ndarray, memo: dict[tuple[float, ...], Evaluation]) -> Evaluation:
        """The gradient evaluation at ``u`` in the unit box (looked up if met in this run)."""
        problem = self.ev.problem
        x = problem.values(np.clip(u, 0.0, 1.0))
        key = self.ev.key(x)
        if key not in memo:
            if self.left() < 1:
                raise BudgetSpent
            e = self.ev.evaluate_one(x, self.run, Stage.POLISH, lambda k: gradient_row(problem, self.groups, k))
            memo[key] = e
            before = self.best
            self.consider([e])
            self.ev.record(self.run, Stage.POLISH, self.best, self.best_rank, self.objective)
            self._stalled(e, improved=self.best != before)
        return memo[key]

    def _stalled(self, e: Evaluation, improved: bool) -> None:
        value = self.objective.energy(self.objective.value(e.row))
        better = math.isfinite(value) and value < self._local_best - STALL_IMPROVEMENT * max(
            abs(self._local_best) if math.isfinite(self._local_best) else 0.0, 1e-300
        )
        if better:
            self._local_best, self._since = value, 0
        else:
            self._since += 1
            if self._since >= self.method.stall:
                raise _LocalEnd

    def _local(self, u0: np.ndarray) -> None:
        """One quasi-Newton run from ``u0`` (unit box)."""
        from scipy.optimize import minimize

        n = len(u0)
        width = np.array([f.hi - f.lo for f in self.ev.problem.free])
        memo: dict[tuple[float, ...], Evaluation] = {}
        self._local_best, self._since = math.inf, 0

        def quantity(u: np.ndarray, name: str) -> tuple[float, np.ndarray]:
            e = self._point(u, memo)
            value = getattr(e.row, name)
            if e.row.status != PointStatus.OK or value is None or not math.isfinite(value):
                raise _LocalEnd  # a point that does not run ends this local run
            return float(value), derivative(e.row, name, n) * width

        def fun(u: np.ndarray) -> tuple[float, np.ndarray]:
            value, grad = quantity(u, self.objective.quantity)
            return self.objective.energy(value), (grad if self.objective.energy(1.0) > 0 else -grad)

        constraints = [_slsqp(c, quantity) for c in self.constraints]
        options: dict[str, Any] = {"maxiter": 200}
        if constraints:
            options.update(ftol=1e-15)
        else:
            options.update(gtol=self.method.gradient_tol, ftol=1e-15)
        try:
            minimize(
                fun,
                u0,
                jac=True,
                method="SLSQP" if constraints else "L-BFGS-B",
                bounds=[(0.0, 1.0)] * n,
                constraints=constraints,
                options=options,
            )
        except _LocalEnd:
            pass


def _slsqp(c: Constraint, quantity: Callable[[np.ndarray, str], tuple[float, np.ndarray]]) -> dict[str, Any]:
    """A constraint as SLSQP takes it: ``fun(u) >= 0`` with its gradient."""
    sign = 1.0 if c.op == ">=" else -1.0

    def fun(u: np.ndarray) -> float:
        return sign * (quantity(u, c.quantity)[0] - c.bound)

    def jac(u: np.ndarray) -> np.ndarray:
        return sign * quantity(u, c.quantity)[1]

    return {"type": "ineq", "fun": fun, "jac": jac}
