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

import copy
import dataclasses
import hashlib
import json
import math
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import Any, cast

import numpy as np

from crawlsim.errors import GaitError, InputError, SweepSpecError
from crawlsim.gait.docpaths import resolve_path, set_value
from crawlsim.gait.document import Gait, gait_from_document
from crawlsim.status import PointStatus
from crawlsim.study.sweep import (
    Axis,
    Journal,
    PointResult,
    SweepInterrupted,
    WorkerPool,
    check_some_point_runs,
    make_grid,
    run_points,
    run_sweep,
)

#: What can be optimised or constrained: numbers of the periodic regime of every point (the
#: columns of a sweep table), with their descriptions.
QUANTITIES = {
    "v0": "asymptotic average velocity v0",
    "cost_of_transport": "cost of transport (dissipation per distance travelled)",
    "dissipation_per_period": "energy dissipated by friction per period",
    "displacement_per_period": "barycentre displacement per period",
}
#: Quantities that are never negative: a constraint ``q <= negative`` cannot be satisfied.
NON_NEGATIVE = ("cost_of_transport", "dissipation_per_period")

#: Members of a differential-evolution population per free parameter (SciPy's ``popsize``).
POPSIZE = 10
#: Default budgets: simulated points per free parameter plus one (one objective), and per point
#: of the Pareto front.
BUDGET_PER_DIMENSION = 150
#: Share of a run's budget kept for the polish when the global search uses all of its own.
POLISH_SHARE = 0.3
#: First step of the pattern search, in units of the box width.
POLISH_STEP = 0.05
#: How the stop reason of a run that ran out of its budget begins (`Run.out_of_budget`).
BUDGET_SPENT = "budget spent"
#: The pattern search stops when its step falls below this, in units of the box width.
POLISH_XTOL = 1e-6
#: Interior points of a Pareto front (epsilon-constraint runs) besides its two ends.
FRONT_POINTS = 5


class Sense(StrEnum):
    MAXIMIZE = "maximize"
    MINIMIZE = "minimize"


class Stage(StrEnum):
    """What a batch of evaluations was: the first population of a run, a later generation of
    differential evolution, or one poll of the pattern search."""

    INITIAL = "initial"
    GENERATION = "generation"
    POLISH = "polish"


# -- the problem --------------------------------------------------------------------------------
def quantity(text: str, option: str) -> str:
    """A quantity of `QUANTITIES` from its name (``cost-of-transport`` or ``cost_of_transport``);
    anything else is a `SweepSpecError` naming ``option``."""
    name = text.strip().replace("-", "_").lower()
    if name not in QUANTITIES:
        raise SweepSpecError(f"{option} {text}", "", "expected one of "
                             + ", ".join(n.replace("_", "-") for n in QUANTITIES))
    return name


@dataclass(frozen=True)
class Free:
    """A free parameter: a dotted path of the gait document and its inclusive bounds."""

    path: str
    lo: float
    hi: float
    spec: str = dataclasses.field(default="", compare=False)  # the option as given

    def __post_init__(self) -> None:
        if not (math.isfinite(self.lo) and math.isfinite(self.hi)):
            raise SweepSpecError(f"--free {self.text}", self.path, "bounds must be finite numbers")
        if self.lo > self.hi:
            raise SweepSpecError(f"--free {self.text}", self.path,
                                 f"bounds reversed: LO = {self.lo!r} > HI = {self.hi!r}; give "
                                 "LO:HI with LO < HI")
        if self.lo == self.hi:
            raise SweepSpecError(f"--free {self.text}", self.path,
                                 f"LO = HI = {self.lo!r} leaves nothing free; set the value in "
                                 "the gait file, or give LO < HI")

    @property
    def text(self) -> str:
        return self.spec or f"{self.path}={self.lo!r}:{self.hi!r}"

    def value(self, u: float) -> float:
        """The parameter at ``u`` in [0, 1], both bounds reached exactly."""
        if u <= 0:
            return self.lo
        if u >= 1:
            return self.hi
        return min(max(self.lo + u * (self.hi - self.lo), self.lo), self.hi)

    def unit(self, value: float) -> float:
        return (value - self.lo) / (self.hi - self.lo)


def parse_free(text: str) -> Free:
    """``PATH=LO:HI`` -> `Free` (a malformed option is a `SweepSpecError` naming it)."""
    path, sep, spec = text.partition("=")
    path, spec = path.strip(), spec.strip()
    if not sep or not path or not spec:
        raise SweepSpecError(f"--free {text}", "", "expected PATH=LO:HI, for example "
                                                   "links.1.phase=0:1")
    if any(part == "" for part in path.split(".")):
        raise SweepSpecError(f"--free {text}", path, "empty key in the dotted path")
    parts = spec.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        lo, hi = float(parts[0]), float(parts[1])
    except ValueError:
        raise SweepSpecError(f"--free {text}", path, f"expected LO:HI, two numbers, got "
                                                     f"{spec!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise SweepSpecError(f"--free {text}", path, f"bounds must be finite numbers, got "
                                                     f"{spec!r}")
    if lo > hi:
        raise SweepSpecError(f"--free {text}", path, f"bounds reversed: LO = {lo!r} > HI = "
                                                     f"{hi!r}; give LO:HI with LO < HI")
    return Free(path, lo, hi, text.strip())


