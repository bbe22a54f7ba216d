"""Run results files (format_version 2): the layout of one run's file, and its writer.

    /                     attrs: the run's measurements (v0, ...), its provenance
                                 (`crawlsim.io.provenance`: gait_yaml, command_line, versions_json,
                                 ...), units_json and Conventions; coordinate variables shared by
                                 the groups: block (N), link (N-1), state (n), state_column (n),
                                 constraint (m) with constraint_block and constraint_limit
    /trajectory/*         dimension time (its coordinate variable /trajectory/time holds the
                          times, also in t): t, w, x, stress, shape, reaction
    /convergence/*        dimension period (its coordinate variable is /convergence/period)
    /limit/*              dimensions limit_time (G+1 grid points) and step (the G steps)
    /limit/solver/*       how the limit was found (`crawlsim.integrate.limit`): attributes method,
                          newton_steps, periods, jacobian_rate, contraction_rate; dimension
                          solver_period (each period the solver simulated)
    /process/*            crawlers: stiffness (link); generic processes: normals
                          (constraint, state), metric (state, state_column)
    /events/*             dimension event_time                        [--integrator exact]
    /energy/*             crawlers: scalars, the energy ledger of the limit period
                          (`crawlsim.analysis.energy`)
    /rigid/*              the rigid limit (`crawlsim.analysis.rigid`): attributes v0,
                          v0_error_estimate, status, message; dimension rigid_interval (the
                          resting block from start to end)                 [crawlsim run --rigid]

The time dimensions (time, limit_time, event_time) are coordinate variables holding the group's
times, so that ``ds.sel(time=...)`` works in xarray; the variable ``t`` of each group holds the
same values, as in the files written before. The tables below (`RUN_VARIABLES`) are the layout's
single source in the code; `ResultsWriter` streams a run's trajectory into a file and
`RowsRecorder` keeps it in memory for `crawlsim.api.simulate`.
"""

from __future__ import annotations

import io
import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal

import h5py
import numpy as np

from crawlsim.gait.units import Units
from crawlsim.io.atomic import DISK_ERRORS, discard, disk_error, publish
from crawlsim.io.layout import (
    LIMIT_FLAGS,
    SLIP_FLAGS,
    SOLVER_PERIOD_FLAGS,
    Scales,
    Var,
    describe_var,
    json_ready,
    target_file,
    write_header,
)

_RUN_COMMENT = (
    "Results of one crawlsim run (docs/model.md §4). Times are absolute except /limit/t, which is "
    "relative to the limit period's start (/limit attribute start). Float attributes are NaN "
    "where a value does not apply or is unknown; periodic_from is -1 when the convergence is not "
    "finite-time. Units: units_json (the gait file's units block; {} = dimensionless) and "
    "attribute_units_json (units of the numeric attributes); every dataset has units and "
    "long_name. gait_yaml is the effective gait document, every override applied: "
    "crawlsim run --from THIS_FILE reruns it."
)

_ROLES = {
    "state": ("force", "length"),
    "multiplier": ("length", "length"),
    "metric": ("compliance", "1"),
}

_W12_COMMENT = (
    "sqrt(int |e|^2 dt + int |e'|^2 dt) over one period, e = w - w_final: the two "
    "terms scale as T and 1/T, so with physical units the number depends on the "
    "time unit; units are those of w"
)

ROOT_COORDINATES: dict[str, Var] = {
    "block": Var(("block",), "block number j (blocks in order along the line; link i joins blocks i and i+1)", "1"),
    "link": Var(("link",), "link number i (link i joins blocks i and i+1)", "1"),
    "state": Var(("state",), "coordinate index of the state w of the sweeping process", "1"),
    "state_column": Var(("state_column",), "column index of an n x n matrix over the state", "1"),
    "constraint": Var(("constraint",), "row i of B w <= c(t), the constraints of K(t)", "1"),
    "constraint_block": Var(("constraint",), "the block whose friction limit the constraint is", "1"),
    "constraint_limit": Var(
        ("constraint",),
        "which friction limit of its block the constraint is: forward (mu+) or backward (mu-)",
        "1",
        LIMIT_FLAGS,
    ),
}

