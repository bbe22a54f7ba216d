"""``crawlsim run``: simulate one gait to its periodic regime."""

from __future__ import annotations

import sys

import click

import crawlsim
from crawlsim import plotting
from crawlsim.analysis.digits import with_error
from crawlsim.analysis.report import not_converged_message, summary_text
from crawlsim.cli import (
    EXIT_NOT_CONVERGED,
    BadInput,
    _output_path,
    feedback_options,
    library_errors,
    main,
    run_progress,
    simulation_options,
    to_json,
)
from crawlsim.cli.guards import check_memory, force_option, max_memory_option, plot_options, warn_unchecked
from crawlsim.io.outputs import FIGURE, check_target

#: Largest ``--save-every``: grid points are counted in int64 (a run has at most 10^8 steps per
#: period, so any larger value saves only each period's first point anyway).
MAX_SAVE_EVERY = 2**62


@main.command()
@click.argument("gait_file", required=False, type=click.Path(exists=True, dir_okay=False))
@click.option(
    "--from",
    "from_results",
    type=click.Path(exists=True, dir_okay=False),
    metavar="RESULT.h5",
    help="Rerun the run recorded in a results file: its effective gait document "
    "and integrator settings (v0 is reproduced bit for bit); options given "
    "override them. Instead of GAIT_FILE.",
)
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, allow_dash=True),
    help="HDF5 results file (default: <gait stem>.h5 in the current folder; "
    "<results stem>-rerun.h5 with --from). HDF5 cannot stream, so not '-': "
    "use --json for a summary on stdout.",
)
@simulation_options
@click.option(
    "--save-every",
    type=click.IntRange(min=1),
    help="Write every K-th grid point of the trajectory (bounds the file size). [default: 1; with --from, the file's]",
)
@click.option(
    "--check-every-step", is_flag=True, help="Run Clarabel at every step instead of the certified fast paths."
)
@click.option(
    "--rigid",
    is_flag=True,
    help="Also compute the rigid limit (links infinitely stiff): its v0 in the summary, "
    "which block rests when in the file's /rigid group, and with --plot its figure.",
)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
@plot_options
@max_memory_option
@force_option
@feedback_options
def run(
    gait_file,
    from_results,
    output,
    settings,
    save_every,
    check_every_step,
    rigid,
    as_json,
    plot,
    figures,
    max_memory,
    force,
    feedback,
):
    """Simulate GAIT_FILE to its periodic regime; report v0 and write an HDF5 file.

    Progress goes to stderr: a bar on a terminal, whose total is the number of periods
    estimated from the contraction of the Poincare steps; elsewhere a line every 10 s.

    \b
    Examples:
      crawlsim run gaits/peristalsis-4.yaml
      crawlsim run gaits/peristalsis-4.yaml --integrator exact -o exact.h5
      crawlsim run gaits/inching-2.yaml --json | python -m json.tool
      crawlsim run gaits/peristalsis-4.yaml --rigid --plot
      crawlsim run gaits/inching-2.yaml --max-periods 500 --quiet -o inching.h5
      crawlsim run gaits/inching-2.yaml -o inching.h5 --plot --plot-format pdf
      crawlsim run --from inching.h5 -o again.h5
    """
    from pathlib import Path

    if (gait_file is None) == (from_results is None):
        raise BadInput("give a gait file or --from RESULT.h5 (one of the two)")
    if output == "-":
        raise BadInput(
            "--output -: the results of a run are an HDF5 file, which cannot be "
            "streamed to stdout; give a file name (-o run.h5), and --json prints "
            "the summary on stdout"
        )
    drawing = plot.settings(figures)
    options, fmt = drawing or (None, "png")
    with library_errors():
        if from_results is not None:
            rerun = crawlsim.api.from_results(from_results, **settings.given())
            gait, check_every_step = rerun.gait, check_every_step or rerun.check_every_step
            save_every = save_every or rerun.save_every
            out = _output_path(output, Path(from_results).stem + "-rerun", force, inputs=[from_results])
        else:
            gait = crawlsim.api.load_gait(gait_file, **settings.given())
            out = _output_path(output, gait_file, force)
            save_every = save_every or 1
        if save_every > MAX_SAVE_EVERY:
            raise BadInput(
                f"--save-every {save_every}: expected a number of steps from 1 to "
                f"{MAX_SAVE_EVERY:,} (the grid points are counted in 64-bit integers)"
            )
        check_memory(gait, max_memory, save_every=save_every)
        limit = None
        if rigid:  # before the run: a gait it refuses is refused at once
            from crawlsim.gait.crawler_spec import need_crawler  # start-up: numpy and YAML when it runs

            need_crawler(gait, "crawlsim run --rigid")
            limit = crawlsim.api.rigid_limit(gait)
        names = (*plotting.FIGURE_NAMES, plotting.RIGID_FIGURE) if rigid else plotting.FIGURE_NAMES
        for name in names if drawing else ():
            target = out.parent / f"{out.stem}-{name}.{fmt}"
            check_target(target, FIGURE, inputs=[gait_file or from_results], force=force, option="--plot")
        warn_unchecked(gait)
        with run_progress(gait, feedback) as progress:
            result = crawlsim.api.run(
                gait,
                output=out,
                save_every=save_every,
                check_every_step=check_every_step,
                progress=progress,
                rigid=limit,
            )
        drawn = [str(f) for f in plotting.plot_results(out, out.parent, fmt=fmt, options=options)] if drawing else []
    if as_json:
        summary = result.summary()
        summary["output"] = str(out)
        if limit is not None:
            summary["rigid"] = limit.summary()
        if drawing:
            summary["figures"] = drawn
        click.echo(to_json(summary))
    else:
        text = summary_text(result.run, str(out), result.units)
        if limit is not None:
            text += f"\n  rigid limit v0           {with_error(limit.v0, limit.v0_error_estimate)} (k -> infinity)"
        click.echo(text)
        for figure in drawn:
            click.echo(f"  figure                   {figure}")
    if not result.converged:
        click.echo(not_converged_message(result.run), err=True)
        sys.exit(EXIT_NOT_CONVERGED)
