"""One single-objective search of gait design on a shared evaluator: batches of points through the
sweep engine (with a cache, the budget and the journal), then differential evolution and the
pattern search."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, cast

import numpy as np

from crawlsim.design.optresult import BUDGET_SPENT, Batch, Evaluation, Run, Stage
from crawlsim.design.problem import Constraint, Method, Objective, Problem, rank
from crawlsim.errors import SweepSpecError
from crawlsim.status import PointStatus
from crawlsim.study.executors import WorkerPool
from crawlsim.study.grid import Axis, check_some_point_runs, make_grid
from crawlsim.study.journal import Journal
from crawlsim.study.points import PointResult, run_points
from crawlsim.study.sweep import SweepInterrupted, run_sweep


# -- evaluation -------------------------------------------------------------------------------
class OptimizationInterrupted(KeyboardInterrupt):
    """Ctrl-C (or SIGTERM) during an optimisation: ``done`` points are finished and kept in
    ``journal`` (None without one)."""

    def __init__(self, done: int, journal: Path | None):
        super().__init__(f"interrupted after {done} evaluations")
        self.done, self.journal = done, journal


class _Window(Journal):
    """The optimisation's journal as one batch sees it: `run_sweep` reads and writes the
    indices 0..S-1 of the batch's grid, the journal holds evaluation numbers start..start+S-1."""

    def __init__(self, journal: Journal, done: dict[int, PointResult], start: int, size: int):
        self.path, self.fingerprint = journal.path, journal.fingerprint
        self._journal, self._done, self._start, self._size = journal, done, start, size

    def load(self) -> dict[int, PointResult]:
        return {
            i - self._start: dataclasses.replace(r, index=i - self._start)
            for i, r in self._done.items()
            if self._start <= i < self._start + self._size
        }

    def append(self, results) -> None:
        self._journal.append([dataclasses.replace(r, index=r.index + self._start) for r in results])

    def flush(self) -> None:
        self._journal.flush()

    def close(self) -> None:
        self._journal.flush()  # the journal stays open for the next batch

    def remove(self) -> None:  # pragma: no cover - the optimisation removes the journal itself
        raise NotImplementedError


class BudgetSpent(Exception):
    """The budget is spent (ends a run)."""


class Evaluator:
    """Evaluates batches of points through the sweep engine: a cache of the points met so far
    (bit-identical parameters are simulated once), the budget, the journal and the history."""

    def __init__(
        self,
        problem: Problem,
        budget: int,
        *,
        jobs: int,
        scheduler: str | None,
        journal: Journal | None,
        progress: Callable[[int], None] | None,
        report: Callable[[Batch], None] | None,
    ):
        self.problem, self.budget = problem, budget
        self.jobs, self.scheduler, self.journal = jobs, scheduler, journal
        self.progress, self.report = progress, report
        self.evaluations: list[Evaluation] = []
        self.cache: dict[tuple[float, ...], int] = {}
        self.history: list[Batch] = []
        self.done = journal.load() if journal is not None else {}
        self.computed = 0
        self.pool: WorkerPool | None = None  # local workers kept for every batch (optimize)

    @property
    def remaining(self) -> int:
        return self.budget - len(self.evaluations)

    def key(self, x: Sequence[float]) -> tuple[float, ...]:
        """A point as the cache knows it: plain floats, clipped to the bounds."""
        return tuple(min(max(float(v), f.lo), f.hi) for f, v in zip(self.problem.free, x))

    def new_points(self, X: np.ndarray) -> list[tuple[float, ...]]:
        keys = [self.key(x) for x in X]
        return list(dict.fromkeys(k for k in keys if k not in self.cache))

    def evaluate(self, X: np.ndarray, run: int, stage: Stage) -> list[Evaluation]:
        """The evaluations of the rows of ``X`` (parameter values), simulating the new ones as
        one batch; `BudgetSpent` when they do not fit in the budget."""
        keys = [self.key(x) for x in X]
        new = list(dict.fromkeys(k for k in keys if k not in self.cache))
        if len(new) > self.remaining:
            raise BudgetSpent
        if new:
            rows = self._simulate(new)
            batch = len(self.history)
            for k, row in zip(new, rows):
                n = len(self.evaluations)
                self.cache[k] = n
                self.evaluations.append(Evaluation(n, k, run, stage, batch, dataclasses.replace(row, index=n)))
        return [self.evaluations[self.cache[k]] for k in keys]

    def evaluate_one(
        self, x: Sequence[float], run: int, stage: Stage, compute: Callable[[tuple[float, ...]], PointResult]
    ) -> Evaluation:
        """One point evaluated here by ``compute`` (a row with extra columns: the gradient
        search's derivatives), always a new evaluation even if the point was met before;
        journaled, and replayed from the journal on a rerun. `BudgetSpent` when none is left."""
        if self.remaining < 1:
            raise BudgetSpent
        n, k = len(self.evaluations), self.key(x)
        row = self.done.get(n)
        if row is None:
            try:
                row = compute(k)
            except KeyboardInterrupt:
                raise OptimizationInterrupted(
                    self._finished(), None if self.journal is None else self.journal.path
                ) from None
            self.computed += 1
            if self.journal is not None:
                self.journal.append([dataclasses.replace(row, index=n)])
        if self.progress is not None:
            self.progress(1)
        self.cache.setdefault(k, n)
        self.evaluations.append(Evaluation(n, k, run, stage, len(self.history), dataclasses.replace(row, index=n)))
        return self.evaluations[-1]

    def _simulate(self, points: list[tuple[float, ...]]) -> list[PointResult]:
        start = len(self.evaluations)
        grid = make_grid(
            self.problem.base,
            [tuple(Axis(f.path, tuple(p[a] for p in points)) for a, f in enumerate(self.problem.free))],
        )
        window = None if self.journal is None else _Window(self.journal, self.done, start, len(points))
        try:
            check_some_point_runs(grid)
        except SweepSpecError:
            # no point of this batch is a valid gait, which run_sweep refuses: each is an
            # invalid row (validation only, nothing to simulate), and the search goes on
            rows = run_points(grid, grid.indices())
            if window is not None:
                window.append(rows)
                window.close()
            if self.progress is not None:
                self.progress(len(rows))
            return rows
        try:
            table = run_sweep(
                grid,
                jobs=self.jobs,
                scheduler=self.scheduler,
                journal=cast(Journal, window),
                progress=self.progress,
                on_rows=self._skipped,
                pool=self.pool,
            )
        except SweepInterrupted:
            raise OptimizationInterrupted(
                self._finished(), None if self.journal is None else self.journal.path
            ) from None
        self.computed += table.computed
        return list(table.rows)

    def _finished(self) -> int:
        """Points kept so far (the journal holds every finished one after an interrupt)."""
        if self.journal is None:
            return len(self.evaluations)
        self.journal.flush()
        return len(self.journal.load())

    def _skipped(self, rows, resumed: bool) -> None:
        if resumed and self.progress is not None:
            self.progress(len(rows))

    def record(
        self,
        run: int,
        stage: Stage,
        best: int,
        rank: tuple[int, float],
        objective: Objective,
        *,
        step: float = math.nan,
    ) -> None:
        value = objective.value(self.evaluations[best].row) if best >= 0 else math.nan
        entry = Batch(
            len(self.history),
            run,
            stage,
            len(self.evaluations),
            value if rank[0] == 0 else math.nan,
            best,
            rank[0] == 0,
            step,
        )
        self.history.append(entry)
        if self.report is not None:
            self.report(entry)


