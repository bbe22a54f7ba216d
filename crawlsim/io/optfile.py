"""Optimisation files (format_version 2, kind "optimization", `write_optimization`): /evaluations
holds every evaluated point (dimension evaluation) with the sweep table's columns and where it came
from, /history the best value per batch, /runs the single-objective runs, /front the Pareto front
(`OPTIMIZATION_VARIABLES`).
"""

from __future__ import annotations

import io
import json
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from crawlsim.errors import ResultsFileError
from crawlsim.gait.units import Units, path_quantity
from crawlsim.io import provenance
from crawlsim.io.layout import (
    Scales,
    Var,
    check_version,
    describe_var,
    open_h5,
    plain,
    read_column,
    root_attrs,
    write_column,
    write_file,
    write_header,
)
from crawlsim.io.sweepfile import SWEEP_VARIABLES, axis_name, worded

_OPTIMIZATION_COMMENT = (
    "Results of crawlsim optimize. Evaluation i is the gait document gait_yaml with the free "
    "parameters (attribute free_json; /evaluations/<name>, the path in attribute path) set to "
    "its values; /evaluations holds every evaluated point in evaluation order with the columns "
    "of a sweep table, /history the best value of each run after every batch, /runs the "
    "single-objective runs (one, or the ends and epsilon-constraint runs of a Pareto front), "
    "/front the non-dominated points of v0 against cost_of_transport (--pareto). Units: "
    "units_json; every dataset has units and long_name."
)

#: Units of the optimisable quantities (`crawlsim.design.optimize.QUANTITIES`).
OBJECTIVE_QUANTITIES = {
    "v0": "velocity",
    "cost_of_transport": "force",
    "dissipation_per_period": "dissipation",
    "displacement_per_period": "length",
}

STAGE_FLAGS = ((0, "initial"), (1, "generation"), (2, "polish"))

OPTIMIZATION_VARIABLES: dict[str, dict[str, Var]] = {
    "evaluations": {
        "evaluation": Var(("evaluation",), "evaluation number, in the order the points were simulated", "1"),
        "run": Var(("evaluation",), "the run that asked for the point (see /runs)", "1"),
        "stage": Var(
            ("evaluation",),
            "what asked for the point: the first population of its "
            "run, a generation of differential evolution, or a poll "
            "of the pattern search",
            "1",
            STAGE_FLAGS,
        ),
        "batch": Var(("evaluation",), "the batch the point was simulated in (see /history)", "1"),
        "feasible": Var(("evaluation",), "1 when the point runs and satisfies the constraints of its run, else 0", "1"),
        "constraint_violation": Var(
            ("evaluation",),
            "total violation of the constraints of its run (0 when satisfied, inf when the point does not run)",
            "1",
        ),
    },
    "history": {
        "batch": Var(("batch",), "batch number (a generation, or a poll of the pattern search)", "1"),
        "run": Var(("batch",), "the run of the batch (see /runs)", "1"),
        "stage": Var(("batch",), "what the batch was", "1", STAGE_FLAGS),
        "evaluations": Var(("batch",), "points simulated so far, all runs", "1"),
        "best": Var(
            ("batch",),
            "best value of the run's objective so far (NaN while no point of the run is feasible)",
            "objective",
        ),
        "best_evaluation": Var(("batch",), "evaluation number of the run's best point so far (-1 before any)", "1"),
        "feasible": Var(("batch",), "1 when the run's best point so far is feasible", "1"),
        "step": Var(
            ("batch",),
            "step of the pattern search after the batch, in units of the box width (NaN for differential evolution)",
            "1",
        ),
        "hypervolume": Var(
            ("batch",),
            "area dominated by the Pareto front of the points "
            "evaluated so far, from the nadir of the final front "
            "(--pareto)",
            "dissipation_rate",
        ),
    },
    "runs": {
        "run": Var(("run",), "run number", "1"),
        "objective": Var(("run",), "objective of the run", "1"),
        "constraints": Var(("run",), "constraints of the run, comma separated", "1"),
        "epsilon": Var(("run",), "lower bound on v0 of an epsilon-constraint run (NaN otherwise)", "velocity"),
        "best_evaluation": Var(("run",), "evaluation number of the run's optimum", "1"),
        "feasible": Var(("run",), "1 when the run's optimum satisfies its constraints", "1"),
        "evaluations": Var(("run",), "points simulated for the run", "1"),
        "stop": Var(("run",), "why the run stopped", "1"),
    },
    "front": {
        "front_point": Var(("front_point",), "point of the Pareto front, by increasing v0", "1"),
        "evaluation": Var(("front_point",), "evaluation number of the point", "1"),
        "v0": Var(("front_point",), "asymptotic average velocity v0", "velocity"),
        "cost_of_transport": Var(("front_point",), "cost of transport", "force"),
        "chosen": Var(
            ("front_point",), "1 for the optimum of a run (an end of the front or an epsilon-constraint point)", "1"
        ),
    },
}


