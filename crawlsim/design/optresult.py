"""The answer of a gait-design search: every evaluated point, the history of the best value,
the runs, and the Pareto front with its hypervolume."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np

from crawlsim.design.problem import (
    Constraint,
    Free,
    InfeasibleError,
    Method,
    Objective,
    Problem,
    Sense,
    parse_constraint,
    rank,
)
from crawlsim.gait.document import Gait, gait_from_document
from crawlsim.gait.yamlsafe import load_yaml
from crawlsim.io.atomic import atomic_path
from crawlsim.io.layout import counts
from crawlsim.io.optfile import STAGE_FLAGS, read_optimization
from crawlsim.io.outputs import GAIT_HEAD
from crawlsim.io.provenance import command_line, effective_yaml
from crawlsim.status import PointStatus
from crawlsim.study.points import PointResult

BUDGET_SPENT = "budget spent"


class Stage(StrEnum):
    """What a batch of evaluations was: the first population of a run, a later generation of
    differential evolution, or one poll of the pattern search."""

    INITIAL = "initial"
    GENERATION = "generation"
    POLISH = "polish"


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
        (`Search`): its optimum may still improve with more evaluations."""
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
        """The evaluation chosen as the answer (`best`)."""
        return self.evaluations[self.best]

    @property
    def best_values(self) -> dict[str, float]:
        """The free parameters of the best point, by path."""
        return dict(zip(self.problem.paths, self.best_point.x))

    @property
    def value(self) -> float:
        """The objective at the best point (NaN when it has none)."""
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
        with atomic_path(path) as tmp:
            tmp.write_text(self.best_yaml(index), encoding="utf-8")
        return Path(path)

    def counts(self) -> dict[str, int]:
        """Evaluated points by `crawlsim.status.PointStatus` (ok, invalid, failed...)."""
        return {str(s): 0 for s in PointStatus} | counts([e.row.status for e in self.evaluations])

    def feasibility(self) -> tuple[list[bool], list[float]]:
        """For each evaluation: does it satisfy its run's constraints (and run), and its total
        violation (0 when feasible, inf when it does not run)."""
        flags, violations = [], []
        for e in self.evaluations:
            run = self.runs[e.run]
            kind, value = rank(e.row, run.objective, run.constraints)
            flags.append(kind == 0)
            violations.append(0.0 if kind == 0 else value)
        return flags, violations

    def stage_counts(self) -> dict[str, int]:
        """Evaluated points of the global stage (first population, generations or sample)
        and of the local polish."""
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
        e = self.evaluations[self.best if index is None else index]
        what = self.runs[e.run].text
        if self.problem.pareto and e.index == self.best:
            what = f"the fastest gait of the Pareto front (found by {what})"
        head = [
            f"{GAIT_HEAD}: {what}",
            f"# from {self.problem.base.source}, evaluation {e.index} of "
            f"{len(self.evaluations)}, seed {self.method.seed}",
            f"# v0 = {e.row.v0!r}, cost_of_transport = {e.row.cost_of_transport!r}",
            *(f"# {p} = {v!r}" for p, v in zip(self.problem.paths, e.x)),
            f"# command: {command_line()}",
        ]
        document = self.problem.document(e.x)
        free = ", ".join(f"{p} = {v!r}" for p, v in zip(self.problem.paths, e.x))
        base = str(document.get("description", "")).split(" [crawlsim optimize: ")[0]
        document["description"] = f"{base} [crawlsim optimize: {what}; {free}]".lstrip()
        return "\n".join(line.replace("\n", " ") for line in head) + "\n" + effective_yaml(document)

    @classmethod
    def from_file(cls, path: Path | str) -> OptimizationResult:
        """The result recorded in an optimisation file (`crawlsim.io.optfile`): the same type
        and the same numbers as the `crawlsim.design.optimize.optimize` that wrote it. What the
        file does not keep comes back empty: ``computed`` is 0 (this process simulated nothing),
        and the rows' ``limit``, ``newton_steps`` and ``extra`` (the gradient search's derivative
        columns) are unset. Raises `ResultsFileError` for a
        file that is not an optimisation file."""
        return _result_of_file(read_optimization(path))

    def summary(self) -> dict[str, Any]:
        """The JSON-ready answer (``crawlsim optimize --json``)."""
        best = self.best_point
        out: dict[str, Any] = {
            "name": self.problem.base.name,
            "objective": self.problem.objective.text,
            "pareto": self.problem.pareto,
            "constraints": [c.text for c in self.problem.constraints],
            "free": [{"path": f.path, "lo": f.lo, "hi": f.hi} for f in self.problem.free],
            "best": self.best_values,
            "best_evaluation": best.index,
            "feasible": self.feasible,
            "value": self.value,
            **{
                name: getattr(best.row, name)
                for name in (
                    "v0",
                    "v0_error_estimate",
                    "displacement_per_period",
                    "dissipation_per_period",
                    "cost_of_transport",
                    "convergence",
                    "periods",
                    "integrator",
                )
            },
            "evaluations": len(self.evaluations),
            "budget": self.budget,
            "computed": self.computed,
            "stages": self.stage_counts(),
            "statuses": self.counts(),
            "method": self.method.name,
            "seed": self.method.seed,
            "runs": [
                {
                    "run": r.text,
                    "best_evaluation": r.best,
                    "evaluations": r.evaluations,
                    "stop": r.stop,
                    "out_of_budget": r.out_of_budget,
                }
                for r in self.runs
            ],
            "wall_time": self.wall_time,
        }
        if self.problem.pareto:
            out["front"] = [
                {
                    **dict(zip(self.problem.paths, self.evaluations[i].x)),
                    "evaluation": i,
                    "v0": self.evaluations[i].row.v0,
                    "cost_of_transport": self.evaluations[i].row.cost_of_transport,
                    "chosen": i in self.chosen,
                }
                for i in self.front
            ]
        return out


