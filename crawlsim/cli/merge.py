"""``crawlsim merge``: join the shards of a sweep into one HDF5 file."""

from __future__ import annotations

import click

from crawlsim.analysis.digits import counted
from crawlsim.cli import BadInput, library_errors, main
from crawlsim.cli.guards import force_option
from crawlsim.io.outputs import SWEEP, check_target


@main.command()
@click.argument("parts", nargs=-1, required=True, type=click.Path(dir_okay=False))
@click.option(
    "-o",
    "--output",
    required=True,
    type=click.Path(dir_okay=False, allow_dash=True),
    help="The merged sweep: OUT.h5 (HDF5), OUT.csv, or - for CSV on stdout.",
)
@force_option
def merge(parts, output, force):
    """Join the shard files PART... of one sweep (written with --shard I/N) into OUTPUT.

    The result is the file an unsharded run of the same sweep writes. Every shard 1..N must be
    given exactly once.

    \b
    Examples:
      for i in 1 2; do crawlsim velocity gaits/inching-2.yaml --sweep 'period=1:3:9' \\
          --shard $i/2 -o part-$i.h5; done
      crawlsim merge part-*.h5 -o sweep.h5
      crawlsim merge part-*.h5 -o - | wc -l
    """
    from pathlib import Path

    from crawlsim.study import table as tables  # start-up: h5py when the command runs

    if output != "-" and Path(output).suffix.lower() not in (".h5", ".hdf5", ".csv"):
        raise BadInput(
            f"--output {output}: name the merged sweep OUT.h5 (HDF5) or OUT.csv, or give - for CSV on stdout"
        )
    with library_errors():
        if output != "-":
            check_target(output, SWEEP, inputs=parts, force=force)
        table = tables.merge_tables(tables.read_table(p) for p in parts)
        if output == "-":
            click.echo(table.to_csv(), nl=False)
            return
        tables.write_table(table, output)
    click.echo(f"{counted(len(table.rows), 'point')} from {counted(len(parts), 'shard')} written to {output}")
