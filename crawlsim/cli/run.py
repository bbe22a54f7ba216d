"""``crawlsim run``: simulate one gait to its periodic regime."""

from __future__ import annotations

import sys

import click

from .. import api
from ..analysis import summary_text
from . import (
    EXIT_NOT_CONVERGED,
    _output_path,
    library_errors,
    load_with_overrides,
    main,
    period_progress,
    simulation_options,
    to_json,
)
from .guards import check_memory, force_option, max_memory_option, warn_unchecked


@main.command()
@click.argument("gait_file", type=click.Path(exists=True, dir_okay=False))
@click.option("-o", "--output", type=click.Path(dir_okay=False),
              help="HDF5 results file (default: <gait stem>.h5 in the current folder).")
@simulation_options
@click.option("--save-every", type=click.IntRange(min=1), default=1, show_default=True,
              help="Write every K-th grid point of the trajectory (bounds the file size).")
@click.option("--check-every-step", is_flag=True,
              help="Run Clarabel at every step instead of the certified fast paths.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
@click.option("--plot", is_flag=True,
              help="Also draw the figures next to the results file (<stem>-<figure>.png).")
@max_memory_option
@force_option
def run(gait_file, output, steps_per_period, max_periods, tolerance, save_every,
        check_every_step, as_json, plot, max_memory, force):
    """Simulate GAIT_FILE to its periodic regime; report v0 and write an HDF5 file.

    \b
    Examples:
      crawlsim run gaits/peristalsis-4.yaml
      crawlsim run gaits/peristalsis-4.yaml --steps-per-period 4000 -o fine.h5
      crawlsim run gaits/inching-2.yaml --json | python -m json.tool
    """
    with library_errors():
        gait = load_with_overrides(gait_file, steps_per_period, max_periods, tolerance)
        check_memory(gait, max_memory, save_every=save_every)
        out = _output_path(output, gait_file, force)
        if plot:
            from ..outputs import FIGURE, check_target
            from ..plotting import FIGURE_NAMES

            for name in FIGURE_NAMES:
                check_target(out.parent / f"{out.stem}-{name}.png", FIGURE, inputs=[gait_file],
                             force=force, option="--plot")
        warn_unchecked(gait)
        with period_progress(gait.simulation.max_periods, not as_json) as progress:
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

