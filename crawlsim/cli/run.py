"""``crawlsim run``: simulate one gait to its periodic regime."""

from __future__ import annotations

import sys

import click

from . import (
    EXIT_NOT_CONVERGED,
    BadInput,
    _output_path,
    check_feedback,
    feedback_options,
    library_errors,
    load_with_overrides,
    main,
    run_progress,
    simulation_options,
    to_json,
)


@main.command()
@click.argument("gait_file", type=click.Path(exists=True, dir_okay=False))
@click.option("-o", "--output", type=click.Path(dir_okay=False, allow_dash=True),
              help="HDF5 results file (default: <gait stem>.h5 in the current folder). HDF5 "
                   "cannot stream, so not '-': use --json for a summary on stdout.")
@simulation_options
@click.option("--save-every", type=click.IntRange(min=1), default=1, show_default=True,
              help="Write every K-th grid point of the trajectory (bounds the file size).")
@click.option("--check-every-step", is_flag=True,
              help="Run Clarabel at every step instead of the certified fast paths.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
@click.option("--plot", is_flag=True,
              help="Also draw the figures next to the results file (<stem>-<figure>.png).")
@feedback_options
def run(gait_file, output, steps_per_period, max_periods, tolerance, save_every,
        check_every_step, as_json, plot, quiet, verbose):
    """Simulate GAIT_FILE to its periodic regime; report v0 and write an HDF5 file.

    Progress goes to stderr: a bar on a terminal, whose total is the number of periods
    estimated from the contraction of the Poincare steps; elsewhere a line every 10 s.

    \b
    Examples:
      crawlsim run gaits/peristalsis-4.yaml
      crawlsim run gaits/peristalsis-4.yaml --integrator exact -o exact.h5
      crawlsim run gaits/inching-2.yaml --json | python -m json.tool
      crawlsim run gaits/inching-2.yaml --max-periods 500 --quiet -o inching.h5
    """
    check_feedback(quiet, verbose)
    if output == "-":
        raise BadInput("--output -: the results of a run are an HDF5 file, which cannot be "
                       "streamed to stdout; give a file name (-o run.h5), and --json prints "
                       "the summary on stdout")
    from .. import api
    from ..analysis import summary_text

    with library_errors():
        gait = load_with_overrides(gait_file, steps_per_period, max_periods, tolerance)
        out = _output_path(output, gait_file)
        with run_progress(gait, quiet, verbose) as progress:
            result = api.run(gait, output=out, save_every=save_every,
                             check_every_step=check_every_step, progress=progress)
        figures = []
        if plot:
            from ..plotting import plot_results

            figures = [str(f) for f in plot_results(out, out.resolve().parent, fmt="png")]
    if as_json:
        summary = result.summary()
        summary["output"] = str(out)
        if plot:
            summary["figures"] = figures
        click.echo(to_json(summary))
    else:
        click.echo(summary_text(result, str(out)))
        for figure in figures:
            click.echo(f"  figure                   {figure}")
    if not result.converged:
        sys.exit(EXIT_NOT_CONVERGED)