@dataclass(frozen=True)
class Objective:
    """Maximise or minimise a quantity of `QUANTITIES`."""

    quantity: str = "v0"
    sense: Sense = Sense.MAXIMIZE

    def __post_init__(self) -> None:
        object.__setattr__(self, "sense", Sense(self.sense))
        if self.quantity not in QUANTITIES:
            raise SweepSpecError(f"--{self.sense}", self.quantity,
                                 "expected one of " + ", ".join(QUANTITIES))

    @property
    def text(self) -> str:
        return f"{self.sense} {self.quantity}"

    def value(self, row: PointResult) -> float:
        """The quantity at a point (NaN when the point has none)."""
        value = getattr(row, self.quantity)
        return math.nan if value is None else float(value)

    def energy(self, value: float) -> float:
        """The value as a number to minimise."""
        return -value if self.sense == Sense.MAXIMIZE else value


_CONSTRAINT = re.compile(r"^\s*([A-Za-z][A-Za-z0-9_-]*)\s*(>=|<=|=>|=<|>|<|==|=|!=)\s*(\S.*?)\s*$")


@dataclass(frozen=True)
class Constraint:
    """``quantity >= bound`` or ``quantity <= bound``."""

    quantity: str
    op: str
    bound: float

    def __post_init__(self) -> None:
        if self.op not in (">=", "<="):
            raise SweepSpecError(f"--subject-to {self.text}", "", "expected >= or <=")

    @property
    def text(self) -> str:
        return f"{self.quantity}{self.op}{self.bound!r}"

    def violation(self, row: PointResult) -> float:
        """How far the point is from satisfying the constraint (0 when it does; infinite when
        the point has no value of the quantity)."""
        value = getattr(row, self.quantity)
        if value is None or not math.isfinite(value):
            return math.inf
        gap = self.bound - value if self.op == ">=" else value - self.bound
        return max(0.0, float(gap))


def parse_constraint(text: str, option: str = "--subject-to") -> Constraint:
    """``QUANTITY>=NUMBER`` or ``QUANTITY<=NUMBER`` (quantities as in `quantity`); anything
    else is a `SweepSpecError` naming ``option`` and saying what was expected."""
    expected = ("expected QUANTITY>=NUMBER or QUANTITY<=NUMBER with QUANTITY one of "
                + ", ".join(QUANTITIES) + ", for example 'v0>=0.2'")
    match = _CONSTRAINT.match(text)
    if match is None:
        raise SweepSpecError(f"{option} {text}", "", expected)
    name, op, number = match.groups()
    op = {"=>": ">=", "=<": "<="}.get(op, op)
    if op not in (">=", "<="):
        raise SweepSpecError(f"{option} {text}", "", f"the comparison {op!r} is not allowed "
                                                     f"(a bound is >= or <=); {expected}")
    name = quantity(name, option)
    try:
        bound = float(number)
    except ValueError:
        raise SweepSpecError(f"{option} {text}", "", f"{number!r} is not a number; "
                                                     f"{expected}") from None
    if not math.isfinite(bound):
        raise SweepSpecError(f"{option} {text}", "", f"the bound must be a finite number, got "
                                                     f"{number!r}")
    return Constraint(name, op, bound)


def check_constraints(constraints: Sequence[Constraint]) -> None:
    """Refuse constraints that no point can satisfy, before anything runs: a lower bound above
    an upper bound of the same quantity, or a negative upper bound of a quantity that is never
    negative (`InfeasibleError`)."""
    for c in constraints:
        if c.op == "<=" and c.quantity in NON_NEGATIVE and c.bound < 0:
            raise InfeasibleError(f"--subject-to {c.text}", "",
                                  f"{c.quantity} is never negative, so no gait satisfies this")
    for lower in (c for c in constraints if c.op == ">="):
        for upper in (c for c in constraints if c.op == "<=" and c.quantity == lower.quantity):
            if lower.bound > upper.bound:
                raise InfeasibleError(f"--subject-to {lower.text} --subject-to {upper.text}", "",
                                      f"{lower.quantity} cannot be at least {lower.bound!r} and "
                                      f"at most {upper.bound!r}")


class InfeasibleError(SweepSpecError):
    """No point satisfies the constraints (exit code 2, no file written)."""


