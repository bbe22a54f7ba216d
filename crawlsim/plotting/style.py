"""The one style of every crawlsim figure: fonts, colours, axis labels and titles.

Every figure of `crawlsim.plotting` is drawn inside `figure_style()` and labelled with `label()`
and `title()`, so that a change here changes all of them.

Colours
    * Series (one colour per block or link, per instant of the shape-space figure): the
      Okabe-Ito palette (Okabe & Ito, *Color Universal Design*, 2008), which stays
      distinguishable under the common forms of colour blindness. More than eight series fall
      back to samples of the colour map.
    * One colour map for every continuous colouring (heat maps, long series): ``cividis``
      (Nuñez, Anderton & Renslow, PLoS ONE 13, 2018), perceptually uniform and built to look
      the same to readers with and without a red-green deficiency.
    * Slip states (stick, forward slip, backward slip) have their own three colours, none of
      them a series colour, so a vermilion line is never also a slip band. They are taken from
      the colour map and differ in lightness (about L* = 91, 13 and 66), so they stay apart
      under colour blindness and in a greyscale print.

Labels
    A gait file may give its units (``units: {length: mm, time: s, force: N}``); results and
    sweep files carry them as the root attribute ``units_json``. Where a unit is given, an axis
    reads "position $x_j$ (mm)". Where it is not, the quantity is written over its scale:
    ``x/ℓ`` for lengths (ℓ: the gait file's unit of length), ``σ/F`` for forces (F: its unit
    of force) and ``t/T`` for times, measured in periods. Periods are the natural clock of a
    rate-independent crawler: its positions depend on t/T only (docs/model.md §4). Indices
    (period q, block j) and phases (in cycles) carry no unit.
"""

from __future__ import annotations

from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any, cast

import matplotlib

matplotlib.use("Agg")

import numpy as np
from matplotlib import cycler  # type: ignore[attr-defined]
from matplotlib.colors import to_hex
from matplotlib.figure import Figure

from crawlsim.gait.units import Units, path_quantity

#: Okabe-Ito palette, in the order that puts the most distinct colours first.
OKABE_ITO = {
    "blue": "#0072B2",
    "vermillion": "#D55E00",
    "bluish green": "#009E73",
    "reddish purple": "#CC79A7",
    "orange": "#E69F00",
    "sky blue": "#56B4E9",
    "yellow": "#F0E442",
    "black": "#000000",
}
PALETTE = [
    OKABE_ITO[k]
    for k in ("blue", "vermillion", "bluish green", "reddish purple", "orange", "sky blue", "black", "yellow")
]

#: The one colour map of every continuous colouring.
COLOUR_MAP = "cividis"

#: Colours of the slip states, keyed by the int8 code of ``/limit/slip``: light grey for stick,
#: and the dark and light-olive ends of the colour map for forward and backward slip.
SLIP_COLOURS = {
    0: "#E6E6E6",
    1: to_hex(matplotlib.colormaps[COLOUR_MAP](0.0)),
    -1: to_hex(matplotlib.colormaps[COLOUR_MAP](0.7)),
}
SLIP_NAMES = {0: "stick", 1: "forward slip", -1: "backward slip"}

#: Reference lines (barycentre, limits, fitted rates) and faint context (early periods).
REFERENCE = "#000000"
FAINT = "#9E9E9E"

#: Sweep points that gave no v0, and how they are marked (matplotlib marker, legend name).
STATUS_MARKERS = {
    "failed": ("x", "failed"),
    "invalid": ("+", "invalid gait"),
    "not-converged": ("o", "not converged"),
}

#: Width of a one-column figure of a two-column paper is about 3.5 in; ours are a little wider
#: and saved at 150 dpi, which keeps the PNGs small and the text sharp.
WIDTH = 6.4
DPI = 150

RC = {
    "font.size": 10,
    "axes.titlesize": 10.5,
    "axes.labelsize": 10,
    "legend.fontsize": 8.5,
    "xtick.labelsize": 9,
    "ytick.labelsize": 9,
    "axes.prop_cycle": cycler(color=PALETTE),
    "axes.spines.top": False,
    "axes.spines.right": False,
    "axes.grid": True,
    "grid.color": "#E5E5E5",
    "grid.linewidth": 0.6,
    "lines.linewidth": 1.6,
    "legend.frameon": False,
    "image.cmap": COLOUR_MAP,
    "figure.dpi": DPI,
    "savefig.dpi": DPI,
    "savefig.bbox": "tight",
    "figure.constrained_layout.use": True,
    "mathtext.fontset": "dejavusans",
}