RUN_VARIABLES: dict[str, dict[str, Var]] = {
    "trajectory": {
        "t": Var(("time",), "time of the saved grid point", "time"),
        "w": Var(("time", "state"), "state w of the sweeping process (crawlers: w = -K z)", "state"),
        "x": Var(("time", "block"), "block position", "length"),
        "stress": Var(("time", "link"), "link stress sigma = K (L - z), compression positive", "force"),
        "shape": Var(("time", "link"), "shape z = D x: link extension x_(i+1) - x_i", "length"),
        "reaction": Var(
            ("time", "constraint"),
            "constraint reaction: sum of the multipliers of the steps since the previous saved point",
            "multiplier",
        ),
    },
    "convergence": {
        "period": Var(("period",), "period index q: t in [t0 + q T, t0 + (q+1) T]", "1"),
        "displacement": Var(("period",), "barycentre displacement y(t0+(q+1)T) - y(t0+qT)", "length"),
        "velocity": Var(("period",), "average velocity over the period: displacement / T", "velocity"),
        "poincare_step": Var(("period",), "Poincare step |w(t0+(q+1)T) - w(t0+qT)|", "state"),
        "w12_distance": Var(
            ("period",), "W^{1,2} distance of w on period q to the final period", "state", comment=_W12_COMMENT
        ),
        "sup_distance": Var(("period",), "sup distance of w on period q to the final period", "state"),
        "slip_l2_distance": Var(
            ("period",),
            "L^2 distance of the slip rates (multiplier rates) on period q to the final period",
            "velocity_l2",
        ),
        "dissipation": Var(
            ("period",),
            "energy dissipated by friction over period q: sum_j mu_j^+ (dx_j)^+ + mu_j^- (dx_j)^-",
            "dissipation",
        ),
    },
    "limit": {
        "t": Var(("limit_time",), "time since the start of the limit period (attribute start)", "time"),
        "step": Var(("step",), "step s of the limit period, from t[s] to t[s+1]", "1"),
        "w": Var(("limit_time", "state"), "state w on the limit period", "state"),
        "multipliers": Var(
            ("step", "constraint"),
            "multipliers of each step (crawlers: the "
            "forward and backward slips of the blocks, "
            "dx = lambda^+ - lambda^-)",
            "multiplier",
        ),
        "x": Var(
            ("limit_time", "block"), "block position in the running frame x - y(start) - v0 (t - start)", "length"
        ),
        "shape": Var(("limit_time", "link"), "shape z = D x", "length"),
        "stress": Var(("limit_time", "link"), "link stress sigma = K (L - z), compression positive", "force"),
        "slip": Var(("step", "block"), "slip state of the block on the step", "1", SLIP_FLAGS),
        "slip_rate": Var(("step", "block"), "slip rate dx/dt of the block on the step", "velocity"),
        "offsets": Var(("limit_time", "constraint"), "offsets c(t) of K(t) = {w : B w <= c(t)}", "state"),
        "lengths": Var(("limit_time", "link"), "actuator length L(t)", "length"),
        "friction": Var(
            ("limit_time", "constraint"),
            "friction coefficient of the constraint's "
            "limit: mu+ (forward) or mu- (backward), "
            "see constraint_limit (times cos(angle) "
            "on a slope)",
            "force",
        ),
        "load": Var(
            ("limit_time", "constraint"),
            "the loads' share of the constraint's "
            "threshold: -F~ (forward) or F~ (backward), "
            "F~ = F - W sin(angle) (docs/model.md §6; "
            "gaits with loads only)",
            "force",
        ),
    },
    "process": {
        "stiffness": Var(
            ("link",),
            "spring stiffness k of the link (crawlers: B = [D^T; -D^T] "
            "and M = K^-1 follow from it and the block count)",
            "stiffness",
        ),
        "normals": Var(("constraint", "state"), "B, the constant normals of K(t) = {w : B w <= c(t)}", "1"),
        "metric": Var(("state", "state_column"), "M, the metric of the projections (crawlers: K^-1)", "metric"),
    },
    "energy": {
        "actuator_work": Var(
            (), "work done by the actuators on the body over the limit period, sum_i oint sigma_i dL_i", "dissipation"
        ),
        "dissipation": Var(
            (),
            "energy dissipated by friction over the limit period (slips at "
            "jumps at the friction limits after the switch)",
            "dissipation",
        ),
        "jump_loss": Var(
            (),
            "elastic energy released at jumps beyond friction work over the limit period, sum_i k_i (Delta z_i)^2 / 2",
            "dissipation",
        ),
        "discretisation_loss": Var(
            (),
            "catch-up only: the scheme's numerical dissipation over the limit period, first order in the step",
            "dissipation",
        ),
        "balance_residual": Var(
            (),
            "actuator_work - dissipation - jump_loss (- discretisation_loss): zero in the periodic regime, "
            "up to roundoff",
            "dissipation",
        ),
        "cost_of_transport_bound": Var(
            (),
            "least cost of transport of the friction in the "
            "direction of motion: sum_j min_t mu_j^+ (d > 0) or "
            "sum_j min_t mu_j^- (d < 0)",
            "force",
        ),
        "efficiency": Var(
            (), "cost_of_transport_bound / cost_of_transport, at most 1; with loads load_work / actuator_work", "1"
        ),
        "load_work": Var(
            (),
            "work against the loads over the limit period, -oint F~ . dx "
            "(on a slope with the potential energy gained; gaits with loads "
            "only)",
            "dissipation",
        ),
    },
    "rigid": {
        "rigid_interval": Var(("rigid_interval",), "interval i of the rigid limit (docs/model.md §7)", "1"),
        "start": Var(("rigid_interval",), "start of the interval (one of length zero is a jump of the links)", "time"),
        "end": Var(("rigid_interval",), "end of the interval", "time"),
        "resting_block": Var(
            ("rigid_interval",), "the block at rest over the interval in the rigid limit k -> infinity", "1"
        ),
    },
    "events": {
        "t": Var(
            ("event_time",), "event time of the exact integrator (every period, never thinned by save_every)", "time"
        ),
        "w": Var(("event_time", "state"), "state w just after the event (a closed form in between)", "state"),
        "x": Var(("event_time", "block"), "block position at the event", "length"),
    },
}

