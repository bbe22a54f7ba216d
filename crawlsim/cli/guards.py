"""Options and checks the commands share to refuse bad requests before any work starts:
finite numbers, the memory limit, and the output targets they may replace (``--force``).

Each check calls a library function (`crawlsim.integrate.resources`, `crawlsim.io.outputs`) so that a Python
user gets the same refusals; here they only become options.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import asdict, dataclass
from typing import Any

import click

from crawlsim.errors import ResourceError
from crawlsim.integrate.resources import check_memory as check_estimate
from crawlsim.integrate.resources import (
    check_signal_work,
    default_limit,
    format_size,
    gait_memory,
    gait_signal_work,
    parse_size,
)
from crawlsim.plotting import FORMATS, figure_format


def grouped(name: str, record: type, *options: Any) -> Any:
    """Click options whose values reach the command as one record ``name`` of type ``record``
    (its fields are the options' names), built and checked when the command is called."""
    fields = [f.name for f in dataclasses.fields(record)]

    def decorate(f: Any) -> Any:
        @functools.wraps(f)
        def command(*args: Any, **kwargs: Any) -> Any:
            kwargs[name] = record(**{k: kwargs.pop(k) for k in fields})
            return f(*args, **kwargs)

        for option in options:
            command = option(command)
        return command

    return decorate


class BadInput(click.ClickException):
    """Bad input: exit code 2 and a one-line message, no usage text."""

    exit_code = 2

    def show(self, file=None):
        click.echo(f"Error: {self.format_message()}", err=True)


class InternalFailure(BadInput):
    """An internal failure (a failed certificate, say): the same one line, exit code 1."""

    exit_code = 1


class FiniteFloatRange(click.FloatRange):
    """A float option that refuses inf and nan: no setting of a run is infinite, and nan passes
    every range comparison unnoticed (``--tolerance nan`` would never stop a run)."""

    name = "finite float"

    def convert(self, value, param, ctx):
        number = super().convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number.", param, ctx)
        return number


def _size(ctx, param, value):
    if value is None:
        return None
    try:
        return parse_size(value)
    except ValueError as exc:
        raise click.BadParameter(str(exc)) from None


def max_memory_option(f):
    """``--max-memory SIZE``: the estimated peak memory a run may need."""
    return click.option(
        "--max-memory",
        callback=_size,
        metavar="SIZE",
        help="Refuse a run whose memory, estimated before it starts, exceeds SIZE (4GiB, 500MB, "
        "2G). Default: the smaller of 8 GiB and half the memory available.",
    )(f)


def force_option(f):
    """``--force``: replace an output that is not a crawlsim output of the same kind."""
    return click.option(
        "--force",
        is_flag=True,
        help="Replace an existing output file even if it is not a crawlsim output of the same "
        "kind (never the input file, nor a device or FIFO).",
    )(f)


def check_memory(
    gait, max_memory, *, save_every: int = 1, batch: int = 1, steps_per_period=None, blocks=None, what: str = "this run"
) -> None:
    """Refuse (ResourceError, exit 2) a gait whose run would not fit in ``max_memory`` bytes
    (None: the default limit), or whose signals would take too long (`resources.signal_work`)."""
    estimate = gait_memory(gait, save_every=save_every, batch=batch, steps_per_period=steps_per_period, blocks=blocks)
    check_estimate(estimate, default_limit() if max_memory is None else max_memory, gait.source, what)
    # and the time its signals would take (fewer blocks at a sweep point cost less; more
    # steps per period only add the tabulation)
    check_signal_work(gait_signal_work(gait, steps_per_period=steps_per_period), gait.source)


def warn_unchecked(gait) -> None:
    """Say on stderr that the gait runs without an exact uniqueness check (it opted in)."""
    if getattr(gait, "uniqueness_unchecked", False):
        click.echo(
            f"Warning: {gait.source}: the uniqueness condition (docs/model.md §3) is beyond "
            "an exact check for this friction and was not checked (simulation: "
            "unchecked_uniqueness: true); the results file records it",
            err=True,
        )


def _figsize(ctx, param, value):
    if value is None:
        return None
    try:
        pair = tuple(float(v) for v in value.split(","))
    except ValueError:
        pair = ()
    if len(pair) != 2 or not all(math.isfinite(v) and 0.5 <= v <= 100 for v in pair):
        raise click.BadParameter(
            f"{value!r}: expected the width and height in inches, each between 0.5 and 100, such as 3.5,2.6"
        )
    return pair


@dataclass(frozen=True)
class Figures:
    """``--dpi``, ``--figsize W,H`` and ``--style``: how figures are written."""

    dpi: float | None = None
    figsize: tuple[float, float] | None = None
    style: str | None = None

    def given(self) -> list[str]:
        """The options given, as the command line spells them."""
        return [f"--{name}" for name, value in asdict(self).items() if value is not None]

    def options(self) -> Any:
        """These as `crawlsim.plotting.style.FigureOptions`, the style sheet checked first (a bad
        one is BadInput, exit 2)."""
        from crawlsim.plotting.style import FigureOptions, check_style  # start-up: matplotlib for figures only

        try:
            style = None if self.style is None else check_style(self.style)
        except ValueError as exc:
            raise BadInput(str(exc)) from None
        return FigureOptions(dpi=self.dpi, figsize=self.figsize, style=style)


#: ``--dpi``, ``--figsize W,H`` and ``--style`` as one record ``figures`` (`Figures`).
figure_options = grouped(
    "figures",
    Figures,
    click.option(
        "--style",
        metavar="STYLE",
        help="A matplotlib style sheet laid over crawlsim's: a name of "
        "matplotlib.style.available (ggplot, seaborn-v0_8-paper, ...) or a "
        ".mplstyle file.",
    ),
    click.option(
        "--figsize",
        callback=_figsize,
        metavar="W,H",
        help="Size of every figure in inches, such as 3.5,2.6 (default: each figure's own, cropped to its content).",
    ),
    click.option(
        "--dpi",
        type=FiniteFloatRange(min=10, max=2400),
        help="Resolution of PNG figures in dots per inch (default: 150).",
    ),
)


@dataclass(frozen=True)
class Plot:
    """``--plot`` and ``--plot-format``: one meaning in every command that draws as it computes
    (run, velocity --sweep): the figures next to the results, as ``crawlsim plot`` names them,
    <stem>-<figure>.<format>."""

    plot: bool = False
    plot_format: str | None = None

    def settings(self, figures: Figures) -> tuple[Any, str] | None:
        """The `FigureOptions` and format of ``--plot`` (None without it); a figure option given
        without ``--plot`` is BadInput (exit 2)."""
        given = ([] if self.plot_format is None else ["--plot-format"]) + figures.given()
        if given and not self.plot:
            raise BadInput(f"{', '.join(given)} set how the figures are drawn: add --plot")
        return (figures.options(), self.plot_format or "png") if self.plot else None


def plot_options(f: Any) -> Any:
    """``--plot`` and ``--plot-format`` as one record ``plot`` (`Plot`), with the
    `figure_options` as ``figures``."""
    return grouped(
        "plot",
        Plot,
        click.option(
            "--plot-format",
            type=click.Choice(FORMATS),
            help="Image format of the --plot figures.  [default: png]",
        ),
        click.option(
            "--plot",
            is_flag=True,
            help="Also draw the figures next to the results (<stem>-<figure>.png), as crawlsim plot RESULTS does.",
        ),
    )(figure_options(f))


def figure_format_of(path, option: str) -> str:
    """The format of a figure file by its extension (png, pdf, svg); any other is BadInput."""
    try:
        return figure_format(path, option)
    except ValueError as exc:
        raise BadInput(str(exc)) from None


def check_sweep_memory(grid, points: int, jobs: int, scheduler, max_memory) -> None:
    """Refuse a sweep whose largest point (most blocks, most steps per period) would not fit,
    in a batch as large as the sweep's tasks, once per local worker."""
    from crawlsim.study.executors import MAX_CHUNK  # start-up: numpy, only for sweeps

    largest = {a.path: int(max(a.values)) for a in grid.axes if a.path in ("blocks", "simulation.steps_per_period")}
    blocks, steps = largest.get("blocks"), largest.get("simulation.steps_per_period")
    batch = min(points, MAX_CHUNK)
    gait = grid.base
    check_memory(
        gait,
        max_memory,
        batch=batch,
        steps_per_period=steps,
        blocks=blocks,
        what=f"this sweep ({'one worker' if scheduler else f'{jobs} worker(s)'} with batches of {batch} points)",
    )
    if scheduler or jobs <= 1:
        return
    limit = default_limit() if max_memory is None else max_memory
    each = gait_memory(gait, batch=batch, blocks=blocks, steps_per_period=steps)
    if jobs * each.total > limit:
        raise ResourceError(
            gait.source,
            "",
            f"{jobs} local workers would need about "
            f"{format_size(jobs * each.total)} together "
            f"({each.describe()} each), more than the memory "
            f"limit of {format_size(limit)} (--max-memory); "
            "use fewer --jobs",
        )
