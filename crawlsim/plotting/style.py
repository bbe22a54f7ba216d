"""The one style of every crawlsim figure: fonts, colours, labels and titles.

Every figure of `crawlsim.plotting` (and the sweep figure of ``crawlsim velocity --plot``) is drawn
inside `figure_style()` and labelled with `label()` and `title()`, so that a change here changes
all of them.

Colours are the Okabe-Ito palette (Okabe & Ito, *Color Universal Design*, 2008), which stays
distinguishable under the common forms of colour blindness; more than eight blocks or links fall
back to the perceptually uniform, colourblind-safe ``cividis`` colour map. Slip states use three
of its colours that also differ in lightness, so a greyscale print keeps them apart.

crawlsim quantities carry no units (the gait file fixes the scales of length, force and time),
so every axis says "(dimensionless)".
"""

from __future__ import annotations

from contextlib import contextmanager

import matplotlib

matplotlib.use("Agg")

import numpy as np
from matplotlib import cycler  # type: ignore[attr-defined]
from matplotlib.figure import Figure

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
PALETTE = [OKABE_ITO[k] for k in ("blue", "vermillion", "bluish green", "reddish purple",
                                  "orange", "sky blue", "black", "yellow")]

#: Colours of the slip states, keyed by the int8 code of ``/limit/slip``.
SLIP_COLOURS = {0: "#D9D9D9", 1: OKABE_ITO["blue"], -1: OKABE_ITO["vermillion"]}
SLIP_NAMES = {0: "stick", 1: "forward slip", -1: "backward slip"}

#: Reference lines (barycentre, limits, fitted rates) and faint context (early periods).
REFERENCE = "#000000"
FAINT = "#9E9E9E"

DIMENSIONLESS = "(dimensionless)"

#: Width of a one-column figure of a two-column paper is about 3.5 in; ours are a little wider
#: and saved at 150 dpi, which keeps the PNGs small and the text sharp.
WIDTH = 6.4
DPI = 150

RC = {
    "font.size": 10,
    "axes.titlesize": 11,
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
    "figure.dpi": DPI,
    "savefig.dpi": DPI,
    "savefig.bbox": "tight",
    "figure.constrained_layout.use": True,
    "mathtext.fontset": "dejavusans",
}


@contextmanager
def figure_style():
    """The rc settings of crawlsim figures, for the duration of the block."""
    with matplotlib.rc_context(RC):
        yield


def new_figure(nrows: int = 1, ncols: int = 1, *, height: float = 4.0, **kwargs):
    """A figure and its axes in the crawlsim style (call inside `figure_style`).

    The figure is not registered with pyplot's state machine (pyplot is never imported), so
    nothing needs closing and no display is ever touched.
    """
    fig = Figure(figsize=(WIDTH, height), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False, **kwargs)
    return fig, axes


def colours(count: int) -> list:
    """``count`` distinguishable colours: Okabe-Ito up to eight, cividis beyond."""
    if count <= len(PALETTE):
        return PALETTE[:count]
    cmap = matplotlib.colormaps["cividis"]
    return [cmap(v) for v in np.linspace(0.0, 0.9, count)]


def label(name: str, symbol: str | None = None, unit: str | None = None) -> str:
    """An axis label: name, symbol in mathtext, and unit, "(dimensionless)" by default.

    >>> label("time", "t")
    'time $t$ (dimensionless)'
    """
    text = name if symbol is None else f"{name} ${symbol}$"
    return f"{text} {DIMENSIONLESS if unit is None else f'({unit})'}"


def title(gait: str, figure: str) -> str:
    """A figure title that names the gait: ``"peristalsis-4: gait diagram"``."""
    return f"{gait}: {figure}"


def block_names(count: int) -> list[str]:
    return [f"block {j + 1}" for j in range(count)]


def link_names(count: int) -> list[str]:
    return [f"link {i + 1}" for i in range(count)]