#: The /energy datasets and the RunResult fields they hold.
_ENERGY = {
    "actuator_work": "actuator_work_per_period",
    "dissipation": "dissipation_per_period",
    "jump_loss": "jump_loss_per_period",
    "discretisation_loss": "discretisation_loss_per_period",
    "balance_residual": "energy_balance_residual",
    "cost_of_transport_bound": "cost_of_transport_bound",
    "efficiency": "efficiency",
    "load_work": "load_work_per_period",
}
#: /limit/solver: the periodic-limit solver's periods (`crawlsim.integrate.limit.solve_limit`).
SOLVER_VARIABLES: dict[str, Var] = {
    "solver_period": Var(
        ("solver_period",),
        "period simulated by the periodic-limit solver, "
        "in order (after the plain periods of "
        "/convergence it started from)",
        "1",
    ),
    "residual": Var(
        ("solver_period",),
        "relative Poincare step |P(w) - w| / max(|P(w)|, "
        "scale of c) of the period: the residual |F| of the "
        "fixed-point equation at its start",
        "1",
    ),
    "kind": Var(
        ("solver_period",),
        "what the period was: a plain iteration, an accepted "
        "Newton step, or a Newton candidate rejected by the "
        "safeguard (its residual did not decrease)",
        "1",
        SOLVER_PERIOD_FLAGS,
    ),
}