#: A matplotlib style sheet laid over `RC` by `figure_style` (``crawlsim plot --style``), set
#: for the duration of a `user_style` block.
_USER_STYLE: ContextVar[str | None] = ContextVar("crawlsim_user_style", default=None)


#: The image formats crawlsim writes, by file extension.
@contextmanager
def figure_style():
    """The rc settings of crawlsim figures, for the duration of the block, with the style sheet
    of the enclosing `user_style` block (if any) laid over them."""
    with matplotlib.rc_context(cast(Any, RC)):
        style = _USER_STYLE.get()
        if style is None:
            yield
        else:
            from matplotlib import style as sheets

            with sheets.context(style):
                yield


@contextmanager
def user_style(style: str | None):
    """Draw the figures of the block with the matplotlib style sheet ``style`` (a name of
    ``matplotlib.style.available`` or a ``.mplstyle`` file) over crawlsim's own; None: crawlsim's
    style alone. Check it first with `check_style`."""
    token = _USER_STYLE.set(style)
    try:
        yield
    finally:
        _USER_STYLE.reset(token)


def check_style(style: str) -> str:
    """``style`` if it names a matplotlib style sheet (a name of ``matplotlib.style.available``)
    or an existing file that matplotlib reads as one; else ValueError saying what was expected,
    with the closest names."""
    import difflib
    import logging
    import warnings
    from pathlib import Path

    from matplotlib import style as sheets

    available = sorted(sheets.available)
    if style in available:
        return style
    path = Path(style)
    if path.is_file():
        # matplotlib reports the bad lines of a style file on its logger (and some as
        # warnings) and skips them: here each is an error, named with its line.
        problems: list[str] = []

        class Collect(logging.Handler):
            def emit(self, record):
                problems.append(record.getMessage())

        collect = Collect(level=logging.WARNING)
        logger = logging.getLogger("matplotlib")
        logger.addHandler(collect)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                matplotlib.rc_params_from_file(str(path), use_default_template=False)
        except (OSError, UnicodeDecodeError, Warning, ValueError) as exc:
            problems.append(str(exc))
        finally:
            logger.removeHandler(collect)
        if problems:
            first = next((line for line in problems[0].splitlines() if line.strip()), "")
            raise ValueError(f"--style {style}: not a matplotlib style sheet: {first.strip()}")
        return str(path)
    close = difflib.get_close_matches(style, available, n=3)
    if close:
        hint = f"; did you mean {' or '.join(map(repr, close))}?"
    else:
        hint = f"; the names are {', '.join(available)}"
    raise ValueError(f"--style {style}: no such matplotlib style sheet or file{hint} (or give a .mplstyle file)")


@dataclass(frozen=True)
class FigureOptions:
    """How figures are written (``--dpi``, ``--figsize``, ``--style``): the resolution of PNGs
    (dots per inch), the size of every figure in inches (width, height; None: each figure's own
    size, cropped to its content), and a matplotlib style sheet laid over crawlsim's."""

    dpi: float | None = None
    figsize: tuple[float, float] | None = None
    style: str | None = None


def new_figure(nrows: int = 1, ncols: int = 1, *, height: float = 4.0, **kwargs):
    """A figure and its axes in the crawlsim style (call inside `figure_style`).

    The figure is not registered with pyplot's state machine (pyplot is never imported), so
    nothing needs closing and no display is ever touched.
    """
    fig = Figure(figsize=(WIDTH, height), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False, **kwargs)
    return fig, axes


def colour_map():
    """The colour map of every continuous colouring (a copy, safe to modify)."""
    return matplotlib.colormaps[COLOUR_MAP].copy()


def diverging_map():
    """The map of a signed quantity (stress, strain) around 0: two series colours through light
    grey (tension or contraction blue, compression or extension vermilion), never a slip colour."""
    from matplotlib.colors import LinearSegmentedColormap

    return LinearSegmentedColormap.from_list("crawlsim-signed", [OKABE_ITO["blue"], "#EDEDED", OKABE_ITO["vermillion"]])


def colours(count: int) -> list:
    """``count`` distinguishable series colours: Okabe-Ito up to eight, the colour map beyond
    (never exactly a slip colour: a sample that falls on one moves to the next entry of the
    map)."""
    if count <= len(PALETTE):
        return PALETTE[:count]
    cmap = matplotlib.colormaps[COLOUR_MAP]
    slip = set(SLIP_COLOURS.values())
    out = []
    for v in np.linspace(0.05, 0.95, count):
        colour = to_hex(cmap(v))
        out.append(to_hex(cmap(v + 1.0 / cmap.N)) if colour in slip else colour)
    return out


