"""``crawlsim velocity``: v0 of a gait, or a table of v0 over a parameter sweep."""

from __future__ import annotations

import os
import sys

import click

from crawlsim.cli import (
    EXIT_NOT_CONVERGED,
    BadInput,
    OrderedCommand,
    check_feedback,
    feedback_options,
    interrupt_exit,
    library_errors,
    load_with_overrides,
    main,
    run_progress,
    simulation_options,
    to_json,
)
from crawlsim.cli.guards import (
    check_memory,
    check_sweep_memory,
    force_option,
    max_memory_option,
    warn_unchecked,
)
from crawlsim.cli.progress import Progress, choose_mode


def _shard(ctx, param, value):
    if value is None:
        return None
    from crawlsim.study.grid import parse_shard

    with library_errors():
        return parse_shard(value)


def _dimensions(sweep_specs, link_specs) -> list[list[str]]:
    """The grid dimensions: each ``--sweep`` with the ``--link`` options that follow it."""
    ctx = click.get_current_context()
    order = ctx.meta.get("crawlsim.option_order", [])
    sweeps_left, links_left = iter(sweep_specs), iter(link_specs)
    groups: list[list[str]] = []
    for name in order:
        if name == "sweep_specs":
            groups.append([next(sweeps_left)])
        elif name == "link_specs":
            spec = next(links_left)
            if not groups:
                raise BadInput(
                    f"--link {spec}: a linked path varies with the --sweep before it; give a --sweep PATH=SPEC first"
                )
            groups[-1].append(spec)
    return groups


