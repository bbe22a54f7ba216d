"""``crawlsim animate``: the blocks and links of a run in motion, as a GIF (or an MP4)."""

from __future__ import annotations

import click

from crawlsim.cli import BadInput, library_errors, main
from crawlsim.cli.guards import FiniteFloatRange, force_option
from crawlsim.io.outputs import FIGURE, check_target


@main.command()
@click.argument("results_file", type=click.Path(exists=True, dir_okay=False))
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False),
    help="The animation: .gif, or .mp4 where ffmpeg is installed (default: <stem>.gif beside the results file).",
)
@click.option(
    "--periods",
    metavar="A:B",
    help="Animate t from A T to B T (periods A to B-1 of the stored trajectory) instead of the limit period.",
)
@click.option(
    "--last",
    type=click.IntRange(min=1),
    metavar="K",
    help="Animate the last K periods of the stored trajectory in a frame that follows the crawler, "
    "with the barycentre's trace. Instead of --periods.",
)
@click.option(
    "--frames-per-period",
    type=click.IntRange(min=2, max=1000),
    default=40,
    show_default=True,
    help="Frames per period (fewer when the periods are many: at most 1200 frames).",
)
@click.option("--fps", type=FiniteFloatRange(min=1, max=100), default=20, show_default=True, help="Frames per second.")
@click.option(
    "--dpi",
    type=FiniteFloatRange(min=20, max=600),
    default=80,
    show_default=True,
    help="Resolution of the frames (dots per inch; frames are 8 x 5.6 in).",
)
@force_option
def animate(results_file, output, periods, last, frames_per_period, fps, dpi, force):
    """Animate the run in RESULTS_FILE: the blocks and links move over the limit period.

    Blocks are coloured by their slip state (stick, forward slip, backward slip, as in the
    gait diagram), links by their stress; below, the length and the stress of each link. A
    100-block crawler is drawn as a thin strip, its lengths and stresses as curves along it.

    \b
    Examples:
      crawlsim run gaits/peristalsis-4.yaml -o p4.h5 && crawlsim animate p4.h5 -o crawl.gif
      crawlsim animate p4.h5 --periods 0:2 -o start.gif --frames-per-period 20
      crawlsim animate p4.h5 --last 2 -o follow.gif --frames-per-period 20
    """
    from pathlib import Path

    from crawlsim.io.runread import read_results  # start-up: h5py and matplotlib when the command runs
    from crawlsim.plotting.animation import ANIMATION_FORMATS, parse_periods, write_animation  # (idem)

    target = Path(output) if output else Path(results_file).with_suffix(".gif")
    if target.suffix.lower().lstrip(".") not in ANIMATION_FORMATS:
        raise BadInput(f"-o {target}: an animation is written as .gif or .mp4")
    span = None
    if periods is not None and last is not None:
        raise BadInput("--periods and --last choose the periods animated: give one of the two")
    if periods is not None:
        try:
            span = parse_periods(periods)
        except ValueError as exc:
            raise BadInput(str(exc)) from None
    with library_errors():
        check_target(target, FIGURE, inputs=[results_file], force=force, option="--output")
        results = read_results(results_file)
        if results["attrs"].get("kind", "crawler") != "crawler":
            raise BadInput(
                f"{results_file}: a generic sweeping process has no blocks to animate; animate a crawler's run"
            )
        try:
            path, count = write_animation(
                results, target, periods=span, frames_per_period=frames_per_period, fps=fps, dpi=dpi, last=last
            )
        except ValueError as exc:
            raise BadInput(f"{results_file}: {exc}") from None
    click.echo(f"{path} ({count} frames, {count / fps:.3g} s)")
