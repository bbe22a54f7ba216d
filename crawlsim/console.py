"""The ``crawlsim`` console script: `crawlsim.cli.main`, except that ``crawlsim --version``
answers without importing click (half of that command's start-up; scripts and installers ask
for the version first).

The answer is click's own (``crawlsim, version X``, from ``click.version_option``);
tests/test_imports.py checks that the two agree.
"""

from __future__ import annotations

import sys


def main() -> None:
    if sys.argv[1:] == ["--version"]:
        from . import __version__

        sys.stdout.write(f"crawlsim, version {__version__}\n")
        sys.exit(0)
    from .cli import main as cli

    cli()