def write_optimization(path: Any, result: Any) -> None:
    """Write a `crawlsim.design.optimize.OptimizationResult` atomically (`crawlsim.io.atomic`);
    ``path`` may be a binary file object (an in-memory image)."""
    write_file(path, lambda f: _write_optimization(f, result))


def _write_optimization(f: h5py.File, result: Any) -> None:
    problem = result.problem
    names: list[str] = []
    for p in problem.paths:
        names.append(axis_name(p, [*names, *OPTIMIZATION_VARIABLES["evaluations"]]))
    units = Units.from_block(problem.base.document.get("units"))
    _write_attributes(f, result, names, units)
    columns = _Columns(Scales(), units, problem.pareto, units.of(OBJECTIVE_QUANTITIES[problem.objective.quantity]))
    _write_evaluations(f, columns, result, names)
    _write_history(f, columns, result)
    _write_runs(f, columns, result)
    if problem.pareto:
        _write_front(f, columns, result, names)


def _write_attributes(f: h5py.File, result: Any, names: Sequence[str], units: Units) -> None:
    """The root attributes: the problem, the method, the best point and the provenance."""
    problem, method = result.problem, result.method
    base, objective = problem.base, problem.objective
    best = result.evaluations[result.best]
    write_header(f, title=f"crawlsim optimisation of {base.name}", comment=_OPTIMIZATION_COMMENT, kind="optimization")
    s = base.simulation
    a = f.attrs
    a["name"] = base.name
    a["source"] = str(base.source)
    a["gait_yaml"] = provenance.effective_yaml(base.document)
    a["gait_file"] = str(base.source)
    a["gait_file_text"] = str(base.source_text)
    a["integrator"] = s.integrator
    a["integrator_json"] = json.dumps(
        {
            "integrator": s.integrator,
            "steps_per_period": s.steps_per_period,
            "max_periods": s.max_periods,
            "tolerance": s.tolerance,
        }
    )
    a["paths"] = json.dumps(list(problem.paths))
    a["axis_names"] = json.dumps(list(names))
    a["free_json"] = json.dumps(
        [{"path": fr.path, "name": n, "lo": fr.lo, "hi": fr.hi} for fr, n in zip(problem.free, names)]
    )
    a["objective"] = "pareto v0 cost_of_transport" if problem.pareto else objective.text
    a["objective_quantity"] = objective.quantity
    a["objective_sense"] = str(objective.sense)
    a["constraints_json"] = json.dumps([c.text for c in problem.constraints])
    a["pareto"] = np.int8(problem.pareto)
    a["method"] = method.name
    a["method_json"] = json.dumps(method.settings())
    a["seed"] = int(method.seed)
    a["max_evaluations"] = int(result.budget)
    a["evaluations"] = len(result.evaluations)
    a["best_evaluation"] = int(best.index)
    a["best_feasible"] = np.int8(result.feasible)
    a["best_value"] = float(result.value)
    a["best_json"] = json.dumps(result.best_values)
    for key in ("v0", "cost_of_transport", "dissipation_per_period", "displacement_per_period"):
        value = getattr(best.row, key)
        a[f"best_{key}"] = np.nan if value is None else float(value)
    a["wall_time"] = float(result.wall_time)
    a["units_json"] = json.dumps(units.to_json())
    for key, value in provenance.session_attrs().items():
        a[key] = value


