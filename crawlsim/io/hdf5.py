"""The one module that reads and writes HDF5: run results files, sweep files and optimisation
files.

The files are netCDF-4 files (HDF5 with the netCDF conventions), written with h5py: every axis of
every dataset is attached to a named dimension scale, and every dataset carries ``units`` (UDUNITS
syntax, "1" when dimensionless) and ``long_name``; enumerations carry the CF ``flag_values`` and
``flag_meanings``. So ``xarray.open_datatree(path, engine="h5netcdf")`` opens every group with named
dimensions, and ``h5dump -H`` reads as documentation. The README's HDF5 section documents the
layout; the tables below (`RUN_VARIABLES`, `SWEEP_VARIABLES`) are its single source in the code.

Run files (format_version 2):

    /                     attrs: the run's measurements (v0, ...), its provenance
                                 (`crawlsim.io.provenance`: gait_yaml, command_line, versions_json,
                                 ...) and units_json; coordinate variables shared by the groups:
                                 block (N), link (N-1), state (n), state_column (n),
                                 constraint (m) with constraint_block and constraint_limit
    /trajectory/*         dimension time: t, w, x, stress, shape, reaction
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

A dimension without values of its own (time, event_time, limit_time) is a netCDF "dimension but
not a variable"; the times are the variable ``t`` of the group, a coordinate of its variables.

Sweep files (format_version 2): /grid holds v0 and the other numbers on the Cartesian grid, one
dimension per swept path (named by `axis_name`, the path in the attribute ``path``); /results holds
one entry per computed point, as in format 1.

Optimisation files (format_version 2, kind "optimization", `write_optimization`): /evaluations
holds every evaluated point (dimension evaluation) with the sweep table's columns and where it came
from, /history the best value per batch, /runs the single-objective runs, /front the Pareto front
(`OPTIMIZATION_VARIABLES`).

Readers accept format_version 1 (the layout before dimension scales, units and provenance) and 2;
the dicts they return have the same keys for both, format 2 adding new keys only. Writes are
atomic (`crawlsim.io.atomic`): a failed run leaves no file behind.
"""

from __future__ import annotations

import io
import json
import math
import re
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import h5py
import numpy as np

from crawlsim import __version__
from crawlsim.errors import ResultsFileError
from crawlsim.gait.units import Units, path_quantity
from crawlsim.io.atomic import (
    DISK_ERRORS,
    GuardedFile,
    atomic_path,
    discard,
    disk_error,
    guarded,
    publish,
    temporary_beside,
)
from crawlsim.kernel.kkt import ChainPolyhedron

FORMAT_VERSION = 2
#: Format versions the readers accept.
READABLE_VERSIONS = (1, 2)

#: netCDF-4 marks a dimension scale that is not a variable by this NAME (followed by its size).
NOT_A_VARIABLE = b"This is a netCDF dimension but not a netCDF variable."

SLIP_FLAGS = ((-1, "backward_slip"), (0, "stick"), (1, "forward_slip"))
LIMIT_FLAGS = ((-1, "backward_limit"), (1, "forward_limit"))
CONVERGENCE_FLAGS = ((-1, "none"), (0, "finite_time"), (1, "asymptotic"), (2, "not_converged"))
SOLVER_PERIOD_FLAGS = ((-1, "rejected_newton"), (0, "plain"), (1, "newton"))
STATUS_FLAGS = ((-1, "not_computed"), (0, "ok"), (1, "not_converged"), (2, "invalid"),
                (3, "failed"))

_RUN_COMMENT = (
    "Results of one crawlsim run (docs/model.md §4). Times are absolute except /limit/t, which is "
    "relative to the limit period's start (/limit attribute start). Float attributes are NaN "
    "where a value does not apply or is unknown; periodic_from is -1 when the convergence is not "
    "finite-time. Units: units_json (the gait file's units block; {} = dimensionless) and "
    "attribute_units_json (units of the numeric attributes); every dataset has units and "
    "long_name. gait_yaml is the effective gait document, every override applied: "
    "crawlsim run --from THIS_FILE reruns it.")

_SWEEP_COMMENT = (
    "Results of a crawlsim parameter sweep. Point i of the grid is the gait document gait_yaml "
    "with the swept values of i (the paths in attribute paths, their dimensions in axis_names; "
    "C order, the last path varying fastest). /grid holds the numbers on the grid, /results one "
    "entry per computed point. Units: units_json (the gait file's units block); every dataset "
    "has units and long_name.")


@dataclass(frozen=True)
class Var:
    """A dataset of the layout: its dimensions, description, the quantity its units follow
    (a key of `crawlsim.gait.units.QUANTITIES`, or a role resolved per kind by `_ROLES`), and the CF
    flags of an enumeration."""

    dims: tuple[str, ...]
    long_name: str
    quantity: str
    flags: tuple[tuple[int, str], ...] = ()
    comment: str = ""


#: Quantities that depend on the kind of run: (crawler, generic sweeping process). A crawler's w
#: is -K z, a force; a generic process's state z is taken as a length, with dimensionless
#: normals and metric, so its multipliers (reactions) are lengths too.
_ROLES = {
    "state": ("force", "length"),
    "multiplier": ("length", "length"),
    "metric": ("compliance", "1"),
}

_W12_COMMENT = ("sqrt(int |e|^2 dt + int |e'|^2 dt) over one period, e = w - w_final: the two "
                "terms scale as T and 1/T, so with physical units the number depends on the "
                "time unit; units are those of w")

ROOT_COORDINATES: dict[str, Var] = {
    "block": Var(("block",), "block number j (blocks in order along the line; link i joins "
                             "blocks i and i+1)", "1"),
    "link": Var(("link",), "link number i (link i joins blocks i and i+1)", "1"),
    "state": Var(("state",), "coordinate index of the state w of the sweeping process", "1"),
    "state_column": Var(("state_column",), "column index of an n x n matrix over the state",
                        "1"),
    "constraint": Var(("constraint",), "row i of B w <= c(t), the constraints of K(t)", "1"),
    "constraint_block": Var(("constraint",), "the block whose friction limit the constraint "
                                             "is", "1"),
    "constraint_limit": Var(("constraint",), "which friction limit of its block the "
                                             "constraint is: forward (mu+) or backward (mu-)",
                            "1", LIMIT_FLAGS),
}

