"""``crawlsim validate``: check gait files without running them, listing every error."""

from __future__ import annotations

import sys

import click

from crawlsim.cli import main


@main.command()
@click.argument("gait_files", nargs=-1, required=True, type=click.Path(dir_okay=False))
@click.option(
    "--explain",
    is_flag=True,
    help="Print the whole uniqueness analysis of each crawler: every subset J of "
    "blocks whose g_J vanishes on an interval, with its times, and the smallest "
    "change of one friction coefficient that restores the condition; the margin to "
    "it; and whether the cell theorem makes the motion periodic from the first period.",
)
def validate(gait_files, explain):
    """Check each GAIT_FILE and list every error in it, one per line as FILE: KEY: message.

    Exit code 0 when every file is valid, 2 otherwise. Structure, types and bounds are all
    listed; the checks of the model (friction positive, admissible initial state, uniqueness)
    run as far as the structure allows.

    \b
    Examples:
      crawlsim validate gaits/*.yaml
      crawlsim validate --explain gaits/peristalsis-4.yaml
      crawlsim validate gaits/inching-2.yaml && crawlsim run gaits/inching-2.yaml -o inching.h5
    """
    from crawlsim.gait.document import uniqueness_explanation, validation_errors  # start-up: numpy and YAML

    invalid = 0
    for path in gait_files:
        errors = validation_errors(path)
        for error in errors:
            click.echo(str(error))
        if errors:
            invalid += 1
        else:
            click.echo(f"{path}: valid")
        if explain:
            for line in uniqueness_explanation(path):
                click.echo(f"{path}: {line}")
    if invalid:
        click.echo(f"{invalid} of {len(gait_files)} gait files invalid", err=True)
        sys.exit(2)