@main.command(cls=OrderedCommand)
@click.argument("gait_file", type=click.Path(exists=True, dir_okay=False))
@click.option(
    "--json", "as_json", is_flag=True, help="Print the run's JSON summary instead of v0 alone (single gait only)."
)
@click.option(
    "--sweep",
    "sweep_specs",
    multiple=True,
    metavar="PATH=SPEC",
    help="Sweep a dotted path of the gait document over SPEC: START:STOP:NUM "
    "(inclusive), log:LO:HI:NUM (log-spaced, inclusive), or a list [a,b,c] "
    "(or a,b,c). Repeat for a Cartesian grid, the last varying fastest.",
)
@click.option(
    "--link",
    "link_specs",
    multiple=True,
    metavar="PATH=SPEC",
    help="Vary PATH together with the --sweep before it (same number of values): "
    "value k of each goes with value k of the other; no new grid dimension.",
)
@click.option(
    "--sensitivity",
    "sensitivity_paths",
    multiple=True,
    metavar="PATH",
    help="Also print dv0/dPATH with its error estimate for every number PATH "
    "names (dotted, * for each element; repeatable): exact, or of the catch-up "
    "scheme's own map; with --sweep, a dv0/dPATH column per number.",
)
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, allow_dash=True),
    help="Write the table to OUT.csv or OUT.h5; - or no -o: CSV on stdout (v0, or JSON with --json, without --sweep).",
)
@click.option("-j", "--jobs", type=click.IntRange(min=1), default=1, show_default=True, help="Local worker processes.")
@click.option(
    "--shard",
    callback=_shard,
    metavar="I/N",
    help="Compute only the I-th of N disjoint parts of the grid (1 <= I <= N); "
    "needs -o PART.h5; join the parts with `crawlsim merge`.",
)
@click.option(
    "--scheduler",
    metavar="ADDRESS",
    help="Run on an existing Dask cluster (tcp://host:8786); needs pip install 'crawlsim[dask]'.",
)
@click.option(
    "--plot",
    "plot_file",
    type=click.Path(dir_okay=False),
    help="Draw v0 against one swept dimension, or a heat map over two (PNG); "
    "`crawlsim plot OUT.h5` draws it from a sweep file later.",
)
@simulation_options
@max_memory_option
@force_option
@feedback_options
def velocity(
    gait_file,
    as_json,
    sweep_specs,
    sensitivity_paths,
    link_specs,
    output,
    jobs,
    shard,
    scheduler,
    plot_file,
    steps_per_period,
    max_periods,
    tolerance,
    integrator,
    limit,
    max_memory,
    force,
    quiet,
    verbose,
):
    """Print v0 of GAIT_FILE, or sweep gait parameters and tabulate v0.

    Without --sweep, prints v0 alone on one line, with the digits its error estimate supports
    (--json: full precision and the estimate; exit code 3 if the run did not converge). A
    sweeping process (kind: sweeping-process) has no velocity and is refused (exit code 2;
    crawlsim run runs it). With
    --sweep, writes one row per grid point: the swept values, v0, v0_error_estimate,
    displacement_per_period, dissipation_per_period, cost_of_transport, convergence, periods,
    integrator, limit (newton or iterate), newton_steps, status (ok, not-converged, invalid,
    failed) and message. A point whose gait is
    invalid or whose run fails is recorded with its reason, the others run, and the exit code
    stays 0; a bad path, or a grid with no valid point, is refused (exit code 2). With -o,
    finished points are kept in OUT.journal: an interrupted sweep (Ctrl-C: exit code 130)
    resumes when the same command is run again.

    \b
    Examples:
      crawlsim velocity gaits/peristalsis-4.yaml
      crawlsim velocity gaits/inching-2.yaml --json
      crawlsim velocity gaits/peristalsis-4.yaml --sensitivity 'links.*.phase' \\
          --sensitivity stiffness
      crawlsim velocity gaits/peristalsis-4.yaml --sweep 'links.*.amplitude=0.1:0.4:7' \\
          --steps-per-period 100
      crawlsim velocity gaits/peristalsis-3.yaml --sweep links.1.phase=0:1:11 \\
          --sweep 'friction.backward=[1.5,2.5,3.5]' -o lag.h5 -j 2 --plot lag.png \\
          --steps-per-period 100
      crawlsim velocity gaits/inching-2.yaml --sweep stiffness=log:5:50:9 -o - | cut -d, -f1,2
      crawlsim velocity gaits/peristalsis-3.yaml --sweep links.0.phase=0:0.5:6 \\
          --link links.1.phase=0:1:6 --steps-per-period 100
      for i in 1 2 3; do crawlsim velocity gaits/inching-2.yaml --sweep period=0.5:2:16 \\
          --shard $i/3 -o part-$i.h5; done && crawlsim merge part-*.h5 -o all.h5
    """
    check_feedback(quiet, verbose)
    output = None if output == "-" else output  # stdout is where the table (or v0) goes
    with library_errors():
        _check_targets(gait_file, output, plot_file, scheduler, force)
        groups = _dimensions(sweep_specs, link_specs)
        gait = load_with_overrides(gait_file, steps_per_period, max_periods, tolerance, integrator, limit)
        from crawlsim.gait.document import need_crawler

        need_crawler(gait)
        warn_unchecked(gait)
        if not groups:
            if shard or plot_file:
                raise BadInput("--shard and --plot need at least one --sweep PATH=SPEC")
            if output is None:
                from crawlsim.analysis.sensitivity_sweep import check_paths

                check_paths(gait, sensitivity_paths)  # before the run
                return _single(gait, sensitivity_paths, as_json, max_memory, quiet, verbose)
        _check_sweep_options(groups, as_json, plot_file, shard)
        from crawlsim.study import sweep as sweeps

        grid = sweeps.make_grid(gait, groups, sensitivity=sensitivity_paths)
        check_sweep_memory(grid, len(grid.indices(shard)), jobs, scheduler, max_memory)
        table = _sweep(grid, output, jobs, shard, scheduler, quiet, verbose)
        if plot_file:
            sweeps.plot_table(table, plot_file)
    if output is None:
        click.echo(table.to_csv(), nl=False)
    counts = table.counts()
    if len(table.rows) != counts["ok"]:
        click.echo(
            f"{len(table.rows)} points: {counts['ok']} ok, {counts['invalid']} invalid, "
            f"{counts['failed']} failed, {counts['not-converged']} not converged (see "
            "the status and message columns)",
            err=True,
        )


