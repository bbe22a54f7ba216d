"""``crawlsim velocity``: v0 of a gait, or a table of v0 over a parameter sweep."""

from __future__ import annotations

import sys
from contextlib import contextmanager

import click

from .. import api
from .. import sweep as sweeps
from . import (
    EXIT_NOT_CONVERGED,
    BadInput,
    library_errors,
    load_with_overrides,
    main,
    simulation_options,
    to_json,
)
from .guards import check_memory, force_option, max_memory_option, warn_unchecked


@contextmanager
def _point_progress(total: int):
    """A tqdm bar over sweep points on stderr, only when stderr is a terminal."""
    if not sys.stderr.isatty():
        yield None
        return
    from tqdm import tqdm

    with tqdm(total=total, unit="point", file=sys.stderr, leave=False) as bar:
        yield bar.update


def _shard(ctx, param, value):
    if value is None:
        return None
    with library_errors():
        return sweeps.parse_shard(value)


def _check_sweep_memory(gait, axes, points, jobs, scheduler, max_memory):
    """The largest point of the grid (most blocks, most steps), in a batch as large as the
    sweep's chunks, once per local worker."""
    largest = {}
    for axis in axes:
        if axis.path in ("blocks", "simulation.steps_per_period"):
            largest[axis.path] = int(max(axis.values))
    batch = min(points, sweeps.MAX_CHUNK)
    check_memory(gait, max_memory, batch=batch,
                 steps_per_period=largest.get("simulation.steps_per_period"),
                 blocks=largest.get("blocks"),
                 what=f"this sweep ({'one worker' if scheduler else f'{jobs} worker(s)'} with "
                      f"batches of {batch} points)")
    if not scheduler and jobs > 1:
        from ..resources import default_limit, gait_memory

        limit = default_limit() if max_memory is None else max_memory
        each = gait_memory(gait, batch=batch, blocks=largest.get("blocks"),
                           steps_per_period=largest.get("simulation.steps_per_period"))
        if jobs * each.total > limit:
            from ..errors import ResourceError
            from ..resources import format_size

            raise ResourceError(gait.source, "", f"{jobs} local workers would need about "
                                                 f"{format_size(jobs * each.total)} together "
                                                 f"({each.describe()} each), more than the memory "
                                                 f"limit of {format_size(limit)} (--max-memory); "
                                                 "use fewer --jobs")


@main.command()
@click.argument("gait_file", type=click.Path(exists=True, dir_okay=False))
@click.option("--json", "as_json", is_flag=True,
              help="Print the run's JSON summary instead of v0 alone (single gait only).")
@click.option("--sweep", "sweep_specs", multiple=True, metavar="PATH=SPEC",
              help="Sweep a dotted path of the gait document over START:STOP:NUM (inclusive) "
                   "or a comma list a,b,c. Repeat for a Cartesian grid.")
@click.option("-o", "--output", type=click.Path(dir_okay=False),
              help="Write the table to OUT.csv or OUT.h5 (default: CSV on stdout).")
@click.option("--jobs", type=click.IntRange(min=1), default=1, show_default=True,
              help="Local worker processes.")
@click.option("--shard", callback=_shard, metavar="I/N",
              help="Compute only the I-th of N disjoint parts of the grid (1 <= I <= N); "
                   "needs -o PART.h5; join the parts with `crawlsim merge`.")
@click.option("--scheduler", metavar="ADDRESS",
              help="Run on an existing Dask cluster (tcp://host:8786); needs "
                   "pip install 'crawlsim[dask]'.")
@click.option("--plot", "plot_file", type=click.Path(dir_okay=False),
              help="Draw v0 against one swept path, or a heat map over two (PNG).")
@simulation_options
@max_memory_option
@force_option
def velocity(gait_file, as_json, sweep_specs, output, jobs, shard, scheduler, plot_file,
             steps_per_period, max_periods, tolerance, max_memory, force):
    """Print v0 of GAIT_FILE, or sweep gait parameters and tabulate v0.

    Without --sweep, prints v0 alone on one line (exit code 3 if the run did not converge).
    With --sweep, writes one row per grid point: the swept values, v0,
    displacement_per_period, convergence, periods, status (ok, not-converged, failed) and
    message. Points that fail or do not converge are recorded in the status column and the
    exit code stays 0. An interrupted sweep with -o resumes when rerun.

    \b
    Examples:
      crawlsim velocity gaits/peristalsis-4.yaml
      crawlsim velocity gaits/inching-2.yaml --json
      crawlsim velocity gaits/peristalsis-4.yaml --sweep 'links.*.amplitude=0.1:0.4:31'
      crawlsim velocity gaits/peristalsis-3.yaml --sweep links.1.phase=0:1:41 \\
          --sweep friction.backward=1.5,2.5,3.5 -o lag.h5 --jobs 2 --plot lag.png
      crawlsim velocity gaits/peristalsis-4.yaml --sweep period=0.5:2:16 \\
          --shard 3/8 -o part-3.h5 && crawlsim merge part-*.h5 -o all.h5
    """
    with library_errors():
        from ..outputs import FIGURE, SWEEP, check_target

        for path, kind, option in ((output, SWEEP, "--output"), (plot_file, FIGURE, "--plot")):
            if path is not None:
                check_target(path, kind, inputs=[gait_file], force=force, option=option)
        gait = load_with_overrides(gait_file, steps_per_period, max_periods, tolerance)
        warn_unchecked(gait)
        if not sweep_specs:
            if shard or plot_file:
                raise BadInput("--shard and --plot need at least one --sweep PATH=SPEC")
            if output is None:
                check_memory(gait, max_memory)
                result = api.run(gait)
                click.echo(to_json(result.summary()) if as_json else repr(result.v0))
                if not result.converged:
                    sys.exit(EXIT_NOT_CONVERGED)
                return
        if as_json and sweep_specs:
            raise BadInput("--json prints one run's summary; with --sweep the table is CSV or "
                           "HDF5 (-o)")
        if plot_file and shard:
            raise BadInput("--plot needs the whole grid: plot after `crawlsim merge`")
        axes = [sweeps.parse_axis(s) for s in sweep_specs]
        if plot_file and len(axes) not in (1, 2):
            raise BadInput(f"--plot draws one or two swept paths, got {len(axes)}")
        grid = sweeps.make_grid(gait, axes)
        total = len(grid.indices(shard))
        _check_sweep_memory(gait, axes, total, jobs, scheduler, max_memory)
        with _point_progress(total) as progress:
            table = sweeps.sweep(gait, axes, output=output, jobs=jobs, shard=shard,
                                 scheduler=scheduler, progress=progress)
        if plot_file:
            sweeps.plot_table(table, plot_file)
    if output is None:
        click.echo(table.to_csv(), nl=False)
    counts = table.counts()
    if counts["failed"] or counts["not-converged"]:
        click.echo(f"{len(table.rows)} points: {counts['failed']} failed, "
                   f"{counts['not-converged']} not converged (see the status column)", err=True)
