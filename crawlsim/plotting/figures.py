"""The figures of a run, by name, and every figure function in one namespace.

Each figure has its own module: `motion`, `gait_diagram`, `kymograph`, `convergence`, `shape_space`, and
`sweeps` for velocity sweeps. A figure of a run takes the run as a results file, the dict of
`crawlsim.io.hdf5.read_results` or a result object of `crawlsim.simulate` (`source.run_data`
converts it) and returns a matplotlib `Figure` in the style of `crawlsim.plotting.style`. A
figure that needs data the run lacks raises `ResultsFileError` naming the missing dataset (the
command line turns it into exit code 2).

Times are drawn as t/T (in periods) unless the file gives a time unit, and every label comes
from `crawlsim.plotting.style.label`, with the file's units when it has them.
"""

from __future__ import annotations

from collections.abc import Callable

from matplotlib.figure import Figure

from crawlsim.plotting.convergence import convergence_figure, convergence_scale, convergence_series
from crawlsim.plotting.gait_diagram import (
    FORCE_ROW_HEIGHT,
    MAX_BAND_LABELS,
    MAX_FORCE_ROWS,
    MAX_SERIES,
    RELATIVE_STRESS_RATIO,
    block_forces,
    gait_figure,
    relative_stress,
    slip_runs,
    stress_bounds,
    stress_mode,
)
from crawlsim.plotting.kymograph import kymograph_figure
from crawlsim.plotting.motion import FOLLOW_PERIODS, MAX_MOTION_BLOCKS, motion_figure
from crawlsim.plotting.rigid import rigid_figure
from crawlsim.plotting.shape_space import (
    NICE_DIVISIONS,
    SHAPE_SPACE_TIMES,
    interval,
    polygon,
    section,
    shape_space_figure,
    shape_space_instants,
)
from crawlsim.plotting.style import shown_series
from crawlsim.plotting.sweeps import (
    JUMP_FLOOR,
    JUMP_RATIO,
    MAX_TICK_LABELS,
    cell_edges,
    is_geometric,
    jump_walls,
    jumps,
    sweep_data_figure,
    sweep_figure,
    swept_ticks,
    zero_contour,
)

#: The figures of one run, by the names of `crawlsim.plotting.FIGURE_NAMES`.
FIGURES: dict[str, Callable[..., Figure]] = {
    "motion": motion_figure,
    "gait-diagram": gait_figure,
    "kymograph": kymograph_figure,
    "convergence": convergence_figure,
    "shape-space": shape_space_figure,
    "rigid": rigid_figure,
}

__all__ = [
    "FIGURES",
    "FOLLOW_PERIODS",
    "FORCE_ROW_HEIGHT",
    "JUMP_FLOOR",
    "JUMP_RATIO",
    "MAX_BAND_LABELS",
    "MAX_FORCE_ROWS",
    "MAX_MOTION_BLOCKS",
    "MAX_SERIES",
    "MAX_TICK_LABELS",
    "NICE_DIVISIONS",
    "RELATIVE_STRESS_RATIO",
    "SHAPE_SPACE_TIMES",
    "block_forces",
    "cell_edges",
    "convergence_figure",
    "convergence_scale",
    "convergence_series",
    "gait_figure",
    "interval",
    "is_geometric",
    "jump_walls",
    "kymograph_figure",
    "jumps",
    "motion_figure",
    "polygon",
    "relative_stress",
    "rigid_figure",
    "section",
    "shape_space_figure",
    "shape_space_instants",
    "shown_series",
    "slip_runs",
    "stress_bounds",
    "stress_mode",
    "sweep_data_figure",
    "sweep_figure",
    "swept_ticks",
    "zero_contour",
]