RUN_VARIABLES: dict[str, dict[str, Var]] = {
    "trajectory": {
        "t": Var(("time",), "time of the saved grid point", "time"),
        "w": Var(("time", "state"), "state w of the sweeping process (crawlers: w = -K z)",
                 "state"),
        "x": Var(("time", "block"), "block position", "length"),
        "stress": Var(("time", "link"), "link stress sigma = K (L - z), compression positive",
                      "force"),
        "shape": Var(("time", "link"), "shape z = D x: link extension x_(i+1) - x_i", "length"),
        "reaction": Var(("time", "constraint"), "constraint reaction: sum of the multipliers of "
                                                "the steps since the previous saved point",
                        "multiplier"),
    },
    "convergence": {
        "period": Var(("period",), "period index q: t in [t0 + q T, t0 + (q+1) T]", "1"),
        "displacement": Var(("period",), "barycentre displacement y(t0+(q+1)T) - y(t0+qT)",
                            "length"),
        "velocity": Var(("period",), "average velocity over the period: displacement / T",
                        "velocity"),
        "poincare_step": Var(("period",), "Poincare step |w(t0+(q+1)T) - w(t0+qT)|", "state"),
        "w12_distance": Var(("period",), "W^{1,2} distance of w on period q to the final "
                                         "period", "state", comment=_W12_COMMENT),
        "sup_distance": Var(("period",), "sup distance of w on period q to the final period",
                            "state"),
        "slip_l2_distance": Var(("period",), "L^2 distance of the slip rates (multiplier "
                                             "rates) on period q to the final period",
                                "velocity_l2"),
        "dissipation": Var(("period",), "energy dissipated by friction over period q: sum_j "
                                        "mu_j^+ (dx_j)^+ + mu_j^- (dx_j)^-", "dissipation"),
    },
    "limit": {
        "t": Var(("limit_time",), "time since the start of the limit period (attribute "
                                  "start)", "time"),
        "step": Var(("step",), "step s of the limit period, from t[s] to t[s+1]", "1"),
        "w": Var(("limit_time", "state"), "state w on the limit period", "state"),
        "multipliers": Var(("step", "constraint"), "multipliers of each step (crawlers: the "
                                                   "forward and backward slips of the blocks, "
                                                   "dx = lambda^+ - lambda^-)", "multiplier"),
        "x": Var(("limit_time", "block"), "block position in the running frame "
                                          "x - y(start) - v0 (t - start)", "length"),
        "shape": Var(("limit_time", "link"), "shape z = D x", "length"),
        "stress": Var(("limit_time", "link"), "link stress sigma = K (L - z), compression "
                                              "positive", "force"),
        "slip": Var(("step", "block"), "slip state of the block on the step", "1",
                    SLIP_FLAGS),
        "slip_rate": Var(("step", "block"), "slip rate dx/dt of the block on the step",
                         "velocity"),
        "offsets": Var(("limit_time", "constraint"), "offsets c(t) of K(t) = {w : B w <= c(t)}",
                       "state"),
        "lengths": Var(("limit_time", "link"), "actuator length L(t)", "length"),
        "friction": Var(("limit_time", "constraint"), "friction coefficient of the constraint's "
                                                      "limit: mu+ (forward) or mu- (backward), "
                                                      "see constraint_limit (times cos(angle) "
                                                      "on a slope)", "force"),
        "load": Var(("limit_time", "constraint"), "the loads' share of the constraint's "
                                                  "threshold: -F~ (forward) or F~ (backward), "
                                                  "F~ = F - W sin(angle) (docs/model.md §6; "
                                                  "gaits with loads only)", "force"),
    },
    "process": {
        "stiffness": Var(("link",), "spring stiffness k of the link (crawlers: B = [D^T; -D^T] "
                                    "and M = K^-1 follow from it and the block count)",
                         "stiffness"),
        "normals": Var(("constraint", "state"), "B, the constant normals of "
                                                "K(t) = {w : B w <= c(t)}", "1"),
        "metric": Var(("state", "state_column"), "M, the metric of the projections "
                                                 "(crawlers: K^-1)", "metric"),
    },
    "energy": {
        "actuator_work": Var((), "work done by the actuators on the body over the limit period, "
                                 "sum_i oint sigma_i dL_i", "dissipation"),
        "dissipation": Var((), "energy dissipated by friction over the limit period (slips at "
                               "jumps at the friction limits after the switch)", "dissipation"),
        "jump_loss": Var((), "elastic energy released at jumps beyond friction work over the "
                             "limit period, sum_i k_i (Delta z_i)^2 / 2", "dissipation"),
        "balance_residual": Var((), "actuator_work - dissipation - jump_loss: zero in the "
                                    "periodic regime, up to roundoff", "dissipation"),
        "cost_of_transport_bound": Var((), "least cost of transport of the friction in the "
                                           "direction of motion: sum_j min_t mu_j^+ (d > 0) or "
                                           "sum_j min_t mu_j^- (d < 0)", "force"),
        "efficiency": Var((), "cost_of_transport_bound / cost_of_transport, at most 1; with "
                              "loads load_work / actuator_work", "1"),
        "load_work": Var((), "work against the loads over the limit period, -oint F~ . dx "
                             "(on a slope with the potential energy gained; gaits with loads "
                             "only)", "dissipation"),
    },
    "events": {
        "t": Var(("event_time",), "event time of the exact integrator (every period, never "
                                  "thinned by save_every)", "time"),
        "w": Var(("event_time", "state"), "state w just after the event (a closed form in "
                                          "between)", "state"),
        "x": Var(("event_time", "block"), "block position at the event", "length"),
    },
}

#: The /energy datasets and the RunResult fields they hold.
_ENERGY = {"actuator_work": "actuator_work_per_period", "dissipation": "dissipation_per_period",
           "jump_loss": "jump_loss_per_period", "balance_residual": "energy_balance_residual",
           "cost_of_transport_bound": "cost_of_transport_bound", "efficiency": "efficiency",
           "load_work": "load_work_per_period"}
#: /limit/solver: the periodic-limit solver's periods (`crawlsim.integrate.limit.solve_limit`).
SOLVER_VARIABLES: dict[str, Var] = {
    "solver_period": Var(("solver_period",), "period simulated by the periodic-limit solver, "
                                             "in order (after the plain periods of "
                                             "/convergence it started from)", "1"),
    "residual": Var(("solver_period",), "relative Poincare step |P(w) - w| / max(|P(w)|, "
                                        "scale of c) of the period: the residual |F| of the "
                                        "fixed-point equation at its start", "1"),
    "kind": Var(("solver_period",), "what the period was: a plain iteration, an accepted "
                                    "Newton step, or a Newton candidate rejected by the "
                                    "safeguard (its residual did not decrease)", "1",
                SOLVER_PERIOD_FLAGS),
}

#: Dimensions that are netCDF "dimensions but not variables": their values are the group's t.
_TIME_DIMENSIONS = {"trajectory": "time", "limit": "limit_time", "events": "event_time"}

#: Units of the numeric root attributes of a run file, by quantity.
_ATTRIBUTE_QUANTITIES = {
    "v0": "velocity", "v0_error_estimate": "velocity", "v0_error_period_iteration": "velocity",
    "v0_error_time_step": "velocity", "displacement_per_period": "length",
    "dissipation_per_period": "dissipation", "cost_of_transport": "force", "period": "time",
    "contraction_rate": "1", "periodic_from": "1", "steps_per_period": "1", "periods": "1",
    "save_every": "1", "actuator_work_per_period": "dissipation",
    "jump_loss_per_period": "dissipation", "energy_balance_residual": "dissipation",
    "cost_of_transport_bound": "force", "efficiency": "1", "load_work_per_period": "dissipation",
    "slope_angle": "angle",
}


# -- writing helpers --------------------------------------------------------------------------
class _Scales:
    """The dimension scales of one file, by name, with their netCDF dimension ids."""

    def __init__(self) -> None:
        self.scales: dict[str, h5py.Dataset] = {}

    def _register(self, name: str, ds: h5py.Dataset) -> None:
        ds.attrs["_Netcdf4Dimid"] = np.int32(len(self.scales))
        self.scales[name] = ds

    def coordinate(self, group: h5py.Group, name: str, data: Any) -> h5py.Dataset:
        """A coordinate variable: a dataset named like its dimension, holding its values."""
        ds = group.create_dataset(name, data=data, track_order=True)
        ds.make_scale(name)
        self._register(name, ds)
        return ds

    def dimension(self, group: h5py.Group, name: str, size: int, values: str) -> h5py.Dataset:
        """A dimension without values of its own (netCDF: a dimension but not a variable, so no
        storage is allocated); ``values`` names the variable that holds its values."""
        ds = group.create_dataset(name, shape=(size,), dtype=">f4", track_order=True)
        ds.make_scale(NOT_A_VARIABLE + b"%10d" % size)
        ds.attrs["long_name"] = f"dimension {name}: its values are {values}"
        ds.attrs["units"] = "1"
        self._register(name, ds)
        return ds

    def attach(self, ds: h5py.Dataset, dims: Sequence[str]) -> None:
        for axis, dim in enumerate(dims):
            if self.scales[dim] != ds:
                ds.dims[axis].attach_scale(self.scales[dim])


def _describe(ds: h5py.Dataset, var: Var, unit: str, coordinates: str = "") -> None:
    """The CF attributes of a dataset: units, long_name, flags, coordinates."""
    ds.attrs["long_name"] = var.long_name
    ds.attrs["units"] = unit
    if var.flags:
        ds.attrs["flag_values"] = np.array([v for v, _ in var.flags], dtype=ds.dtype)
        ds.attrs["flag_meanings"] = " ".join(m for _, m in var.flags)
    if var.comment:
        ds.attrs["comment"] = var.comment
    if coordinates:
        ds.attrs["coordinates"] = coordinates


def _unit(units: Units, quantity: str, crawler: bool) -> str:
    if quantity in _ROLES:
        quantity = _ROLES[quantity][0 if crawler else 1]
    return units.of(quantity)


def _target_file(target: Any) -> tuple[h5py.File, Path | None, GuardedFile | None]:
    """Open a results target: a path (a temporary file beside it, written through
    `crawlsim.io.atomic.GuardedFile` and renamed at the end) or a binary file object (an in-memory
    image: `io.BytesIO`)."""
    if isinstance(target, io.IOBase):
        return h5py.File(target, "w", track_order=True), None, None
    tmp = temporary_beside(Path(target))
    try:
        raw = GuardedFile(tmp, "w+")
        return h5py.File(raw, "w", track_order=True), tmp, raw
    except BaseException:
        discard(tmp)
        raise


@contextmanager
def _atomic_h5(path: Any) -> Iterator[h5py.File]:
    """A new HDF5 file written atomically (`crawlsim.io.atomic`), a full disk an `OutputError`."""
    with atomic_path(path) as tmp, guarded(tmp) as raw, h5py.File(raw, "w", track_order=True) as f:
        yield f