# -- one run: differential evolution, then the pattern search ---------------------------------
class Search:
    """One single-objective run on the shared evaluator."""

    def __init__(
        self,
        ev: Evaluator,
        method: Method,
        run: int,
        objective: Objective,
        constraints: tuple[Constraint, ...],
        budget: int,
        seed: Sequence[int],
        init: np.ndarray | None = None,
    ):
        self.ev, self.method, self.run = ev, method, run
        self.objective, self.constraints = objective, constraints
        self.start = len(ev.evaluations)
        self.limit = min(ev.budget, self.start + budget)  # evaluation count this run may reach
        self.rng = np.random.default_rng(list(seed))
        self.seed = list(seed)
        self.init = init
        self.best = -1
        self.best_rank: tuple[int, float] = (3, math.inf)
        self.stop = ""

    def rank(self, e: Evaluation) -> tuple[int, float]:
        return rank(e.row, self.objective, self.constraints)

    def consider(self, evaluations: Sequence[Evaluation]) -> bool:
        improved = False
        for e in evaluations:
            r = self.rank(e)
            if r < self.best_rank:
                self.best, self.best_rank, improved = e.index, r, True
        return improved

    def left(self) -> int:
        return min(self.limit, self.ev.budget) - len(self.ev.evaluations)

    def evaluate(self, X: np.ndarray, stage: Stage, step: float = math.nan) -> list[Evaluation]:
        """Evaluate a batch for this run and record the best so far (when anything new was
        simulated: SciPy also asks for single points it has seen, to report them)."""
        new = len(self.ev.new_points(X))
        if new > self.left():
            raise BudgetSpent
        out = self.ev.evaluate(X, self.run, stage)
        self.consider(out)
        if new:
            self.ev.record(self.run, stage, self.best, self.best_rank, self.objective, step=step)
        return out

    def solve(self) -> Run:
        n = self.ev.problem.dimension
        try:
            self._global(n)
            self._polish(n)
        except BudgetSpent:  # the polish (or the one point of a tiny budget) was cut short
            before = (
                "" if not self.stop or self.stop.startswith(BUDGET_SPENT) else f" (differential evolution: {self.stop})"
            )
            self.stop = f"{BUDGET_SPENT} in the polish{before}" if self.stop else BUDGET_SPENT
        return self._finished()

    def _finished(self) -> Run:
        """The run's record once its search stopped (a budget spent before any point says so)."""
        if self.best < 0:
            self.stop = BUDGET_SPENT + " before the first point"
        return Run(
            self.run,
            self.objective,
            self.constraints,
            self.best,
            self.best_rank[0] == 0,
            sum(1 for e in self.ev.evaluations[self.start :] if e.run == self.run),
            self.stop,
        )

    # differential evolution --------------------------------------------------------------
    def _global(self, n: int) -> None:
        """Differential evolution on what the run may spend, less the polish's share. Each
        generation is one call of the (vectorised) constraint function, which evaluates the
        whole trial population as one batch; the objective then only looks the points up."""
        from scipy.optimize import NonlinearConstraint, differential_evolution

        problem, method = self.ev.problem, self.method
        share = self.left() - int(self.left() * method.polish_share)
        popsize = method.popsize
        if self.init is None and share < 2 * method.population(n):
            popsize = max(1, share // (2 * n))  # a small budget: a small population
        population = max(5, popsize * n) if self.init is None else len(self.init)
        if share < 2 * population:  # not even two generations: the polish starts at the centre
            self.evaluate(np.array([problem.values([0.5] * n)]), Stage.INITIAL)
            self.stop = "budget too small for differential evolution"
            return
        stage = [Stage.INITIAL]

        def constraint(X):
            evaluations = self.evaluate(np.atleast_2d(X.T), stage[0])
            if len(evaluations) > 1:  # SciPy first probes one point of the first population
                stage[0] = Stage.GENERATION
            return np.array([self._violations(e) for e in evaluations]).T

        def energy(X):
            return np.array(
                [
                    self.rank(e)[1] if self.rank(e)[0] == 0 else math.inf
                    for e in self.ev.evaluate(np.atleast_2d(X.T), self.run, Stage.GENERATION)
                ]
            )

        def callback(intermediate_result):
            return self.left() < population  # the next generation would not fit

        init: Any = method.init if self.init is None else self.init
        maxiter = share // population - 1
        try:
            result = differential_evolution(
                energy,
                [(f.lo, f.hi) for f in problem.free],
                strategy=method.strategy,
                maxiter=maxiter,
                popsize=popsize,
                tol=method.tol,
                atol=0,
                mutation=method.mutation,
                recombination=method.recombination,
                rng=self.rng,
                callback=callback,
                polish=False,
                init=init,
                updating="deferred",
                vectorized=True,
                constraints=NonlinearConstraint(constraint, -np.inf, 0.0),
            )
        except BudgetSpent:
            self.stop = BUDGET_SPENT
            return
        # its generations are the run's budget: stopping at maxiter, or at the callback's "the
        # next generation would not fit", is running out of it, not convergence
        if not result.success and (result.nit >= maxiter or self.left() < population):
            self.stop = f"{BUDGET_SPENT} in differential evolution ({result.nit} generations)"
        else:
            self.stop = str(result.message)

    def _violations(self, e: Evaluation) -> list[float]:
        """The constraints SciPy sees, satisfied at <= 0: "the point runs and has a value of the
        objective" (0 or 1), then each constraint's violation (infinite where the point does not
        run)."""
        runs = e.row.status == PointStatus.OK and math.isfinite(self.objective.value(e.row))
        return [0.0 if runs else 1.0, *((c.violation(e.row) if runs else math.inf) for c in self.constraints)]

    # the pattern search ------------------------------------------------------------------
    def _polish(self, n: int) -> None:
        """Poll ``u +- step d`` for the columns d of an orthogonal matrix (the coordinate axes
        first, then a fresh rotation after every poll that finds nothing better), clipped to the
        box; move to the best poll point if it beats the current one, else halve the step."""
        if self.best < 0 or self.best_rank[0] == 2:
            self.stop = self.stop or "no point runs"
            return
        problem, method = self.ev.problem, self.method
        u = np.array([f.unit(v) for f, v in zip(problem.free, self.ev.evaluations[self.best].x)])
        step, directions = method.polish_step, np.eye(n)
        while step >= method.polish_xtol:
            poll = np.clip(np.concatenate([u + step * directions.T, u - step * directions.T]), 0.0, 1.0)
            X = [problem.values(p) for p in poll]
            new = self.ev.new_points(np.array(X))
            if len(new) > self.left():  # the budget ends inside this poll: poll what fits
                if self.left() <= 0:
                    raise BudgetSpent
                fits = set(new[: self.left()])
                X = [x for x in X if self.ev.key(x) in fits or self.ev.key(x) in self.ev.cache]
            before = self.best
            self.evaluate(np.array(X), Stage.POLISH, step)
            if self.best != before:
                u = np.array([f.unit(v) for f, v in zip(problem.free, self.ev.evaluations[self.best].x)])
            else:
                step /= 2
                directions = _rotation(self.rng, n)
        self.stop = f"pattern search step below {method.polish_xtol:g} of the box"


def _rotation(rng: np.random.Generator, n: int) -> np.ndarray:
    """A random orthogonal matrix (Haar-distributed: QR of a Gaussian matrix with the signs of
    R's diagonal moved into Q)."""
    q, r = np.linalg.qr(rng.standard_normal((n, n)))
    return q * np.sign(np.diag(r))