#: The time dimension of each group: a coordinate variable holding the group's t.
TIME_DIMENSIONS = {"trajectory": "time", "limit": "limit_time", "events": "event_time"}

#: Units of the numeric root attributes of a run file, by quantity.
_ATTRIBUTE_QUANTITIES = {
    "v0": "velocity",
    "v0_error_estimate": "velocity",
    "v0_error_period_iteration": "velocity",
    "v0_error_time_step": "velocity",
    "displacement_per_period": "length",
    "dissipation_per_period": "dissipation",
    "cost_of_transport": "force",
    "period": "time",
    "contraction_rate": "1",
    "periodic_from": "1",
    "steps_per_period": "1",
    "periods": "1",
    "save_every": "1",
    "actuator_work_per_period": "dissipation",
    "jump_loss_per_period": "dissipation",
    "discretisation_loss_per_period": "dissipation",
    "energy_balance_residual": "dissipation",
    "cost_of_transport_bound": "force",
    "efficiency": "1",
    "load_work_per_period": "dissipation",
    "slope_angle": "angle",
}


def _unit(units: Units, quantity: str, crawler: bool) -> str:
    if quantity in _ROLES:
        quantity = _ROLES[quantity][0 if crawler else 1]
    return units.of(quantity)


def period_rows(
    process: Any, record: Any, save_every: int, carry: np.ndarray
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The /trajectory rows of one period's saved grid points (its first point only for period
    0), and the reaction carried to the next period (generic processes)."""
    p = process
    first = 0 if record.index == 0 else 1
    local = np.arange(first, p.steps + 1)
    global_index = record.index * p.steps + local
    sel = local[global_index % save_every == 0]
    c = p.crawler
    reaction = None
    if c is None:
        reaction, carry = _reaction_rows(record.multipliers, sel, carry)
    if sel.size == 0:
        return {}, carry
    rows = {"t": record.start + p.times[sel], "w": record.w[sel]}
    if c is not None:
        rows.update(x=record.x[sel], stress=c.stress(record.w[sel], sel), shape=c.shape(record.w[sel]))
    if reaction is not None:
        rows["reaction"] = reaction
    return rows, carry


def _reaction_rows(multipliers: np.ndarray, sel: np.ndarray, carry: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Reactions of the m constraints at the saved grid points ``sel`` of one period, and the
    carry to the next.

    The multipliers of catch-up steps are the constraints' reaction impulses (docs/model.md
    §3). Row s sums the multipliers of the steps since the previous saved point, so with
    ``save_every = 1`` it is the multiplier of the step ending at t_s, and a larger
    ``save_every`` loses nothing of the total.
    """
    rows = np.zeros((len(sel), multipliers.shape[1]))
    ends = sel[sel > 0]  # grid point s ends step s - 1
    if ends.size == 0:
        return rows, carry + multipliers.sum(axis=0)
    starts = np.concatenate([[0], ends[:-1]])
    sums = np.add.reduceat(multipliers, starts, axis=0)
    sums[-1] = multipliers[starts[-1] : ends[-1]].sum(axis=0)
    sums[0] += carry
    rows[len(sel) - len(ends) :] = sums
    return rows, multipliers[ends[-1] :].sum(axis=0)


def trajectory_columns(process: Any) -> dict[str, tuple[int, ...]]:
    """The /trajectory variables of a process and the shape of one row of each: t, w and, for
    crawlers, x, stress and shape, for generic processes the reactions."""
    n, m = process.polyhedron.n, process.polyhedron.m
    columns: dict[str, tuple[int, ...]] = {"t": (), "w": (n,)}
    c = process.crawler
    columns.update({"x": (c.blocks,), "stress": (n,), "shape": (n,)} if c is not None else {"reaction": (m,)})
    return columns