# -- run files --------------------------------------------------------------------------------
def period_rows(process: Any, record: Any, save_every: int,
                carry: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The /trajectory rows of one period's saved grid points (its first point only for period
    0), and the reaction carried to the next period (generic processes)."""
    p = process
    first = 0 if record.index == 0 else 1
    local = np.arange(first, p.steps + 1)
    global_index = record.index * p.steps + local
    sel = local[global_index % save_every == 0]
    reaction = None
    if not p.is_crawler:
        reaction, carry = _reaction_rows(record.multipliers, sel, carry)
    if sel.size == 0:
        return {}, carry
    rows = {"t": record.start + p.times[sel], "w": record.w[sel]}
    if p.is_crawler:
        rows.update(x=record.x[sel], stress=record.w[sel] + p.stress_offset[sel],
                    shape=-record.w[sel] / p.stiffness)
    if reaction is not None:
        rows["reaction"] = reaction
    return rows, carry


def _reaction_rows(multipliers: np.ndarray, sel: np.ndarray,
                   carry: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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
    sums[-1] = multipliers[starts[-1]:ends[-1]].sum(axis=0)
    sums[0] += carry
    rows[len(sel) - len(ends):] = sums
    return rows, multipliers[ends[-1]:].sum(axis=0)


class RowsRecorder:
    """The in-memory twin of `ResultsWriter` (`crawlsim.api.simulate`): it keeps the rows a
    results file would hold and writes the file only when `image` is asked for, so a result
    nobody saves costs no HDF5."""

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
        p = self.process
        n = p.polyhedron.n
        widths = {"t": (), "w": (n,)}
        widths.update({"x": (p.blocks,), "stress": (n,), "shape": (n,)} if p.is_crawler
                      else {"reaction": (p.polyhedron.m,)})
        return {name: (np.concatenate(self._rows[name]) if name in self._rows
                       else np.zeros((0,) + tail)) for name, tail in widths.items()}

    def events(self) -> dict[str, np.ndarray] | None:
        return {name: np.concatenate(rows) for name, rows in self._events.items()} or None

    def image(self, result: Any, provenance: Any, *, units: Units | None = None,
              kind: str = "crawler", unchecked_uniqueness: bool = False) -> bytes:
        """The results file of the run, written now into memory."""
        buffer = io.BytesIO()
        with ResultsWriter(buffer, self.process, save_every=self.save_every, units=units,
                           trajectory=self.keep) as writer:
            events = self.events()
            if events is not None:
                writer._append_events(tuple(events.get(name) for name in ("t", "w", "x")))
            for name, rows in self._rows.items():
                writer._append(name, np.concatenate(rows))
            writer.finish(result, provenance, kind=kind,
                          unchecked_uniqueness=unchecked_uniqueness)
        return buffer.getvalue()


class ResultsWriter:
    """Streams a run's trajectory into a results file; `finish` writes the rest and publishes.

    ``target`` is a path (written to a temporary file beside it, renamed into place by `finish`)
    or a binary file object such as `io.BytesIO` (an in-memory file: `crawlsim.api.simulate`).
    Use as a context manager: leaving the block with an exception deletes the temporary file.
    Only every ``save_every``-th grid point is written (none when ``trajectory`` is False), and
    nothing is kept in memory.
    """

    def __init__(self, target: Any, process: Any, *, save_every: int = 1,
                 units: Units | None = None, trajectory: bool = True):
        self.path = None if isinstance(target, io.IOBase) else Path(target)
        self.process = process
        self.save_every = int(save_every)
        self.units = units or Units()
        self.keep = bool(trajectory)
        self.file, self._tmp, self._raw = _target_file(target)
        self._scales = _Scales()
        self._traj = self.file.create_group("trajectory", track_order=True)
        self._sets: dict[str, h5py.Dataset] = {}
        self._columns = ["t", "w"] + (["x", "stress", "shape"] if process.is_crawler
                                      else ["reaction"])
        m, n = process.polyhedron.m, process.polyhedron.n
        self._reaction_carry = np.zeros(m)
        widths = {"t": (), "w": (n,),
                  "x": (process.blocks,), "stress": (process.blocks - 1,),
                  "shape": (process.blocks - 1,), "reaction": (m,)}
        for name in self._columns:
            tail = widths[name]
            rows = max(1, min(4096, (1 << 16) // max(1, math.prod(tail))))
            self._sets[name] = self._traj.create_dataset(
                name, shape=(0,) + tail, maxshape=(None,) + tail, dtype=float,
                chunks=(rows,) + tail, track_order=True)

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
        rows, self._reaction_carry = period_rows(self.process, record, self.save_every,
                                                 self._reaction_carry)
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
                group.create_dataset(name, shape=(0,) + rows.shape[1:],
                                     maxshape=(None,) + rows.shape[1:], dtype=float,
                                     chunks=(256,) + rows.shape[1:], track_order=True)
            ds = group[name]
            n = ds.shape[0]
            ds.resize(n + len(rows), axis=0)
            ds[n:] = rows

    def finish(self, result: Any, provenance: Any, kind: str = "crawler",
               unchecked_uniqueness: bool = False) -> None:
        """Write the analysis, the coordinates, the attributes; close and publish.

        ``unchecked_uniqueness`` records (the root attribute of that name, 0 or 1) that the
        gait opted out of an exact check of the uniqueness condition it was beyond."""
        f, p, scales, units = self.file, self.process, self._scales, self.units
        crawler = p.is_crawler
        self._write_root_coordinates()
        groups: dict[str, dict[str, Any]] = {
            "trajectory": dict(self._sets),
            "convergence": {name: getattr(result.history, name)
                            for name in RUN_VARIABLES["convergence"]},
            "limit": {name: getattr(result.limit, name) for name in
                      ("t", "w", "multipliers", "x", "shape", "stress", "slip", "slip_rate")},
            # a crawler's B and M are of size N^2 but follow from k: store k only
            "process": ({"stiffness": p.stiffness} if crawler
                        else {"normals": p.normals, "metric": p.metric}),
        }
        groups["limit"].update(step=np.arange(p.steps, dtype=np.int64), offsets=p.offsets)
        if crawler:
            groups["limit"].update(lengths=p.lengths, friction=p.friction, load=p.load)
        if "events" in f:
            groups["events"] = {name: f["events"][name] for name in f["events"]}
        if crawler and getattr(result, "actuator_work_per_period", None) is not None:
            groups["energy"] = {name: getattr(result, attr) for name, attr in _ENERGY.items()}
        for gname, values in groups.items():
            group = f.require_group(gname) if gname in f else f.create_group(gname,
                                                                           track_order=True)
            table = RUN_VARIABLES[gname]
            time_dim = _TIME_DIMENSIONS.get(gname)
            if time_dim is not None:
                scales.dimension(group, time_dim, len(values["t"]), f"/{gname}/t")
            if gname == "convergence":
                scales.coordinate(group, "period", np.asarray(values.pop("period"),
                                                              dtype=np.int64))
                _describe(group["period"], table["period"], "1")
            if gname == "limit":
                scales.coordinate(group, "step", values.pop("step"))
                _describe(group["step"], table["step"], "1")
            for name, value in values.items():
                if value is None:
                    continue
                ds = value if isinstance(value, h5py.Dataset) else group.create_dataset(
                    name, data=value, track_order=True)
                var = table[name]
                scales.attach(ds, var.dims)
                coords = "t" if time_dim is not None and name != "t" and var.dims[0] == time_dim \
                    else ""
                _describe(ds, var, _unit(units, var.quantity, crawler), coords)
        f["limit"].attrs["start"] = result.limit.start
        f["limit"].attrs["comment"] = ("the final period, taken as the periodic limit; t is "
                                       "relative to its start (attribute start, absolute time)")
        self._write_solver(result)
        self._write_root_attributes(result, provenance, kind)
        f.attrs["unchecked_uniqueness"] = int(bool(unchecked_uniqueness))
        f.close()
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
        residuals = getattr(result, "limit_residuals", None)
        kinds = getattr(result, "limit_kinds", None)
        residuals = np.zeros(0) if residuals is None else np.asarray(residuals, dtype=float)
        kinds = (np.zeros(len(residuals), dtype=np.int8) if kinds is None
                 else np.asarray(kinds, dtype=np.int8))
        ds = self._scales.coordinate(group, "solver_period",
                                     np.arange(len(residuals), dtype=np.int64))
        _describe(ds, SOLVER_VARIABLES["solver_period"], "1")
        for name, data in (("residual", residuals), ("kind", kinds)):
            ds = group.create_dataset(name, data=data, track_order=True)
            self._scales.attach(ds, ("solver_period",))
            _describe(ds, SOLVER_VARIABLES[name], "1")
        a = group.attrs
        a["method"] = str(getattr(result, "limit_method", "iterate"))
        a["newton_steps"] = int(getattr(result, "limit_newton_steps", 0))
        a["periods"] = int(getattr(result, "limit_periods", 0))
        for key in ("jacobian_rate", "contraction_rate"):
            value = getattr(result, key, None)
            a[key] = np.nan if value is None else float(value)
        a["comment"] = (
            "how the periodic limit was found. method newton: the periodic-limit solver "
            "(safeguarded semismooth Newton on F(w) = P(w) - w, P the period map, Jacobian from "
            "the active sets the period visited) found it from the last state of /convergence "
            "and verified it by a plain period, in `periods` periods (solver_period), "
            "`newton_steps` of them accepted Newton steps; method iterate: the periods of "
            "/convergence reached it themselves (solver_period empty). jacobian_rate: the "
            "largest |eigenvalue| below 1 of the Jacobian at the limit (NaN when not formed); "
            "contraction_rate: fitted to the Poincare steps of /convergence (NaN for "
            "finite-time convergence)")

    def _write_root_coordinates(self) -> None:
        p, f, scales = self.process, self.file, self._scales
        n, m = p.polyhedron.n, p.polyhedron.m
        values: dict[str, Any] = {"state": np.arange(n), "state_column": np.arange(n),
                                  "constraint": np.arange(m)}
        if p.is_crawler:
            N = p.blocks
            values.update(block=np.arange(1, N + 1), link=np.arange(1, N))
        for name in ("block", "link", "state", "state_column", "constraint"):
            if name in values:
                scales.coordinate(f, name, np.asarray(values[name], dtype=np.int64))
                _describe(f[name], ROOT_COORDINATES[name], "1")
        if p.is_crawler:
            N = p.blocks
            aux = {"constraint_block": np.tile(np.arange(1, N + 1), 2).astype(np.int64),
                   "constraint_limit": np.repeat(np.array([1, -1], dtype=np.int8), N)}
            for name, data in aux.items():
                ds = f.create_dataset(name, data=data, track_order=True)
                scales.attach(ds, ("constraint",))
                _describe(ds, ROOT_COORDINATES[name], "1")
            # xarray reads a global `coordinates` attribute as the root's auxiliary coordinates
            f.attrs["coordinates"] = "constraint_block constraint_limit"

    def _write_root_attributes(self, result: Any, provenance: Any, kind: str) -> None:
        a, units = self.file.attrs, self.units
        a["title"] = f"crawlsim run of {result.name}"
        a["comment"] = _RUN_COMMENT
        a["crawlsim_version"] = __version__
        a["format_version"] = FORMAT_VERSION
        a["kind"] = kind
        a["name"] = result.name
        a["convergence"] = str(result.convergence)
        a["periodic_from"] = -1 if result.periodic_from is None else int(result.periodic_from)
        summary = result.summary()
        for key in ("v0", "v0_error_estimate", "v0_error_period_iteration", "v0_error_time_step",
                    "contraction_rate", "displacement_per_period", "dissipation_per_period",
                    "cost_of_transport", "actuator_work_per_period", "jump_loss_per_period",
                    "energy_balance_residual", "cost_of_transport_bound", "efficiency",
                    "load_work_per_period"):
            value = summary.get(key, getattr(result, key, None))
            a[key] = np.nan if value is None else float(value)
        # the loads (docs/model.md §6): the effective document (gait_yaml) holds the whole
        # loads: block; the angle in degrees is repeated here, NaN without a slope
        angle = self.process.slope_angle
        a["slope_angle"] = np.nan if angle is None else float(angle)
        a["period"] = result.period
        a["steps_per_period"] = result.steps_per_period
        a["periods"] = result.periods
        a["save_every"] = self.save_every if self.keep else 0
        a["units_json"] = json.dumps(units.to_json())
        a["attribute_units_json"] = json.dumps(
            {key: units.of(q) for key, q in _ATTRIBUTE_QUANTITIES.items()})
        for key, value in provenance.attrs().items():
            a[key] = value
        a["summary_json"] = json.dumps(_json_ready(summary))

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


def _json_ready(summary: Mapping[str, Any]) -> dict[str, Any]:
    """NaN and infinities (not JSON) become null."""
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in summary.items()}


# -- reading ----------------------------------------------------------------------------------
def _open(path: Path, what: str) -> h5py.File:
    """Open an HDF5 file for reading, or raise `ResultsFileError` saying why it can't be."""
    if not path.exists():
        raise ResultsFileError(f"{path}: no such {what}")
    try:
        return h5py.File(path, "r")
    except OSError as exc:
        raise ResultsFileError(f"{path}: not an HDF5 file ({exc})") from None