@dataclass(frozen=True, eq=False)
class Problem:
    """A base gait, its free parameters, the objective and the constraints (validated when
    built: `make_problem`)."""

    base: Gait
    free: tuple[Free, ...]
    objective: Objective = Objective()
    constraints: tuple[Constraint, ...] = ()
    pareto: bool = False

    @property
    def paths(self) -> tuple[str, ...]:
        return tuple(f.path for f in self.free)

    @property
    def dimension(self) -> int:
        return len(self.free)

    def values(self, u: Sequence[float]) -> tuple[float, ...]:
        """The free parameters at ``u`` in the unit box."""
        return tuple(f.value(float(v)) for f, v in zip(self.free, u))

    def document(self, x: Sequence[float]) -> dict:
        """The base document with the free parameters set to ``x``."""
        doc = copy.deepcopy(self.base.document)
        for f, value in zip(self.free, x):
            for keys in resolve_path(self.base.document, f.path, self.base.source):
                set_value(doc, keys, float(value))
        return doc

    def label(self, x: Sequence[float]) -> str:
        return f"{self.base.source} with " + ", ".join(f"{p}={v!r}"
                                                        for p, v in zip(self.paths, x))

    def gait(self, x: Sequence[float]) -> Gait:
        gait = gait_from_document(self.document(x), self.label(x),
                                  source_text=self.base.source_text,
                                  default_name=self.base.name)
        assert isinstance(gait, Gait)
        return gait


def make_problem(base: Gait, free: Sequence[Free | str], *, objective: Objective | None = None,
                 constraints: Sequence[Constraint | str] = (), pareto: bool = False) -> Problem:
    """Check and build a `Problem`: every path resolves in the base document and names a number,
    no two paths set the same value, the constraints can be satisfied (`check_constraints`), and
    some point of the box is a valid gait (its centre or a corner). ``free`` items are `Free`
    or ``PATH=LO:HI``; ``constraints`` are `Constraint` or ``QUANTITY>=NUMBER`` text. With
    ``pareto`` the objectives are v0 and the cost of transport, so no other ``objective`` is
    taken."""
    if not isinstance(base, Gait):
        raise SweepSpecError(str(getattr(base, "source", "gait")), "",
                             "crawlsim optimize designs crawler gaits; a generic sweeping "
                             "process has no velocity to optimise")
    items = tuple(parse_free(f) if isinstance(f, str) else f for f in free)
    if not items:
        raise SweepSpecError("--free", "", "give at least one free parameter, PATH=LO:HI")
    seen: dict[tuple, str] = {}
    for f in items:
        try:
            targets = resolve_path(base.document, f.path, base.source)
        except GaitError as exc:
            raise SweepSpecError(f"--free {f.text}", f.path,
                                 f"{exc.message} (in {base.source})") from None
        for keys in targets:
            if keys in seen:
                raise SweepSpecError(f"--free {f.text}", f.path,
                                     f"this path sets {'.'.join(map(str, keys))}, which --free "
                                     f"{seen[keys]} sets too: free each value once")
            seen[keys] = f.path
    cons = tuple(parse_constraint(c) if isinstance(c, str) else c for c in constraints)
    check_constraints(cons)
    if pareto and objective is not None and objective != Objective():
        raise SweepSpecError(f"--{objective.sense} {objective.quantity}", "",
                             "--pareto optimises v0 and cost_of_transport together; drop the "
                             "objective option")
    problem = Problem(base, items, objective or Objective(), cons, pareto)
    _check_some_point_is_valid(problem)
    return problem


def _check_some_point_is_valid(problem: Problem) -> None:
    """Refuse a box in which neither the centre nor any corner is a valid gait (a free path that
    the schema refuses, a box outside the valid values): nothing could run."""
    n = problem.dimension
    corners = [tuple((k >> i) & 1 for i in range(n)) for k in range(min(2 ** n, 64))]
    first: InputError | None = None
    for u in [(0.5,) * n, *corners]:
        try:
            problem.gait(problem.values(u))
        except InputError as exc:
            first = first or exc
        else:
            return
    assert first is not None
    raise SweepSpecError(first.source, first.keypath,
                         f"{first.message} (neither the centre nor a corner of the box of "
                         "--free is a valid gait; this is the first)")


# -- the method -------------------------------------------------------------------------------
MAX_SEED = 2**63 - 1
"""Largest seed: the results file stores it as an HDF5 64-bit integer."""