class RowsRecorder:
    """The in-memory twin of `ResultsWriter` (`crawlsim.api.simulate`): it keeps the rows a
    results file would hold; the API's result holds them as its trajectory, and writes the
    file from it (`ResultsWriter.write_rows`) only when asked, so a result nobody saves costs no
    HDF5."""

    def __init__(self, process: Any, *, save_every: int = 1, trajectory: bool = True):
        self.process = process
        self.save_every = int(save_every)
        self.keep = bool(trajectory)
        self._rows: dict[str, list[np.ndarray]] = {}
        self._events: dict[str, list[np.ndarray]] = {}
        self._carry = np.zeros(process.polyhedron.m)

    def add_period(self, record: Any) -> None:
        if not self.keep:
            return
        events = getattr(record, "events", None)
        if events is not None:
            for name, rows in zip(("t", "w", "x"), events):
                if rows is not None:
                    self._events.setdefault(name, []).append(np.asarray(rows, dtype=float))
        rows, self._carry = period_rows(self.process, record, self.save_every, self._carry)
        for name, values in rows.items():
            self._rows.setdefault(name, []).append(np.asarray(values, dtype=float))

    def trajectory(self) -> dict[str, np.ndarray]:
        """The /trajectory variables, as `read_results` would give them."""
        return {
            name: (np.concatenate(self._rows[name]) if name in self._rows else np.zeros((0,) + tail))
            for name, tail in trajectory_columns(self.process).items()
        }

    def events(self) -> dict[str, np.ndarray] | None:
        return {name: np.concatenate(rows) for name, rows in self._events.items()} or None