def _check_targets(gait_file, output, plot_file, scheduler, force) -> None:
    """Refuse, before the gait is read, a --scheduler that is no address and outputs that may
    not be written (`crawlsim.io.outputs.check_target`)."""
    from crawlsim.io.outputs import FIGURE, SWEEP, check_target

    if scheduler is not None:
        from crawlsim.study.executors import check_scheduler

        check_scheduler(scheduler)
    if output is not None and plot_file is not None and os.path.abspath(output) == os.path.abspath(plot_file):
        raise BadInput(f"--plot {plot_file}: is also the --output file; give two names")
    for path, kind, option in ((output, SWEEP, "--output"), (plot_file, FIGURE, "--plot")):
        if path is not None:
            check_target(path, kind, inputs=[gait_file], force=force, option=option)
    if plot_file is not None and os.path.splitext(plot_file)[1].lower() not in (".png", ".pdf", ".svg"):
        raise BadInput(f"--plot {plot_file}: a figure is written as .png, .pdf or .svg")


def _check_sweep_options(groups, as_json, plot_file, shard) -> None:
    if as_json and groups:
        raise BadInput("--json prints one run's summary; with --sweep the table is CSV or HDF5 (-o)")
    if plot_file and shard:
        raise BadInput("--plot needs the whole grid: plot after `crawlsim merge`")
    if plot_file and len(groups) not in (1, 2):
        raise BadInput(f"--plot draws one or two swept dimensions, got {len(groups)}")


def _single(gait, sensitivity_paths, as_json, max_memory, quiet, verbose):
    """v0 of one gait (`crawlsim.api.run`), with its sensitivities if asked; exit code 3 when
    the run did not converge."""
    from crawlsim import api

    check_memory(gait, max_memory)
    with run_progress(gait, quiet, verbose) as progress:
        result = api.run(gait, progress=progress, history=False)
        derivatives = None
        if sensitivity_paths:
            from crawlsim.cli import sensitivities

            derivatives = sensitivities.compute(gait, sensitivity_paths, result)
    summary = result.summary()
    if as_json:
        if derivatives is not None:
            summary["sensitivity"] = derivatives.summary()
        click.echo(to_json(summary))
    else:  # the digits its error estimate supports (--json: full precision)
        from crawlsim.analysis.digits import supported

        assert result.v0 is not None  # a crawler (need_crawler): v0 is measured
        click.echo(supported(result.v0, result.v0_error_estimate)[0])
        if derivatives is not None:
            sensitivities.echo(derivatives, summary["integrator"])
    if not result.converged:
        from crawlsim.analysis.run import not_converged_message

        s = gait.simulation
        click.echo(not_converged_message(result, s.max_periods, s.tolerance, s.limit), err=True)
        sys.exit(EXIT_NOT_CONVERGED)


def _sweep(grid, output, jobs, shard, scheduler, quiet, verbose):
    """Run the sweep with progress on stderr; an interrupt says what was kept, then exits 130."""
    from crawlsim.study import sweep as sweeps

    total = len(grid.indices(shard))
    bar = Progress("velocity", "point", total, mode=choose_mode(quiet))

    def on_rows(rows, resumed):
        if resumed:
            bar.skip(len(rows))
            if verbose:
                bar.message(f"resuming: {len(rows)} of {total} points read from {sweeps.journal_path(output)}")
        elif verbose:
            for r in rows:
                if r.status in ("invalid", "failed"):
                    bar.message(f"point {r.index} {r.status}: {r.message}")

    try:
        table = sweeps.sweep(
            grid, output=output, jobs=jobs, shard=shard, scheduler=scheduler, progress=bar.update, on_rows=on_rows
        )
    except sweeps.SweepInterrupted as exc:
        bar.close()
        where = "not kept (no -o)" if exc.journal is None else "nothing to keep"
        if exc.journal is not None and exc.done:  # the journal exists once a point is in it
            where = f"kept in {exc.journal}; run the same command again to resume"
        click.echo(f"Interrupted: {exc.done} of {exc.total} points finished, {where}.", err=True)
        raise interrupt_exit(exc) from None
    except BaseException:
        bar.close()
        raise
    bar.close(complete=True)
    return table