def _check_version(f: h5py.File, path: Any) -> int:
    if "format_version" not in f.attrs:
        raise ResultsFileError(f"{path}: not a crawlsim results file (no format_version "
                               "attribute)")
    version = int(_plain(f.attrs["format_version"]))
    if version not in READABLE_VERSIONS:
        raise ResultsFileError(f"{path}: format_version {version} was written by a newer crawlsim "
                               f"({_plain(f.attrs.get('crawlsim_version', '?'))}); this crawlsim "
                               f"({__version__}) reads format_version "
                               f"{', '.join(map(str, READABLE_VERSIONS))}: upgrade crawlsim")
    return version


def _variables(group: h5py.Group) -> dict[str, np.ndarray]:
    """The group's datasets, without the netCDF dimensions that are not variables."""
    out = {}
    for name, ds in group.items():
        if not isinstance(ds, h5py.Dataset):
            continue
        name_attr = ds.attrs.get("NAME", b"")
        if isinstance(name_attr, str):
            name_attr = name_attr.encode()
        if NOT_A_VARIABLE in bytes(name_attr):
            continue
        out[name] = ds[()]
    return out


def read_results(path: Any) -> dict[str, Any]:
    """Load a results file (format_version 1 or 2) into plain dicts of arrays: ``{"attrs",
    "trajectory", "convergence", "limit"}`` and the groups' attributes as ``"<group>_attrs"``,
    plus ``"process"``, ``"events"`` and ``"energy"`` when the file has them. Format 2 adds
    ``"coordinates"`` (the root coordinate variables: block, link, constraint, ...) and
    ``/limit/step``; files that record the periodic-limit solver add ``"limit_solver"`` and
    ``"limit_solver_attrs"`` (``/limit/solver``). Raises `ResultsFileError` naming what is
    missing."""
    source = path
    if isinstance(path, io.IOBase):
        f = h5py.File(path, "r")
    else:
        source = Path(path)
        f = _open(source, "results file")
    with f:
        _check_version(f, source)
        if _plain(f.attrs.get("kind", "")) == "sweep":
            raise ResultsFileError(f"{source}: a sweep file, not a run's results file: read it "
                                   "with crawlsim.study.sweep.read_table")
        if _plain(f.attrs.get("kind", "")) == "optimization":
            raise ResultsFileError(f"{source}: an optimisation file, not a run's results file: "
                                   "read it with crawlsim.io.hdf5.read_optimization")
        out: dict[str, Any] = {"attrs": {k: _plain(v) for k, v in f.attrs.items()}}
        for group in ("trajectory", "convergence", "limit"):
            if group not in f:
                raise ResultsFileError(f"{source}: missing group /{group}")
            out[group] = _variables(f[group])
            out[group + "_attrs"] = {k: _plain(v) for k, v in f[group].attrs.items()}
        for group in ("process", "events", "energy"):
            if group in f:
                out[group] = _variables(f[group])
        if "solver" in f["limit"]:  # files since the periodic-limit solver
            out["limit_solver"] = _variables(f["limit"]["solver"])
            out["limit_solver_attrs"] = {k: _plain(v) for k, v in f["limit"]["solver"].attrs.items()}
        process = out.get("process", {})
        if "stiffness" in process and "normals" not in process:
            chain = ChainPolyhedron(process["stiffness"], 1.0)
            process.update(normals=chain.dense_normals(), metric=chain.dense_metric())
        coordinates = _variables(f)
        if coordinates:
            out["coordinates"] = coordinates
    return out


def read_provenance(path: Any) -> dict[str, Any]:
    """What a rerun needs from a run's results file: ``kind``, ``name``, ``gait_yaml`` (the
    effective document), ``integrator_settings`` and ``save_every``.

    Only format_version 2 files record the effective document and the integrator's settings; a
    format_version 1 file, or a sweep file, is refused with a `ResultsFileError` saying so.
    """
    path = Path(path)
    with _open(path, "results file") as f:
        version = _check_version(f, path)
        a = {k: _plain(v) for k, v in f.attrs.items()}
    if a.get("kind") == "optimization":
        raise ResultsFileError(f"{path}: an optimisation file; --from reruns a run's results "
                               "file. Write the best gait with crawlsim optimize --write-best "
                               "BEST.yaml and run that (its command line was: "
                               f"{a.get('command_line', 'not recorded')})")
    if a.get("kind") == "sweep":
        raise ResultsFileError(f"{path}: a sweep file; --from reruns a run's results file (the "
                               f"sweep's command line was: {a.get('command_line', 'not recorded')})")
    if version < 2 or "integrator_json" not in a:
        raise ResultsFileError(f"{path}: format_version {version} files do not record the "
                               "command-line overrides or the integrator, so the run cannot be "
                               "reproduced from it; rerun from the gait file (crawlsim run "
                               "GAIT.yaml with the same options)")
    return {"kind": a["kind"], "name": a["name"], "gait_yaml": a["gait_yaml"],
            "integrator_settings": json.loads(a["integrator_json"]),
            "save_every": int(a.get("save_every", 1)) or 1, "format_version": version}


def read_attrs(path: Any) -> dict[str, Any]:
    """The root attributes of a results or sweep file (a path or a file object)."""
    if isinstance(path, io.IOBase):
        with h5py.File(path, "r") as f:
            return {k: _plain(v) for k, v in f.attrs.items()}
    with _open(Path(path), "results file") as f:
        return {k: _plain(v) for k, v in f.attrs.items()}


