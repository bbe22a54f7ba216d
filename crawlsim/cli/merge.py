"""``crawlsim merge``: join the shards of a sweep into one HDF5 file."""

from __future__ import annotations

import click

from .. import sweep as sweeps
from . import BadInput, library_errors, main
from .guards import force_option


@main.command()
@click.argument("parts", nargs=-1, required=True, type=click.Path(dir_okay=False))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="The merged sweep file (HDF5).")
@force_option
def merge(parts, output, force):
    """Join the shard files PART... of one sweep (written with --shard I/N) into OUTPUT.

    The result is the file an unsharded run of the same sweep writes. Every shard 1..N must be
    given exactly once.

    \b
    Example:
      crawlsim merge part-*.h5 -o sweep.h5
    """
    if not sweeps.is_hdf5(output):
        raise BadInput(f"--output {output}: the merged sweep is HDF5; name it OUT.h5")
    with library_errors():
        from ..outputs import SWEEP, check_target

        check_target(output, SWEEP, inputs=parts, force=force)
        table = sweeps.merge_tables(sweeps.read_table(p) for p in parts)
        sweeps.write_table(table, output)
    click.echo(f"{len(table.rows)} points from {len(parts)} shards written to {output}")
