"""The ``crawlsim`` console script: `crawlsim.cli.main`, except that ``crawlsim --version`` and
``crawlsim --help`` answer without importing click (more than the interpreter's own start-up;
scripts and installers ask for the version first, people for the help).

The answers are click's own: ``crawlsim, version X`` (``click.version_option``) and the help
text click renders at 80 columns (`crawlsim._help`, generated), printed only where click would
render that width too (a terminal or ``COLUMNS`` of 80 or more, or no terminal at all) and when
the program is called ``crawlsim``; tests/test_imports.py checks that both agree with click.
"""

from __future__ import annotations

import os
import signal
import sys

from crawlsim import __version__
from crawlsim._help import TEXT


def _columns() -> int:
    """The width `shutil.get_terminal_size` reports (``COLUMNS``, else the terminal's, else 80),
    without importing shutil."""
    try:
        columns = int(os.environ.get("COLUMNS", "0"))
    except ValueError:
        columns = 0
    if columns <= 0:
        try:
            columns = os.get_terminal_size(sys.__stdout__.fileno()).columns  # type: ignore[union-attr]
        except (AttributeError, ValueError, OSError):
            columns = 0
    return columns if columns > 0 else 80


def main() -> None:
    if sys.argv[1:] == ["--version"]:
        sys.stdout.write(f"crawlsim, version {__version__}\n")
        sys.exit(0)
    if sys.argv[1:] == ["--help"] and os.path.basename(sys.argv[0]) == "crawlsim" and _columns() >= 80:
        sys.stdout.write(TEXT)
        sys.exit(0)
    from crawlsim.cli import main as cli  # start-up: click only beyond --version and --help

    try:
        cli()
    finally:  # the exit code is decided: a signal now would only lose it
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
