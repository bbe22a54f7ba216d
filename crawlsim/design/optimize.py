"""Gait design: the fastest or the cheapest gait in a box of gait parameters (``crawlsim optimize``).

A problem is a base gait, its **free parameters** (dotted paths of the gait document, the syntax
of ``--sweep``, each with inclusive bounds ``LO:HI``), an **objective** (maximise or minimise one
of `QUANTITIES` of the periodic regime, docs/model.md §4) and **constraints**
(``v0>=0.2``, ``cost_of_transport<=6``). ``pareto=True`` asks instead for the front of v0
(maximised) against the cost of transport (minimised).

The search, and why (docs/optimize.md has the long form):

* **Global: differential evolution** (`scipy.optimize.differential_evolution`), seeded, with
  ``vectorized=True`` and ``updating='deferred'``: a whole generation is one batch through the
  sweep engine (`crawlsim.study.sweep.run_sweep`), so ``jobs``, a Dask ``scheduler`` and the journal
  apply to it unchanged. v0 is continuous but only piecewise smooth in the gait parameters (it
  has kinks where the sequence of stick and slip phases changes), and multimodal: a population
  method that uses no derivative fits.
* **Constraints** by SciPy's feasibility rules (Lampinen's, a form of Deb's rules: a feasible
  point beats an infeasible one, two feasible points compare by the objective, two infeasible
  ones by their constraint violations). A point whose gait is invalid, whose run fails or does
  not converge, or which has no value of the objective (the cost of transport of a crawler that
  does not move) violates a constraint of its own, "the point runs": it is recorded, never
  chosen over a point that runs, and never stops the search.
* **Local polish: a pattern search** on the best point, batched: every iteration polls the 2n
  points ``u +- step * d`` (u the parameters scaled to the unit box, d the columns of an
  orthogonal matrix) in one batch, moves to the best of them if it is better by the same rules,
  and otherwise halves the step and draws a new rotation (seeded). It needs no derivative,
  tolerates kinks, and its directions become dense as the step shrinks, so it does not stall on a
  ridge that is not aligned with the axes, where a compass search (fixed coordinate directions)
  does (Audet & Dennis, *Mesh adaptive direct search*, SIAM J. Optim. 17, 2006).
* **The budget** ``max_evaluations`` counts simulated points. A point met again (the same
  parameters, bit for bit) is looked up, not simulated again.
* **Pareto front** of v0 against the cost of transport: the two ends (maximise v0, minimise the
  cost of transport), then epsilon-constraint runs (minimise the cost of transport subject to
  ``v0 >= eps_k``, eps_k evenly spaced between the two ends), each started from a population
  that holds the front found so far. The front is the non-dominated set of *all* evaluated points
  that satisfy the constraints; the optima of the runs are its "chosen" gaits.

Everything is deterministic for a given seed: the exact integrator gives v0 to roundoff whatever
the batching or the number of workers, and the search draws from generators seeded by
``seed``. So rerunning an interrupted optimisation with its journal replays the finished points
and goes on where it stopped.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from crawlsim.design.descent import Descent
from crawlsim.design.optresult import Batch, Evaluation, OptimizationResult, Run, hypervolume, non_dominated
from crawlsim.design.problem import Constraint, Method, Objective, Problem, Sense, feasible, rank
from crawlsim.design.search import Evaluator, Search
from crawlsim.errors import GaitError, SweepSpecError
from crawlsim.io.optfile import write_optimization
from crawlsim.study.executors import WorkerPool
from crawlsim.study.journal import Journal, journal_path


# -- the driver -------------------------------------------------------------------------------
def fingerprint(problem: Problem, method: Method, budget: int) -> str:
    """Identity of an optimisation (its journal is refused by any other)."""
    spec = json.dumps(
        [
            "optimize",
            problem.base.document,
            [f.text for f in problem.free],
            problem.objective.text,
            [c.text for c in problem.constraints],
            problem.pareto,
            method.identity(),
            budget,
        ],
        default=str,
    )
    return hashlib.sha256(spec.encode()).hexdigest()


def optimize(
    problem: Problem,
    method: Method | None = None,
    *,
    output: Path | str | None = None,
    jobs: int = 1,
    scheduler: str | None = None,
    progress: Callable[[int], None] | None = None,
    report: Callable[[Batch], None] | None = None,
) -> OptimizationResult:
    """Solve ``problem``: the library entry point behind ``crawlsim optimize``.

    ``jobs`` and ``scheduler`` run each batch as `crawlsim.study.sweep.run_sweep` does. With
    ``output`` (an HDF5 path) every finished point is kept in ``OUTPUT.journal`` while the
    search runs, so that rerunning the same optimisation after an interruption replays them and
    simulates only the rest (the journal of another optimisation is refused); at the end the
    results file is written atomically and the journal removed. ``progress(k)`` is called as k
    more points finish, ``report(batch)`` after every batch with the best value so far.

    When no evaluated point satisfies the constraints, the result says so (``feasible`` is
    False, `OptimizationResult.check_feasible` raises `InfeasibleError`), the journal is
    removed and no file is written. Ctrl-C raises `OptimizationInterrupted` once the journal
    holds every finished point.
    """
    method = method or Method()
    budget = method.budget(problem)
    began = time.perf_counter()
    book = None
    if output is not None:
        book = Journal(journal_path(output), fingerprint(problem, method, budget))
        try:
            book.load()
        except GaitError:
            raise SweepSpecError(
                str(book.path),
                "",
                "this journal belongs to a different "
                "optimisation (other gait, parameters, "
                "objective, constraints, settings or "
                "seed); delete it to start afresh, or "
                "rerun the command that wrote it",
            ) from None
    ev = Evaluator(problem, budget, jobs=jobs, scheduler=scheduler, journal=book, progress=progress, report=report)
    try:
        if jobs > 1 and not scheduler:
            ev.pool = WorkerPool(jobs)
        if problem.pareto:
            runs = _pareto(ev, problem, method)
        else:
            runs = [
                _runner(method)(ev, method, 0, problem.objective, problem.constraints, budget, (method.seed, 0)).solve()
            ]
    except BaseException:
        if ev.pool is not None:
            ev.pool.stop()
        raise
    else:
        if ev.pool is not None:
            ev.pool.close()
    finally:
        if book is not None:
            book.close()
    evaluations = tuple(ev.evaluations)
    front: tuple[int, ...] = ()
    history = tuple(ev.history)
    if problem.pareto:
        front = _front(evaluations, problem.constraints)
        history = _with_hypervolume(history, evaluations, problem.constraints, front)
    good = [r for r in runs if r.feasible]
    if good:
        best, ok = good[0].best, True
        if problem.pareto:  # the fastest gait evaluated, whichever run found it
            best = fastest(evaluations, problem.constraints)
    else:  # the least infeasible point of the first run, for the record
        best, ok = max(runs[0].best, 0), False
    result = OptimizationResult(
        problem,
        method,
        budget,
        evaluations,
        history,
        tuple(runs),
        best,
        ok,
        front,
        time.perf_counter() - began,
        ev.computed,
    )
    if book is not None:
        if ok and evaluations:
            write_optimization(output, result)
        book.remove()
    return result


def _runner(method: Method) -> type[Search]:
    """The search of one run: the gradient search, or differential evolution and the pattern
    search."""
    if method.gradient:
        return Descent
    return Search


def _pareto(ev: Evaluator, problem: Problem, method: Method) -> list[Run]:
    """The two ends of the front, then epsilon-constraint runs between them, each with an even
    share of what is left of the budget."""
    cot = Objective("cost_of_transport", Sense.MINIMIZE)
    runs: list[Run] = []
    total = 2 + method.front_points
    share = ev.budget // total
    runs.append(_runner(method)(ev, method, 0, Objective(), problem.constraints, share, (method.seed, 0)).solve())
    runs.append(_runner(method)(ev, method, 1, cot, problem.constraints, share, (method.seed, 1)).solve())
    if not (runs[0].feasible and runs[1].feasible):
        return runs
    v_max = ev.evaluations[runs[0].best].row.v0
    v_cheap = ev.evaluations[runs[1].best].row.v0
    assert v_max is not None and v_cheap is not None
    n = problem.dimension
    for k in range(1, method.front_points + 1):
        eps = v_cheap + k * (v_max - v_cheap) / (method.front_points + 1)
        left = ev.remaining // (total - len(runs))
        constraints = (*problem.constraints, Constraint("v0", ">=", float(eps)))
        init = _seed_population(
            ev, problem, method.population(n), constraints, cot, np.random.default_rng([method.seed, len(runs), 1])
        )
        run = _runner(method)(
            ev, method, len(runs), cot, constraints, left, (method.seed, len(runs)), init=init
        ).solve()
        runs.append(dataclasses.replace(run, epsilon=float(eps)))
    return runs


def fastest(evaluations: Sequence[Evaluation], constraints: Sequence[Constraint]) -> int:
    """The evaluation of largest v0 among those that run and satisfy the constraints (of equal
    v0, the cheaper): the fast end of the Pareto front. The run that maximises v0 need not find
    it; an epsilon-constraint run may evaluate a faster point."""
    ok = [e for e in evaluations if feasible(e.row, Objective(), constraints)]
    cot = [math.inf if e.row.cost_of_transport is None else e.row.cost_of_transport for e in ok]
    k = max(range(len(ok)), key=lambda i: (ok[i].row.v0, -cot[i]))
    return ok[k].index


def _seed_population(
    ev: Evaluator,
    problem: Problem,
    size: int,
    constraints: tuple[Constraint, ...],
    objective: Objective,
    rng: np.random.Generator,
) -> np.ndarray:
    """A first population for an epsilon-constraint run: the best evaluated points for it (the
    front found so far is among them), the rest drawn uniformly in the box (seeded)."""
    ranked = sorted((e for e in ev.evaluations if e.runs), key=lambda e: rank(e.row, objective, constraints))
    keep = [e.x for e in ranked[: size // 2]]
    fresh = [problem.values(u) for u in rng.random((size - len(keep), problem.dimension))]
    return np.array(keep + fresh, dtype=float)


def _front(evaluations: Sequence[Evaluation], constraints: Sequence[Constraint]) -> tuple[int, ...]:
    """The non-dominated points of v0 against the cost of transport among the evaluated points
    that run, move and satisfy the constraints."""
    cot = Objective("cost_of_transport", Sense.MINIMIZE)
    ok = [e for e in evaluations if feasible(e.row, cot, constraints) and e.row.v0 is not None]
    if not ok:
        return ()
    points = np.array([[e.row.v0, e.row.cost_of_transport] for e in ok], dtype=float)
    return tuple(ok[i].index for i in non_dominated(points))


def _with_hypervolume(
    history: Sequence[Batch], evaluations: Sequence[Evaluation], constraints: Sequence[Constraint], front: Sequence[int]
) -> tuple[Batch, ...]:
    """The history with the hypervolume of the front of the points evaluated so far, measured
    from the nadir of the final front (its smallest v0 and largest cost of transport)."""
    if len(front) < 2:
        return tuple(history)
    final = np.array([[evaluations[i].row.v0, evaluations[i].row.cost_of_transport] for i in front], dtype=float)
    reference = (float(final[:, 0].min()), float(final[:, 1].max()))
    cot = Objective("cost_of_transport", Sense.MINIMIZE)
    ok = np.array([feasible(e.row, cot, constraints) and e.row.v0 is not None for e in evaluations])
    points = np.array(
        [
            [
                e.row.v0 if e.row.v0 is not None else np.nan,
                e.row.cost_of_transport if e.row.cost_of_transport is not None else np.nan,
            ]
            for e in evaluations
        ],
        dtype=float,
    )
    out = []
    for b in history:
        upto = ok[: b.evaluations]
        out.append(dataclasses.replace(b, hypervolume=hypervolume(points[: b.evaluations][upto], reference)))
    return tuple(out)
