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

from crawlsim.analysis.run import RunResult
from crawlsim.analysis.run import simulate as _simulate_process
from crawlsim.gait.document import Gait, ProcessSpec, parse_gait, with_simulation
from crawlsim.gait.document import load_gait as _load_gait
from crawlsim.gait.units import Units
from crawlsim.io import provenance as _provenance
from crawlsim.model.process import compile

if TYPE_CHECKING:
    import xarray

    from crawlsim.analysis.rigid import RigidLimit

Spec = Gait | ProcessSpec
Progress = Callable[[int, float], None]


def load_gait(path: str | Path) -> Spec:
    """Read and validate a gait file (or a ``kind: sweeping-process`` file) into an immutable
    `Gait` (`ProcessSpec`); change it with ``gait.replace("links.*.amplitude", 0.2)``."""
    return _load_gait(path)


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
class SimulationResult(RunResult):
    """A `RunResult` with what a study needs besides: the trajectory (None when not kept), the
    units of the gait file, the provenance, and the same data as an xarray tree
    (`to_xarray`). It keeps arrays, never an HDF5 image: the results file is written when it is
    asked for (`save`, `to_xarray`, `image`). Made by one constructor per source: `from_run`
    (a run in memory) and `from_file` (a results file, `open_run`)."""

    trajectory: Trajectory | None = None
    units: Units = Units()
    provenance: _provenance.Provenance | None = None
    output: Path | None = None  # the results file written, if any
    # writes the results file of this result from its arrays (None: read from `output`)
    _write: Writer | None = field(default=None, repr=False)

    @classmethod
    def from_run(
        cls,
        run: RunResult,
        *,
        units: Units | None = None,
        provenance: _provenance.Provenance | None = None,
        trajectory: Trajectory | None = None,
        output: Path | None = None,
        write: Writer | None = None,
    ) -> SimulationResult:
        """The result of a run in memory (`crawlsim.analysis.run.simulate`), with what the
        caller kept besides."""
        fields = {f.name: getattr(run, f.name) for f in dataclasses.fields(RunResult)}
        return cls(
            **fields, trajectory=trajectory, units=units or Units(), provenance=provenance, output=output, _write=write
        )

    @classmethod
    def from_file(cls, path: str | Path) -> SimulationResult:
        """The result recorded in a run's results file: the same type and the same numbers as
        the `simulate` that wrote it (`crawlsim.io.runread.read_results`)."""
        from crawlsim.io.runread import read_results

        data = read_results(path)
        return cls(**_fields_of_file(data), output=Path(path))

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
                from crawlsim.io.atomic import atomic_path

                with atomic_path(target) as tmp:
                    tmp.write_bytes(data)
        else:
            raise ValueError(
                "this result holds no results file: use crawlsim.simulate, or crawlsim.api.run with output="
            )

    def summary(self) -> dict[str, Any]:
        """The JSON-ready numbers of `RunResult.summary`, plus ``units`` (the gait file's
        ``units:`` block, {} when dimensionless)."""
        out: dict[str, Any] = super().summary()
        out["units"] = self.units.to_json()
        return out

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
    return SimulationResult.from_file(path)


def _none(value: Any) -> Any:
    """NaN (a float attribute that does not apply) as None."""
    return None if isinstance(value, float) and math.isnan(value) else value


def _fields_of_file(data: Mapping[str, Any]) -> dict[str, Any]:
    """The fields of a `SimulationResult` from `read_results`'s dicts: the scalars of the
    summary (summary_json; files written before a field existed give its default), the arrays
    of /convergence, /limit, /limit/solver and /trajectory."""
    from crawlsim.analysis.run import SUMMARY_KEYS, ConvergenceHistory, LimitPeriod
    from crawlsim.status import Convergence, LimitMethod, RunStatus

    attrs = data["attrs"]
    summary = json.loads(attrs.get("summary_json", "{}"))
    known = {f.name for f in dataclasses.fields(RunResult)}
    fields: dict[str, Any] = {k: summary[k] for k in SUMMARY_KEYS if k in summary and k in known}
    for key in ("name", "period", "steps_per_period", "periods"):
        fields[key] = attrs[key]
    fields["convergence"] = Convergence(attrs["convergence"])
    fields["periodic_from"] = None if attrs["periodic_from"] < 0 else int(attrs["periodic_from"])
    for key in (
        "v0",
        "v0_error_estimate",
        "displacement_per_period",
        "dissipation_per_period",
        "cost_of_transport",
        "contraction_rate",
    ):
        fields[key] = _none(attrs.get(key, math.nan))
    fields["status"] = RunStatus(summary.get("status", RunStatus.SUCCESSFUL))
    fields["limit_method"] = LimitMethod(
        data.get("limit_solver_attrs", {}).get("method", summary.get("limit_method", LimitMethod.ITERATE))
    )
    if summary.get("exact_convergence") is not None:
        fields["exact_convergence"] = Convergence(summary["exact_convergence"])
    conv, lim = data["convergence"], data["limit"]
    fields["history"] = ConvergenceHistory(**{f.name: conv[f.name] for f in dataclasses.fields(ConvergenceHistory)})
    fields["limit"] = LimitPeriod(
        start=float(data["limit_attrs"]["start"]),
        t=lim["t"],
        w=lim["w"],
        multipliers=lim["multipliers"],
        **{k: lim.get(k) for k in ("x", "shape", "stress", "slip", "slip_rate")},
    )
    solver = data.get("limit_solver", {})
    if len(solver.get("residual", ())):
        fields.update(limit_residuals=solver["residual"], limit_kinds=solver["kind"])
    fields.setdefault("clarabel_calls", 0)
    fields.setdefault("wall_time", math.nan)
    fields["units"] = Units.from_block(json.loads(attrs.get("units_json", "{}")))
    fields["provenance"] = _provenance.Provenance.from_attrs(attrs)
    fields["trajectory"] = _trajectory_of_file(data) if attrs.get("save_every", 1) else None
    if "terrain" in data:
        from crawlsim.analysis.terrain import TerrainReport

        terrain = TerrainReport.from_group(data["terrain"], data["terrain_attrs"], fields["period"], fields["periods"])
        fields["terrain"] = terrain
    return fields