def _plain(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.generic):
        return value.item()
    return value


# -- sweep files ------------------------------------------------------------------------------
#: /grid and /results variables of a sweep file besides the swept paths.
SWEEP_VARIABLES: dict[str, Var] = {
    "v0": Var(("point",), "asymptotic average velocity v0 (NaN where the point failed)",
              "velocity"),
    "displacement_per_period": Var(("point",), "barycentre displacement per period of the "
                                               "limit period", "length"),
    "convergence": Var(("point",), "how the point reached its periodic regime", "1",
                       CONVERGENCE_FLAGS),
    "periods": Var(("point",), "periods simulated", "1"),
    "status": Var(("point",), "outcome of the point (message says why it failed)", "1",
                  STATUS_FLAGS),
    "message": Var(("point",), "the reason of a failure, else empty", "1"),
    "point": Var(("point",), "grid index of the point (C order over the swept paths)", "1"),
    "steps": Var(("point",), "catch-up steps simulated (periods x steps per period)", "1"),
    "v0_error_estimate": Var(("point",), "error bound of v0", "velocity"),
    "dissipation_per_period": Var(("point",), "energy dissipated by friction in the limit "
                                              "period", "dissipation"),
    "cost_of_transport": Var(("point",), "dissipation per distance travelled (NaN without net "
                                         "motion)", "force"),
    "integrator": Var(("point",), "integrator of the point: catch-up or exact", "1"),
    "limit": Var(("point",), "how the periodic limit was found: newton (periodic-limit "
                             "solver) or iterate (plain periods)", "1"),
    "newton_steps": Var(("point",), "Newton iterations of the periodic-limit solver (-1: the "
                                    "point did not run)", "1"),
}
#: Numeric columns written on the grid when a table has them (files of crawlsim 0.1 do not).
_OPTIONAL_GRID = ("v0_error_estimate", "dissipation_per_period", "cost_of_transport")


_WORDS = {"convergence": "finite-time, asymptotic or not-converged; empty when the point failed",
          "status": "ok, not-converged, invalid or failed"}


def axis_name(path: str, taken: Sequence[str] = ()) -> str:
    """A netCDF- and Python-safe name for a swept path: ``links.*.amplitude`` ->
    ``links_all_amplitude``, ``links.1.phase`` -> ``links_1_phase`` (the path itself is kept in
    the attribute ``path``). Names already ``taken`` get a numeric suffix."""
    name = re.sub(r"[^A-Za-z0-9_]", "_", path.replace("*", "all"))
    if not name or not (name[0].isalpha()):
        name = "p_" + name
    base, k = name, 2
    while name in taken or name in SWEEP_VARIABLES:
        name, k = f"{base}_{k}", k + 1
    return name


def _flag_codes(values: Any, flags: tuple[tuple[int, str], ...]) -> np.ndarray:
    """Strings (``finite-time``, ``not-converged``, "") as their CF flag codes; "" -> -1."""
    code = {m: v for v, m in flags}
    return np.array([code.get(str(s).replace("-", "_"), -1) if s else -1 for s in values],
                    dtype=np.int8)


def write_sweep(path: Any, *, paths: Sequence[str], axes: Sequence[Any], points: Any,
                columns: Mapping[str, Any], gait_yaml: str, source: str, shard: str,
                steps: Any, dimensions: Sequence[int] | None = None) -> None:
    """Write a sweep table atomically (`crawlsim.io.atomic`). ``dimensions`` gives the grid
    dimension of each swept path (linked paths share one; default: each path its own)."""
    dims = list(range(len(paths))) if dimensions is None else [int(d) for d in dimensions]
    if isinstance(path, io.IOBase):
        with h5py.File(path, "w", track_order=True) as f:
            _write_sweep(f, paths, axes, points, columns, gait_yaml, source, shard, steps, dims)
        return
    with _atomic_h5(path) as f:
        _write_sweep(f, paths, axes, points, columns, gait_yaml, source, shard, steps, dims)


def _write_sweep(f: h5py.File, paths: Sequence[str], axes: Sequence[Any], points: Any,
                 columns: Mapping[str, Any], gait_yaml: str, source: str, shard: str,
                 steps: Any, dims: Sequence[int]) -> None:
    import yaml

    from crawlsim.gait.document import Simulation
    from crawlsim.io import provenance

    document = yaml.safe_load(gait_yaml) or {}
    kind = document.get("kind", "crawler")
    units = Units.from_block(document.get("units"))
    # the integrator the rows ran (a shard or a grid of invalid points has none: the document's,
    # with the default of `crawlsim.gait.document.Simulation`); several, comma-separated, if they differ
    used = sorted({str(s) for s in columns.get("integrator", ())} - {""})
    simulation = document.get("simulation")
    if not isinstance(simulation, dict):
        simulation = {}
    integrator = ",".join(used) if used else str(simulation.get("integrator", Simulation.integrator))
    names: list[str] = []
    for p in paths:
        names.append(axis_name(p, names))
    # one grid dimension per distinct entry of dims, named after its first path; linked paths
    # are auxiliary coordinates along it
    first = {d: i for i, d in reversed(list(enumerate(dims)))}
    order = sorted(first, key=lambda d: first[d])
    dim_names = [names[first[d]] for d in order]
    shape = tuple(len(axes[first[d]]) for d in order)
    points = np.asarray(points, dtype=np.int64)

    a = f.attrs
    a["title"] = "crawlsim parameter sweep"
    a["comment"] = _SWEEP_COMMENT
    a["crawlsim_version"] = __version__
    a["format_version"] = FORMAT_VERSION
    a["kind"] = "sweep"
    a["gait_yaml"] = gait_yaml
    a["source"] = str(source)
    a["paths"] = json.dumps(list(paths))
    a["axis_names"] = json.dumps(names)
    a["shape"] = np.array(shape, dtype=np.int64)
    a["shard"] = shard
    a["dimensions"] = json.dumps([order.index(d) for d in dims])
    a["units_json"] = json.dumps(units.to_json())
    a["integrator"] = integrator
    a["sweep_json"] = json.dumps([{"path": p, "name": n, "values": np.asarray(v).tolist()}
                                  for p, n, v in zip(paths, names, axes)])
    for key, value in provenance.session_attrs().items():
        a[key] = value

    scales = _Scales()
    text = h5py.string_dtype()

    def axis_var(path: str) -> Var:
        quantity = path_quantity(kind, tuple(int(k) if k.isdigit() else k
                                             for k in path.split(".")))
        return Var((), f"swept value of {path}", quantity)

    grid = f.create_group("grid", track_order=True)
    grid.attrs["comment"] = ("the sweep's numbers on the grid; points not computed (another "
                             "shard's) are NaN, status not_computed")
    for p, n, values, d in zip(paths, names, axes, dims):
        if n in dim_names:
            ds = scales.coordinate(grid, n, np.asarray(values))
        else:  # a path linked to another: a coordinate along that path's dimension
            ds = grid.create_dataset(n, data=np.asarray(values), track_order=True)
            scales.attach(ds, (names[first[d]],))
        _describe(ds, axis_var(p), units.of(axis_var(p).quantity))
        ds.attrs["path"] = p
    full = np.zeros(math.prod(shape), dtype=bool)
    full[points] = True
    gridded = ["v0", "displacement_per_period", "convergence", "status", "periods", "steps"]
    gridded += [c for c in _OPTIONAL_GRID if c in columns]
    for name in gridded:
        values = steps if name == "steps" else columns[name]
        var = SWEEP_VARIABLES[name]
        if var.flags:
            data = np.full(full.size, -1, dtype=np.int8)
            data[points] = _flag_codes(values, var.flags)
        elif name in ("periods", "steps"):
            data = np.zeros(full.size, dtype=np.int64)
            data[points] = np.asarray(values, dtype=np.int64)
        else:
            data = np.full(full.size, np.nan)
            data[points] = np.asarray(values, dtype=float)
        ds = grid.create_dataset(name, data=data.reshape(shape), track_order=True)
        scales.attach(ds, dim_names)
        _describe(ds, var, units.of(var.quantity))
    messages = np.full(full.size, "", dtype=object)
    messages[points] = np.asarray(columns["message"], dtype=object).astype(str)
    ds = grid.create_dataset("message", data=messages.reshape(shape).tolist(), dtype=text,
                             shape=shape, track_order=True)
    scales.attach(ds, dim_names)
    _describe(ds, SWEEP_VARIABLES["message"], "1")

    results = f.create_group("results", track_order=True)
    results.attrs["comment"] = "one entry per computed point, in grid order"
    ds = scales.coordinate(results, "point", points)
    _describe(ds, SWEEP_VARIABLES["point"], "1")
    for p, n in zip(paths, names):
        ds = results.create_dataset(n, data=np.asarray(columns[p]), track_order=True)
        scales.attach(ds, ("point",))
        _describe(ds, axis_var(p), units.of(axis_var(p).quantity))
        ds.attrs["path"] = p
    table = ["v0", "displacement_per_period", "convergence", "periods", "status", "message"]
    table += [c for c in (*_OPTIONAL_GRID, "integrator", "limit", "newton_steps")
              if c in columns]
    for name, values in [(k, columns[k]) for k in table] + [("steps", steps)]:
        values = np.asarray(values)
        if values.dtype == object or values.dtype.kind in "US":
            ds = results.create_dataset(name, data=values.astype(str).tolist(), dtype=text,
                                        shape=values.shape, track_order=True)
        else:
            ds = results.create_dataset(name, data=values, track_order=True)
        var = SWEEP_VARIABLES[name]
        scales.attach(ds, ("point",))
        # the table keeps the words (as in the CSV table); /grid has the CF flags
        _describe(ds, Var(var.dims, var.long_name, var.quantity, comment=_WORDS.get(name, "")),
                  units.of(var.quantity))
    _write_derivatives(grid, results, scales, columns, units, kind, names, points, shape,
                       dim_names)


