"""The library entry points: the command line calls these, and so does a Python study.

    import crawlsim
    gait = crawlsim.load_gait("gaits/peristalsis-4.yaml")
    result = crawlsim.simulate(gait.replace("links.*.amplitude", 0.2), integrator="exact")
    result.v0, result.trajectory.x, result.to_xarray()
    grid = crawlsim.sweep(gait, {"links.*.amplitude": [0.1, 0.2, 0.3]})   # an xarray.Dataset

Every result records its provenance (`crawlsim.io.provenance`): the effective gait document, the
integrator and its settings, the versions, and the call that made it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from crawlsim.errors import SweepSpecError
from crawlsim.gait.document import Gait
from crawlsim.io import provenance as _provenance
from crawlsim.study.simulation import (
    Rerun,
    SimulationResult,
    Spec,
    Trajectory,
    _as_spec,
    _with_settings,
    from_results,
    load_gait,
    open_run,
    run,
    simulate,
)

if TYPE_CHECKING:
    import xarray

    from crawlsim.analysis.rigid import RigidLimit
    from crawlsim.analysis.run import Settled
    from crawlsim.analysis.sensitivity import SensitivityResult
    from crawlsim.design.optresult import OptimizationResult
    from crawlsim.study.grid import SweepGrid
    from crawlsim.study.table import SweepTable

__all__ = [
    "Rerun",
    "SimulationResult",
    "Trajectory",
    "from_results",
    "load_gait",
    "open_optimization",
    "open_run",
    "open_sweep",
    "rigid_limit",
    "run",
    "sensitivity",
    "simulate",
    "sweep",
]


def sweep(
    gait: Spec | str | Path | SweepGrid,
    axes: Mapping[str, Iterable[float]] | None = None,
    *,
    jobs: int = 1,
    integrator: str | None = None,
    steps_per_period: int | None = None,
    max_periods: int | None = None,
    tolerance: float | None = None,
    output: str | Path | None = None,
    progress: Callable[[int], None] | None = None,
    sensitivity: Sequence[str] = (),
) -> xarray.Dataset | SweepTable:
    """v0 over the Cartesian grid of ``axes`` (``{"links.*.amplitude": [0.1, 0.2], ...}``: the
    dotted paths of ``--sweep``, in grid order, the last varying fastest).

    Returns an `xarray.Dataset` on the grid, one dimension per swept path, named by the path as
    given (``grid.v0.sel({"links.*.amplitude": 0.2})``; the file names it
    `crawlsim.io.sweepfile.axis_name`, ``links_all_amplitude``):
    v0, displacement_per_period, periods, steps, convergence and status (CF flags: see their
    ``flag_meanings``) and message, with the provenance as attributes, exactly the ``/grid``
    group of a sweep file. **Without xarray** (``pip install 'crawlsim[xarray]'``) it returns
    the `crawlsim.study.sweep.SweepTable` instead. ``output`` also writes the sweep file (.h5) or CSV
    table. Settings given override the gait's ``simulation`` block. ``gait`` may also be a
    grid already made (`crawlsim.study.grid.make_grid`: linked paths, extra columns), swept as
    it is (no ``axes``, no settings). ``sensitivity``: dotted paths (with ``*``) whose
    ``dv0/dPATH`` are added at every point, with units (`crawlsim.study.points.with_derivatives`).
    """
    from crawlsim.study import grid  # start-up: numpy and YAML only for sweeps (its axes)
    from crawlsim.study import sweep as sweeps  # start-up: h5py and the sweep engine only for sweeps

    if isinstance(gait, grid.SweepGrid):
        return sweeps.dataset(sweeps.sweep(gait, output=output, jobs=jobs, progress=progress, sensitivity=sensitivity))
    spec = _with_settings(
        _as_spec(gait),
        integrator=integrator,
        steps_per_period=steps_per_period,
        max_periods=max_periods,
        tolerance=tolerance,
    )
    if not isinstance(spec, Gait):
        raise SweepSpecError(
            spec.source, "", "sweeps run crawler gaits (kind: crawler), not generic sweeping processes"
        )
    axis_list = [grid.Axis(path, _axis_values(path, values)) for path, values in (axes or {}).items()]
    call = _provenance.python_call(
        "crawlsim.sweep",
        gait,
        {a.path: list(a.values) for a in axis_list},
        jobs=jobs if jobs != 1 else None,
        integrator=integrator,
        steps_per_period=steps_per_period,
        max_periods=max_periods,
        tolerance=tolerance,
        output=output,
        sensitivity=list(sensitivity) or None,
    )
    with _provenance.recording(call):
        table = sweeps.sweep(spec, axis_list, output=output, jobs=jobs, progress=progress, sensitivity=sensitivity)
        return sweeps.dataset(table)


def open_sweep(path: str | Path) -> xarray.Dataset | SweepTable:
    """Read a sweep file as `sweep` returns it: the `xarray.Dataset` of its ``/grid`` with the
    provenance as attributes, or without xarray the `crawlsim.study.sweep.SweepTable`. Raises
    `crawlsim.errors.ResultsFileError` for a file that is not a sweep file."""
    from crawlsim.study import sweep as sweeps  # start-up: h5py and the sweep engine only for sweeps

    return sweeps.open_dataset(path)


def open_optimization(path: str | Path) -> OptimizationResult:
    """Read an optimisation file (``crawlsim optimize -o``) as the
    `crawlsim.design.optresult.OptimizationResult` that `crawlsim.design.optimize.optimize`
    returns (`OptimizationResult.from_file`). Raises `crawlsim.errors.ResultsFileError` for a
    file that is not an optimisation file."""
    from crawlsim.design.optresult import OptimizationResult  # start-up: h5py only for its file

    return OptimizationResult.from_file(path)


def _axis_values(path: str, values: Iterable[float]) -> tuple[float, ...]:
    """The values of one swept path as numbers (integers stay integers: ``blocks``)."""
    array = np.asarray([] if isinstance(values, (str, bytes)) else list(values)).ravel()
    items: list[Any] = array.tolist() if array.dtype.kind in "iuf" else []
    if not items or not all(math.isfinite(v) for v in items):
        raise SweepSpecError(
            f"crawlsim.sweep(..., {{{path!r}: ...}})",
            path,
            f"expected a non-empty list of finite numbers, got {values!r}",
        )
    return tuple(items)


def sensitivity(
    gait: Spec | str | Path, paths: Sequence[str] | str, *, one_sided: bool = True, run: Settled | None = None
) -> SensitivityResult:
    """The exact derivatives of v0, of the displacement and dissipation per period and of the
    cost of transport with respect to the numbers ``paths`` name in ``gait`` (dotted paths with
    ``*`` as in ``--sweep``; each ``*`` expands to one parameter per element), at the verified
    periodic limit of the gait's integrator: the exact integrator's, or the catch-up scheme's own
    discrete map's (``method: catch-up``; docs/sensitivity.md).

        r = crawlsim.sensitivity(gait, ["links.*.phase", "stiffness"])
        r["links.1.phase"].v0.value, r["links.1.phase"].v0.error_estimate, r.summary()

    Where v0 has a kink or a jump, a parameter's ``smooth`` is False, ``v0.value`` is None and
    ``left`` / ``right`` hold one-sided derivatives measured with the same integrator
    (``one_sided=False`` skips them). ``run``: what a run of this gait settled on (the
    ``settled`` of `run`'s result), whose limit period is walked instead of searched again.
    """
    from crawlsim.analysis.sensitivity import sensitivity as _sensitivity  # start-up: its kernels only when asked

    spec = _as_spec(gait)
    if not isinstance(spec, Gait):
        raise SweepSpecError(
            spec.source,
            "",
            "sensitivities are defined for crawler gaits (kind: crawler), not generic sweeping processes",
        )
    return _sensitivity(spec, paths, one_sided=one_sided, run=run)


def rigid_limit(gait: Spec | str | Path) -> RigidLimit:
    """v0 of a crawler gait as its links stiffen without bound (docs/model.md §7), with its
    error estimate and the resting block as a piecewise-constant function of time: exact
    between events found in closed form or by certified sampling, no stepping.

        r = crawlsim.rigid_limit("gaits/peristalsis-4.yaml")
        r.v0, r.v0_error_estimate, r.times, r.resting

    Raises `crawlsim.errors.DegenerateModelError` where the balance does not fix the motion.
    """
    from crawlsim.analysis.rigid import rigid_limit as _rigid_limit
    from crawlsim.gait.crawler_spec import need_crawler

    spec = _as_spec(gait)
    need_crawler(spec, "crawlsim.rigid_limit")
    assert isinstance(spec, Gait)
    return _rigid_limit(spec)