# --------------------------------------------------------------------------------------------
# Units and labels


#: How a quantity's dimension is written when its units are not given: ℓ the gait file's unit
#: of length, F its unit of force, T the period (times are measured in periods).
SCALE_SYMBOLS = {"length": r"\ell", "force": "F", "time": "T"}

#: Dimensions as (numerator, denominator) of base dimensions; "cycles" is a phase.
DIMENSIONS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "length": (("length",), ()),
    "force": (("force",), ()),
    "time": (("time",), ()),
    "stiffness": (("force",), ("length",)),
    "velocity": (("length",), ("time",)),
}


def units_of(data: dict) -> Units:
    """The units of a results dict (`crawlsim.io.runread.read_results`) or a sweep dict
    (`crawlsim.io.sweepfile.read_sweep`): the ``units_json`` attribute when the file has it, else the
    ``units:`` block of the stored gait document, else none."""
    attrs = data.get("attrs") or {}
    for holder in (attrs, data):
        if holder.get("units_json"):
            return Units.parse(holder["units_json"])
    text = attrs.get("gait_yaml", data.get("gait_yaml"))
    if isinstance(text, str) and "units" in text:
        import yaml

        try:
            document = yaml.safe_load(text)
        except yaml.YAMLError:
            return Units()
        if isinstance(document, dict):
            return Units.parse(document.get("units"))
    return Units()


def unit_text(dimension: str, units: Units) -> str | None:
    """The unit of ``dimension`` as given by ``units`` ("N/mm"), or None when a part is
    missing."""
    top, bottom = DIMENSIONS[dimension]
    parts = [[getattr(units, d) for d in side] for side in (top, bottom)]
    if any(p is None for side in parts for p in side):
        return None
    num = " ".join(parts[0]) or "1"
    return num if not parts[1] else f"{num}/{' '.join(parts[1])}"


def _scaled(symbol: str, dimension: str) -> str:
    """``symbol`` made dimensionless by the scales of `SCALE_SYMBOLS`: x/ℓ, kℓ/F, t/T."""
    top, bottom = DIMENSIONS[dimension]
    if any(op in symbol for op in "+-=,"):
        symbol = f"({symbol})"
    times = "".join(SCALE_SYMBOLS[d] for d in bottom)
    over = "".join(SCALE_SYMBOLS[d] for d in top)
    return f"{symbol}{times}/{over}" if over else f"{symbol}{times}"


def label(name: str, symbol: str | None = None, dimension: str | None = None, units: Units | None = None) -> str:
    """An axis label: name, symbol in mathtext, and unit.

    ``dimension`` is None (a pure number or an index), ``"cycles"`` (a phase), or one of
    `DIMENSIONS`. With the unit given: ``name $symbol$ (unit)``. Without it, the symbol over its
    scale: ``position $x_j/\\ell$``, ``time $t/T$`` (the caller plots t/T then).

    >>> label("time", "t", "time")
    'time $t/T$'
    >>> label("stress", "\\\\sigma_i", "force", Units(force="N"))
    'stress $\\\\sigma_i$ (N)'
    """
    units = units or Units()
    if dimension is None:
        return name if symbol is None else f"{name} ${symbol}$"
    if dimension == "cycles":
        text = name if symbol is None else f"{name} ${symbol}$"
        return f"{text} (cycles)"
    unit = unit_text(dimension, units)
    if unit is not None:
        text = name if symbol is None else f"{name} ${symbol}$"
        return f"{text} ({unit})"
    if symbol is None:
        # A name without a symbol: the scale in parentheses, as a unit.
        return f"{name} ({mixed_unit(dimension, units)})"
    if any(getattr(units, d) for side in DIMENSIONS[dimension] for d in side):
        # Some parts given, some not: the unit written with the scales of the missing parts.
        return f"{name} ${symbol}$ ({mixed_unit(dimension, units)})"
    return f"{name} ${_scaled(symbol, dimension)}$"


