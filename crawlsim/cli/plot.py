"""``crawlsim plot``: draw the figures of a results file (a run, a sweep or an optimisation)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import click

from crawlsim import plotting
from crawlsim.cli import BadInput, library_errors, main
from crawlsim.cli.guards import figure_format_of, figure_options, force_option
from crawlsim.errors import CrawlsimError
from crawlsim.io.outputs import FIGURE, check_target
from crawlsim.plotting import FIGURE_NAMES, OPTIMIZATION_FIGURES, RIGID_FIGURE

if TYPE_CHECKING:  # pathlib is imported where used: `crawlsim --help` needs none of it
    from pathlib import Path


def _coords(ctx, param, value):
    try:
        pair = tuple(int(v) for v in value.split(","))
    except ValueError:
        pair = ()
    if len(pair) != 2 or pair[0] == pair[1] or min(pair) < 1:
        raise click.BadParameter(f"{value!r}: expected two different shape coordinates, counted from 1, such as 1,3")
    return pair[0] - 1, pair[1] - 1


@main.command()
@click.argument("results_file", type=click.Path(dir_okay=False))
@click.option(
    "-o",
    "--output",
    "--output-dir",
    "output",
    type=click.Path(),
    help="A folder for the figures (default: the results file's folder; created if "
    "missing), or a file FIG.png, FIG.pdf or FIG.svg for one figure (--only, or "
    "a sweep file), its extension giving the format.",
)
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["png", "pdf", "svg"]),
    help="Image format of the figures written into a folder.  [default: png]",
)
@click.option(
    "--only",
    type=click.Choice((*FIGURE_NAMES, RIGID_FIGURE, *OPTIMIZATION_FIGURES)),
    help="Draw this figure only (runs, optimisations).",
)
@click.option(
    "--coords",
    default="1,2",
    show_default=True,
    callback=_coords,
    help="Shape coordinates i,j of the shape-space figure when there are more than "
    "two (four or more blocks): it shows sections of K(t) in that plane.",
)
@click.option(
    "--last",
    type=click.IntRange(min=1),
    metavar="K",
    help="The motion figure and the kymograph zoom on the last K periods of the run, following "
    "the crawler (default: the motion figure does so over 3 periods beyond 32 blocks).",
)
@figure_options
@force_option
def plot(results_file, output, fmt, only, coords, last, figures, force):
    """Draw the figures of RESULTS_FILE as <stem>-<figure>.<format>.

    \b
    Figures of a run (crawlsim run): motion (block positions, barycentre, slope v0),
    gait-diagram (slip bands, lengths, stresses and block forces against the friction limits
    over the limit period), kymograph (strain, slip and stress over the body and the limit
    period, or the last periods with --last), convergence (Poincare step, W^{1,2} distance to the last
    period, displacement of each period against v0 T), shape-space (K(t) and the orbit of
    w(t)).
    The figure of a sweep file (crawlsim velocity --sweep ... -o SWEEP.h5, crawlsim merge):
    <stem>-sweep, v0 against the swept value for one swept dimension, a heat map over two,
    points without a v0 (invalid or failed) marked, jumps of v0 drawn as jumps.
    The figures of an optimisation file (crawlsim optimize): <stem>-objective, the best value
    against the points simulated; with --pareto, <stem>-pareto-front, the cost of transport
    against v0 with the front and the chosen gaits marked.

    \b
    Examples:
      crawlsim run gaits/peristalsis-4.yaml && crawlsim plot peristalsis-4.h5
      crawlsim plot peristalsis-4.h5 --only shape-space --coords 1,3 -o figures --format pdf
      crawlsim plot peristalsis-4.h5 --only motion -o motion.pdf --figsize 3.5,2.6
      crawlsim plot peristalsis-4.h5 -o png300 --dpi 300 --style ggplot
      crawlsim plot peristalsis-4.h5 --only kymograph --last 2 -o last.png
      crawlsim velocity gaits/inching-2.yaml --sweep 'friction.backward=0.5:3:11' \\
          -o sweep.h5 && crawlsim plot sweep.h5
    """
    from pathlib import Path

    from crawlsim.io.describe import describe  # start-up: h5py when the command runs

    options = figures.options()
    target = None
    if output is not None and Path(output).suffix and not Path(output).is_dir():
        target = Path(output)
        fmt_of_file = figure_format_of(target, "-o")
        if fmt is not None and fmt != fmt_of_file:
            raise BadInput(
                f"--format {fmt} and -o {output}: the file's extension gives the format; give one of the two"
            )
        fmt = fmt_of_file
        output = None
    fmt = fmt or "png"
    if Path(results_file).suffix.lower() in (".yaml", ".yml") and Path(results_file).is_file():
        raise BadInput(
            f"{results_file}: a gait file, not a results file: `crawlsim run {results_file} --plot` "
            "runs it and draws its figures"
        )
    with library_errors():
        kind = describe(results_file)["file_kind"]
        if target is not None:
            check_target(target, FIGURE, inputs=[results_file], force=force, option="--output")
        else:
            _check_targets(results_file, output, fmt, only, kind, force)
        if kind == "sweep":
            written = [_plot_sweep(results_file, output, fmt, only, options, target)]
        else:
            written = _plot_file(results_file, output, fmt, only, coords, options, target, kind, last)
    for path in written:
        click.echo(str(path))


def _check_targets(results_file, output_dir, fmt, only, kind, force) -> None:
    """Refuse figure files that may not be replaced (`crawlsim.io.outputs.check_target`)."""
    from pathlib import Path

    folder = Path(output_dir) if output_dir else Path(results_file).parent
    if not folder.is_dir():
        return  # created by plot_results: nothing in it to protect
    every = {"sweep": ["sweep"], "optimization": list(OPTIMIZATION_FIGURES)}.get(kind, [*FIGURE_NAMES, RIGID_FIGURE])
    names = [only] if only and only in every else every
    for name in names:
        check_target(
            folder / f"{Path(results_file).stem}-{name}.{fmt}",
            FIGURE,
            inputs=[results_file],
            force=force,
            option="--output-dir",
        )


def _plot_file(results_file, output_dir, fmt, only, coords, options, target, kind, last):
    """The figures of a run or an optimisation file (`crawlsim.plotting.plot_results`)."""
    if only is not None and kind == "optimization" and only not in OPTIMIZATION_FIGURES:
        raise BadInput(
            f"--only {only}: {results_file} is an optimisation file, whose figures "
            f"are {', '.join(OPTIMIZATION_FIGURES)}"
        )
    try:
        return plotting.plot_results(
            results_file, output_dir, fmt=fmt, only=only, coords=coords, options=options, target=target, last=last
        )
    except ValueError as exc:
        if isinstance(exc, CrawlsimError):
            raise
        raise BadInput(f"{results_file}: {exc}") from None


def _plot_sweep(results_file, output_dir, fmt, only, options, target) -> Path:
    from pathlib import Path

    from crawlsim.study import sweep as sweeps  # start-up: matplotlib and the sweep table, when drawn

    if only is not None:
        raise BadInput(
            f"--only {only}: {results_file} is a sweep file, whose one figure is "
            "the sweep; --only chooses among the figures of a run"
        )
    table = sweeps.read_table(results_file)
    if len(table.dimension_paths()) not in (1, 2):
        raise BadInput(
            f"{results_file}: a sweep figure shows one or two swept dimensions, "
            f"this sweep has {len(table.dimension_paths())}"
        )
    if table.shard is not None:
        raise BadInput(
            f"{results_file}: is shard {table.shard[0]}/{table.shard[1]} of a "
            "sweep; plot the file `crawlsim merge` writes from all the shards"
        )
    path = Path(results_file)
    if target is None:
        folder = Path(output_dir) if output_dir is not None else path.resolve().parent
        target = folder / f"{path.stem}-sweep.{fmt}"
    target.parent.mkdir(parents=True, exist_ok=True)
    sweeps.plot_table(table, target, options=options)
    return target