def _result_of_file(data: dict[str, Any]) -> OptimizationResult:
    """`OptimizationResult.from_file` on `read_optimization`'s dicts."""
    a = data["attrs"]
    base = gait_from_document(
        load_yaml(a["gait_yaml"], a["source"]),
        a["source"],
        source_text=a.get("gait_file_text") or None,
        default_name=a["name"],
    )
    assert isinstance(base, Gait)
    free = tuple(Free(f["path"], float(f["lo"]), float(f["hi"])) for f in data["free"])
    pareto = bool(a["pareto"])
    objective = Objective(a["objective_quantity"], Sense(a["objective_sense"]))
    problem = Problem(
        base, free, objective, tuple(parse_constraint(c) for c in json.loads(a["constraints_json"])), pareto
    )
    stages = dict(STAGE_FLAGS)
    ev = data["evaluations"]
    names = [f["name"] for f in data["free"]]
    evaluations = tuple(
        Evaluation(
            n,
            tuple(float(ev[name][n]) for name in names),
            int(ev["run"][n]),
            Stage(stages[int(ev["stage"][n])]),
            int(ev["batch"][n]),
            PointResult.from_columns(ev, n, n, int(ev["steps"][n])),
        )
        for n in range(len(ev["run"]))
    )
    hist = data["history"]
    history = tuple(
        Batch(
            int(hist["batch"][n]),
            int(hist["run"][n]),
            Stage(stages[int(hist["stage"][n])]),
            int(hist["evaluations"][n]),
            float(hist["best"][n]),
            int(hist["best_evaluation"][n]),
            bool(hist["feasible"][n]),
            float(hist["step"][n]),
            float(hist["hypervolume"][n]) if "hypervolume" in hist else math.nan,
        )
        for n in range(len(hist["batch"]))
    )
    r = data["runs"]
    runs = tuple(
        Run(
            int(r["run"][n]),
            _objective_of(str(r["objective"][n])),
            tuple(parse_constraint(c) for c in str(r["constraints"][n]).split(", ") if c),
            int(r["best_evaluation"][n]),
            bool(r["feasible"][n]),
            int(r["evaluations"][n]),
            str(r["stop"][n]),
            float(r["epsilon"][n]),
        )
        for n in range(len(r["run"]))
    )
    front = tuple(int(i) for i in data["front"]["evaluation"]) if "front" in data else ()
    return OptimizationResult(
        problem,
        _method_of(a),
        int(a["max_evaluations"]),
        evaluations,
        history,
        runs,
        int(a["best_evaluation"]),
        bool(a["best_feasible"]),
        front,
        float(a["wall_time"]),
    )


def _objective_of(text: str) -> Objective:
    """`Objective.text` (``maximize v0``) back as the objective."""
    sense, _, quantity = text.partition(" ")
    return Objective(quantity, Sense(sense))


def _method_of(attrs: dict[str, Any]) -> Method:
    """The `Method` whose `Method.settings` and seed the file recorded (the settings the search
    used: the file keeps each one it reads)."""
    settings = json.loads(attrs["method_json"])
    gradient = "sample_per_parameter" in settings
    fields: dict[str, Any] = {
        "seed": int(attrs["seed"]),
        "max_evaluations": int(attrs["max_evaluations"]),
        "search": "gradient" if gradient else "evolution",
        "strategy": settings["strategy"],
        "popsize": int(settings["popsize_per_parameter"]),
        "polish_share": float(settings["polish_share"]),
        "front_points": int(settings["front_points"]),
    }
    if gradient:
        fields.update(
            sample=int(settings["sample_per_parameter"]),
            restarts=int(settings["restarts"]),
            gradient_tol=float(settings["gradient_tol"]),
            stall=int(settings["stall"]),
        )
    else:
        fields.update(
            mutation=tuple(float(m) for m in settings["mutation"]),
            recombination=float(settings["recombination"]),
            init=settings["init"],
            tol=float(settings["tol"]),
            polish_step=float(settings["polish_step"]),
            polish_xtol=float(settings["polish_xtol"]),
        )
    return Method(**fields)


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


def infeasible_error(problem: Problem, evaluations: Sequence[Evaluation]) -> InfeasibleError:
    """The error of a search in which no point satisfies the constraints: it names them and
    the closest point found."""
    runs = [e for e in evaluations if e.runs]
    if not runs:
        first = evaluations[0].row.message if evaluations else "nothing ran"
        return InfeasibleError(
            "--free", "", f"none of the {len(evaluations)} evaluated points ran (the first: {first})"
        )
    if not problem.constraints:
        return InfeasibleError(
            f"--{problem.objective.sense} {problem.objective.quantity}",
            "",
            f"no evaluated point has a value of {problem.objective.quantity} (the cost of transport needs net motion)",
        )
    what = " --subject-to ".join(repr(c.text) for c in problem.constraints)
    closest = min(runs, key=lambda e: sum(c.violation(e.row) for c in problem.constraints))
    values = ", ".join(f"{c.quantity} = {getattr(closest.row, c.quantity)!r}" for c in problem.constraints)
    return InfeasibleError(
        f"--subject-to {what}",
        "",
        f"no evaluated point satisfies the constraints ({len(evaluations)} "
        f"points; the closest, {problem.label(closest.x)}, has {values}); "
        "relax the constraints or widen the --free bounds",
    )