@dataclass(frozen=True)
class Method:
    """The settings of the search (the module docstring says why each is what it is)."""

    seed: int = 0
    max_evaluations: int | None = None  # None: `default_budget`
    popsize: int = POPSIZE
    strategy: str = "best1bin"
    mutation: tuple[float, float] = (0.5, 1.0)
    recombination: float = 0.7
    init: str = "latinhypercube"
    tol: float = 0.01  # differential evolution stops when std(energy) <= tol |mean(energy)|
    polish_share: float = POLISH_SHARE
    polish_step: float = POLISH_STEP
    polish_xtol: float = POLISH_XTOL
    front_points: int = FRONT_POINTS

    def __post_init__(self) -> None:
        if not 0 <= self.seed <= MAX_SEED:
            raise SweepSpecError("--seed", "", f"expected an integer from 0 to 2**63 - 1 (the "
                                               f"results file stores it as a 64-bit integer), "
                                               f"got {self.seed}")
        if self.max_evaluations is not None and self.max_evaluations < 1:
            raise SweepSpecError("--max-evaluations", "", f"expected a positive number, got "
                                                          f"{self.max_evaluations}")
        if self.front_points < 0:
            raise SweepSpecError("--front-points", "", "expected 0 or more")

    def budget(self, problem: Problem) -> int:
        return self.max_evaluations or default_budget(problem.dimension, problem.pareto,
                                                      self.front_points)

    def population(self, dimension: int) -> int:
        """SciPy's population size for ``latinhypercube`` and ``random`` initialisation."""
        return max(5, self.popsize * dimension)

    def settings(self) -> dict:
        return {"global": "scipy.optimize.differential_evolution", "strategy": self.strategy,
                "popsize_per_parameter": self.popsize, "mutation": list(self.mutation),
                "recombination": self.recombination, "init": self.init, "tol": self.tol,
                "updating": "deferred", "vectorized": True,
                "constraints": "feasibility rules (Lampinen); a point that does not run is "
                               "infeasible",
                "polish": "pattern search, 2n rotated directions per poll (batched)",
                "polish_share": self.polish_share, "polish_step": self.polish_step,
                "polish_xtol": self.polish_xtol, "front_points": self.front_points}

    @property
    def name(self) -> str:
        return "differential evolution + pattern search"


def default_budget(dimension: int, pareto: bool = False, front_points: int = FRONT_POINTS) -> int:
    """``BUDGET_PER_DIMENSION (n + 1)`` simulated points for one objective; a Pareto front
    gives each of its runs (two ends, ``front_points`` inside) half of that."""
    single = BUDGET_PER_DIMENSION * (dimension + 1)
    return single if not pareto else (single * (front_points + 2)) // 2


# -- results ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Evaluation:
    """One evaluated point: its number in evaluation order, the free parameters, the run and
    batch that asked for it, and the sweep table's row (``row.index`` is ``index``)."""

    index: int
    x: tuple[float, ...]
    run: int
    stage: Stage
    batch: int
    row: PointResult

    @property
    def runs(self) -> bool:
        return self.row.status == PointStatus.OK


@dataclass(frozen=True)
class Batch:
    """The state of the search after one batch: the best value of its run so far (NaN while no
    evaluated point of the run is feasible), the polish step, and for a Pareto front its
    hypervolume."""

    batch: int
    run: int
    stage: Stage
    evaluations: int  # simulated points so far, in all runs
    best: float
    best_index: int  # -1 before any point
    feasible: bool
    step: float = math.nan
    hypervolume: float = math.nan


@dataclass(frozen=True)
class Run:
    """One single-objective search: the optimisation itself, or one run of a Pareto front
    (``epsilon``: the lower bound on v0 of an epsilon-constraint run)."""

    index: int
    objective: Objective
    constraints: tuple[Constraint, ...]
    best: int  # evaluation index of its optimum
    feasible: bool
    evaluations: int  # points simulated for this run
    stop: str
    epsilon: float = math.nan

    @property
    def text(self) -> str:
        extra = [c.text for c in self.constraints]
        return self.objective.text + (" subject to " + ", ".join(extra) if extra else "")

    @property
    def out_of_budget(self) -> bool:
        """The run stopped because its share of the budget ran out, not because it converged
        (`_Search`): its optimum may still improve with more evaluations."""
        return self.stop.startswith(BUDGET_SPENT)


