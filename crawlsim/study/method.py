"""The settings of a gait-design search (`Method`) and its default budget.

Two searches share the evaluator, the budget, the constraints and the results
(`crawlsim.study.search`): ``evolution``, differential evolution then a pattern search (no
derivative), and ``gradient``, a coarse sample then quasi-Newton runs on the exact
sensitivities of the objective and the constraints (`crawlsim.study.descent`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING

from crawlsim.errors import SweepSpecError

if TYPE_CHECKING:
    from crawlsim.study.problem import Problem

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
    search: str = "evolution"  # or "gradient" (`crawlsim.study.descent`)
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
