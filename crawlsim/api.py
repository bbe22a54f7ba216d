"""The library entry points behind the command line: a Python user calls these too."""

from __future__ import annotations

from pathlib import Path

from .analysis import RunResult, simulate
from .gait import Gait, ProcessSpec, load_gait
from .h5io import ResultsWriter
from .model import compile


def run(gait: Gait | ProcessSpec | str | Path, *, output=None, save_every: int = 1,
        check_every_step: bool = False, progress=None) -> RunResult:
    """Simulate a gait to its periodic regime; write the HDF5 results file if ``output`` is given.

    ``gait`` is a `Gait`, a `ProcessSpec` (a generic sweeping process, whose run has no velocity:
    v0 and the other crawler keys are None) or the path of either file. Its ``simulation`` settings (steps per period,
    maximum periods, tolerance) are used as they are: change them with
    `crawlsim.gait.with_simulation`.
    """
    if not isinstance(gait, (Gait, ProcessSpec)):
        gait = load_gait(gait)
    process = compile(gait)
    s = gait.simulation
    options = dict(max_periods=s.max_periods, tolerance=s.tolerance, integrator=s.integrator,
                   check_every_step=check_every_step, progress=progress)
    if output is None:
        return simulate(process, **options)
    with ResultsWriter(output, process, save_every=save_every) as writer:
        result = simulate(process, sink=writer, **options)
        writer.finish(result, gait.source_text, kind=gait.document.get("kind", "crawler"),
                      unchecked_uniqueness=getattr(gait, "uniqueness_unchecked", False))
    return result