def _write_derivatives(grid: h5py.Group, results: h5py.Group, scales: _Scales,
                       columns: Mapping[str, Any], units: Units, kind: str,
                       names: Sequence[str], points: np.ndarray, shape: tuple[int, ...],
                       dim_names: Sequence[str]) -> None:
    """The dv0/dPATH columns of ``--sensitivity`` (`crawlsim.analysis.sensitivity_sweep`), on
    the grid and in the table, with the units of v0 over PATH; the column in ``column``."""
    from crawlsim.analysis.sensitivity_sweep import variables

    for column, name, unit, long_name in variables(columns, units, kind,
                                                   [*names, *SWEEP_VARIABLES]):
        values = np.asarray(columns[column], dtype=float)
        data = np.full(math.prod(shape), np.nan)
        data[points] = values
        for group, array, dims in ((grid, data.reshape(shape), dim_names),
                                   (results, values, ("point",))):
            ds = group.create_dataset(name, data=array, track_order=True)
            scales.attach(ds, dims)
            _describe(ds, Var(tuple(dims), long_name, "1"), unit)
            ds.attrs["column"] = column


def read_sweep(path: Any) -> dict[str, Any]:
    """A sweep file (format_version 1 or 2) as ``{paths, axes, points, steps, columns,
    gait_yaml, source, shard}``; format 2 adds ``attrs`` (every root attribute).

    Raises `ResultsFileError` naming what is missing when the file is not a sweep file.
    """
    path = Path(path)
    with _open(path, "sweep file") as f:
        if _plain(f.attrs.get("kind", "")) != "sweep":
            raise ResultsFileError(f"{path}: not a crawlsim sweep file (attribute kind is not "
                                   "'sweep')")
        version = _check_version(f, path)
        paths = json.loads(_plain(f.attrs["paths"]))
        if version == 1:
            names, axes_group = list(paths), "axes"
        else:
            names, axes_group = json.loads(_plain(f.attrs["axis_names"])), "grid"
        for group in (axes_group, "results"):
            if group not in f:
                raise ResultsFileError(f"{path}: missing group /{group}")
        missing = [n for n in names if n not in f[axes_group]]
        if missing:
            raise ResultsFileError(f"{path}: missing /{axes_group}/{missing[0]}")
        results = f["results"]
        columns = {}
        for name, key in [*zip(names, paths)] + [(c, c) for c in (
                "v0", "displacement_per_period", "convergence", "periods", "status", "message",
                "point", "steps")]:
            if name not in results:
                raise ResultsFileError(f"{path}: missing /results/{name}")
            ds = results[name]
            columns[key] = (np.array(ds.asstr()[()], dtype=object)
                            if h5py.check_string_dtype(ds.dtype) else ds[()])
        for name in results:  # later columns (v0_error_estimate, ...), when the file has them
            if name not in columns and name not in names:
                ds = results[name]
                columns[_plain(ds.attrs.get("column", name))] = (
                    np.array(ds.asstr()[()], dtype=object)
                                 if h5py.check_string_dtype(ds.dtype) else ds[()])
        dimensions = (json.loads(_plain(f.attrs["dimensions"])) if "dimensions" in f.attrs
                      else None)
        out = dict(paths=paths, axes=[f[axes_group][n][()] for n in names],
                   points=columns.pop("point"), steps=columns.pop("steps"), columns=columns,
                   gait_yaml=_plain(f.attrs["gait_yaml"]), source=_plain(f.attrs["source"]),
                   shard=_plain(f.attrs["shard"]), dimensions=dimensions)
        if version >= 2:
            out["attrs"] = {k: _plain(v) for k, v in f.attrs.items()}
        return out


# --------------------------------------------------------------------------------------------
# A summary of any results file (`crawlsim info`).

#: Root attributes that `describe` reports under their own names (the others, provenance
#: included, are listed under "attributes" when they are short).
_DESCRIBED = {"crawlsim_version", "format_version", "kind", "name", "convergence",
              "periodic_from", "v0", "contraction_rate", "v0_error_estimate",
              "displacement_per_period", "dissipation_per_period", "cost_of_transport",
              "period", "steps_per_period", "periods", "save_every", "gait_yaml",
              "summary_json", "source", "paths", "shape", "shard", "dimensions", "integrator"}


#: Root attributes of an optimisation file that `describe` reports under its own keys (or that
#: repeat them).
_OPTIMIZATION_DESCRIBED = {"objective", "constraints_json", "free_json", "seed", "evaluations",
                           "max_evaluations", "best_json", "best_feasible", "best_value",
                           "best_v0", "best_cost_of_transport", "axis_names", "title",
                           "objective_quantity", "objective_sense", "gait_file"}


def describe(path: Any) -> dict[str, Any]:
    """What a results file holds, without reading its trajectories: ``file_kind`` (``run`` or
    ``sweep``), the identity and outcome of the run or the grid and the counts of statuses of the
    sweep, and the other short root attributes (provenance). Raises `ResultsFileError` for a file
    that is not a crawlsim results file."""
    path = Path(path)
    with _open(path, "results file") as f:
        attrs = {k: _plain(v) for k, v in f.attrs.items()}
        if "format_version" not in attrs:
            raise ResultsFileError(f"{path}: not a crawlsim results file (no format_version "
                                   "attribute)")
        described = _DESCRIBED | (_OPTIMIZATION_DESCRIBED if attrs.get("kind") == "optimization"
                                  else set())
        other = {k: v for k, v in attrs.items()
                 if k not in described and (not isinstance(v, str) or len(v) <= 200)
                 and np.ndim(v) == 0}
        if "provenance" in f:
            other.update({k: _plain(v) for k, v in f["provenance"].attrs.items()})
        out = {"file": str(path), "crawlsim_version": attrs.get("crawlsim_version"),
               "format_version": attrs.get("format_version"), "attributes": other}
        if attrs.get("kind") == "sweep":
            out.update(_describe_sweep(path, f, attrs))
        elif attrs.get("kind") == "optimization":
            out.update(_describe_optimization(path, f, attrs))
        else:
            out.update(_describe_run(path, f, attrs))
    return out


def _number(value: Any) -> Any:
    """NaN and -1 (null in the attributes) become None."""
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return None
    return value


def _describe_run(path: Path, f: h5py.File, attrs: dict[str, Any]) -> dict[str, Any]:
    try:
        summary = json.loads(attrs.get("summary_json", "{}"))
    except json.JSONDecodeError:
        summary = {}
    periodic_from = attrs.get("periodic_from", -1)
    solver = ({k: _plain(v) for k, v in f["limit"]["solver"].attrs.items()}
              if "limit" in f and "solver" in f["limit"] else {})
    return {
        "file_kind": "run", "kind": attrs.get("kind", "crawler"), "name": attrs.get("name"),
        "integrator": attrs.get("integrator", summary.get("integrator")),
        "v0": _number(attrs.get("v0")), "v0_error_estimate": _number(attrs.get("v0_error_estimate")),
        "convergence": attrs.get("convergence"),
        "periodic_from": None if periodic_from is None or periodic_from < 0 else periodic_from,
        "contraction_rate": _number(attrs.get("contraction_rate")),
        "periods": attrs.get("periods"), "steps_per_period": attrs.get("steps_per_period"),
        "period": attrs.get("period"),
        "displacement_per_period": _number(attrs.get("displacement_per_period")),
        "dissipation_per_period": _number(attrs.get("dissipation_per_period")),
        "cost_of_transport": _number(attrs.get("cost_of_transport")),
        "final_poincare_step": summary.get("final_poincare_step"),
        "limit_method": solver.get("method", summary.get("limit_method")),
        "limit_newton_steps": solver.get("newton_steps", summary.get("limit_newton_steps")),
        "limit_periods": solver.get("periods", summary.get("limit_periods")),
        "jacobian_rate": _number(solver.get("jacobian_rate", summary.get("jacobian_rate"))),
    }