@dataclass(frozen=True)
class _Columns:
    """Writes the one-dimensional columns of an optimisation file with their units."""

    scales: Scales
    units: Units
    pareto: bool
    objective_unit: str

    def unit_of(self, var: Var) -> str:
        if var.quantity == "objective":
            return "1" if self.pareto else self.objective_unit
        if var.quantity == "dissipation_rate":  # v0 times a cost of transport
            return self.units.compose({"force": Fraction(1), "length": Fraction(1), "time": Fraction(-1)})
        return self.units.of(var.quantity)

    def index(self, group: h5py.Group, var: Var, values: Any) -> None:
        """The group's dimension coordinate."""
        dim = var.dims[0]
        describe_var(self.scales.coordinate(group, dim, np.asarray(values, dtype=np.int64)), var, "1")

    def column(self, group: h5py.Group, name: str, values: Any, var: Var, dim: str) -> None:
        ds = write_column(group, name, values)
        self.scales.attach(ds, (dim,))
        describe_var(ds, Var((dim,), var.long_name, var.quantity, var.flags, var.comment), self.unit_of(var))

    def free(self, group: h5py.Group, name: str, path: str, values: Any, dim: str) -> None:
        """The values of one free parameter, its path in the attribute ``path``."""
        quantity = path_quantity("crawler", tuple(int(k) if k.isdigit() else k for k in path.split(".")))
        ds = group.create_dataset(name, data=np.asarray(values, dtype=float), track_order=True)
        self.scales.attach(ds, (dim,))
        describe_var(ds, Var((dim,), f"free parameter {path}", quantity), self.units.of(quantity))
        ds.attrs["path"] = path


_STAGE_CODE = {m: v for v, m in STAGE_FLAGS}


def _write_evaluations(f: h5py.File, c: _Columns, result: Any, names: Sequence[str]) -> None:
    """/evaluations: the sweep table's columns, then where each point came from."""
    evals = result.evaluations
    table = OPTIMIZATION_VARIABLES["evaluations"]
    group = f.create_group("evaluations", track_order=True)
    group.attrs["comment"] = "every evaluated point, in evaluation order"
    c.index(group, table["evaluation"], np.arange(len(evals)))
    for k, (name, path) in enumerate(zip(names, result.problem.paths)):
        c.free(group, name, path, [e.x[k] for e in evals], "evaluation")
    for name in ("v0", "v0_error_estimate", "displacement_per_period", "dissipation_per_period", "cost_of_transport"):
        c.column(
            group,
            name,
            np.array([np.nan if getattr(e.row, name) is None else getattr(e.row, name) for e in evals], dtype=float),
            SWEEP_VARIABLES[name],
            "evaluation",
        )
    for name in ("convergence", "status", "message", "integrator"):
        c.column(
            group,
            name,
            np.array([str(getattr(e.row, name)) for e in evals], dtype=object),
            worded(SWEEP_VARIABLES[name], name),
            "evaluation",
        )
    for name in ("periods", "steps"):
        c.column(
            group,
            name,
            np.array([getattr(e.row, name) for e in evals], dtype=np.int64),
            SWEEP_VARIABLES[name],
            "evaluation",
        )
    feasible, violation = result.feasibility()
    for name, values in {
        "run": np.array([e.run for e in evals], dtype=np.int64),
        "stage": np.array([_STAGE_CODE[str(e.stage)] for e in evals], dtype=np.int8),
        "batch": np.array([e.batch for e in evals], dtype=np.int64),
        "feasible": np.asarray(feasible, dtype=np.int8),
        "constraint_violation": np.asarray(violation, dtype=float),
    }.items():
        c.column(group, name, values, table[name], "evaluation")


