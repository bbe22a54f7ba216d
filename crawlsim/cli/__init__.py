"""The ``crawlsim`` command line. Each command parses, calls the library, prints.

One module per command; this one holds the group and the options and helpers they share.

Start-up is part of the interface (shell loops call ``crawlsim velocity`` thousands of times):
this package and every command module import only click and crawlsim's light modules (errors,
statuses, progress) at the top; numpy, scipy, Clarabel, h5py, jsonschema and matplotlib are
imported inside the commands that need them. ``tests/test_imports.py`` guards this.

Exit codes: 0 converged, 3 not converged within max_periods (results still written),
2 bad input (no traceback, no file written), 1 internal failure (a failed certificate included),
130 interrupted (Ctrl-C) and 143 terminated (SIGTERM), with a sweep's finished points kept
(where the interrupt is raised: `crawlsim.interrupts`).
"""

from __future__ import annotations

import dataclasses
import importlib
import math
import signal
import sys
import warnings
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import click

from crawlsim import __version__, interrupts
from crawlsim.cli.guards import BadInput, FiniteFloatRange, InternalFailure, grouped
from crawlsim.cli.progress import RunProgress, choose_mode
from crawlsim.errors import CrawlsimError, InputError
from crawlsim.interrupts import Terminated
from crawlsim.io.outputs import RUN, check_target
from crawlsim.status import Integrator

if TYPE_CHECKING:  # json and pathlib are imported where used: `crawlsim --help` needs neither
    from pathlib import Path

    from click.parser import _OptionParser

EXIT_NOT_CONVERGED = 3
#: 128 + the signal number, as shells report a process ended by a signal.
EXIT_INTERRUPTED = 128 + signal.SIGINT
EXIT_TERMINATED = 128 + signal.SIGTERM

#: The defaults of the gait file's ``simulation`` mapping (`crawlsim.gait.settings.Simulation`), for the
#: help texts; tests/test_cli_help.py checks that they agree.
DEFAULT_STEPS_PER_PERIOD = 1000
DEFAULT_MAX_PERIODS = 1000
DEFAULT_TOLERANCE = 1e-12
DEFAULT_INTEGRATOR = Integrator.EXACT
DEFAULT_LIMIT = "newton"


@contextmanager
def library_errors():
    """Library errors become click errors: bad input is exit 2, everything else exit 1."""
    try:
        yield
    except InputError as exc:
        raise BadInput(str(exc)) from None
    except CrawlsimError as exc:
        raise InternalFailure(str(exc)) from None


#: The command modules (``crawlsim.cli.<name>``, each attaching its command to `main`). Only
#: the invoked one is imported (``--help`` imports them all, for their one-line help).
COMMANDS = ("animate", "info", "merge", "optimize", "plot", "run", "stall", "validate", "velocity", "warmup")


class CrawlsimGroup(click.Group):
    """The command group. Commands load on demand (`COMMANDS`); Ctrl-C exits 130 and SIGTERM
    143, after the commands' clean-up, with one line on stderr instead of click's "Aborted!" and
    exit code 1."""

    def list_commands(self, ctx):
        return sorted(set(self.commands) | set(COMMANDS))

    def get_command(self, ctx, cmd_name):
        if cmd_name not in self.commands and cmd_name in COMMANDS:
            importlib.import_module(f"{__name__}.{cmd_name}")
        return self.commands.get(cmd_name)

    def invoke(self, ctx):
        try:
            with interrupts.installed():
                try:
                    return super().invoke(ctx)
                finally:  # the outputs the command claimed (`crawlsim.io.outputs.claim`)
                    outputs = sys.modules.get("crawlsim.io.outputs")
                    if outputs is not None:
                        outputs.release()
        except Terminated:
            click.echo("Terminated.", err=True)
            raise click.exceptions.Exit(EXIT_TERMINATED) from None
        except KeyboardInterrupt:
            click.echo("Interrupted.", err=True)
            raise click.exceptions.Exit(EXIT_INTERRUPTED) from None


def interrupt_exit(exc: BaseException) -> click.exceptions.Exit:
    """The exit of an interrupted command (after it said what was kept)."""
    terminated = isinstance(exc, Terminated) or isinstance(exc.__context__, Terminated)
    return click.exceptions.Exit(EXIT_TERMINATED if terminated else EXIT_INTERRUPTED)


class OrderedCommand(click.Command):
    """A command that records the order of its options on the command line in
    ``ctx.meta["crawlsim.option_order"]`` (click keeps the values of each option, not how
    different options interleave): ``--link`` joins the ``--sweep`` before it."""

    def make_parser(self, ctx: click.Context) -> _OptionParser:
        parser = super().make_parser(ctx)
        parse = parser.parse_args

        def parse_args(args: list[str]) -> tuple[dict[str, Any], list[str], list[click.Parameter]]:
            opts, largs, order = parse(args)
            ctx.meta["crawlsim.option_order"] = [getattr(p, "name", None) for p in order]
            return opts, largs, order

        parser.parse_args = parse_args  # type: ignore[method-assign]
        return parser


