"""Parameter sweeps of v0: a grid of edited gait documents, run in batches.

The pieces, in the order a sweep uses them:

* `crawlsim.study.grid`: the axes (``PATH=SPEC``), linked dimensions and the grid of edited gait
  documents (`make_grid`, `SweepGrid`);
* `crawlsim.study.points`: a point validated, compiled and run (`run_points`, `PointResult`),
  with the grid's extra columns (`PointQuantity`);
* `crawlsim.study.executors`: where the points run (this process, local workers, a Dask
  cluster), in tasks sized to their measured cost;
* `crawlsim.study.journal`: finished points kept across interruptions;
* `crawlsim.study.table`: the table, its CSV and HDF5 files, and the join of shards.

Every path is resolved against the base document before anything runs, so a bad path is an
`InputError` (exit code 2) and nothing is computed or written; so is a grid in which no point is
a valid gait (no point could run). A point whose edited document is not a valid gait (a friction
value that breaks the uniqueness condition, a non-positive length) is recorded with status
``invalid`` and the reason, and the others run. Each point runs as its single run does
(`crawlsim.study.points`), in-process, on local worker processes, or on a Dask cluster; a point
that fails while running is recorded with status ``failed`` and its reason. With local workers
(``jobs > 1``) the first task runs here and measures the cost of a point, and the workers start
only when they save more than their start-up (`crawlsim.study.executors.run_local`).

Nothing finished is lost: finished points go to a journal next to the output (``OUT.journal``,
JSON lines), flushed and fsynced every `JOURNAL_SECONDS` seconds, at the end and on an
interrupt, and read back on a rerun of the same sweep so that finished points are not
recomputed. The output file is written atomically at the end.
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from crawlsim import plotting
from crawlsim.errors import SweepSpecError
from crawlsim.gait.document import Gait
from crawlsim.io.runread import read_attrs
from crawlsim.io.sweepfile import read_sweep, write_sweep
from crawlsim.study.executors import MIN_CHUNK, WorkerPool, run_dask, run_local, run_on_pool
from crawlsim.study.grid import SweepGrid, check_some_point_runs, make_grid
from crawlsim.study.journal import Journal, journal_path
from crawlsim.study.simulation import _xarray
from crawlsim.study.table import SweepTable, is_hdf5, read_table, table_payload, write_table

if TYPE_CHECKING:
    import xarray

    from crawlsim.plotting.style import FigureOptions


class SweepInterrupted(KeyboardInterrupt):
    """A sweep stopped by Ctrl-C (or SIGTERM): ``done`` of ``total`` points are finished and
    kept in ``journal`` (None when the sweep has no output, and so no journal)."""

    def __init__(self, done: int, total: int, journal: Path | None):
        super().__init__(f"interrupted after {done} of {total} points")
        self.done, self.total, self.journal = done, total, journal


def run_sweep(
    grid: SweepGrid,
    *,
    jobs: int = 1,
    shard=None,
    scheduler: str | None = None,
    journal: Journal | None = None,
    progress=None,
    on_rows=None,
    pool: WorkerPool | None = None,
) -> SweepTable:
    """Evaluate the grid (or one shard of it) and return its table, in grid order.

    ``journal`` (see `Journal`) keeps finished points across interruptions and skips them on a
    rerun. ``progress(k)`` is called as k more points finish (from a helper thread with local
    workers); ``on_rows(rows, resumed)`` receives the rows read from the journal
    (``resumed=True``) and then every batch of finished rows. An interrupt (KeyboardInterrupt)
    becomes `SweepInterrupted` once the journal holds every finished point. ``pool`` (a
    `WorkerPool`, instead of ``jobs``) runs the points on workers that outlive this sweep;
    ``jobs`` local workers start only when they pay for their start-up (`run_local`).
    """
    done = journal.load() if journal is not None else {}  # refuses a FIFO before any work
    check_some_point_runs(grid)
    indices = grid.indices(shard)
    todo = np.array([i for i in indices if int(i) not in done], dtype=np.int64)
    finished = dict(done)
    if done and on_rows is not None:
        on_rows([done[i] for i in sorted(done)], True)

    def collect(rows):
        for r in rows:
            finished[r.index] = r
        if journal is not None:
            journal.append(rows)
        if on_rows is not None:
            on_rows(rows, False)

    try:
        if scheduler:
            run_dask(grid, todo, scheduler, collect, progress)
        elif pool is not None and len(todo) > MIN_CHUNK:
            run_on_pool(grid, todo, pool, collect, progress)
        else:
            run_local(grid, todo, jobs, collect, progress)
    except KeyboardInterrupt:
        raise SweepInterrupted(len(finished), len(indices), None if journal is None else journal.path) from None
    finally:
        if journal is not None:
            journal.close()
    return SweepTable(
        grid.paths,
        tuple(np.asarray(a.values) for a in grid.axes),
        np.asarray(indices),
        tuple(finished[int(i)] for i in indices),
        grid.gait_yaml,
        grid.source,
        shard,
        computed=len(todo),
        dims=grid.dims,
        quantities=tuple(q.name for q in grid.quantities),
    )


def sweep(
    grid: SweepGrid | Gait,
    axes=None,
    *,
    output=None,
    jobs: int = 1,
    shard=None,
    scheduler: str | None = None,
    progress=None,
    on_rows=None,
    sensitivity: Sequence[str] = (),
) -> SweepTable:
    """The library entry point behind ``crawlsim velocity --sweep``.

    ``grid`` is a `SweepGrid` (`make_grid`), or a base gait and its ``axes`` as `make_grid`
    takes them (``PATH=SPEC`` texts or `Axis`, a sequence of them for linked paths). Runs the
    points, keeps a journal next to ``output`` while running, and writes ``output`` (CSV or
    HDF5) atomically at the end, removing the journal. Without ``output`` nothing is written.
    ``progress`` and ``on_rows`` as in `run_sweep`. ``sensitivity``: paths whose ``dv0/dPATH``
    columns are added (`crawlsim.study.points.with_derivatives`), with a base gait.
    """
    if not isinstance(grid, SweepGrid):
        grid = make_grid(grid, () if axes is None else axes, sensitivity=sensitivity)
    elif axes is not None:
        raise TypeError("sweep(grid, axes): a SweepGrid has its axes already")
    elif sensitivity:
        raise TypeError(
            "sweep(grid, sensitivity=...): a SweepGrid has its sensitivity already (make_grid(..., sensitivity=...))"
        )
    check_shard_output(shard, output)
    journal = Journal(journal_path(output), grid.fingerprint(shard)) if output else None
    table = run_sweep(
        grid, jobs=jobs, shard=shard, scheduler=scheduler, journal=journal, progress=progress, on_rows=on_rows
    )
    if output is not None and journal is not None:
        write_table(table, output)
        journal.remove()
    return table


def dataset(table: SweepTable) -> xarray.Dataset | SweepTable:
    """The ``/grid`` group of the table's sweep file as an `xarray.Dataset` (`crawlsim.sweep`;
    the table itself without xarray)."""
    try:
        _xarray()
    except ImportError:
        return table
    buffer = io.BytesIO()
    write_sweep(buffer, **table_payload(table))
    return _grid_dataset(buffer)


def open_dataset(path: str | Path) -> xarray.Dataset | SweepTable:
    """A sweep file as `crawlsim.sweep` returns it (`crawlsim.open_sweep`): the `xarray.Dataset`
    of its ``/grid`` with the provenance as attributes, or without xarray its `SweepTable`."""
    read_sweep(path)  # refuses what is not a sweep file, naming what is missing
    try:
        _xarray()
    except ImportError:
        return read_table(path)
    return _grid_dataset(path)


def _grid_dataset(source: Any) -> xarray.Dataset:
    """The ``/grid`` group of a sweep file (a path or a binary file object) as a Dataset, the
    root attributes (provenance) merged into its own."""
    xr = _xarray()
    if isinstance(source, io.IOBase):
        source.seek(0)
    attrs = read_attrs(source)
    if isinstance(source, io.IOBase):
        source.seek(0)
    if not hasattr(xr.Dataset, "crawlsim"):
        _register_accessor(xr)
    with xr.open_dataset(source, engine="h5netcdf", group="grid", decode_timedelta=False) as ds:
        grid = cast("xarray.Dataset", ds.load())
    grid.attrs = {**attrs, **grid.attrs}
    # keyed by the paths the user passed (the file's names, `axis_name`, avoid dots)
    return grid.rename({name: grid[name].attrs["path"] for name in grid.coords if "path" in grid[name].attrs})


def _register_accessor(xr: Any) -> None:
    """``grid.crawlsim.plot()`` on the Datasets of `crawlsim.sweep` and `crawlsim.open_sweep`:
    the sweep figure, as ``crawlsim plot SWEEP.h5`` draws it (``grid.plot`` is xarray's own)."""

    @xr.register_dataset_accessor("crawlsim")
    class SweepAccessor:
        def __init__(self, grid: Any) -> None:
            self._grid = grid

        def plot(self) -> Any:
            return plotting.sweep_data_figure(self._grid)


def check_shard_output(shard, output) -> None:
    """A shard is written to an HDF5 file, or `crawlsim merge` could not join it."""
    if shard is not None and (output is None or not is_hdf5(output)):
        raise SweepSpecError(
            "--shard",
            "",
            "a shard must be written to an HDF5 file (-o part-I.h5) so that `crawlsim merge` can join the parts",
        )


def plot_table(table: SweepTable, path, options: FigureOptions | None = None) -> None:
    """The sweep figure of ``table`` (`crawlsim.plotting.sweeps.sweep_data_figure`), drawn with
    ``options`` (`crawlsim.plotting.style.FigureOptions`: dpi, size, style sheet) and written
    atomically."""
    from crawlsim.plotting.style import FigureOptions, user_style  # start-up: matplotlib for figures only

    options = options or FigureOptions()
    with user_style(options.style):
        figure = plotting.sweep_data_figure(table_payload(table))
        plotting.save_figure(figure, path, dpi=options.dpi, figsize=options.figsize)
