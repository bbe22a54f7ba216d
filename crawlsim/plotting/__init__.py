"""Figures of a crawlsim run, drawn from its results file alone (matplotlib, Agg backend).

* `style` holds the one style of all figures (fonts, palettes, the colour map, labels with
  units, titles);
* one module per figure of a run, `motion`, `gait_diagram`, `kymograph`, `convergence` and
  `shape_space`,
  each function taking the run (a results file, the dict of `crawlsim.io.runread.read_results`, or
  the result of `crawlsim.simulate`: `source.run_data`) and returning a matplotlib `Figure`;
  `output.FIGURES` names them;
* `sweeps` draws velocity sweeps (`sweep_figure`, `sweep_data_figure`);
* `optimization` has the figures of an optimisation file (`objective_figure`, `pareto_figure`);
* `animation` draws the crawler in motion (`write_animation`, ``crawlsim animate``);
* `output.plot_results` reads a results or sweep file and writes its figures next to it.

The names below are imported lazily (PEP 562), so that ``import crawlsim.plotting`` and the
command line stay fast and never import matplotlib until a figure is drawn.
"""

from __future__ import annotations

#: The figures of one run, in drawing order; ``--only`` takes one of these names.
FIGURE_NAMES = ("motion", "gait-diagram", "kymograph", "convergence", "shape-space")
#: The one figure of a sweep file (``crawlsim plot SWEEP.h5``).
SWEEP_FIGURE = "sweep"
#: The figures of an optimisation file (``crawlsim plot OPT.h5``): the convergence of the
#: objective, and with --pareto the front.
OPTIMIZATION_FIGURES = ("objective", "pareto-front")
#: The figure of a run's rigid limit (``crawlsim run --rigid``), drawn when the file has one.
RIGID_FIGURE = "rigid"
#: Figures that need block positions, stresses and slips: crawler runs only.
CRAWLER_FIGURES = ("motion", "gait-diagram", "kymograph")
#: Figures that zoom on the last periods of a run (``crawlsim plot --last K``).
LAST_FIGURES = ("motion", "kymograph")
#: The formats a figure is written in.
FORMATS = ("png", "pdf", "svg")

_LAZY = {
    "plot_results": "output",
    "available_figures": "output",
    "draw_figure": "output",
    "save_figure": "output",
    "motion_figure": "motion",
    "gait_figure": "gait_diagram",
    "kymograph_figure": "kymograph",
    "convergence_figure": "convergence",
    "shape_space_figure": "shape_space",
    "rigid_figure": "rigid",
    "sweep_figure": "sweeps",
    "sweep_data_figure": "sweeps",
    "run_data": "source",
    "FIGURES": "output",
    "objective_figure": "optimization",
    "pareto_figure": "optimization",
    "write_animation": "animation",
    "FigureOptions": "style",
}

__all__ = [
    "CRAWLER_FIGURES",
    "FIGURES",
    "FIGURE_NAMES",
    "OPTIMIZATION_FIGURES",
    "RIGID_FIGURE",
    "objective_figure",
    "pareto_figure",
    "convergence_figure",
    "gait_figure",
    "kymograph_figure",
    "motion_figure",
    "SWEEP_FIGURE",
    "plot_results",
    "save_figure",
    "rigid_figure",
    "shape_space_figure",
    "sweep_data_figure",
    "sweep_figure",
    "write_animation",
    "FigureOptions",
    "run_data",
]


def figure_format(path, option: str = "-o") -> str:
    """The image format of a figure file, by its extension (png, pdf or svg); ValueError for
    any other."""
    from pathlib import Path

    suffix = Path(path).suffix.lower().lstrip(".")
    if suffix not in FORMATS:
        given = f"extension .{suffix}" if suffix else "no extension"
        raise ValueError(f"{option} {path}: {given}; a figure is written as .png, .pdf or .svg")
    return suffix


def __getattr__(name):
    if name in _LAZY:
        import importlib

        module = importlib.import_module(f"{__name__}.{_LAZY[name]}")
        return getattr(module, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
