"""``crawlsim velocity``: v0 of a gait, or a table of v0 over a parameter sweep."""

from __future__ import annotations

import sys
from pathlib import Path

import click

import crawlsim
from crawlsim.analysis.digits import counted, supported, with_error
from crawlsim.analysis.report import not_converged_message
from crawlsim.cli import (
    EXIT_NOT_CONVERGED,
    BadInput,
    OrderedCommand,
    feedback_options,
    interrupt_exit,
    library_errors,
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
    plot_options,
    warn_unchecked,
)
from crawlsim.cli.progress import Progress
from crawlsim.io.outputs import FIGURE, SWEEP, check_target

#: Kinks a line of ``--sensitivity`` names one by one; more are counted, and ``--json`` keeps them all.
MAX_KINKS = 3


def _shard(ctx, param, value):
    if value is None:
        return None
    from crawlsim.study.grid import parse_shard  # start-up: numpy and YAML only when the command runs

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
@click.argument("gait_files", nargs=-1, required=True, type=click.Path(exists=True, dir_okay=False))
@click.option(
    "--json",
    "as_json",
    is_flag=True,
    help="Print the run's JSON summary instead of v0 alone; with several gait files, a JSON line per file.",
)
@click.option(
    "--rigid",
    is_flag=True,
    help="v0 in the rigid limit (links infinitely stiff): exact, without stepping; "
    "--json adds its estimate and which block rests when.",
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
@plot_options
@simulation_options
@max_memory_option
@force_option
@feedback_options
def velocity(
    gait_files,
    as_json,
    rigid,
    sweep_specs,
    sensitivity_paths,
    link_specs,
    output,
    jobs,
    shard,
    scheduler,
    plot,
    figures,
    settings,
    max_memory,
    force,
    feedback,
):
    """Print v0 of GAIT_FILE, tabulate v0 of several, or sweep gait parameters.

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

    With several GAIT_FILEs (a shell glob, say), all run in this process (or on -j workers, a
    --scheduler or --shard parts, as a sweep's points) and the table has a row per file: its
    first column gait is the file, the others those of a sweep; a file that is not a valid
    crawler gait is a row with status invalid and its reason, and the exit code stays 0 (2 if
    no file is valid).

    \b
    Examples:
      crawlsim velocity gaits/peristalsis-4.yaml
      crawlsim velocity gaits/inching-2.yaml --json
      crawlsim velocity gaits/*.yaml -o all.csv
      crawlsim velocity gaits/peristalsis-4.yaml --rigid
      crawlsim velocity gaits/peristalsis-4.yaml --sensitivity 'links.*.phase' \\
          --sensitivity stiffness
      crawlsim velocity gaits/peristalsis-4.yaml --sweep 'links.*.amplitude=0.1:0.4:7' \\
          --steps-per-period 100
      crawlsim velocity gaits/peristalsis-3.yaml --sweep links.1.phase=0:1:11 \\
          --sweep 'friction.backward=[1.5,2.5,3.5]' -o lag.h5 -j 2 --plot \\
          --steps-per-period 100
      crawlsim velocity gaits/inching-2.yaml --sweep stiffness=log:5:50:9 -o - | cut -d, -f1,2
      crawlsim velocity gaits/peristalsis-3.yaml --sweep links.0.phase=0:0.5:6 \\
          --link links.1.phase=0:1:6 --steps-per-period 100
      for i in 1 2 3; do crawlsim velocity gaits/inching-2.yaml --sweep period=0.5:2:16 \\
          --shard $i/3 -o part-$i.h5; done && crawlsim merge part-*.h5 -o all.h5
    """
    from crawlsim.gait.crawler_spec import need_crawler  # start-up: numpy and YAML when the command runs
    from crawlsim.gait.docpaths import check_number_paths

    output = None if output == "-" else output  # stdout is where the table (or v0) goes
    if len(gait_files) > 1:
        if sweep_specs or link_specs or sensitivity_paths or plot.plot or rigid:
            raise BadInput("--sweep, --link, --sensitivity, --plot and --rigid take one gait file; several were given")
        return _files(gait_files, settings.given(), output, as_json, jobs, shard, scheduler, feedback, force)
    (gait_file,) = gait_files
    drawing = plot.settings(figures)
    # the sweep's figure as `crawlsim plot OUT.h5` names it, next to OUT (or the gait's stem here)
    plot_file = None if drawing is None else _figure_path(output or Path(gait_file).name, drawing[1])
    with library_errors():
        _check_targets(gait_files, output, plot_file, scheduler, force)
        groups = _dimensions(sweep_specs, link_specs)
        gait = crawlsim.api.load_gait(gait_file, **settings.given())
        need_crawler(gait)
        warn_unchecked(gait)
        if rigid:
            if groups or sensitivity_paths or output:
                raise BadInput("--rigid prints one gait's rigid limit: without --sweep, --sensitivity or -o")
            return _rigid(gait, as_json)
        if not groups:
            if shard or plot_file:
                raise BadInput(
                    "--shard and --plot need at least one --sweep PATH=SPEC "
                    "(crawlsim run GAIT --plot draws the figures of one run)"
                )
            if output is None:
                check_number_paths(gait, sensitivity_paths, continuous=True)  # before the run
                return _single(gait, sensitivity_paths, as_json, max_memory, feedback)
        _check_sweep_options(groups, as_json, plot_file, shard)
        from crawlsim.study import sweep as sweeps  # start-up: h5py and the sweep engine only for sweeps

        grid = sweeps.make_grid(gait, groups, sensitivity=sensitivity_paths)
        check_sweep_memory(grid, len(grid.indices(shard)), jobs, scheduler, max_memory)
        table = _sweep(sweeps, grid, output, jobs, shard, scheduler, feedback)
        if drawing is not None:
            sweeps.plot_table(table, plot_file, options=drawing[0])
    if output is None:
        click.echo(table.to_csv(), nl=False)
    if drawing is not None:
        click.echo(str(plot_file), err=output is None)  # stdout holds the table without -o
    _count_line(table, counted(len(table.rows), "point"))


def _count_line(table, what: str) -> None:
    """On stderr, when some rows are not ok: how many of each status."""
    counts = table.counts()
    if len(table.rows) != counts["ok"]:
        click.echo(
            f"{what}: {counts['ok']} ok, {counts['invalid']} invalid, {counts['failed']} failed, "
            f"{counts['not-converged']} not converged (see the status and message columns)",
            err=True,
        )


def _files(gait_files, overrides, output, as_json, jobs, shard, scheduler, feedback, force):
    """v0 of every file: a sweep whose one dimension is the file (`crawlsim.study.grid.FileGrid`)."""
    from crawlsim.study import sweep as sweeps  # start-up: h5py and the sweep engine only for sweeps
    from crawlsim.study.grid import FileGrid  # (idem)

    with library_errors():
        _check_targets(gait_files, output, None, scheduler, force)
        sweeps.check_shard_output(shard, output)
        table = _sweep(sweeps, FileGrid.of(gait_files, overrides), output, jobs, shard, scheduler, feedback)
    if as_json:
        columns = table.columns()
        for n in range(len(table.rows)):
            click.echo(to_json({name: getattr(c[n], "item", lambda v=c[n]: v)() for name, c in columns.items()}))
    elif output is None:
        click.echo(table.to_csv(), nl=False)
    _count_line(table, f"{len(table.rows)} gait files")


def _figure_path(results, fmt: str) -> Path:
    """<stem>-sweep.<fmt> beside ``results``."""
    results = Path(results)
    return results.with_name(f"{results.stem}-sweep.{fmt}")


def _check_targets(gait_files, output, plot_file, scheduler, force) -> None:
    """Refuse, before the gait is read, a --scheduler that is no address and outputs that may
    not be written (`crawlsim.io.outputs.check_target`)."""
    if scheduler is not None:
        from crawlsim.study.executors import check_scheduler  # start-up: the sweep engine for sweeps

        check_scheduler(scheduler)
    for path, kind, option in ((output, SWEEP, "--output"), (plot_file, FIGURE, "--plot")):
        if path is not None:
            check_target(path, kind, inputs=list(gait_files), force=force, option=option)


def _check_sweep_options(groups, as_json, plot_file, shard) -> None:
    if as_json and groups:
        raise BadInput("--json prints one run's summary; with --sweep the table is CSV or HDF5 (-o)")
    if plot_file and shard:
        raise BadInput("--plot needs the whole grid: plot after `crawlsim merge`")
    if plot_file and len(groups) not in (1, 2):
        raise BadInput(f"--plot draws one or two swept dimensions, got {len(groups)}")


def _single(gait, sensitivity_paths, as_json, max_memory, feedback):
    """v0 of one gait (`crawlsim.api.run`), with its sensitivities if asked, at the limit
    period of this run (not searched twice); exit code 3 when the run did not converge."""
    check_memory(gait, max_memory)
    with run_progress(gait, feedback) as progress:
        result = crawlsim.api.run(gait, progress=progress, history=False)
        paths = list(sensitivity_paths)
        derivatives = crawlsim.api.sensitivity(gait, paths, run=result.settled) if paths else None
    summary = result.summary()
    if as_json:
        if derivatives is not None:
            summary["sensitivity"] = derivatives.summary()
        click.echo(to_json(summary))
    else:  # the digits its error estimate supports (--json: full precision)
        assert result.v0 is not None  # a crawler (need_crawler): v0 is measured
        click.echo(supported(result.v0, result.estimate.error_estimate)[0])
        for line in [] if derivatives is None else _sensitivity_lines(derivatives, summary["integrator"]):
            click.echo(line)
    if not result.converged:
        click.echo(not_converged_message(result.run), err=True)
        sys.exit(EXIT_NOT_CONVERGED)


def _sensitivity_lines(result, integrator: str) -> list[str]:
    """One line per parameter: dv0/dPATH with the digits its error estimate supports, or why
    it is not smooth with the one-sided values (whether they agree), or why it was not
    computed."""
    out = []
    for p in result.parameters:
        name = f"dv0/d{p.path}"
        if p.method == "unsupported":
            out.append(f"{name}: not computed: {p.reason}")
        elif p.smooth:
            out.append(f"{name} = {with_error(p.v0.value, p.v0.error_estimate)}")
        else:
            sides = []
            for side, why in (("left", p.left_reason), ("right", p.right_reason)):
                d = getattr(p, side)
                sides.append(f"{side} {with_error(d.value, d.error_estimate)}" if d is not None else f"{side}: {why}")
            kinks = (p.reason or "").split("; ")
            if len(kinks) > MAX_KINKS:  # a long body's many coincident events: --json lists them
                kinks = [f"{len(kinks)} coincident events, the first: {kinks[0]}; --json lists them all"]
            left, right = p.left, p.right
            if left is not None and right is not None and left.value is not None and right.value is not None:
                if abs(left.value - right.value) <= (left.error_estimate or 0.0) + (right.error_estimate or 0.0):
                    sides[-1] += ": the one-sided derivatives agree"
            out.append(f"{name}: not smooth ({'; '.join(kinks)}); " + ", ".join(sides))
    if integrator != "exact":
        out.append(
            f"(derivatives of the {integrator} scheme's own discrete period map at its "
            f"v0 = {result.v0:.12g}, not of the exact v0: method {integrator})"
        )
    return out


def _rigid(gait, as_json):
    """v0 in the rigid limit (`crawlsim.api.rigid_limit`), with the digits its estimate supports
    (--json: full precision, the estimate and the resting block's intervals)."""
    result = crawlsim.api.rigid_limit(gait)
    click.echo(
        to_json({"name": gait.name, **result.summary()})
        if as_json
        else supported(result.v0, result.v0_error_estimate)[0]
    )


def _sweep(sweeps, grid, output, jobs, shard, scheduler, feedback):
    """Run the sweep (``sweeps``: `crawlsim.study.sweep`) with progress on stderr; an interrupt
    says what was kept, then exits 130."""
    total = len(grid.indices(shard))
    bar = Progress("velocity", "point", total, mode=feedback.mode)

    def on_rows(rows, resumed):
        if resumed:
            bar.skip(len(rows))
            if feedback.verbose:
                bar.message(f"resuming: {len(rows)} of {total} points read from {sweeps.journal_path(output)}")
        elif feedback.verbose:
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
