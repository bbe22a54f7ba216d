"""The compiled kernel made ready: every entry point compiled into numba's cache, in parallel.

`crawlsim.kernel.jit` runs small work interpreted and switches to the compiled kernel once it is
in the cache. ``crawlsim warmup`` puts it there: each task below compiles the entry points of one
path (the exact period, catch-up, the Newton step, the sensitivity walks, the generic processes'
closed forms) by running a small gait through that path, with what the path needs before its
entry points (a run to a limit, say) done interpreted, so that no two tasks compile the same
entry point. Tasks run in separate processes, as many at once as there are cores; the stamp
(`crawlsim.kernel.jit.stamp`) is written once all have succeeded, and from then on every
command loads the kernel from the cache instead of compiling it.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Callable
from typing import Any

from crawlsim.analysis.run import simulate
from crawlsim.analysis.sensitivity import sensitivity
from crawlsim.gait.document import parse_gait
from crawlsim.kernel import jit
from crawlsim.model.process import compile

#: A four-block wave with smooth (Fourier) links and time-controlled friction: its events need
#: the closed forms and the certified sampling, its limit the exact and catch-up walks.
GAIT = """
name: warmup
blocks: 4
period: 1.0
stiffness: [10.0, 12.0, 10.0]
links:
  - {kind: cosine, mean: 1.0, amplitude: 0.3, phase: 0.0}
  - {kind: fourier, mean: 1.0, cos: [0.25, 0.05], sin: [0.0, 0.02], phase: 0.3}
  - {kind: piecewise-linear, times: [0, 0.5, 1], values: [1.2, 0.8, 1.2]}
friction:
  forward: {kind: cosine, mean: 1.2, amplitude: 0.4, phase: 0.0}
  backward: 2.0
simulation: {steps_per_period: 200, max_periods: 60}
"""
#: The wave onto rougher ground (docs/model.md §8): catch-up's steps on terrain, its one entry
#: point of its own (the exact loop's ground is in its period, compiled on uniform ground too).
TERRAIN = "terrain: {patches: [{from: 3.5, forward: 1.5, backward: 1.5}]}\n"
#: A generic process (the paper's triangle): the Python exact loop's compiled closed forms, whose
#: zeros are found by kind of offsets (`crawlsim.integrate.exact`): linear pieces alone, one
#: harmonic beside them, several harmonics (sampled).
PROCESS = """
kind: sweeping-process
name: warmup-process
period: 1.0
normals: [[0.0, -1.0], [0.8660254037844386, 0.5], [-0.8660254037844386, 0.5]]
initial: [0.0, 0.0]
simulation: {steps_per_period: 60, max_periods: 20}
offsets:
"""
LINEAR = "  - {kind: piecewise-linear, times: [0, 0.5, 1], values: [0.3, 0.8, 0.3]}\n"
COSINE = "  - {kind: cosine, mean: 0.3, amplitude: 0.5, phase: 0.0}\n"
FOURIER = "  - {kind: fourier, mean: 0.3, cos: [0.5, 0.1], sin: [0.0, 0.05], phase: 0.3}\n"
OFFSETS = (3 * LINEAR, COSINE + 2 * LINEAR, COSINE + FOURIER + LINEAR)


def _gait() -> Any:
    return parse_gait(GAIT, "warmup.yaml")


def _exact() -> None:
    with jit.forced("compiled"):
        simulate(compile(_gait()), integrator="exact", max_periods=3, limit="iterate")


def _catch_up() -> None:
    with jit.forced("compiled"):
        simulate(compile(_gait()), integrator="catch-up", max_periods=60)
        simulate(compile(parse_gait(GAIT + TERRAIN, "warmup.yaml")), integrator="catch-up", max_periods=3)


def _sensitivity() -> None:
    gait = _gait()
    for integrator in ("exact", "catch-up"):
        g = gait.replace("simulation.integrator", integrator)
        with jit.forced("python"):
            sensitivity(g, "period")  # the run and its limit, interpreted: cached in the gait
        with jit.forced("compiled"):
            sensitivity(g, ["stiffness.*", "friction.forward.mean", "links.0.amplitude"])


def _process() -> None:
    with jit.forced("compiled"):
        for offsets in OFFSETS:
            simulate(compile(parse_gait(PROCESS + offsets, "warmup-process.yaml")), integrator="exact", max_periods=3)


#: The tasks, longest first (so that the longest starts first).
TASKS: dict[str, Callable[[], None]] = {
    "exact": _exact,
    "sensitivity": _sensitivity,
    "catch-up": _catch_up,
    "process": _process,
}


def run_task(name: str) -> None:
    """Compile one task's entry points in this process."""
    TASKS[name]()


def warmup(jobs: int | None = None, *, report: Callable[[str], None] = lambda s: None) -> float:
    """Compile every task, ``jobs`` processes at a time (default: the cores), write the stamp,
    and return the wall time. A task that fails raises `RuntimeError` with its output."""
    jobs = jobs or os.cpu_count() or 1
    start = time.perf_counter()
    pending, running = list(TASKS), dict[str, subprocess.Popen[str]]()
    argv, env = jit.this_python("-m", "crawlsim.study.warmup")
    env["CRAWLSIM_BACKGROUND_COMPILE"] = "0"
    try:
        while pending or running:
            while pending and len(running) < jobs:
                name = pending.pop(0)
                running[name] = subprocess.Popen(
                    [*argv, name],
                    env=env,
                    stdout=subprocess.PIPE,
                    stderr=subprocess.STDOUT,
                    text=True,
                )
            time.sleep(0.1)
            for name, proc in list(running.items()):
                if proc.poll() is None:
                    continue
                del running[name]
                out = proc.stdout.read() if proc.stdout else ""
                if proc.returncode:
                    raise RuntimeError(f"compiling the kernel ({name}) failed:\n{out}")
                report(f"compiled {name} ({time.perf_counter() - start:.0f} s)")
    finally:
        for proc in running.values():
            proc.kill()
            proc.wait()
    path = jit.stamp()
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f"{time.time()}\n")
    return time.perf_counter() - start


if __name__ == "__main__":
    run_task(sys.argv[1])
