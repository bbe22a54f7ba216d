"""The problem of gait design: free parameters in a box, an objective, constraints, and the
feasibility rules that rank evaluated points (``crawlsim optimize --free/--maximize/--subject-to``);
and the settings of the search that solves it (`Method`) with its default budget.

Two searches share the evaluator, the budget, the constraints and the results
(`crawlsim.design.search`): ``evolution``, differential evolution then a pattern search (no
derivative), and ``gradient``, a coarse sample then quasi-Newton runs on the exact
sensitivities of the objective and the constraints (`crawlsim.design.descent`)."""

from __future__ import annotations

import copy
import dataclasses
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum

from crawlsim.errors import GaitError, InputError, SweepSpecError
from crawlsim.gait.crawler_spec import CRAWLER_SCHEMA
from crawlsim.gait.docpaths import resolve_path, set_values
from crawlsim.gait.document import Gait, gait_from_document
from crawlsim.gait.schemaerrors import check_schema
from crawlsim.status import PointStatus
from crawlsim.study.points import PointResult

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


class Sense(StrEnum):
    MAXIMIZE = "maximize"
    MINIMIZE = "minimize"


def quantity(text: str, option: str) -> str:
    """A quantity of `QUANTITIES` from its name (``cost-of-transport`` or ``cost_of_transport``);
    anything else is a `SweepSpecError` naming ``option``."""
    name = text.strip().replace("-", "_").lower()
    if name not in QUANTITIES:
        raise SweepSpecError(
            f"{option} {text}", "", "expected one of " + ", ".join(n.replace("_", "-") for n in QUANTITIES)
        )
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
            raise SweepSpecError(
                f"--free {self.text}",
                self.path,
                f"bounds reversed: LO = {self.lo!r} > HI = {self.hi!r}; give LO:HI with LO < HI",
            )
        if self.lo == self.hi:
            raise SweepSpecError(
                f"--free {self.text}",
                self.path,
                f"LO = HI = {self.lo!r} leaves nothing free; set the value in the gait file, or give LO < HI",
            )

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
        raise SweepSpecError(f"--free {text}", "", "expected PATH=LO:HI, for example links.1.phase=0:1")
    if any(part == "" for part in path.split(".")):
        raise SweepSpecError(f"--free {text}", path, "empty key in the dotted path")
    parts = spec.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        lo, hi = float(parts[0]), float(parts[1])
    except ValueError:
        raise SweepSpecError(f"--free {text}", path, f"expected LO:HI, two numbers, got {spec!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise SweepSpecError(f"--free {text}", path, f"bounds must be finite numbers, got {spec!r}")
    if lo > hi:
        raise SweepSpecError(
            f"--free {text}", path, f"bounds reversed: LO = {lo!r} > HI = {hi!r}; give LO:HI with LO < HI"
        )
    return Free(path, lo, hi, text.strip())


@dataclass(frozen=True)
class Objective:
    """Maximise or minimise a quantity of `QUANTITIES`."""

    quantity: str = "v0"
    sense: Sense = Sense.MAXIMIZE

    def __post_init__(self) -> None:
        object.__setattr__(self, "sense", Sense(self.sense))
        if self.quantity not in QUANTITIES:
            raise SweepSpecError(f"--{self.sense}", self.quantity, "expected one of " + ", ".join(QUANTITIES))

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
    expected = (
        "expected QUANTITY>=NUMBER or QUANTITY<=NUMBER with QUANTITY one of "
        + ", ".join(QUANTITIES)
        + ", for example 'v0>=0.2'"
    )
    match = _CONSTRAINT.match(text)
    if match is None:
        raise SweepSpecError(f"{option} {text}", "", expected)
    name, op, number = match.groups()
    op = {"=>": ">=", "=<": "<="}.get(op, op)
    if op not in (">=", "<="):
        raise SweepSpecError(
            f"{option} {text}", "", f"the comparison {op!r} is not allowed (a bound is >= or <=); {expected}"
        )
    name = quantity(name, option)
    try:
        bound = float(number)
    except ValueError:
        raise SweepSpecError(f"{option} {text}", "", f"{number!r} is not a number; {expected}") from None
    if not math.isfinite(bound):
        raise SweepSpecError(f"{option} {text}", "", f"the bound must be a finite number, got {number!r}")
    return Constraint(name, op, bound)


def check_constraints(constraints: Sequence[Constraint]) -> None:
    """Refuse constraints that no point can satisfy, before anything runs: a lower bound above
    an upper bound of the same quantity, or a negative upper bound of a quantity that is never
    negative (`InfeasibleError`)."""
    for c in constraints:
        if c.op == "<=" and c.quantity in NON_NEGATIVE and c.bound < 0:
            raise InfeasibleError(
                f"--subject-to {c.text}", "", f"{c.quantity} is never negative, so no gait satisfies this"
            )
    for lower in (c for c in constraints if c.op == ">="):
        for upper in (c for c in constraints if c.op == "<=" and c.quantity == lower.quantity):
            if lower.bound > upper.bound:
                raise InfeasibleError(
                    f"--subject-to {lower.text} --subject-to {upper.text}",
                    "",
                    f"{lower.quantity} cannot be at least {lower.bound!r} and at most {upper.bound!r}",
                )


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
        base, source = self.base.document, self.base.source
        set_values(doc, [(keys, float(v)) for f, v in zip(self.free, x) for keys in resolve_path(base, f.path, source)])
        return doc

    def label(self, x: Sequence[float]) -> str:
        return f"{self.base.source} with " + ", ".join(f"{p}={v!r}" for p, v in zip(self.paths, x))

    def gait(self, x: Sequence[float]) -> Gait:
        gait = gait_from_document(
            self.document(x), self.label(x), source_text=self.base.source_text, default_name=self.base.name
        )
        assert isinstance(gait, Gait)
        return gait


def make_problem(
    base: Gait,
    free: Sequence[Free | str],
    *,
    objective: Objective | None = None,
    constraints: Sequence[Constraint | str] = (),
    pareto: bool = False,
) -> Problem:
    """Check and build a `Problem`: every path resolves in the base document and names a number,
    no two paths set the same value, the constraints can be satisfied (`check_constraints`), and
    some point of the box is a valid gait (its centre or a corner). ``free`` items are `Free`
    or ``PATH=LO:HI``; ``constraints`` are `Constraint` or ``QUANTITY>=NUMBER`` text. With
    ``pareto`` the objectives are v0 and the cost of transport, so no other ``objective`` is
    taken."""
    if not isinstance(base, Gait):
        raise SweepSpecError(
            str(getattr(base, "source", "gait")),
            "",
            "crawlsim optimize designs crawler gaits; a generic sweeping process has no velocity to optimise",
        )
    items = tuple(parse_free(f) if isinstance(f, str) else f for f in free)
    if not items:
        raise SweepSpecError("--free", "", "give at least one free parameter, PATH=LO:HI")
    seen: dict[tuple, str] = {}
    for f in items:
        try:
            targets = resolve_path(base.document, f.path, base.source)
        except GaitError as exc:
            raise SweepSpecError(f"--free {f.text}", f.path, f"{exc.message} (in {base.source})") from None
        for keys in targets:
            if keys in seen:
                raise SweepSpecError(
                    f"--free {f.text}",
                    f.path,
                    f"this path sets {'.'.join(map(str, keys))}, which --free "
                    f"{seen[keys]} sets too: free each value once",
                )
            seen[keys] = f.path
    cons = tuple(parse_constraint(c) if isinstance(c, str) else c for c in constraints)
    check_constraints(cons)
    if pareto and objective is not None and objective != Objective():
        raise SweepSpecError(
            f"--{objective.sense} {objective.quantity}",
            "",
            "--pareto optimises v0 and cost_of_transport together; drop the objective option",
        )
    problem = Problem(base, items, objective or Objective(), cons, pareto)
    _check_bounds(problem)
    _check_some_point_is_valid(problem)
    return problem


def _check_bounds(problem: Problem) -> None:
    """Refuse a bound of --free that the schema refuses (``period=1:1e300``), each end with the
    other free values at the box's centre: the points beyond it could never run."""
    for i, f in enumerate(problem.free):
        for end, name in ((0.0, f"LO = {f.lo!r}"), (1.0, f"HI = {f.hi!r}")):
            u = [0.5] * problem.dimension
            u[i] = end
            try:
                check_schema(problem.document(problem.values(u)), CRAWLER_SCHEMA, problem.base.source)
            except GaitError as exc:
                raise SweepSpecError(f"--free {f.text}", f.path, f"{name} is refused: {exc.message}") from None


def _check_some_point_is_valid(problem: Problem) -> None:
    """Refuse a box in which neither the centre nor any corner is a valid gait (a free path that
    the schema refuses, a box outside the valid values): nothing could run."""
    n = problem.dimension
    corners = [tuple((k >> i) & 1 for i in range(n)) for k in range(min(2**n, 64))]
    first: InputError | None = None
    for u in [(0.5,) * n, *corners]:
        try:
            problem.gait(problem.values(u))
        except InputError as exc:
            first = first or exc
        else:
            return
    assert first is not None
    raise SweepSpecError(
        first.source,
        first.keypath,
        f"{first.message} (neither the centre nor a corner of the box of --free is a valid gait; this is the first)",
    )


def rank(row: PointResult, objective: Objective, constraints: Sequence[Constraint]) -> tuple[int, float]:
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
    return rank(row, objective, constraints)[0] == 0


#: Members of a differential-evolution population per free parameter (SciPy's ``popsize``).
POPSIZE = 10
#: Default budgets: simulated points per free parameter plus one (one objective), and per point
#: of the Pareto front.
BUDGET_PER_DIMENSION = 150
#: Share of a run's budget kept for the polish when the global search uses all of its own.
POLISH_SHARE = 0.3
#: First step of the pattern search, in units of the box width.
POLISH_STEP = 0.05
#: The pattern search stops when its step falls below this, in units of the box width.
POLISH_XTOL = 1e-6
#: Interior points of a Pareto front (epsilon-constraint runs) besides its two ends.
FRONT_POINTS = 5
#: The gradient search's coarse sample: points per free parameter of its grid, while the grid
#: has at most `SAMPLE_GRID` points (else differential evolution is its global stage), and the
#: quasi-Newton runs started from the best points of that stage.
SAMPLE_PER_PARAMETER = 4
SAMPLE_GRID = 64
RESTARTS = 3
#: A quasi-Newton run stops when its gradient (in units of the box) falls below this, or when
#: `STALL` evaluations in a row improve its best value by less than 1e-13 relative (a line
#: search stuck on a kink of v0).
GRADIENT_TOL = 1e-10
STALL = 8


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
    search: str = "evolution"  # or "gradient" (`crawlsim.design.descent`)
    sample: int = SAMPLE_PER_PARAMETER
    restarts: int = RESTARTS
    gradient_tol: float = GRADIENT_TOL
    stall: int = STALL

    def __post_init__(self) -> None:
        if not 0 <= self.seed <= MAX_SEED:
            raise SweepSpecError(
                "--seed",
                "",
                f"expected an integer from 0 to 2**63 - 1 (the "
                f"results file stores it as a 64-bit integer), "
                f"got {self.seed}",
            )
        if self.max_evaluations is not None and self.max_evaluations < 1:
            raise SweepSpecError("--max-evaluations", "", f"expected a positive number, got {self.max_evaluations}")
        if self.front_points < 0:
            raise SweepSpecError("--front-points", "", "expected 0 or more")
        if self.search not in ("evolution", "gradient"):
            raise SweepSpecError("--method", self.search, "expected evolution or gradient")

    def budget(self, problem: Problem) -> int:
        return self.max_evaluations or default_budget(problem.dimension, problem.pareto, self.front_points)

    def population(self, dimension: int) -> int:
        """SciPy's population size for ``latinhypercube`` and ``random`` initialisation."""
        return max(5, self.popsize * dimension)

    @property
    def gradient(self) -> bool:
        return self.search == "gradient"

    def identity(self) -> dict:
        """The settings that make a search what it is (its journal's fingerprint): an
        evolution search's as before the gradient search existed, so its journals resume."""
        out = dataclasses.asdict(self)
        if not self.gradient:
            for name in ("search", "sample", "restarts", "gradient_tol", "stall"):
                out.pop(name)
        return out

    def settings(self) -> dict:
        if self.gradient:
            return {
                "global": "grid of sample points per parameter, or "
                "scipy.optimize.differential_evolution when the grid would exceed "
                "sample_grid points",
                "sample_per_parameter": self.sample,
                "sample_grid": SAMPLE_GRID,
                "strategy": self.strategy,
                "popsize_per_parameter": self.popsize,
                "polish_share": self.polish_share,
                "local": "scipy.optimize.minimize: L-BFGS-B in the box, SLSQP with "
                "constraints; exact gradients (crawlsim.sensitivity)",
                "restarts": self.restarts,
                "gradient_tol": self.gradient_tol,
                "stall": self.stall,
                "constraints": "SLSQP on the constraints' exact gradients; a point that does not run is infeasible",
                "front_points": self.front_points,
            }
        return {
            "global": "scipy.optimize.differential_evolution",
            "strategy": self.strategy,
            "popsize_per_parameter": self.popsize,
            "mutation": list(self.mutation),
            "recombination": self.recombination,
            "init": self.init,
            "tol": self.tol,
            "updating": "deferred",
            "vectorized": True,
            "constraints": "feasibility rules (Lampinen); a point that does not run is infeasible",
            "polish": "pattern search, 2n rotated directions per poll (batched)",
            "polish_share": self.polish_share,
            "polish_step": self.polish_step,
            "polish_xtol": self.polish_xtol,
            "front_points": self.front_points,
        }

    @property
    def name(self) -> str:
        if self.gradient:
            return "sample + quasi-Newton on exact gradients"
        return "differential evolution + pattern search"


def default_budget(dimension: int, pareto: bool = False, front_points: int = FRONT_POINTS) -> int:
    """``BUDGET_PER_DIMENSION (n + 1)`` simulated points for one objective; a Pareto front
    gives each of its runs (two ends, ``front_points`` inside) half of that."""
    single = BUDGET_PER_DIMENSION * (dimension + 1)
    return single if not pareto else (single * (front_points + 2)) // 2


def default_search(problem: Problem, search: str | None = None) -> str:
    """The search to run: ``search`` if given, else the gradient search where it was measured
    to beat the evolution search (maximise v0 in a box with the exact integrator, no
    constraints, no Pareto front: scripts/optimize-gradient.py), else the evolution search. The
    gradient search follows the exact integrator's sensitivities, so it refuses a catch-up
    gait."""
    exact = problem.base.simulation.integrator == "exact"
    if search == "gradient" and not exact:
        raise SweepSpecError(
            "--method gradient",
            "",
            "the gradient search follows the exact "
            "integrator's sensitivities: use "
            "--integrator exact, or --method evolution",
        )
    if search is not None:
        return search
    plain = problem.objective.quantity == "v0" and problem.objective.sense == "maximize"
    if exact and plain and not problem.constraints and not problem.pareto:
        return "gradient"
    return "evolution"