def mixed_unit(dimension: str, units: Units) -> str:
    """The unit of ``dimension`` with the given units and, for the missing ones, their scales
    of `SCALE_SYMBOLS` in mathtext: "N/$\\ell$" for a stiffness with a force unit only."""
    top, bottom = DIMENSIONS[dimension]
    num = " ".join(getattr(units, d) or f"${SCALE_SYMBOLS[d]}$" for d in top)
    den = " ".join(getattr(units, d) or f"${SCALE_SYMBOLS[d]}$" for d in bottom)
    return f"{num}{'/' + den if den else ''}"


def time_axis(units: Units, period: float, *, symbol: str = "t", name: str = "time") -> tuple[float, str]:
    """How a figure draws times: (factor, label). Times are plotted as ``factor * t``:
    in the file's time unit when it is given (factor 1), else in periods, t/T (factor 1/T)."""
    if units.time is not None:
        return 1.0, label(name, symbol, "time", units)
    return 1.0 / period, label(name, symbol, "time", units)


def velocity_axis(units: Units, *, name: str = "average velocity") -> tuple[bool, str]:
    """How a figure draws v0: (per_period, label). With a time unit, v0 itself ("mm/s");
    without one, the displacement per period v0 T, a length."""
    if units.time is not None:
        return False, label(name, "v_0", "velocity", units)
    return True, label("displacement per period", "v_0T", "length", units)


def path_dimension(path: str) -> str | None:
    """The dimension of a swept dotted path (``links.*.amplitude`` is a length,
    ``friction.backward`` and ``loads.force.0`` forces, ``loads.slope.angle`` an angle,
    ``links.1.phase`` a phase in cycles, ``simulation.*`` a pure number): the quantity of
    `crawlsim.gait.units.path_quantity`."""
    keys = tuple(k for k in path.split(".") if not (k == "*" or k.isdigit()))
    if keys and keys[-1] in ("phase", "times", "phase_step"):
        return "cycles"
    quantity = path_quantity("crawler", keys)
    return None if quantity == "1" else quantity


def path_label(path: str, units: Units) -> str:
    """The axis label of a swept path: the path itself (so it can be pasted back into
    ``--sweep``), then its unit."""
    dimension = path_dimension(path)
    if dimension is None:
        return path
    if dimension in ("cycles", "angle"):
        return f"{path} ({'cycles' if dimension == 'cycles' else 'degrees'})"
    unit = unit_text(dimension, units)
    if unit is not None:
        return f"{path} ({unit})"
    if dimension == "time":
        return path  # a swept period, in the gait file's own time unit: nothing to divide by
    return f"{path} ({mixed_unit(dimension, units)})"


def title(gait: str, figure: str) -> str:
    """A figure title that names the gait: ``"peristalsis-4: gait diagram"``."""
    return f"{gait}: {figure}"


def format_number(value: float) -> str:
    """A value for a legend or a tick: four significant digits, no trailing zeros."""
    return f"{value:.4g}"


#: A figure narrower than this (inches, ``--figsize``) gets its legends below the axes, not on
#: their right, where they would take most of a journal column (`legends_below`).
NARROW = 5.0


def legend_right(ax, **kwargs):
    """The legend of ``ax`` outside it, on its right, top-aligned (below it on a narrow figure:
    `legends_below`)."""
    legend = ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0, **kwargs)
    legend.set_gid("right")
    return legend


def legends_below(fig) -> None:
    """The legends `legend_right` put on the right of their axes, as one legend below the figure,
    in columns: on a figure narrower than `NARROW` they left the plot 40 % of a 3.4 in width."""
    handles: dict[str, Any] = {}
    for ax in fig.axes:
        legend = ax.get_legend()
        if legend is not None and legend.get_gid() == "right":
            handles.update(zip((t.get_text() for t in legend.get_texts()), legend.legend_handles))
            legend.remove()
    if handles:
        fig.legend(
            handles.values(),
            handles.keys(),
            loc="outside lower center",
            ncol=min(2, len(handles)),
            fontsize="small",
            handlelength=1.5,
            columnspacing=1.0,
        )


def shown_series(count: int, limit: int) -> np.ndarray:
    """The 0-based indices of the series drawn out of ``count``: all of them up to ``limit``,
    else ``limit`` evenly spaced ones, the first and the last included."""
    if count <= limit:
        return np.arange(count)
    return np.unique(np.round(np.linspace(0, count - 1, limit)).astype(int))


def shown_title(shown: np.ndarray, count: int, what: str) -> str | None:
    """The legend title of a thinned panel ("8 of 999 links"), None when all are drawn."""
    return None if len(shown) == count else f"{len(shown)} of {count} {what}"