def _write_history(f: h5py.File, c: _Columns, result: Any) -> None:
    """/history: one entry per batch."""
    hist = result.history
    table = OPTIMIZATION_VARIABLES["history"]
    group = f.create_group("history", track_order=True)
    group.attrs["comment"] = "the best value of each run after every batch; the runs' objectives are in /runs"
    c.index(group, table["batch"], [b.batch for b in hist])
    columns: dict[str, Any] = {
        "run": np.array([b.run for b in hist], dtype=np.int64),
        "stage": np.array([_STAGE_CODE[str(b.stage)] for b in hist], dtype=np.int8),
        "evaluations": np.array([b.evaluations for b in hist], dtype=np.int64),
        "best": np.array([b.best for b in hist], dtype=float),
        "best_evaluation": np.array([b.best_index for b in hist], dtype=np.int64),
        "feasible": np.array([b.feasible for b in hist], dtype=np.int8),
        "step": np.array([b.step for b in hist], dtype=float),
    }
    if c.pareto:
        columns["hypervolume"] = np.array([b.hypervolume for b in hist], dtype=float)
    for name, values in columns.items():
        c.column(group, name, values, table[name], "batch")


def _write_runs(f: h5py.File, c: _Columns, result: Any) -> None:
    """/runs: one entry per single-objective run."""
    runs = result.runs
    table = OPTIMIZATION_VARIABLES["runs"]
    group = f.create_group("runs", track_order=True)
    c.index(group, table["run"], [r.index for r in runs])
    for name, values in {
        "objective": np.array([r.objective.text for r in runs], dtype=object),
        "constraints": np.array([", ".join(k.text for k in r.constraints) for r in runs], dtype=object),
        "epsilon": np.array([r.epsilon for r in runs], dtype=float),
        "best_evaluation": np.array([r.best for r in runs], dtype=np.int64),
        "feasible": np.array([r.feasible for r in runs], dtype=np.int8),
        "evaluations": np.array([r.evaluations for r in runs], dtype=np.int64),
        "stop": np.array([r.stop for r in runs], dtype=object),
    }.items():
        c.column(group, name, values, table[name], "run")


def _write_front(f: h5py.File, c: _Columns, result: Any, names: Sequence[str]) -> None:
    """/front (--pareto): the non-dominated points, by increasing v0."""
    evals = result.evaluations
    table = OPTIMIZATION_VARIABLES["front"]
    group = f.create_group("front", track_order=True)
    front = list(result.front)
    c.index(group, table["front_point"], np.arange(len(front)))
    c.column(group, "evaluation", np.array(front, dtype=np.int64), table["evaluation"], "front_point")
    for k, (name, path) in enumerate(zip(names, result.problem.paths)):
        c.free(group, name, path, [evals[i].x[k] for i in front], "front_point")
    c.column(group, "v0", np.array([evals[i].row.v0 for i in front], dtype=float), table["v0"], "front_point")
    c.column(
        group,
        "cost_of_transport",
        np.array([evals[i].row.cost_of_transport for i in front], dtype=float),
        table["cost_of_transport"],
        "front_point",
    )
    chosen = set(result.chosen)
    c.column(group, "chosen", np.array([i in chosen for i in front], dtype=np.int8), table["chosen"], "front_point")


def read_optimization(path: Any) -> dict[str, Any]:
    """An optimisation file as ``{attrs, free, evaluations, history, runs, front}`` (front
    only with --pareto), each group a dict of arrays (strings as Python str). Raises
    `ResultsFileError` naming what is missing when the file is not an optimisation file."""
    if isinstance(path, io.IOBase):
        f = h5py.File(path, "r")
        source: Any = "<memory>"
    else:
        source = Path(path)
        f = open_h5(source, "optimisation file")
    with f:
        check_version(f, source)
        if plain(f.attrs.get("kind", "")) != "optimization":
            raise ResultsFileError(f"{source}: not a crawlsim optimisation file (attribute kind is not 'optimization')")
        out: dict[str, Any] = {"attrs": root_attrs(f)}
        for group in ("evaluations", "history", "runs", "front"):
            if group not in f:
                if group == "front":
                    continue
                raise ResultsFileError(f"{source}: missing group /{group}")
            out[group] = {name: read_column(ds) for name, ds in f[group].items() if isinstance(ds, h5py.Dataset)}
        out["free"] = json.loads(out["attrs"].get("free_json", "[]"))
    return out