@dataclass(frozen=True, eq=False)
class OptimizationResult:
    """The answer: every evaluated point, the history of the best value per batch, the runs,
    the best point and, for a Pareto problem, the front (evaluation indices, by v0)."""

    problem: Problem
    method: Method
    budget: int
    evaluations: tuple[Evaluation, ...]
    history: tuple[Batch, ...]
    runs: tuple[Run, ...]
    best: int
    feasible: bool
    front: tuple[int, ...] = ()
    wall_time: float = 0.0
    computed: int = 0  # points simulated by this process (the others came from the journal)

    @property
    def best_point(self) -> Evaluation:
        return self.evaluations[self.best]

    @property
    def best_values(self) -> dict[str, float]:
        return dict(zip(self.problem.paths, self.best_point.x))

    @property
    def value(self) -> float:
        return self.problem.objective.value(self.best_point.row)

    @property
    def chosen(self) -> tuple[int, ...]:
        """The optima of the runs (for a Pareto front: its ends and the epsilon-constraint
        points), distinct, in run order."""
        return tuple(dict.fromkeys(r.best for r in self.runs if r.feasible))

    def check_feasible(self) -> None:
        """Raise `InfeasibleError` when no evaluated point satisfies the constraints."""
        if not self.feasible:
            raise infeasible_error(self.problem, self.evaluations)

    def write_best(self, path: Path | str, index: int | None = None) -> Path:
        """Write `best_yaml` to ``path`` atomically."""
        from crawlsim.io.atomic import atomic_path

        with atomic_path(path) as tmp:
            tmp.write_text(self.best_yaml(index), encoding="utf-8")
        return Path(path)

    def counts(self) -> dict[str, int]:
        out = {str(s): 0 for s in PointStatus}
        for e in self.evaluations:
            out[e.row.status] += 1
        return out

    def feasibility(self) -> tuple[list[bool], list[float]]:
        """For each evaluation: does it satisfy its run's constraints (and run), and its total
        violation (0 when feasible, inf when it does not run)."""
        flags, violations = [], []
        for e in self.evaluations:
            run = self.runs[e.run]
            kind, value = _rank(e.row, run.objective, run.constraints)
            flags.append(kind == 0)
            violations.append(0.0 if kind == 0 else value)
        return flags, violations

    def stage_counts(self) -> dict[str, int]:
        out = {"global": 0, "polish": 0}
        for e in self.evaluations:
            out["polish" if e.stage == Stage.POLISH else "global"] += 1
        return out

    def best_document(self, index: int | None = None) -> dict:
        """The base gait document with the free parameters of evaluation ``index`` (the best
        by default)."""
        return self.problem.document(self.evaluations[self.best if index is None else index].x)

    def best_yaml(self, index: int | None = None) -> str:
        """`best_document` as YAML: a gait file that ``crawlsim run`` reproduces (floats written
        with repr, so the values are the optimiser's bit for bit), headed by a comment that says
        where it comes from."""
        from crawlsim.io.provenance import command_line, effective_yaml

        e = self.evaluations[self.best if index is None else index]
        what = self.runs[e.run].text
        if self.problem.pareto and e.index == self.best:
            what = f"the fastest gait of the Pareto front (found by {what})"
        head = [f"# written by crawlsim optimize: {what}",
                f"# from {self.problem.base.source}, evaluation {e.index} of "
                f"{len(self.evaluations)}, seed {self.method.seed}",
                f"# v0 = {e.row.v0!r}, cost_of_transport = {e.row.cost_of_transport!r}",
                *(f"# {p} = {v!r}" for p, v in zip(self.problem.paths, e.x)),
                f"# command: {command_line()}"]
        return "\n".join(line.replace("\n", " ") for line in head) + "\n" + \
            effective_yaml(self.problem.document(e.x))

    def summary(self) -> dict[str, Any]:
        """The JSON-ready answer (``crawlsim optimize --json``)."""
        best = self.best_point
        out: dict[str, Any] = {
            "name": self.problem.base.name, "objective": self.problem.objective.text,
            "pareto": self.problem.pareto,
            "constraints": [c.text for c in self.problem.constraints],
            "free": [{"path": f.path, "lo": f.lo, "hi": f.hi} for f in self.problem.free],
            "best": self.best_values, "best_evaluation": best.index, "feasible": self.feasible,
            "value": self.value,
            **{name: getattr(best.row, name) for name in
               ("v0", "v0_error_estimate", "displacement_per_period", "dissipation_per_period",
                "cost_of_transport", "convergence", "periods", "integrator")},
            "evaluations": len(self.evaluations), "budget": self.budget,
            "computed": self.computed, "stages": self.stage_counts(), "statuses": self.counts(),
            "method": self.method.name, "seed": self.method.seed,
            "runs": [{"run": r.text, "best_evaluation": r.best, "evaluations": r.evaluations,
                      "stop": r.stop, "out_of_budget": r.out_of_budget} for r in self.runs],
            "wall_time": self.wall_time,
        }
        if self.problem.pareto:
            out["front"] = [{**dict(zip(self.problem.paths, self.evaluations[i].x)),
                             "evaluation": i, "v0": self.evaluations[i].row.v0,
                             "cost_of_transport": self.evaluations[i].row.cost_of_transport,
                             "chosen": i in self.chosen} for i in self.front]
        return out


