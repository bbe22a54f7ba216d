"""``crawlsim stall``: the stall force of a gait, or the steepest slope it climbs."""

from __future__ import annotations

import click

from crawlsim.analysis.digits import with_error
from crawlsim.cli import BadInput, library_errors, main, to_json


@main.command()
@click.argument("gait_file", type=click.Path(dir_okay=False))
@click.option(
    "--force",
    "force_path",
    metavar="PATH",
    help="A force of the gait's loads: block to vary, such as loads.force.0 (the "
    "force on block 1) or loads.force (one force on every block).",
)
@click.option(
    "--slope",
    is_flag=True,
    help="Vary loads.slope.angle instead: the steepest slope, in degrees, at which the gait still climbs.",
)
@click.option("--json", "as_json", is_flag=True, help="Print the result as JSON, at full precision, with its bracket.")
def stall(gait_file, force_path, slope, as_json):
    """Print the load at which v0 reaches 0: the stall force (--force PATH) or the steepest
    climbable slope (--slope), with the bracket it was found in and its cause.

    The load is varied from the gait's own value in the direction that opposes the motion, and
    the boundary of the loads at which the crawler still moves its way is bracketed and bisected
    (docs/model.md §6). The cause is a smooth zero of v0, a jump of v0 where the shifted
    friction thresholds violate the uniqueness condition (the blocks J are named), or the body
    no longer holding its loads. Only the digits the bracket supports are printed.

    \b
    Examples:
      crawlsim stall gaits/inching-2-towing.yaml --force loads.force.0
      crawlsim stall gaits/climbing-3.yaml --slope --json
    """
    if (force_path is None) == (not slope):
        raise BadInput("give exactly one of --force PATH and --slope")
    with library_errors():
        from crawlsim.design.stall import stall as find_stall  # start-up: the library when the command runs

        result = find_stall(gait_file, force=force_path, slope=slope)
    if as_json:
        click.echo(to_json(result.summary()))
        return
    unit = f" {result.unit}" if result.unit else ""
    what = "steepest climbable slope" if result.quantity == "slope" else f"stall force ({result.path})"
    lo, hi = sorted(result.bracket)
    cause = {
        "smooth-zero": "v0 reaches 0 smoothly",
        "jump": "v0 jumps to 0 or across it where the shifted thresholds violate the uniqueness "
        "condition" + ("" if result.subset is None else f" (J = {{{', '.join(map(str, result.subset))}}})"),
        "hold": "the body can no longer hold its loads",
    }[str(result.cause)]
    click.echo(f"{what}: {with_error(result.value, result.error_estimate, unit)}")
    click.echo(f"  bracket  [{lo:.12g}, {hi:.12g}]{unit}")
    click.echo(f"  cause    {result.cause}: {cause}")
    click.echo(
        f"  v0       {result.v0_start:.12g} at {result.start:.12g}{unit}, "
        f"{result.v0_moving:.6g} at the bracket's moving side"
    )