def _describe_sweep(path: Path, f: h5py.File, attrs: dict[str, Any]) -> dict[str, Any]:
    if "results" not in f or "status" not in f["results"]:
        raise ResultsFileError(f"{path}: missing /results/status")
    results = f["results"]
    paths = json.loads(attrs.get("paths", "[]"))
    dims = json.loads(attrs["dimensions"]) if "dimensions" in attrs else list(range(len(paths)))
    grouped: dict[int, list[str]] = {}
    for p, d in zip(paths, dims):
        grouped.setdefault(int(d), []).append(p)
    if "axis_names" in attrs:  # format 2: the values are the coordinates of /grid
        names = json.loads(attrs["axis_names"])
        values = {p: f["grid"][n][()] for p, n in zip(paths, names)
                  if "grid" in f and n in f["grid"]}
    else:
        values = {p: f["axes"][p][()] for p in paths if "axes" in f and p in f["axes"]}
    grid = [{"paths": grouped[d], "values": len(values.get(grouped[d][0], ())),
             "min": _number(float(np.min(values[grouped[d][0]]))) if grouped[d][0] in values
             else None,
             "max": _number(float(np.max(values[grouped[d][0]]))) if grouped[d][0] in values
             else None} for d in sorted(grouped)]
    status = [str(s) for s in results["status"].asstr()[()]]
    counts: dict[str, int] = {}
    for s in status:
        counts[s] = counts.get(s, 0) + 1
    v0 = results["v0"][()] if "v0" in results else np.array([])
    ok = np.array([s == "ok" for s in status], dtype=bool)
    good = v0[ok & np.isfinite(v0)] if v0.size == ok.size else np.array([])
    integrators = (sorted({str(s) for s in results["integrator"].asstr()[()]} - {""})
                   if "integrator" in results else [])
    import yaml

    try:
        document = yaml.safe_load(attrs.get("gait_yaml", "")) or {}
    except yaml.YAMLError:
        document = {}
    name = document.get("name") if isinstance(document, dict) else None
    return {
        "file_kind": "sweep", "kind": "sweep",
        "name": name or Path(str(attrs.get("source", path))).stem,
        "source": attrs.get("source"),
        "shard": attrs.get("shard") or None, "grid": grid,
        "points": len(status), "statuses": counts,
        "integrator": ", ".join(integrators) or None,
        "v0_min": float(good.min()) if good.size else None,
        "v0_max": float(good.max()) if good.size else None,
    }


# --------------------------------------------------------------------------------------------
# Optimisation files (format_version 2): crawlsim optimize.

_OPTIMIZATION_COMMENT = (
    "Results of crawlsim optimize. Evaluation i is the gait document gait_yaml with the free "
    "parameters (attribute free_json; /evaluations/<name>, the path in attribute path) set to "
    "its values; /evaluations holds every evaluated point in evaluation order with the columns "
    "of a sweep table, /history the best value of each run after every batch, /runs the "
    "single-objective runs (one, or the ends and epsilon-constraint runs of a Pareto front), "
    "/front the non-dominated points of v0 against cost_of_transport (--pareto). Units: "
    "units_json; every dataset has units and long_name.")

#: Units of the optimisable quantities (`crawlsim.study.optimize.QUANTITIES`).
OBJECTIVE_QUANTITIES = {"v0": "velocity", "cost_of_transport": "force",
                        "dissipation_per_period": "dissipation",
                        "displacement_per_period": "length"}

STAGE_FLAGS = ((0, "initial"), (1, "generation"), (2, "polish"))

OPTIMIZATION_VARIABLES: dict[str, dict[str, Var]] = {
    "evaluations": {
        "evaluation": Var(("evaluation",), "evaluation number, in the order the points were "
                                           "simulated", "1"),
        "run": Var(("evaluation",), "the run that asked for the point (see /runs)", "1"),
        "stage": Var(("evaluation",), "what asked for the point: the first population of its "
                                      "run, a generation of differential evolution, or a poll "
                                      "of the pattern search", "1", STAGE_FLAGS),
        "batch": Var(("evaluation",), "the batch the point was simulated in (see /history)",
                     "1"),
        "feasible": Var(("evaluation",), "1 when the point runs and satisfies the constraints "
                                         "of its run, else 0", "1"),
        "constraint_violation": Var(("evaluation",), "total violation of the constraints of "
                                                     "its run (0 when satisfied, inf when the "
                                                     "point does not run)", "1"),
    },
    "history": {
        "batch": Var(("batch",), "batch number (a generation, or a poll of the pattern "
                                 "search)", "1"),
        "run": Var(("batch",), "the run of the batch (see /runs)", "1"),
        "stage": Var(("batch",), "what the batch was", "1", STAGE_FLAGS),
        "evaluations": Var(("batch",), "points simulated so far, all runs", "1"),
        "best": Var(("batch",), "best value of the run's objective so far (NaN while no point "
                                "of the run is feasible)", "objective"),
        "best_evaluation": Var(("batch",), "evaluation number of the run's best point so far "
                                           "(-1 before any)", "1"),
        "feasible": Var(("batch",), "1 when the run's best point so far is feasible", "1"),
        "step": Var(("batch",), "step of the pattern search after the batch, in units of the "
                                "box width (NaN for differential evolution)", "1"),
        "hypervolume": Var(("batch",), "area dominated by the Pareto front of the points "
                                       "evaluated so far, from the nadir of the final front "
                                       "(--pareto)", "dissipation_rate"),
    },
    "runs": {
        "run": Var(("run",), "run number", "1"),
        "objective": Var(("run",), "objective of the run", "1"),
        "constraints": Var(("run",), "constraints of the run, comma separated", "1"),
        "epsilon": Var(("run",), "lower bound on v0 of an epsilon-constraint run (NaN "
                                 "otherwise)", "velocity"),
        "best_evaluation": Var(("run",), "evaluation number of the run's optimum", "1"),
        "feasible": Var(("run",), "1 when the run's optimum satisfies its constraints", "1"),
        "evaluations": Var(("run",), "points simulated for the run", "1"),
        "stop": Var(("run",), "why the run stopped", "1"),
    },
    "front": {
        "front_point": Var(("front_point",), "point of the Pareto front, by increasing v0",
                           "1"),
        "evaluation": Var(("front_point",), "evaluation number of the point", "1"),
        "v0": Var(("front_point",), "asymptotic average velocity v0", "velocity"),
        "cost_of_transport": Var(("front_point",), "cost of transport", "force"),
        "chosen": Var(("front_point",), "1 for the optimum of a run (an end of the front or an "
                                        "epsilon-constraint point)", "1"),
    },
}


def write_optimization(path: Any, result: Any) -> None:
    """Write a `crawlsim.study.optimize.OptimizationResult` atomically (`crawlsim.io.atomic`); ``path``
    may be a binary file object (an in-memory image)."""
    if isinstance(path, io.IOBase):
        with h5py.File(path, "w", track_order=True) as f:
            _write_optimization(f, result)
        return
    with _atomic_h5(path) as f:
        _write_optimization(f, result)


