"""``crawlsim plot``: draw the figures of a results file."""

from __future__ import annotations

import click

from ..errors import CrawlsimError
from ..plotting import FIGURE_NAMES
from . import BadInput, library_errors, main
from .guards import force_option


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
@click.option("--only", type=click.Choice(FIGURE_NAMES), help="Draw this figure only.")
@click.option("--coords", default="1,2", show_default=True, callback=_coords,
              help="Shape coordinates i,j of the shape-space figure when there are more than "
                   "two (four or more blocks): it shows sections of K(t) in that plane.")
@force_option
def plot(results_file, output_dir, fmt, only, coords, force):
    """Draw the figures of RESULTS_FILE as <stem>-<figure>.<format>.

    \b
    Figures: motion (block positions, barycentre, slope v0), gait-diagram (slip bands, lengths,
    stresses and block forces against the friction limits over the limit period), convergence
    (Poincare step, W^{1,2} distance, |v_q - v0| per period), shape-space (K(t) and the orbit
    of w(t)).

    \b
    Examples:
      crawlsim plot peristalsis-4.h5
      crawlsim plot run.h5 -o figures --format pdf
      crawlsim plot peristalsis-4.h5 --only shape-space --coords 1,3
    """
    from pathlib import Path

    from ..outputs import FIGURE, check_target
    from ..plotting import plot_results

    with library_errors():
        folder = Path(output_dir) if output_dir else Path(results_file).parent
        if folder.is_dir():
            for name in [only] if only else FIGURE_NAMES:
                check_target(folder / f"{Path(results_file).stem}-{name}.{fmt}", FIGURE,
                             inputs=[results_file], force=force, option="--output-dir")
        try:
            written = plot_results(results_file, output_dir, fmt=fmt, only=only, coords=coords)
        except ValueError as exc:
            if isinstance(exc, CrawlsimError):
                raise
            raise BadInput(f"{results_file}: {exc}") from None
    for path in written:
        click.echo(str(path))
