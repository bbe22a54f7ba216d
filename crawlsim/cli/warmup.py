"""``crawlsim warmup``: compile the kernel into numba's cache, on every core."""

from __future__ import annotations

import os
from pathlib import Path

import click

from crawlsim.cli import InternalFailure, main


@main.command()
@click.option(
    "-j", "--jobs", type=click.IntRange(min=1), help="Processes compiling at once (default: the number of cores)."
)
@click.option("--background", is_flag=True, hidden=True, help="One process at low priority, once per cache.")
def warmup(jobs, background):
    """Compile crawlsim's kernel for every command, so that no run compiles it again.

    Small work runs interpreted and long work switches to the compiled kernel once it is in
    numba's cache; a long run on a fresh install compiles it in the background (one core) and
    switches when it is done. warmup compiles it now, on every core: for a container image, a
    cluster's shared cache (NUMBA_CACHE_DIR), CI, or after an upgrade. Running it again loads
    what is cached and compiles nothing.

    \b
    Examples:
      crawlsim warmup
      crawlsim warmup -j 8
    """
    from crawlsim.kernel import jit
    from crawlsim.study.warmup import warmup as compile_all

    if background:
        lock = jit.stamp().with_suffix(".lock")
        fd = _lock(lock)
        if fd is None:
            return  # another process compiles into this cache (or it cannot be written)
        try:
            os.nice(10)
            compile_all(1)
        finally:
            os.close(fd)
            lock.unlink(missing_ok=True)
        return
    click.echo(f"compiling the kernel into {jit.cache_dir()} ...", err=True)
    try:
        seconds = compile_all(jobs, report=lambda line: click.echo(f"  {line}", err=True))
    except RuntimeError as exc:
        raise InternalFailure(str(exc)) from None
    click.echo(f"the kernel is compiled ({seconds:.0f} s); runs load it from the cache")


def _lock(path: Path) -> int | None:
    """The cache's compile lock (holding this process's pid), taken over from a process that
    died holding it; None while a live process holds it."""
    for _ in range(2):
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
            os.write(fd, str(os.getpid()).encode())
            return fd
        except FileExistsError:
            try:
                os.kill(int(path.read_text() or 0), 0)
                return None
            except (ProcessLookupError, ValueError, FileNotFoundError):
                path.unlink(missing_ok=True)
        except OSError:
            return None
    return None
