"""The ``crawlsim`` command line. Each command parses, calls the library, prints.

One module per command; this one holds the group and the options and helpers they share.

Exit codes: 0 converged, 3 not converged within max_periods (results still written),
2 bad input (no traceback, no file written), 1 internal failure (a failed certificate included).
"""

from __future__ import annotations

import json
import math
import sys
import warnings
from contextlib import contextmanager
from pathlib import Path

import click

from .. import __version__
from ..errors import CrawlsimError, InputError
from ..gait import load_gait, with_simulation
from ..stepping import STEPPERS
from .guards import FiniteFloatRange

EXIT_NOT_CONVERGED = 3


class BadInput(click.ClickException):
    """Bad input: exit code 2 and a one-line message, no usage text."""

    exit_code = 2

    def show(self, file=None):
        click.echo(f"Error: {self.format_message()}", err=True)


class InternalFailure(BadInput):
    """An internal failure (a failed certificate, say): the same one line, exit code 1."""

    exit_code = 1


@contextmanager
def library_errors():
    """Library errors become click errors: bad input is exit 2, everything else exit 1."""
    try:
        yield
    except InputError as exc:
        raise BadInput(str(exc)) from None
    except CrawlsimError as exc:
        raise InternalFailure(str(exc)) from None


def _output_path(output, gait_file, force: bool = False) -> Path:
    """The results file of a run, refused (`crawlsim.outputs.check_target`) when it may not be
    replaced."""
    from ..outputs import RUN, check_target

    out = Path(output) if output else Path(Path(gait_file).stem + ".h5")
    return check_target(out, RUN, inputs=[gait_file], force=force)


def to_json(summary: dict) -> str:
    """One JSON object; NaN and infinities (HDF5's stand-ins for null) become null."""
    clean = {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
             for k, v in summary.items()}
    return json.dumps(clean)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="crawlsim")
def main():
    """Exact simulation of soft crawlers with dry friction.

    \b
    Examples:
      crawlsim run gaits/peristalsis-4.yaml
      crawlsim run gaits/inching-2.yaml --json -o inching.h5
      crawlsim run gaits/peristalsis-4.yaml --integrator exact --plot
      crawlsim velocity gaits/peristalsis-4.yaml --sweep 'links.*.amplitude=0.1:0.4:31'
      crawlsim plot peristalsis-4.h5 --format pdf
    """
    warnings.showwarning = _show_warning


def _show_warning(message, category, filename, lineno, file=None, line=None):
    """Warnings (LICQ failures of generic processes, for example) as one line on stderr."""
    click.echo(f"Warning: {message}", err=True)


def simulation_options(f):
    """Options that override the gait file's ``simulation`` mapping."""
    f = click.option("--tolerance", type=FiniteFloatRange(min=0, min_open=True),
                     help="Stop when the Poincare step is at most this, relative to |w| "
                          "(default from the gait file, else 1e-12).")(f)
    f = click.option("--max-periods", type=click.IntRange(min=1),
                     help="Give up after this many periods (default 1000).")(f)
    f = click.option("--steps-per-period", type=click.IntRange(min=1),
                     help="Uniform catch-up steps per period; breakpoints are added "
                          "(default 1000). With --integrator exact, only the output grid.")(f)
    f = click.option("--integrator", type=click.Choice(list(STEPPERS)), expose_value=False,
                     callback=_remember_integrator,
                     help="catch-up: first order in the step, robust for any gait. exact: "
                          "event-driven, v0 to roundoff, fast for smooth or piecewise-linear "
                          "gaits (default from the gait file, else catch-up).")(f)
    return f


def _remember_integrator(ctx, param, value):
    """``--integrator`` is consumed by `load_with_overrides`, so commands need no parameter."""
    if value is not None:
        ctx.meta["crawlsim.integrator"] = value


def load_with_overrides(gait_file, steps_per_period, max_periods, tolerance, integrator=None):
    """The gait file with the command line's simulation options applied (``--integrator``
    included, taken from the click context when not given)."""
    if integrator is None:
        ctx = click.get_current_context(silent=True)
        integrator = None if ctx is None else ctx.meta.get("crawlsim.integrator")
    gait = load_gait(gait_file)
    overrides = {k: v for k, v in dict(steps_per_period=steps_per_period,
                                       max_periods=max_periods, tolerance=tolerance,
                                       integrator=integrator).items()
                 if v is not None}
    return with_simulation(gait, **overrides) if overrides else gait


@contextmanager
def period_progress(max_periods: int, enabled: bool):
    """A tqdm bar over periods on stderr, only when stderr is a terminal."""
    if not enabled or not sys.stderr.isatty():
        yield None
        return
    from tqdm import tqdm

    with tqdm(total=max_periods, unit="period", file=sys.stderr, leave=False) as bar:
        def update(q, rel_step):
            bar.update(1)
            bar.set_postfix_str(f"Poincare step {rel_step:.2e}")
        yield update


# Each command module attaches itself to `main`.
from . import merge, plot, run, validate, velocity  # noqa: E402,F401
