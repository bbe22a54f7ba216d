"""``crawlsim plot``: draw the figures of a results file (a run, a sweep or an optimisation)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import click

from ..errors import CrawlsimError
from ..plotting import FIGURE_NAMES, OPTIMIZATION_FIGURES
from . import BadInput, library_errors, main
from .guards import force_option

if TYPE_CHECKING:  # pathlib is imported where used: `crawlsim --help` needs none of it
    from pathlib import Path


def _coords(ctx, param, value):
    try:
        pair = tuple(int(v) for v in value.split(","))
    except ValueError:
        pair = ()
    if len(pair) != 2 or pair[0] == pair[1] or min(pair) < 1:
        raise click.BadParameter(f"{value!r}: expected two different shape coordinates, "
                                 "counted from 1, such as 1,3")
    return pair[0] - 1, pair[1] - 1


@main.command()
@click.argument("results_file", type=click.Path(dir_okay=False))
@click.option("-o", "--output-dir", type=click.Path(file_okay=False),
              help="Folder for the figures (default: the results file's folder; created if "
                   "missing).")
@click.option("--format", "fmt", type=click.Choice(["png", "pdf", "svg"]), default="png",
              show_default=True, help="Image format.")
@click.option("--only", type=click.Choice(FIGURE_NAMES + OPTIMIZATION_FIGURES),
              help="Draw this figure only (runs, optimisations).")
@click.option("--coords", default="1,2", show_default=True, callback=_coords,
              help="Shape coordinates i,j of the shape-space figure when there are more than "
                   "two (four or more blocks): it shows sections of K(t) in that plane.")
@force_option
def plot(results_file, output_dir, fmt, only, coords, force):
    """Draw the figures of RESULTS_FILE as <stem>-<figure>.<format>.

    \b
    Figures of a run (crawlsim run): motion (block positions, barycentre, slope v0),
    gait-diagram (slip bands, lengths, stresses and block forces against the friction limits
    over the limit period), convergence (Poincare step, W^{1,2} distance, |v_q - v0| per
    period), shape-space (K(t) and the orbit of w(t)).
    The figure of a sweep file (crawlsim velocity --sweep ... -o SWEEP.h5, crawlsim merge):
    <stem>-sweep, v0 against the swept value for one swept dimension, a heat map over two,
    points without a v0 (invalid or failed) marked.
    The figures of an optimisation file (crawlsim optimize): <stem>-objective, the best value
    against the points simulated; with --pareto, <stem>-pareto-front, the cost of transport
    against v0 with the front and the chosen gaits marked.

    \b
    Examples:
      crawlsim run gaits/peristalsis-4.yaml && crawlsim plot peristalsis-4.h5
      crawlsim plot peristalsis-4.h5 --only shape-space --coords 1,3 -o figures --format pdf
      crawlsim velocity gaits/inching-2.yaml --sweep 'friction.backward=0.5:3:11' \\
          -o sweep.h5 && crawlsim plot sweep.h5
    """
    from ..h5io import describe

    with library_errors():
        kind = describe(results_file)["file_kind"]
        _check_targets(results_file, output_dir, fmt, only, kind, force)
        if kind == "sweep":
            written = [_plot_sweep(results_file, output_dir, fmt, only)]
        elif kind == "optimization":
            written = _plot_optimization(results_file, output_dir, fmt, only)
        else:
            written = _plot_run(results_file, output_dir, fmt, only, coords)
    for path in written:
        click.echo(str(path))


def _check_targets(results_file, output_dir, fmt, only, kind, force) -> None:
    """Refuse figure files that may not be replaced (`crawlsim.outputs.check_target`)."""
    from pathlib import Path

    from ..outputs import FIGURE, check_target

    folder = Path(output_dir) if output_dir else Path(results_file).parent
    if not folder.is_dir():
        return  # created by plot_results: nothing in it to protect
    every = {"sweep": ["sweep"], "optimization": list(OPTIMIZATION_FIGURES)}.get(kind,
                                                                                 FIGURE_NAMES)
    names = [only] if only and only in every else every
    for name in names:
        check_target(folder / f"{Path(results_file).stem}-{name}.{fmt}", FIGURE,
                     inputs=[results_file], force=force, option="--output-dir")


def _plot_optimization(results_file, output_dir, fmt, only):
    from ..plotting import plot_results

    if only is not None and only not in OPTIMIZATION_FIGURES:
        raise BadInput(f"--only {only}: {results_file} is an optimisation file, whose figures "
                       f"are {', '.join(OPTIMIZATION_FIGURES)}")
    try:
        return plot_results(results_file, output_dir, fmt=fmt, only=only)
    except ValueError as exc:
        if isinstance(exc, CrawlsimError):
            raise
        raise BadInput(f"{results_file}: {exc}") from None


def _plot_run(results_file, output_dir, fmt, only, coords):
    from ..plotting import plot_results

    try:
        return plot_results(results_file, output_dir, fmt=fmt, only=only, coords=coords)
    except ValueError as exc:
        if isinstance(exc, CrawlsimError):
            raise
        raise BadInput(f"{results_file}: {exc}") from None


def _plot_sweep(results_file, output_dir, fmt, only) -> Path:
    from pathlib import Path

    from .. import sweep as sweeps

    if only is not None:
        raise BadInput(f"--only {only}: {results_file} is a sweep file, whose one figure is "
                       "the sweep; --only chooses among the figures of a run")
    table = sweeps.read_table(results_file)
    if len(table.dimension_paths()) not in (1, 2):
        raise BadInput(f"{results_file}: a sweep figure shows one or two swept dimensions, "
                       f"this sweep has {len(table.dimension_paths())}")
    if table.shard is not None:
        raise BadInput(f"{results_file}: is shard {table.shard[0]}/{table.shard[1]} of a "
                       "sweep; plot the file `crawlsim merge` writes from all the shards")
    path = Path(results_file)
    folder = Path(output_dir) if output_dir is not None else path.resolve().parent
    folder.mkdir(parents=True, exist_ok=True)
    target = folder / f"{path.stem}-sweep.{fmt}"
    sweeps.plot_table(table, target)
    return target