def _output_path(output, gait_file, force: bool = False, inputs=None) -> Path:
    """The results file of a run, refused (`crawlsim.io.outputs.check_target`) when it may not be
    replaced; ``inputs`` are the files the run reads (never replaced, default the gait file)."""
    from pathlib import Path

    out = Path(output) if output else Path(Path(gait_file).stem + ".h5")
    return check_target(out, RUN, inputs=[gait_file] if inputs is None else inputs, force=force)


def to_json(summary: dict) -> str:
    """One JSON object; NaN and infinities (HDF5's stand-ins for null) become null."""
    import json

    clean = {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in summary.items()}
    return json.dumps(clean)


_COMPLETION = """\b
Shell completion (bash; zsh and fish alike with zsh_source, fish_source):
  eval "$(_CRAWLSIM_COMPLETE=bash_source crawlsim)"   # in ~/.bashrc
"""


@click.group(cls=CrawlsimGroup, context_settings={"help_option_names": ["-h", "--help"]}, epilog=_COMPLETION)
@click.version_option(__version__, prog_name="crawlsim")
def main():
    """Exact simulation of soft crawlers with dry friction.

    \b
    Examples:
      crawlsim run gaits/peristalsis-4.yaml --integrator exact
      crawlsim run gaits/inching-2.yaml --json -o inching.h5
      crawlsim velocity gaits/peristalsis-4.yaml --sweep 'links.*.amplitude=0.1:0.4:7'
      crawlsim info inching.h5
      crawlsim plot inching.h5 --only motion --format pdf
    """
    warnings.showwarning = _show_warning


def _show_warning(message, category, filename, lineno, file=None, line=None):
    """Warnings (LICQ failures of generic processes, for example) as one line on stderr."""
    click.echo(f"Warning: {message}", err=True)


@dataclass(frozen=True)
class Settings:
    """The command line's overrides of the gait file's ``simulation`` mapping (None: the file's)."""

    steps_per_period: int | None = None
    max_periods: int | None = None
    tolerance: float | None = None
    integrator: str | None = None
    limit: str | None = None

    def given(self) -> dict[str, Any]:
        return {k: v for k, v in dataclasses.asdict(self).items() if v is not None}


simulation_options = grouped(
    "settings",
    Settings,
    click.option(
        "--tolerance",
        type=FiniteFloatRange(min=0, min_open=True),
        help="Stop when the Poincare step is at most this, relative to |w| "
        f"(default: the gait file's value, else {DEFAULT_TOLERANCE:g}).",
    ),
    click.option(
        "--max-periods",
        type=click.IntRange(min=1),
        help=f"Give up after this many periods (default: the gait file's value, else {DEFAULT_MAX_PERIODS}).",
    ),
    click.option(
        "--steps-per-period",
        type=click.IntRange(min=1),
        help="Uniform catch-up steps per period; breakpoints are added (default: "
        f"the gait file's value, else {DEFAULT_STEPS_PER_PERIOD}). With "
        "--integrator exact, only the output grid.",
    ),
    click.option(
        "--integrator",
        type=click.Choice([str(i) for i in Integrator]),
        help="exact: event-driven, v0 to roundoff. catch-up: the paper's time "
        "discretisation, first order in the step (its time-step error is "
        "measured against exact) (default: the gait file's value, else "
        f"{DEFAULT_INTEGRATOR}).",
    ),
    click.option(
        "--limit",
        type=click.Choice(["newton", "iterate"]),
        help="How the periodic limit is found: newton, the periodic-limit solver "
        "(a few periods even when the iterates converge slowly), or iterate, "
        "period after period (default: the gait file's value, else "
        f"{DEFAULT_LIMIT}).",
    ),
)


@dataclass(frozen=True)
class Feedback:
    """``--quiet`` and ``--verbose``: how much goes to stderr besides errors and warnings."""

    quiet: bool = False
    verbose: bool = False

    def __post_init__(self) -> None:
        if self.quiet and self.verbose:
            raise BadInput("--quiet and --verbose: choose one")

    @property
    def mode(self) -> str:
        """The progress mode (`crawlsim.cli.progress.choose_mode`)."""
        return choose_mode(self.quiet)


feedback_options = grouped(
    "feedback",
    Feedback,
    click.option(
        "-v",
        "--verbose",
        is_flag=True,
        help="More detail on stderr: every period's Poincare step, every invalid "
        "or failed sweep point with its reason, resumed points.",
    ),
    click.option(
        "-q",
        "--quiet",
        is_flag=True,
        help="No progress on stderr (warnings and errors are still printed). "
        "Progress is a bar on a terminal, else a line every 10 s "
        "(CRAWLSIM_PROGRESS_INTERVAL).",
    ),
)


def run_progress(gait, feedback: Feedback) -> RunProgress:
    """Progress over the periods of one run of ``gait`` (`progress.RunProgress`)."""
    s = gait.simulation
    return RunProgress(gait.name, s.tolerance, s.max_periods, mode=feedback.mode, verbose=feedback.verbose)
