"""One gait simulated to its periodic regime: the unit every study is made of.

`run` and `simulate` step a gait (or a generic sweeping process) with the driver of
`crawlsim.analysis.run`, record its provenance (`crawlsim.io.provenance`) and return a
`SimulationResult`, which keeps its arrays in memory and writes its HDF5 results file only when
asked; `open_run` reads such a file back into the same type. The Python API (`crawlsim.api`)
and the studies built of many runs (sweeps, the stall search, the paper's checks, optimize)
call these.
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from crawlsim.analysis.convergence import RateFit
from crawlsim.analysis.energy import EnergyLedger
from crawlsim.analysis.report import result_html, result_repr
from crawlsim.analysis.run import (
    ConvergenceHistory,
    Effort,
    ExactVerdict,
    LimitPeriod,
    LimitSolver,
    RunResult,
    Settled,
    V0Estimate,
    settle,
)
from crawlsim.gait.document import Gait, ProcessSpec, parse_gait, with_simulation
from crawlsim.gait.document import load_gait as _load_gait
from crawlsim.gait.units import Units
from crawlsim.io import provenance as _provenance
from crawlsim.io.atomic import atomic_path
from crawlsim.model.process import SweepingProcess, compile
from crawlsim.status import Convergence, LimitMethod, RunStatus

if TYPE_CHECKING:
    import xarray

    from crawlsim.analysis.rigid import RigidLimit
    from crawlsim.io.runfile import ResultsWriter

Spec = Gait | ProcessSpec
Progress = Callable[[int, float], None]


def load_gait(path: str | Path, **settings: Any) -> Spec:
    """Read and validate a gait file (or a ``kind: sweeping-process`` file) into an immutable
    `Gait` (`ProcessSpec`); ``settings`` replace those of its ``simulation`` block (validated;
    None keeps the file's). Change it with ``gait.replace("links.*.amplitude", 0.2)``."""
    return _with_settings(_load_gait(path), **settings)


@dataclass(frozen=True, eq=False)
class Trajectory:
    """The run's trajectory at the saved grid times, as in the results file's /trajectory (and
    /events for the exact integrator). Crawlers have x, stress and shape; generic processes have
    reaction instead."""

    t: np.ndarray
    w: np.ndarray
    x: np.ndarray | None = None
    stress: np.ndarray | None = None
    shape: np.ndarray | None = None
    reaction: np.ndarray | None = None
    events: Mapping[str, np.ndarray] | None = None  # t, w (and x): the exact integrator's events

    def columns(self) -> dict[str, np.ndarray]:
        """The /trajectory variables held, by name (those that are None left out)."""
        names = ("t", "w", "x", "stress", "shape", "reaction")
        return {n: v for n in names if (v := getattr(self, n)) is not None}


#: Writes a result's results file into a target (a path, or a binary file object).
Writer = Callable[[Any], None]


@dataclass(frozen=True, eq=False, repr=False)
class SimulationResult:
    """A `RunResult` (``run``) with what a study needs besides: the trajectory (None when not
    kept), the units of the gait file, the provenance, and the same data as an xarray tree
    (`to_xarray`). Every attribute of the run reads through (``result.v0``,
    ``result.convergence``, ``result.estimate``, ...). It keeps arrays, never an HDF5 image:
    the results file is written when it is asked for (`save`, `to_xarray`, `image`). Made by a
    run in memory (`simulate`, `run`) or from a results file (`open_run`)."""

    run: RunResult
    trajectory: Trajectory | None = None
    units: Units = Units()
    provenance: _provenance.Provenance | None = None
    output: Path | None = None  # the results file written, if any
    # the limit period the run settled on, walked again by `crawlsim.sensitivity` (run=)
    settled: Settled | None = field(default=None, repr=False)
    # writes the results file of this result from its arrays (None: read from `output`)
    _write: Writer | None = field(default=None, repr=False)

    def __getattr__(self, name: str) -> Any:
        if name == "run" or name.startswith("__"):  # not set yet (copy, pickle)
            raise AttributeError(name)
        return getattr(self.run, name)

    def __repr__(self) -> str:
        return result_repr(self.run, self.units, self._rows(), "SimulationResult")

    def _repr_html_(self) -> str:
        return result_html(self.run, self.units, self._rows(), "SimulationResult")

    def _rows(self) -> list[tuple[str, str]]:
        """What the result holds besides the run: the trajectory kept and the file written."""
        rows = []
        if self.trajectory is not None:
            t, names = self.trajectory, ", ".join(self.trajectory.columns())
            events = "" if t.events is None else f", {len(t.events['t'])} events"
            rows.append(("trajectory", f"{len(t.t)} saved points ({names}){events}"))
        if self.output is not None:
            rows.append(("written", str(self.output)))
        return rows

    @property
    def image(self) -> bytes:
        """The results file, written now into memory (it is not kept)."""
        buffer = io.BytesIO()
        self._write_to(buffer)
        return buffer.getvalue()

    def _write_to(self, target: Any) -> None:
        if self._write is not None:
            self._write(target)
        elif self.output is not None:
            data = Path(self.output).read_bytes()
            if isinstance(target, io.IOBase):
                target.write(data)
            else:
                with atomic_path(target) as tmp:
                    tmp.write_bytes(data)
        else:
            raise ValueError(
                "this result holds no results file: use crawlsim.simulate, or crawlsim.api.run with output="
            )

    def summary(self) -> dict[str, Any]:
        """The JSON-ready numbers of `RunResult.summary`, plus ``units`` (the gait file's
        ``units:`` block, {} when dimensionless)."""
        return {**self.run.summary(), "units": self.units.to_json()}

    def save(self, path: str | Path) -> Path:
        """Write the results file of this result to ``path``, atomically."""
        self._write_to(Path(path))
        return Path(path)

    def plot(self, figure: str = "motion", **options: Any) -> Any:
        """The matplotlib figure ``figure`` of this run, as ``crawlsim plot`` draws it: one of
        `crawlsim.plotting.FIGURE_NAMES` (motion, gait-diagram, kymograph, convergence,
        shape-space), with its function's options (``last=3``, ``coords=(0, 2)``)."""
        from crawlsim.plotting.output import draw_figure

        return draw_figure(self, figure, **options)

    def to_xarray(self) -> xarray.DataTree:
        """The results as an `xarray.DataTree` with the groups, names, dimensions and
        attributes of the results file (it is read from the same bytes): ``time`` is an index,
        so ``tree["trajectory"].to_dataset().sel(time=5.0)`` picks a saved point. Needs
        ``pip install 'crawlsim[xarray]'``."""
        xr = _xarray()
        source: Any = self.output if self._write is None else io.BytesIO(self.image)
        if source is None:
            raise ValueError(
                "this result keeps no results file: use crawlsim.simulate, or crawlsim.api.run with output="
            )
        with xr.open_datatree(source, engine="h5netcdf", decode_timedelta=False) as tree:
            return cast("xarray.DataTree", tree.load())


def open_run(path: str | Path) -> SimulationResult:
    """Read a run's results file as the `SimulationResult` `simulate` returns: the summary's
    numbers, the convergence history, the limit period, the trajectory, units and provenance.
    Raises `crawlsim.errors.ResultsFileError` for a file that is not a run's results file."""
    from crawlsim.io.runread import read_results  # start-up: h5py only when a file is read

    data = read_results(path)
    attrs = data["attrs"]
    trajectory = _trajectory_of_file(data) if attrs.get("save_every", 1) else None
    return SimulationResult(
        _run_of_file(data),
        trajectory,
        Units.from_block(json.loads(attrs.get("units_json", "{}"))),
        _provenance.Provenance.from_attrs(attrs),
        Path(path),
    )


def _none(value: Any) -> Any:
    """NaN (a float attribute that does not apply) as None."""
    return None if isinstance(value, float) and math.isnan(value) else value


#: The summary's keys of `EnergyLedger`'s fields, in their order.
_LEDGER_KEYS = (
    "dissipation_per_period",
    "dissipation_error_estimate",
    "cost_of_transport",
    "actuator_work_per_period",
    "jump_loss_per_period",
    "energy_balance_residual",
    "cost_of_transport_bound",
    "efficiency",
    "load_work_per_period",
    "discretisation_loss_per_period",
)


def _run_of_file(data: Mapping[str, Any]) -> RunResult:
    """The `RunResult` of `read_results`'s dicts: the scalars of the summary (summary_json;
    files written before a number existed give its default, or the root attribute of the same
    name), the arrays of /convergence, /limit and /limit/solver."""
    attrs = data["attrs"]
    summary = json.loads(attrs.get("summary_json", "{}"))

    def get(key: str, default: Any = None) -> Any:
        return summary[key] if key in summary else _none(attrs.get(key, default))

    estimate = energy = None
    if get("v0") is not None:
        estimate = V0Estimate(
            get("v0"),
            get("v0_error_estimate"),
            get("v0_error_period_iteration"),
            get("v0_error_time_step"),
            get("v0_error_reason"),
            get("displacement_per_period"),
        )
        energy = EnergyLedger(*(get(key) for key in _LEDGER_KEYS))
    fit = None
    if get("contraction_rate") is not None:
        fit = RateFit(get("contraction_rate"), get("contraction_rate_error"), get("contraction_rate_periods", 0))
    solver = data.get("limit_solver", {})
    method = data.get("limit_solver_attrs", {}).get("method", summary.get("limit_method", LimitMethod.ITERATE))
    residuals = solver.get("residual")
    found = residuals is not None and len(residuals) > 0
    exact = None
    if summary.get("exact_convergence") is not None:
        exact = ExactVerdict(Convergence(summary["exact_convergence"]), get("exact_rate"), get("grid_note"))
    conv, lim = data["convergence"], data["limit"]
    return RunResult(
        name=attrs["name"],
        integrator=get("integrator", "catch-up"),
        status=RunStatus(summary.get("status", RunStatus.SUCCESSFUL)),
        message=get("message", ""),
        period=attrs["period"],
        periods=attrs["periods"],
        convergence=Convergence(attrs["convergence"]),
        periodic_from=None if attrs["periodic_from"] < 0 else int(attrs["periodic_from"]),
        estimate=estimate,
        energy=energy,
        rate=fit,
        solver=LimitSolver(
            LimitMethod(method),
            get("limit_newton_steps", 0),
            get("limit_periods", 0),
            residuals if found else None,
            solver["kind"] if found else None,
            get("jacobian_rate"),
        ),
        exact=exact,
        effort=Effort(get("steps", 0), get("clarabel_calls", 0), get("wall_time", math.nan)),
        history=ConvergenceHistory(**{f.name: conv[f.name] for f in dataclasses.fields(ConvergenceHistory)}),
        limit=LimitPeriod(
            start=float(data["limit_attrs"]["start"]),
            t=lim["t"],
            w=lim["w"],
            multipliers=lim["multipliers"],
            **{k: lim.get(k) for k in ("x", "shape", "stress", "slip", "slip_rate")},
        ),
    )


def _trajectory_of_file(data: Mapping[str, Any]) -> Trajectory:
    columns = {name: data["trajectory"].get(name) for name in ("t", "w", "x", "stress", "shape", "reaction")}
    return Trajectory(**columns, events=data.get("events"))


def _xarray() -> Any:
    try:
        import xarray
    except ImportError:
        raise ImportError("xarray is not installed: pip install 'crawlsim[xarray]'") from None
    return xarray


def _as_spec(gait: Spec | str | Path) -> Spec:
    return gait if isinstance(gait, (Gait, ProcessSpec)) else _load_gait(gait)


def _with_settings(spec: Spec, **overrides: Any) -> Spec:
    """``spec`` with simulation settings replaced (validated), the None ones left alone."""
    given = {k: v for k, v in overrides.items() if v is not None}
    if not given:
        return spec
    # with_simulation rebuilds a frozen dataclass of either kind; it is annotated for Gait only
    return cast(Spec, with_simulation(cast(Gait, spec), **given))


def _settle(
    spec: Spec,
    process: SweepingProcess,
    check_every_step: bool,
    progress: Progress | None,
    sink: Any = None,
    history: bool = True,
) -> Settled:
    """``process`` (compiled from ``spec``) run with the spec's settings, v0's time-step error
    measured."""
    s = spec.simulation
    return settle(
        process,
        max_periods=s.max_periods,
        tolerance=s.tolerance,
        integrator=s.integrator,
        check_every_step=check_every_step,
        sink=sink,
        progress=progress,
        limit=s.limit,
        history=history,
        series=history,  # without a history (v0 alone) no distances to the limit either
        time_step_error=True,
    )


def _writer(target: Any, process: SweepingProcess, spec: Spec, save_every: int, trajectory: bool) -> ResultsWriter:
    from crawlsim.io.runfile import ResultsWriter  # start-up: h5py only when a file is written

    return ResultsWriter(target, process, save_every=save_every, units=spec.units, trajectory=trajectory)


def _finish(writer: ResultsWriter, result: SimulationResult, spec: Spec, rigid: RigidLimit | None = None) -> None:
    """The results file's analysis, coordinates and attributes (and ``rigid``), and its
    publication."""
    kind = str(spec.document.get("kind", "crawler"))
    unchecked = getattr(spec, "uniqueness_unchecked", False)
    writer.finish(result, result.provenance, kind=kind, unchecked_uniqueness=unchecked, rigid=rigid)


def run(
    gait: Spec | str | Path,
    *,
    output: str | Path | None = None,
    save_every: int = 1,
    check_every_step: bool = False,
    progress: Progress | None = None,
    history: bool = True,
    rigid: RigidLimit | None = None,
) -> SimulationResult:
    """Simulate a gait to its periodic regime; write the HDF5 results file if ``output`` is given
    (the command line's ``crawlsim run``), with ``rigid``, the gait's rigid limit
    (`crawlsim.api.rigid_limit`), in its /rigid group.

    ``gait`` is a `Gait`, a `ProcessSpec` (a generic sweeping process, whose run has no velocity:
    v0 and the other crawler keys are None) or the path of either file. Its ``simulation``
    settings are used as they are (`simulate` takes them as arguments). The file records the
    command line of this process (``sys.argv``) unless a `crawlsim.io.provenance.recording` is
    active. The result keeps no trajectory. ``history=False`` (without ``output``: v0 alone)
    stops at the verified periodic limit instead of following the iterates to it.
    """
    spec = _as_spec(gait)
    process = compile(spec)
    record = _provenance.for_gait(spec, check_every_step=check_every_step)
    if output is None:
        settled = _settle(spec, process, check_every_step, progress, history=history)
        return SimulationResult(settled.result, units=spec.units, provenance=record, settled=settled)
    with _writer(Path(output), process, spec, save_every, True) as writer:
        run_ = _settle(spec, process, check_every_step, progress, sink=writer).result
        result = SimulationResult(run_, units=spec.units, provenance=record, output=Path(output))
        _finish(writer, result, spec, rigid)
    return result


def simulate(
    gait: Spec | str | Path,
    *,
    integrator: str | None = None,
    steps_per_period: int | None = None,
    max_periods: int | None = None,
    tolerance: float | None = None,
    limit: str | None = None,
    keep_trajectory: bool = True,
    save_every: int = 1,
    check_every_step: bool = False,
    progress: Progress | None = None,
) -> SimulationResult:
    """Simulate ``gait`` (a `Gait`, a `ProcessSpec` or a file) to its periodic regime.

    The keyword settings override the gait's ``simulation`` block (None keeps it; ``limit`` is
    ``"newton"``, the periodic-limit solver, or ``"iterate"``, plain periods). The result is
    a `RunResult` with, besides, ``trajectory`` (every ``save_every``-th grid point in memory;
    None with ``keep_trajectory=False``, when nothing per step is kept beyond what the analysis
    needs), ``units``, ``provenance`` and ``to_xarray()``; ``result.save(path)`` writes the
    results file it holds.
    """
    call = _provenance.python_call(
        "crawlsim.simulate",
        gait,
        integrator=integrator,
        steps_per_period=steps_per_period,
        max_periods=max_periods,
        tolerance=tolerance,
        limit=limit,
        keep_trajectory=None if keep_trajectory else False,
        save_every=None if save_every == 1 else save_every,
        check_every_step=check_every_step or None,
    )
    spec = _with_settings(
        _as_spec(gait),
        integrator=integrator,
        steps_per_period=steps_per_period,
        max_periods=max_periods,
        tolerance=tolerance,
        limit=limit,
    )
    with _provenance.recording(call):
        return _in_memory(
            spec,
            save_every=save_every,
            check_every_step=check_every_step,
            progress=progress,
            keep_trajectory=keep_trajectory,
        )


def _in_memory(
    spec: Spec, *, save_every: int, check_every_step: bool, progress: Progress | None, keep_trajectory: bool
) -> SimulationResult:
    """Run ``spec`` keeping the rows of its results file in memory (`RowsRecorder`): the
    trajectory holds them, and the file is written from it only when it is asked for."""
    from crawlsim.io.runfile import RowsRecorder  # start-up: h5py only for crawlsim.simulate

    process = compile(spec)
    recorder = RowsRecorder(process, save_every=save_every, trajectory=keep_trajectory)
    run_ = _settle(spec, process, check_every_step, progress, sink=recorder).result
    trajectory = Trajectory(**recorder.trajectory(), events=recorder.events()) if keep_trajectory else None
    del recorder  # its rows are the trajectory's now

    def write(target: Any) -> None:
        with _writer(target, process, spec, save_every, keep_trajectory) as writer:
            if trajectory is not None:
                writer.write_rows(trajectory.columns(), trajectory.events)
            _finish(writer, result, spec)

    record = _provenance.for_gait(spec, check_every_step=check_every_step)
    result = SimulationResult(run_, trajectory, spec.units, record, _write=write)
    return result


@dataclass(frozen=True)
class Rerun:
    """What ``crawlsim run --from RESULT.h5`` reruns: the effective gait of the file and the
    integrator settings that are not in the gait document."""

    gait: Spec
    check_every_step: bool
    save_every: int


def from_results(path: str | Path, **settings: Any) -> Rerun:
    """The run recorded in a results file (format_version 2), ready to rerun: the effective
    gait document (every override of the original command applied, and ``settings`` on top, as
    `load_gait` takes them) and ``check_every_step``. Rerunning it with `run` reproduces v0 bit
    for bit on the same versions (``versions_json``)."""
    from crawlsim.io.runread import read_provenance  # start-up: h5py only when a file is read

    info = read_provenance(path)
    spec = parse_gait(info["gait_yaml"], source=f"{path} (gait_yaml)", default_name=str(info["name"]))
    check = bool(info["integrator_settings"].get("check_every_step", False))
    return Rerun(_with_settings(spec, **settings), check, int(info["save_every"]))