# -- ranking ----------------------------------------------------------------------------------
def _rank(row: PointResult, objective: Objective, constraints: Sequence[Constraint]
          ) -> tuple[int, float]:
    """Deb's feasibility rules as a sort key, smaller is better: (0, objective to minimise) for
    a feasible point, (1, total violation) for a point that runs but violates a constraint, and
    (2, inf) for a point that does not run or has no value of the objective."""
    value = objective.value(row)
    if row.status != PointStatus.OK or not math.isfinite(value):
        return 2, math.inf
    violation = sum(c.violation(row) for c in constraints)
    if violation > 0:
        return 1, violation
    return 0, objective.energy(value)


def feasible(row: PointResult, objective: Objective, constraints: Sequence[Constraint]) -> bool:
    return _rank(row, objective, constraints)[0] == 0


def non_dominated(points: np.ndarray) -> np.ndarray:
    """Indices of the non-dominated rows of ``points`` (n, 2) = (v0, cost of transport), v0
    maximised and the cost minimised; of equal points the first is kept. Sorted by v0."""
    if len(points) == 0:
        return np.zeros(0, dtype=np.int64)
    order = np.lexsort((points[:, 1], -points[:, 0]))  # v0 descending, then cost ascending
    keep, best_cost = [], math.inf
    for i in order:
        if points[i, 1] < best_cost:
            keep.append(i)
            best_cost = points[i, 1]
    return np.array(sorted(keep, key=lambda i: points[i, 0]), dtype=np.int64)


def hypervolume(points: np.ndarray, reference: tuple[float, float]) -> float:
    """Area dominated by ``points`` (v0 maximised, cost minimised) and bounded by the reference
    point (v0_ref, cost_ref): the usual convergence measure of a two-objective front."""
    v_ref, c_ref = reference
    inside = points[(points[:, 0] > v_ref) & (points[:, 1] < c_ref)] if len(points) else points
    if len(inside) == 0:
        return 0.0
    front = inside[non_dominated(inside)]  # v0 ascending, cost ascending along a front
    area, v_prev = 0.0, v_ref
    for v, c in front:
        area += (v - v_prev) * (c_ref - c)
        v_prev = v
    return float(area)


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
        return {i - self._start: dataclasses.replace(r, index=i - self._start)
                for i, r in self._done.items() if self._start <= i < self._start + self._size}

    def append(self, results) -> None:
        self._journal.append([dataclasses.replace(r, index=r.index + self._start)
                              for r in results])

    def flush(self) -> None:
        self._journal.flush()

    def close(self) -> None:
        self._journal.flush()  # the journal stays open for the next batch

    def remove(self) -> None:  # pragma: no cover - the optimisation removes the journal itself
        raise NotImplementedError


class _Budget(Exception):
    """The budget is spent (internal: ends a run)."""