class ResultsWriter:
    """Streams a run's trajectory into a results file; `finish` writes the rest and publishes.

    ``target`` is a path (written to a temporary file beside it, renamed into place by `finish`)
    or a binary file object such as `io.BytesIO` (an in-memory file: `crawlsim.api.simulate`).
    Use as a context manager: leaving the block with an exception deletes the temporary file.
    Only every ``save_every``-th grid point is written (none when ``trajectory`` is False), and
    nothing is kept in memory.
    """

    def __init__(
        self, target: Any, process: Any, *, save_every: int = 1, units: Units | None = None, trajectory: bool = True
    ):
        self.path = None if isinstance(target, io.IOBase) else Path(target)
        self.process = process
        self.save_every = int(save_every)
        self.units = units or Units()
        self.keep = bool(trajectory)
        self.file, self._tmp, self._raw = target_file(target)
        self._scales = Scales()
        self._traj = self.file.create_group("trajectory", track_order=True)
        self._sets: dict[str, h5py.Dataset] = {}
        self._reaction_carry = np.zeros(process.polyhedron.m)
        for name, tail in trajectory_columns(process).items():
            rows = max(1, min(4096, (1 << 16) // max(1, math.prod(tail))))
            self._sets[name] = self._traj.create_dataset(
                name, shape=(0,) + tail, maxshape=(None,) + tail, dtype=float, chunks=(rows,) + tail, track_order=True
            )

    def _append(self, name: str, rows: Any) -> None:
        if self._raw is not None:
            self._raw.check()  # a full disk stops the run at its next write
        rows = np.asarray(rows, dtype=float)
        ds = self._sets[name]
        n = ds.shape[0]
        ds.resize(n + len(rows), axis=0)
        ds[n:] = rows

    def add_period(self, record: Any) -> None:
        """Append the saved grid points of one period (its first point only for period 0)."""
        if not self.keep:
            return
        if getattr(record, "events", None) is not None:
            self._append_events(record.events)
        rows, self._reaction_carry = period_rows(self.process, record, self.save_every, self._reaction_carry)
        for name, values in rows.items():
            self._append(name, values)

    def _append_events(self, events: Any) -> None:
        """Append one period's event trajectory ``(t, w, x)`` to /events (exact integrator)."""
        group = self.file.require_group("events")
        for name, rows in zip(("t", "w", "x"), events):
            if rows is None:
                continue
            rows = np.asarray(rows, dtype=float)
            if name not in group:
                group.create_dataset(
                    name,
                    shape=(0,) + rows.shape[1:],
                    maxshape=(None,) + rows.shape[1:],
                    dtype=float,
                    chunks=(256,) + rows.shape[1:],
                    track_order=True,
                )
            ds = group[name]
            n = ds.shape[0]
            ds.resize(n + len(rows), axis=0)
            ds[n:] = rows

    def write_rows(self, rows: Mapping[str, np.ndarray], events: Mapping[str, np.ndarray] | None = None) -> None:
        """Append trajectory rows (and events) kept elsewhere: `RowsRecorder`, a result's
        `crawlsim.api.Trajectory`."""
        if events is not None:
            self._append_events(tuple(events.get(name) for name in ("t", "w", "x")))
        for name, values in rows.items():
            if values is not None and name in self._sets:
                self._append(name, values)

    def finish(
        self,
        result: Any,
        provenance: Any,
        kind: str = "crawler",
        unchecked_uniqueness: bool = False,
        rigid: Any = None,
    ) -> None:
        """Write the analysis, the coordinates, the attributes; close and publish.

        ``unchecked_uniqueness`` records (the root attribute of that name, 0 or 1) that the
        gait opted out of an exact check of the uniqueness condition it was beyond. ``rigid``,
        the gait's `crawlsim.analysis.rigid.RigidLimit`, is written to /rigid."""
        f = self.file
        self._write_root_coordinates()
        for gname, values in self._groups(result).items():
            self._write_group(gname, values)
        if rigid is not None:
            t = rigid.times
            group = {
                "rigid_interval": np.arange(len(t) - 1),
                "start": t[:-1],
                "end": t[1:],
                "resting_block": rigid.resting,
            }
            self._write_group("rigid", group)
            for name in ("v0", "v0_error_estimate", "displacement_per_period", "status", "message"):
                f["rigid"].attrs[name] = getattr(rigid, name) if name != "status" else str(rigid.status)
        f["limit"].attrs["start"] = result.limit.start
        f["limit"].attrs["comment"] = (
            "the final period, taken as the periodic limit; t is relative to its start (attribute start, absolute time)"
        )
        self._write_solver(result)
        self._write_root_attributes(result, provenance, kind)
        f.attrs["unchecked_uniqueness"] = int(bool(unchecked_uniqueness))
        self._publish()

    def _groups(self, result: Any) -> dict[str, dict[str, Any]]:
        """The values of each group, by dataset name (None: not written)."""
        p, f = self.process, self.file
        c = p.crawler
        groups: dict[str, dict[str, Any]] = {
            "trajectory": dict(self._sets),
            "convergence": {name: getattr(result.history, name) for name in RUN_VARIABLES["convergence"]},
            "limit": {
                name: getattr(result.limit, name)
                for name in ("t", "w", "multipliers", "x", "shape", "stress", "slip", "slip_rate")
            },
            # a crawler's B and M are of size N^2 but follow from k: store k only
            "process": ({"stiffness": c.stiffness} if c is not None else {"normals": p.normals, "metric": p.metric}),
        }
        groups["limit"].update(step=np.arange(p.steps, dtype=np.int64), offsets=p.offsets)
        if c is not None:
            groups["limit"].update(lengths=c.lengths, friction=c.friction, load=c.load)
        if "events" in f:
            groups["events"] = {name: f["events"][name] for name in f["events"]}
        summary = result.summary()
        if c is not None and summary["actuator_work_per_period"] is not None:
            groups["energy"] = {name: summary[key] for name, key in _ENERGY.items()}
        return groups

    def _write_group(self, gname: str, values: dict[str, Any]) -> None:
        """One group: its dimension coordinates (time, period, step), then its variables with
        their dimensions and CF attributes."""
        f, scales = self.file, self._scales
        crawler = self.process.crawler is not None
        group = f.require_group(gname) if gname in f else f.create_group(gname, track_order=True)
        table = RUN_VARIABLES[gname]
        time_dim = TIME_DIMENSIONS.get(gname)
        if time_dim is not None:
            ds = scales.coordinate(group, time_dim, np.asarray(values["t"][()], dtype=float))
            describe_var(
                ds,
                Var((time_dim,), f"time: the index of dimension {time_dim} (the values of /{gname}/t)", "time"),
                _unit(self.units, "time", crawler),
            )
        for name in ("period", "step", "rigid_interval"):
            if name in values and name in table:
                scales.coordinate(group, name, np.asarray(values.pop(name), dtype=np.int64))
                describe_var(group[name], table[name], "1")
        for name, value in values.items():
            if value is None:
                continue
            ds = value if isinstance(value, h5py.Dataset) else group.create_dataset(name, data=value, track_order=True)
            var = table[name]
            scales.attach(ds, var.dims)
            coords = "t" if time_dim is not None and name != "t" and var.dims[0] == time_dim else ""
            describe_var(ds, var, _unit(self.units, var.quantity, crawler), coords)

    def _publish(self) -> None:
        """Close the file and rename it into place (a path), raising a write error libhdf5
        swallowed."""
        self.file.close()
        if self._raw is not None:
            self._raw.close()
            if self._raw.error is not None:
                raise self._raw.error  # written over by libhdf5's own error, or swallowed
        if self._tmp is not None and self.path is not None:
            publish(self._tmp, self.path)

    def _write_solver(self, result: Any) -> None:
        """/limit/solver: how the limit was found (docs/model.md §4). With ``method`` newton the
        periodic-limit solver found and verified it in ``periods`` periods of its own, listed
        along solver_period; with ``iterate`` the true iterates of /convergence reached it and
        solver_period is empty. jacobian_rate (the Jacobian's subdominant spectral radius at
        the limit) and contraction_rate (fitted to the true iterates) should agree."""
        group = self.file["limit"].create_group("solver", track_order=True)
        solver, summary = result.solver, result.summary()
        residuals, kinds = solver.residuals, solver.kinds
        residuals = np.zeros(0) if residuals is None else np.asarray(residuals, dtype=float)
        kinds = np.zeros(len(residuals), dtype=np.int8) if kinds is None else np.asarray(kinds, dtype=np.int8)
        ds = self._scales.coordinate(group, "solver_period", np.arange(len(residuals), dtype=np.int64))
        describe_var(ds, SOLVER_VARIABLES["solver_period"], "1")
        for name, data in (("residual", residuals), ("kind", kinds)):
            ds = group.create_dataset(name, data=data, track_order=True)
            self._scales.attach(ds, ("solver_period",))
            describe_var(ds, SOLVER_VARIABLES[name], "1")
        a = group.attrs
        a["method"] = str(solver.method)
        a["newton_steps"] = int(solver.newton_steps)
        a["periods"] = int(solver.periods)
        for key in ("jacobian_rate", "contraction_rate"):
            a[key] = np.nan if summary[key] is None else float(summary[key])
        a["comment"] = (
            "how the periodic limit was found. method newton: the periodic-limit solver "
            "(safeguarded semismooth Newton on F(w) = P(w) - w, P the period map, Jacobian from "
            "the active sets the period visited) found it from the last state of /convergence "
            "and verified it by a plain period, in `periods` periods (solver_period), "
            "`newton_steps` of them accepted Newton steps; method iterate: the periods of "
            "/convergence reached it themselves (solver_period empty). jacobian_rate: the "
            "largest |eigenvalue| below 1 of the Jacobian at the limit (NaN when not formed); "
            "contraction_rate: fitted to the Poincare steps of /convergence (NaN for "
            "finite-time convergence)"
        )

    def _write_root_coordinates(self) -> None:
        p, f, scales = self.process, self.file, self._scales
        n, m = p.polyhedron.n, p.polyhedron.m
        values: dict[str, Any] = {"state": np.arange(n), "state_column": np.arange(n), "constraint": np.arange(m)}
        aux: dict[str, np.ndarray] = {}
        if p.crawler is not None:
            N = p.crawler.blocks
            values.update(block=np.arange(1, N + 1), link=np.arange(1, N))
            aux = {
                "constraint_block": np.tile(np.arange(1, N + 1), 2).astype(np.int64),
                "constraint_limit": np.repeat(np.array([1, -1], dtype=np.int8), N),
            }
        for name in ("block", "link", "state", "state_column", "constraint"):
            if name in values:
                scales.coordinate(f, name, np.asarray(values[name], dtype=np.int64))
                describe_var(f[name], ROOT_COORDINATES[name], "1")
        # the crawler's auxiliary coordinates of the constraints, after the dimensions they use
        for name, data in aux.items():
            ds = f.create_dataset(name, data=data, track_order=True)
            scales.attach(ds, ("constraint",))
            describe_var(ds, ROOT_COORDINATES[name], "1")
        if aux:
            # xarray reads a global `coordinates` attribute as the root's auxiliary coordinates
            f.attrs["coordinates"] = "constraint_block constraint_limit"

    def _write_root_attributes(self, result: Any, provenance: Any, kind: str) -> None:
        a, units = self.file.attrs, self.units
        write_header(self.file, title=f"crawlsim run of {result.name}", comment=_RUN_COMMENT, kind=kind)
        a["name"] = result.name
        a["convergence"] = str(result.convergence)
        a["periodic_from"] = -1 if result.periodic_from is None else int(result.periodic_from)
        summary = result.summary()
        for key in (
            "v0",
            "v0_error_estimate",
            "v0_error_period_iteration",
            "v0_error_time_step",
            "contraction_rate",
            "displacement_per_period",
            "dissipation_per_period",
            "cost_of_transport",
            "actuator_work_per_period",
            "jump_loss_per_period",
            "discretisation_loss_per_period",
            "energy_balance_residual",
            "cost_of_transport_bound",
            "efficiency",
            "load_work_per_period",
        ):
            a[key] = np.nan if summary[key] is None else float(summary[key])
        # the loads (docs/model.md §6): the effective document (gait_yaml) holds the whole
        # loads: block; the angle in degrees is repeated here, NaN without a slope
        c = self.process.crawler
        angle = None if c is None else c.slope_angle
        a["slope_angle"] = np.nan if angle is None else float(angle)
        a["period"] = result.period
        a["steps_per_period"] = result.steps_per_period
        a["periods"] = result.periods
        a["save_every"] = self.save_every if self.keep else 0
        a["units_json"] = json.dumps(units.to_json())
        a["attribute_units_json"] = json.dumps({key: units.of(q) for key, q in _ATTRIBUTE_QUANTITIES.items()})
        for key, value in provenance.attrs().items():
            a[key] = value
        a["summary_json"] = json.dumps(json_ready(summary))

    def abort(self) -> None:
        try:
            self.file.close()  # after a failed write, GuardedFile drops what libhdf5 flushes
        finally:
            if self._raw is not None:
                self._raw.close()
            if self._tmp is not None:
                discard(self._tmp)

    def __enter__(self) -> ResultsWriter:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> Literal[False]:
        if exc_type is not None or (self._tmp is not None and self._tmp.exists()):
            self.abort()
        error = None if self._raw is None else self._raw.error
        if error is not None and error.errno in DISK_ERRORS and exc_type is not KeyboardInterrupt:
            raise disk_error(self.path, error) from None
        if error is not None and exc_type is None:
            raise error
        return False