def _write_optimization(f: h5py.File, result: Any) -> None:
    from crawlsim.io import provenance

    problem, method = result.problem, result.method
    base = problem.base
    document = base.document
    units = Units.from_block(document.get("units"))
    objective = problem.objective
    names: list[str] = []
    for p in problem.paths:
        names.append(axis_name(p, [*names, *OPTIMIZATION_VARIABLES["evaluations"]]))
    best = result.evaluations[result.best]

    a = f.attrs
    a["title"] = f"crawlsim optimisation of {base.name}"
    a["comment"] = _OPTIMIZATION_COMMENT
    a["crawlsim_version"] = __version__
    a["format_version"] = FORMAT_VERSION
    a["kind"] = "optimization"
    a["name"] = base.name
    a["source"] = str(base.source)
    a["gait_yaml"] = provenance.effective_yaml(document)
    a["gait_file"] = str(base.source)
    a["gait_file_text"] = str(base.source_text)
    a["integrator"] = base.simulation.integrator
    a["integrator_json"] = json.dumps({"integrator": base.simulation.integrator,
                                       "steps_per_period": base.simulation.steps_per_period,
                                       "max_periods": base.simulation.max_periods,
                                       "tolerance": base.simulation.tolerance})
    a["paths"] = json.dumps(list(problem.paths))
    a["axis_names"] = json.dumps(names)
    a["free_json"] = json.dumps([{"path": fr.path, "name": n, "lo": fr.lo, "hi": fr.hi}
                                 for fr, n in zip(problem.free, names)])
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

    scales = _Scales()
    text = h5py.string_dtype()
    objective_unit = units.of(OBJECTIVE_QUANTITIES[objective.quantity])

    def unit_of(var: Var) -> str:
        if var.quantity == "objective":
            return "1" if problem.pareto else objective_unit
        if var.quantity == "dissipation_rate":  # v0 times a cost of transport
            from fractions import Fraction

            return units.compose({"force": Fraction(1), "length": Fraction(1),
                                  "time": Fraction(-1)})
        return units.of(var.quantity)

    def column(group: h5py.Group, name: str, values: Any, var: Var, dim: str) -> None:
        values = np.asarray(values)
        if values.dtype == object or values.dtype.kind in "US":
            ds = group.create_dataset(name, data=values.astype(str).tolist(), dtype=text,
                                      shape=values.shape, track_order=True)
        else:
            ds = group.create_dataset(name, data=values, track_order=True)
        scales.attach(ds, (dim,))
        _describe(ds, Var((dim,), var.long_name, var.quantity, var.flags, var.comment),
                  unit_of(var))

    def free_column(group: h5py.Group, name: str, path: str, values: Any, dim: str) -> None:
        quantity = path_quantity("crawler", tuple(int(k) if k.isdigit() else k
                                                  for k in path.split(".")))
        ds = group.create_dataset(name, data=np.asarray(values, dtype=float), track_order=True)
        scales.attach(ds, (dim,))
        _describe(ds, Var((dim,), f"free parameter {path}", quantity), units.of(quantity))
        ds.attrs["path"] = path

    # /evaluations: the sweep table's columns, then where each point came from
    evals = result.evaluations
    table = OPTIMIZATION_VARIABLES["evaluations"]
    group = f.create_group("evaluations", track_order=True)
    group.attrs["comment"] = "every evaluated point, in evaluation order"
    ds = scales.coordinate(group, "evaluation", np.arange(len(evals), dtype=np.int64))
    _describe(ds, table["evaluation"], "1")
    for a_, (name, path) in enumerate(zip(names, problem.paths)):
        free_column(group, name, path, [e.x[a_] for e in evals], "evaluation")
    for name in ("v0", "v0_error_estimate", "displacement_per_period", "dissipation_per_period",
                 "cost_of_transport"):
        column(group, name, np.array([np.nan if getattr(e.row, name) is None
                                      else getattr(e.row, name) for e in evals], dtype=float),
               SWEEP_VARIABLES[name], "evaluation")
    for name in ("convergence", "status", "message", "integrator"):
        var = SWEEP_VARIABLES[name]
        column(group, name, np.array([str(getattr(e.row, name)) for e in evals], dtype=object),
               Var(var.dims, var.long_name, var.quantity, comment=_WORDS.get(name, "")),
               "evaluation")
    column(group, "periods", np.array([e.row.periods for e in evals], dtype=np.int64),
           SWEEP_VARIABLES["periods"], "evaluation")
    column(group, "steps", np.array([e.row.steps for e in evals], dtype=np.int64),
           SWEEP_VARIABLES["steps"], "evaluation")
    stage_code = {m: v for v, m in STAGE_FLAGS}
    column(group, "run", np.array([e.run for e in evals], dtype=np.int64), table["run"],
           "evaluation")
    column(group, "stage", np.array([stage_code[str(e.stage)] for e in evals], dtype=np.int8),
           table["stage"], "evaluation")
    column(group, "batch", np.array([e.batch for e in evals], dtype=np.int64), table["batch"],
           "evaluation")
    feasible, violation = result.feasibility()
    column(group, "feasible", np.asarray(feasible, dtype=np.int8), table["feasible"],
           "evaluation")
    column(group, "constraint_violation", np.asarray(violation, dtype=float),
           table["constraint_violation"], "evaluation")

    # /history: one entry per batch
    hist = result.history
    table = OPTIMIZATION_VARIABLES["history"]
    group = f.create_group("history", track_order=True)
    group.attrs["comment"] = ("the best value of each run after every batch; the runs' "
                              "objectives are in /runs")
    ds = scales.coordinate(group, "batch", np.array([b.batch for b in hist], dtype=np.int64))
    _describe(ds, table["batch"], "1")
    columns_: dict[str, Any] = {
        "run": np.array([b.run for b in hist], dtype=np.int64),
        "stage": np.array([stage_code[str(b.stage)] for b in hist], dtype=np.int8),
        "evaluations": np.array([b.evaluations for b in hist], dtype=np.int64),
        "best": np.array([b.best for b in hist], dtype=float),
        "best_evaluation": np.array([b.best_index for b in hist], dtype=np.int64),
        "feasible": np.array([b.feasible for b in hist], dtype=np.int8),
        "step": np.array([b.step for b in hist], dtype=float),
    }
    if problem.pareto:
        columns_["hypervolume"] = np.array([b.hypervolume for b in hist], dtype=float)
    for name, values in columns_.items():
        column(group, name, values, table[name], "batch")

    # /runs
    runs = result.runs
    table = OPTIMIZATION_VARIABLES["runs"]
    group = f.create_group("runs", track_order=True)
    ds = scales.coordinate(group, "run", np.array([r.index for r in runs], dtype=np.int64))
    _describe(ds, table["run"], "1")
    for name, values in {
        "objective": np.array([r.objective.text for r in runs], dtype=object),
        "constraints": np.array([", ".join(c.text for c in r.constraints) for r in runs],
                                dtype=object),
        "epsilon": np.array([r.epsilon for r in runs], dtype=float),
        "best_evaluation": np.array([r.best for r in runs], dtype=np.int64),
        "feasible": np.array([r.feasible for r in runs], dtype=np.int8),
        "evaluations": np.array([r.evaluations for r in runs], dtype=np.int64),
        "stop": np.array([r.stop for r in runs], dtype=object),
    }.items():
        column(group, name, values, table[name], "run")

    # /front (--pareto)
    if problem.pareto:
        table = OPTIMIZATION_VARIABLES["front"]
        group = f.create_group("front", track_order=True)
        front = list(result.front)
        ds = scales.coordinate(group, "front_point", np.arange(len(front), dtype=np.int64))
        _describe(ds, table["front_point"], "1")
        column(group, "evaluation", np.array(front, dtype=np.int64), table["evaluation"],
               "front_point")
        for a_, (name, path) in enumerate(zip(names, problem.paths)):
            free_column(group, name, path, [evals[i].x[a_] for i in front], "front_point")
        column(group, "v0", np.array([evals[i].row.v0 for i in front], dtype=float),
               table["v0"], "front_point")
        column(group, "cost_of_transport",
               np.array([evals[i].row.cost_of_transport for i in front], dtype=float),
               table["cost_of_transport"], "front_point")
        chosen = set(result.chosen)
        column(group, "chosen", np.array([i in chosen for i in front], dtype=np.int8),
               table["chosen"], "front_point")


def read_optimization(path: Any) -> dict[str, Any]:
    """An optimisation file as ``{attrs, free, evaluations, history, runs, front}`` (front
    only with --pareto), each group a dict of arrays (strings as Python str). Raises
    `ResultsFileError` naming what is missing when the file is not an optimisation file."""
    if isinstance(path, io.IOBase):
        f = h5py.File(path, "r")
        source: Any = "<memory>"
    else:
        source = Path(path)
        f = _open(source, "optimisation file")
    with f:
        _check_version(f, source)
        if _plain(f.attrs.get("kind", "")) != "optimization":
            raise ResultsFileError(f"{source}: not a crawlsim optimisation file (attribute kind "
                                   "is not 'optimization')")
        out: dict[str, Any] = {"attrs": {k: _plain(v) for k, v in f.attrs.items()}}
        for group in ("evaluations", "history", "runs", "front"):
            if group not in f:
                if group == "front":
                    continue
                raise ResultsFileError(f"{source}: missing group /{group}")
            out[group] = {name: (np.array(ds.asstr()[()], dtype=object)
                                 if h5py.check_string_dtype(ds.dtype) else ds[()])
                          for name, ds in f[group].items() if isinstance(ds, h5py.Dataset)}
        out["free"] = json.loads(out["attrs"].get("free_json", "[]"))
    return out


def _describe_optimization(path: Path, f: h5py.File, attrs: dict[str, Any]) -> dict[str, Any]:
    if "evaluations" not in f or "status" not in f["evaluations"]:
        raise ResultsFileError(f"{path}: missing /evaluations/status")
    status = [str(s) for s in f["evaluations"]["status"].asstr()[()]]
    counts: dict[str, int] = {}
    for s in status:
        counts[s] = counts.get(s, 0) + 1
    return {
        "file_kind": "optimization", "kind": "optimization", "name": attrs.get("name"),
        "source": attrs.get("source"), "objective": attrs.get("objective"),
        "constraints": json.loads(attrs.get("constraints_json", "[]")),
        "free": json.loads(attrs.get("free_json", "[]")),
        "integrator": attrs.get("integrator"), "seed": attrs.get("seed"),
        "evaluations": len(status), "max_evaluations": attrs.get("max_evaluations"),
        "statuses": counts, "best": json.loads(attrs.get("best_json", "{}")),
        "best_feasible": bool(attrs.get("best_feasible", 0)),
        "best_value": _number(attrs.get("best_value")), "v0": _number(attrs.get("best_v0")),
        "cost_of_transport": _number(attrs.get("best_cost_of_transport")),
        "front_points": int(f["front"]["front_point"].shape[0]) if "front" in f else None,
    }