class _Evaluator:
    """Evaluates batches of points through the sweep engine: a cache of the points met so far
    (bit-identical parameters are simulated once), the budget, the journal and the history."""

    def __init__(self, problem: Problem, budget: int, *, jobs: int, scheduler: str | None,
                 journal: Journal | None, progress: Callable[[int], None] | None,
                 report: Callable[[Batch], None] | None):
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
        one batch; `_Budget` when they do not fit in the budget."""
        keys = [self.key(x) for x in X]
        new = list(dict.fromkeys(k for k in keys if k not in self.cache))
        if len(new) > self.remaining:
            raise _Budget
        if new:
            rows = self._simulate(new)
            batch = len(self.history)
            for k, row in zip(new, rows):
                n = len(self.evaluations)
                self.cache[k] = n
                self.evaluations.append(Evaluation(n, k, run, stage, batch,
                                                   dataclasses.replace(row, index=n)))
        return [self.evaluations[self.cache[k]] for k in keys]

    def _simulate(self, points: list[tuple[float, ...]]) -> list[PointResult]:
        start = len(self.evaluations)
        grid = make_grid(self.problem.base, [tuple(Axis(f.path, tuple(p[a] for p in points))
                                                   for a, f in enumerate(self.problem.free))])
        window = None if self.journal is None else _Window(self.journal, self.done, start,
                                                           len(points))
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
            table = run_sweep(grid, jobs=self.jobs, scheduler=self.scheduler,
                              journal=cast(Journal, window), progress=self.progress,
                              on_rows=self._skipped, pool=self.pool)
        except SweepInterrupted:
            raise OptimizationInterrupted(self._finished(),
                                          None if self.journal is None else self.journal.path
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

    def record(self, run: int, stage: Stage, best: int, rank: tuple[int, float],
               objective: Objective, *, step: float = math.nan) -> None:
        value = objective.value(self.evaluations[best].row) if best >= 0 else math.nan
        entry = Batch(len(self.history), run, stage, len(self.evaluations),
                      value if rank[0] == 0 else math.nan, best, rank[0] == 0, step)
        self.history.append(entry)
        if self.report is not None:
            self.report(entry)


# -- one run: differential evolution, then the pattern search ---------------------------------
class _Search:
    """One single-objective run on the shared evaluator."""

    def __init__(self, ev: _Evaluator, method: Method, run: int, objective: Objective,
                 constraints: tuple[Constraint, ...], budget: int, seed: Sequence[int],
                 init: np.ndarray | None = None):
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
        return _rank(e.row, self.objective, self.constraints)

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
            raise _Budget
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
        except _Budget:  # the polish (or the one point of a tiny budget) was cut short
            before = "" if not self.stop or self.stop.startswith(BUDGET_SPENT) else \
                f" (differential evolution: {self.stop})"
            self.stop = f"{BUDGET_SPENT} in the polish{before}" if self.stop else BUDGET_SPENT
        if self.best < 0:
            self.stop = BUDGET_SPENT + " before the first point"
        return Run(self.run, self.objective, self.constraints, self.best,
                   self.best_rank[0] == 0,
                   sum(1 for e in self.ev.evaluations[self.start:] if e.run == self.run),
                   self.stop)

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
            return np.array([self.rank(e)[1] if self.rank(e)[0] == 0 else math.inf
                             for e in self.ev.evaluate(np.atleast_2d(X.T), self.run,
                                                       Stage.GENERATION)])

        def callback(intermediate_result):
            return self.left() < population  # the next generation would not fit

        init: Any = method.init if self.init is None else self.init
        maxiter = share // population - 1
        try:
            result = differential_evolution(
                energy, [(f.lo, f.hi) for f in problem.free], strategy=method.strategy,
                maxiter=maxiter,
                popsize=popsize,
                tol=method.tol, atol=0, mutation=method.mutation,
                recombination=method.recombination, rng=self.rng, callback=callback,
                polish=False, init=init, updating="deferred", vectorized=True,
                constraints=NonlinearConstraint(constraint, -np.inf, 0.0))
        except _Budget:
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
        return [0.0 if runs else 1.0, *((c.violation(e.row) if runs else math.inf)
                                        for c in self.constraints)]

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
            poll = np.clip(np.concatenate([u + step * directions.T, u - step * directions.T]),
                           0.0, 1.0)
            X = [problem.values(p) for p in poll]
            new = self.ev.new_points(np.array(X))
            if len(new) > self.left():  # the budget ends inside this poll: poll what fits
                if self.left() <= 0:
                    raise _Budget
                fits = set(new[:self.left()])
                X = [x for x in X if self.ev.key(x) in fits or self.ev.key(x) in self.ev.cache]
            before = self.best
            self.evaluate(np.array(X), Stage.POLISH, step)
            if self.best != before:
                u = np.array([f.unit(v) for f, v in
                              zip(problem.free, self.ev.evaluations[self.best].x)])
            else:
                step /= 2
                directions = _rotation(self.rng, n)
        self.stop = f"pattern search step below {method.polish_xtol:g} of the box"


def _rotation(rng: np.random.Generator, n: int) -> np.ndarray:
    """A random orthogonal matrix (Haar-distributed: QR of a Gaussian matrix with the signs of
    R's diagonal moved into Q)."""
    q, r = np.linalg.qr(rng.standard_normal((n, n)))
    return q * np.sign(np.diag(r))


# -- the driver -------------------------------------------------------------------------------
def fingerprint(problem: Problem, method: Method, budget: int) -> str:
    """Identity of an optimisation (its journal is refused by any other)."""
    spec = json.dumps(["optimize", problem.base.document, [f.text for f in problem.free],
                       problem.objective.text, [c.text for c in problem.constraints],
                       problem.pareto, dataclasses.asdict(method), budget], default=str)
    return hashlib.sha256(spec.encode()).hexdigest()


def optimize(problem: Problem, method: Method | None = None, *, output: Path | str | None = None,
             jobs: int = 1, scheduler: str | None = None,
             progress: Callable[[int], None] | None = None,
             report: Callable[[Batch], None] | None = None) -> OptimizationResult:
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
    from crawlsim.study.sweep import journal_path

    method = method or Method()
    budget = method.budget(problem)
    began = time.perf_counter()
    book = None
    if output is not None:
        book = Journal(journal_path(output), fingerprint(problem, method, budget))
        try:
            book.load()
        except GaitError:
            raise SweepSpecError(str(book.path), "", "this journal belongs to a different "
                                                     "optimisation (other gait, parameters, "
                                                     "objective, constraints, settings or "
                                                     "seed); delete it to start afresh, or "
                                                     "rerun the command that wrote it") from None
    ev = _Evaluator(problem, budget, jobs=jobs, scheduler=scheduler, journal=book,
                    progress=progress, report=report)
    try:
        if jobs > 1 and not scheduler:
            ev.pool = WorkerPool(jobs)
        if problem.pareto:
            runs = _pareto(ev, problem, method)
        else:
            runs = [_Search(ev, method, 0, problem.objective, problem.constraints, budget,
                            (method.seed, 0)).solve()]
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
    result = OptimizationResult(problem, method, budget, evaluations, history, tuple(runs), best,
                                ok, front, time.perf_counter() - began, ev.computed)
    if book is not None:
        if ok and evaluations:
            from crawlsim.io.hdf5 import write_optimization

            write_optimization(output, result)
        book.remove()
    return result


def infeasible_error(problem: Problem, evaluations: Sequence[Evaluation]) -> InfeasibleError:
    """The error of a search in which no point satisfies the constraints: it names them and
    the closest point found."""
    runs = [e for e in evaluations if e.runs]
    if not runs:
        first = evaluations[0].row.message if evaluations else "nothing ran"
        return InfeasibleError("--free", "", f"none of the {len(evaluations)} evaluated points "
                                             f"ran (the first: {first})")
    if not problem.constraints:
        return InfeasibleError(f"--{problem.objective.sense} {problem.objective.quantity}", "",
                               f"no evaluated point has a value of {problem.objective.quantity} "
                               "(the cost of transport needs net motion)")
    what = " --subject-to ".join(repr(c.text) for c in problem.constraints)
    closest = min(runs, key=lambda e: sum(c.violation(e.row) for c in problem.constraints))
    values = ", ".join(f"{c.quantity} = {getattr(closest.row, c.quantity)!r}"
                       for c in problem.constraints)
    return InfeasibleError(f"--subject-to {what}", "",
                           f"no evaluated point satisfies the constraints ({len(evaluations)} "
                           f"points; the closest, {problem.label(closest.x)}, has {values}); "
                           "relax the constraints or widen the --free bounds")


def _pareto(ev: _Evaluator, problem: Problem, method: Method) -> list[Run]:
    """The two ends of the front, then epsilon-constraint runs between them, each with an even
    share of what is left of the budget."""
    cot = Objective("cost_of_transport", Sense.MINIMIZE)
    runs: list[Run] = []
    total = 2 + method.front_points
    share = ev.budget // total
    runs.append(_Search(ev, method, 0, Objective(), problem.constraints, share,
                        (method.seed, 0)).solve())
    runs.append(_Search(ev, method, 1, cot, problem.constraints, share,
                        (method.seed, 1)).solve())
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
        init = _seed_population(ev, problem, method.population(n), constraints, cot,
                                np.random.default_rng([method.seed, len(runs), 1]))
        run = _Search(ev, method, len(runs), cot, constraints, left, (method.seed, len(runs)),
                      init=init).solve()
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


def _seed_population(ev: _Evaluator, problem: Problem, size: int,
                     constraints: tuple[Constraint, ...], objective: Objective,
                     rng: np.random.Generator) -> np.ndarray:
    """A first population for an epsilon-constraint run: the best evaluated points for it (the
    front found so far is among them), the rest drawn uniformly in the box (seeded)."""
    ranked = sorted((e for e in ev.evaluations if e.runs),
                    key=lambda e: _rank(e.row, objective, constraints))
    keep = [e.x for e in ranked[:size // 2]]
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


def _with_hypervolume(history: Sequence[Batch], evaluations: Sequence[Evaluation],
                      constraints: Sequence[Constraint], front: Sequence[int]) -> tuple[Batch, ...]:
    """The history with the hypervolume of the front of the points evaluated so far, measured
    from the nadir of the final front (its smallest v0 and largest cost of transport)."""
    if len(front) < 2:
        return tuple(history)
    final = np.array([[evaluations[i].row.v0, evaluations[i].row.cost_of_transport]
                      for i in front], dtype=float)
    reference = (float(final[:, 0].min()), float(final[:, 1].max()))
    cot = Objective("cost_of_transport", Sense.MINIMIZE)
    ok = np.array([feasible(e.row, cot, constraints) and e.row.v0 is not None
                   for e in evaluations])
    points = np.array([[e.row.v0 if e.row.v0 is not None else np.nan,
                        e.row.cost_of_transport if e.row.cost_of_transport is not None
                        else np.nan] for e in evaluations], dtype=float)
    out = []
    for b in history:
        upto = ok[:b.evaluations]
        out.append(dataclasses.replace(
            b, hypervolume=hypervolume(points[:b.evaluations][upto], reference)))
    return tuple(out)


__all__ = ["QUANTITIES", "Batch", "Constraint", "Evaluation", "Free", "InfeasibleError",
           "Method", "Objective", "OptimizationInterrupted", "OptimizationResult", "Problem",
           "Run", "Sense", "Stage", "check_constraints", "default_budget", "feasible",
           "fingerprint", "hypervolume", "infeasible_error", "make_problem", "non_dominated",
           "optimize", "parse_constraint", "parse_free", "quantity"]