def _trajectory_of_file(data: Mapping[str, Any]) -> Trajectory:
    t = data["trajectory"]
    return Trajectory(
        t=t["t"],
        w=t["w"],
        x=t.get("x"),
        stress=t.get("stress"),
        shape=t.get("shape"),
        reaction=t.get("reaction"),
        events=data.get("events"),
    )


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


def _execute(
    spec: Spec,
    target: Any,
    *,
    save_every: int,
    check_every_step: bool,
    progress: Progress | None,
    keep_trajectory: bool,
    rigid: Any = None,
) -> SimulationResult:
    """Run ``spec`` with its settings, writing its results file (and ``rigid``) into ``target``."""
    from crawlsim.io.hdf5 import ResultsWriter  # h5py only when a results file is written

    process = compile(spec)
    s = spec.simulation
    record = _provenance.for_gait(spec, check_every_step=check_every_step)
    kind = str(spec.document.get("kind", "crawler"))
    with ResultsWriter(target, process, save_every=save_every, units=spec.units, trajectory=keep_trajectory) as writer:
        run = _simulate_process(
            process,
            max_periods=s.max_periods,
            tolerance=s.tolerance,
            integrator=s.integrator,
            check_every_step=check_every_step,
            sink=writer,
            progress=progress,
            limit=s.limit,
            time_step_error=True,
        )
        result = SimulationResult.from_run(run, units=spec.units, provenance=record)
        unchecked = getattr(spec, "uniqueness_unchecked", False)
        writer.finish(result, record, kind=kind, unchecked_uniqueness=unchecked, rigid=rigid)
    return result


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
    if output is None:
        s = spec.simulation
        run_ = _simulate_process(
            compile(spec),
            max_periods=s.max_periods,
            tolerance=s.tolerance,
            integrator=s.integrator,
            check_every_step=check_every_step,
            progress=progress,
            limit=s.limit,
            history=history,
            time_step_error=True,
        )
        return SimulationResult.from_run(
            run_, units=spec.units, provenance=_provenance.for_gait(spec, check_every_step=check_every_step)
        )
    result = _execute(
        spec,
        Path(output),
        save_every=save_every,
        check_every_step=check_every_step,
        progress=progress,
        keep_trajectory=True,
        rigid=rigid,
    )
    return dataclasses.replace(result, output=Path(output))


def simulate(
    gait: Spec | str | Path,
    *,
    integrator: str | None = None,
    steps_per_period: int | None = None,
    max_periods: int | None = None,
    tolerance: float | None = None,
    keep_trajectory: bool = True,
    save_every: int = 1,
    check_every_step: bool = False,
    progress: Progress | None = None,
) -> SimulationResult:
    """Simulate ``gait`` (a `Gait`, a `ProcessSpec` or a file) to its periodic regime.

    The keyword settings override the gait's ``simulation`` block (None keeps it). The result is
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
    from crawlsim.io.runfile import RowsRecorder

    process = compile(spec)
    s = spec.simulation
    record = _provenance.for_gait(spec, check_every_step=check_every_step)
    recorder = RowsRecorder(process, save_every=save_every, trajectory=keep_trajectory)
    run = _simulate_process(
        process,
        max_periods=s.max_periods,
        tolerance=s.tolerance,
        integrator=s.integrator,
        check_every_step=check_every_step,
        sink=recorder,
        progress=progress,
        limit=s.limit,
        time_step_error=True,
    )
    trajectory = None
    if keep_trajectory:
        t = recorder.trajectory()
        trajectory = Trajectory(
            t=t["t"],
            w=t["w"],
            x=t.get("x"),
            stress=t.get("stress"),
            shape=t.get("shape"),
            reaction=t.get("reaction"),
            events=recorder.events(),
        )
    del recorder  # its rows are the trajectory's now
    result = SimulationResult.from_run(run, units=spec.units, provenance=record, trajectory=trajectory)
    kind = str(spec.document.get("kind", "crawler"))
    unchecked = bool(getattr(spec, "uniqueness_unchecked", False))

    def write(target: Any) -> None:
        from crawlsim.io.runfile import ResultsWriter

        with ResultsWriter(
            target, process, save_every=save_every, units=spec.units, trajectory=keep_trajectory
        ) as writer:
            if trajectory is not None:
                writer.write_rows(trajectory.columns(), trajectory.events)
            writer.finish(result, record, kind=kind, unchecked_uniqueness=unchecked)

    return dataclasses.replace(result, _write=write)


@dataclass(frozen=True)
class Rerun:
    """What ``crawlsim run --from RESULT.h5`` reruns: the effective gait of the file and the
    integrator settings that are not in the gait document."""

    gait: Spec
    check_every_step: bool
    save_every: int


def from_results(path: str | Path) -> Rerun:
    """The run recorded in a results file (format_version 2), ready to rerun: the effective
    gait document (every override of the original command applied) and ``check_every_step``.
    Rerunning it with `run` reproduces v0 bit for bit on the same versions
    (``versions_json``)."""
    from crawlsim.io.hdf5 import read_provenance

    info = read_provenance(path)
    spec = parse_gait(info["gait_yaml"], source=f"{path} (gait_yaml)", default_name=str(info["name"]))
    settings = info["integrator_settings"]
    return Rerun(spec, bool(settings.get("check_every_step", False)), int(info["save_every"]))
