#!/usr/bin/env python
"""Benchmark: what a study costs beyond the arithmetic, as ratios measured in one run.

* **sweep point**: the marginal cost of a point of an exact peristalsis-4 sweep (a 121-point
  sweep over links.1.phase against an 11-point one, in-process, CPU time) in reference periods:
  a compiled 1000-step catch-up period of the same chain without certificate
  (`reference_period` of scripts/bench-kernel.py), timed in the same rounds (bar: at most 6);
* **gait files**: the marginal cost of a file of ``crawlsim velocity F1.yaml ... F120.yaml``
  (120 small corpus gaits against 12 of them, fresh processes, CPU time) against the same
  files' in-process ``crawlsim.simulate`` (bar: at most 2);
* **Newton**: the periodic-limit solver against plain iteration on the 20-block retrograde
  wave, whose iterates contract slowly (about 170 periods to 1e-12), in the runs' own
  ``wall_time`` (bar: newton / iterate at most 1/2);
* **catch-up step** through ``crawlsim velocity --integrator catch-up`` at N = 64 and 256: the
  margin of 4000 over 1000 steps a period, per step and period, against the reference step
  (bar: at most 5).

The kernel is compiled (``CRAWLSIM_KERNEL=compiled``; `crawlsim warmup` first): these are the
costs around the compiled arithmetic. Medians of ``--repeat`` rounds, with the load average.

    python scripts/bench-study.py [--repeat 5]
"""

from __future__ import annotations

import os

os.environ.setdefault("CRAWLSIM_KERNEL", "compiled")  # the compiled kernel's speed (crawlsim.kernel.jit)

import argparse
import importlib.util
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml
from benchclock import run_clocked  # scripts/benchclock.py

import crawlsim
from crawlsim.analysis.run import simulate
from crawlsim.gait.corpus import random_gait
from crawlsim.gait.document import gait_from_document
from crawlsim.integrate.stepping import CatchUpStepper
from crawlsim.model.process import compile as compile_gait
from crawlsim.study.sweep import sweep

ROOT = Path(__file__).resolve().parents[1]
ENV = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")  # one thread: comparable runs


def _script(name: str):
    spec = importlib.util.spec_from_file_location(name.replace("-", "_"), ROOT / "scripts" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # numba's cache finds the module of a cached function by name
    spec.loader.exec_module(module)
    return module


KERNEL = _script("bench-kernel")
LIMIT = _script("bench-limit")


def reference_seconds(gait, steps: int = 1000) -> float:
    """One compiled 1000-step reference period of ``gait``'s chain (CPU seconds), from the state
    and active set a catch-up period ends on."""
    process = compile_gait(gait.replace("simulation.steps_per_period", steps), steps)
    stepper = CatchUpStepper(process)
    record = stepper.step_period()
    k = np.ascontiguousarray(process.polyhedron.stiffness, dtype=float)
    C = np.ascontiguousarray(process.offsets)
    signs = np.zeros(process.blocks, dtype=np.int8)
    W = np.empty((C.shape[0], process.blocks - 1))
    KERNEL.reference_period(k, C, record.w[-1], signs, W)  # compile, settle the set
    began = time.process_time()
    KERNEL.reference_period(k, C, record.w[-1], signs, W)
    return time.process_time() - began


def sweep_point(repeat: int) -> tuple[float, float]:
    """(marginal CPU seconds of an exact sweep point, reference period seconds)."""
    gait = crawlsim.load_gait(ROOT / "gaits" / "peristalsis-4.yaml")
    sweep(gait, ["links.1.phase=0:1:11"])  # warm
    big, small, ref = [], [], []
    for _ in range(repeat):
        for n, out in ((121, big), (11, small)):
            began = time.process_time()
            sweep(gait, [f"links.1.phase=0:1:{n}"])
            out.append(time.process_time() - began)
        ref.append(reference_seconds(gait))
    return (statistics.median(big) - statistics.median(small)) / 110, statistics.median(ref)


def gait_files(folder: Path, count: int) -> list[str]:
    """``count`` small corpus gaits (2-5 blocks, 100 steps a period) as files in ``folder``."""
    paths = []
    for seed in range(count):
        gait = random_gait(seed, blocks=(2, 5))
        document = dict(gait.document, simulation={"steps_per_period": 100, "max_periods": 200})
        path = folder / f"gait-{seed:03d}.yaml"
        path.write_text(yaml.safe_dump(document, sort_keys=False))
        paths.append(str(path))
    return paths


def files(repeat: int) -> tuple[float, float]:
    """(marginal CPU seconds of a file of one velocity call, in-process simulate seconds)."""
    with tempfile.TemporaryDirectory(prefix="crawlsim-files-") as folder:
        paths = gait_files(Path(folder), 120)
        command = [sys.executable, "-m", "crawlsim", "velocity", "-o", f"{folder}/out.csv"]
        many, few, alone = [], [], []
        gaits = [crawlsim.load_gait(p) for p in paths]
        for g in gaits:  # warm
            crawlsim.simulate(g, keep_trajectory=False)
        for _ in range(repeat):
            for out, some in ((many, paths), (few, paths[:12])):
                Path(f"{folder}/out.csv").unlink(missing_ok=True)
                out.append(run_clocked([*command, *some], cwd=ROOT, env=ENV)[1])
            began = time.process_time()
            for g in gaits:
                crawlsim.simulate(g)
            alone.append((time.process_time() - began) / len(gaits))
    return (statistics.median(many) - statistics.median(few)) / 108, statistics.median(alone)


def newton(repeat: int) -> dict[str, tuple[float, float, int]]:
    """(newton wall_time, iterate wall_time, iterate periods) on the 20-block wave: the
    library's run without history (what velocity and sweeps run), ``crawlsim.simulate`` (the
    history and the trajectory kept) and ``crawlsim run`` (the run's own wall_time, --json)."""
    gait = gait_from_document(LIMIT.wave_document(20, 1000), "wave-20")
    process = compile_gait(gait)
    out = {}
    with tempfile.TemporaryDirectory(prefix="crawlsim-newton-") as folder:
        path = Path(folder) / "wave-20.yaml"
        path.write_text(yaml.safe_dump(gait.document))
        ways = {
            "library": lambda limit: simulate(process, integrator="exact", limit=limit, history=False),
            "crawlsim.simulate": lambda limit: crawlsim.simulate(gait, limit=limit),
        }
        for name, call in ways.items():
            times: dict[str, list[float]] = {"newton": [], "iterate": []}
            for _ in range(repeat):
                for limit in times:
                    run = call(limit)
                    times[limit].append(run.effort.wall_time)
                    periods = run.periods if limit == "iterate" else 0
            out[name] = (statistics.median(times["newton"]), statistics.median(times["iterate"]), periods)
        times = {"newton": [], "iterate": []}
        for _ in range(repeat):
            for limit in times:
                done = subprocess.run(
                    [
                        sys.executable,
                        "-m",
                        "crawlsim",
                        "run",
                        str(path),
                        "--limit",
                        limit,
                        "--json",
                        "-o",
                        f"{folder}/r.h5",
                    ],
                    capture_output=True,
                    text=True,
                    env=ENV,
                    check=True,
                )
                summary = yaml.safe_load(done.stdout)
                times[limit].append(summary["wall_time"])
                periods = summary["periods"] if limit == "iterate" else 0
        out["crawlsim run"] = (statistics.median(times["newton"]), statistics.median(times["iterate"]), periods)
    return out


def catch_up_step(N: int, repeat: int, periods: int = 6) -> tuple[float, float]:
    """(margin per catch-up step of ``crawlsim velocity --integrator catch-up`` from 1000 to 4000
    steps a period, reference step), CPU seconds. The runs are ``periods`` plain periods each
    (``--limit iterate --max-periods``: exit code 3), so that both do the same periods, and the
    exact run that measures the time-step error with them."""
    document = KERNEL._bench_scale().wave_document(N, 1000, wave="segments")
    with tempfile.TemporaryDirectory(prefix="crawlsim-steps-") as folder:
        times: dict[int, list[float]] = {1000: [], 4000: []}
        for steps in times:
            path = Path(folder) / f"wave-{steps}.yaml"
            path.write_text(yaml.safe_dump(dict(document, simulation={"steps_per_period": steps})))
        for _ in range(repeat):
            for steps in times:
                command = [sys.executable, "-m", "crawlsim", "velocity", f"{folder}/wave-{steps}.yaml"]
                command += ["--integrator", "catch-up", "--limit", "iterate", "--max-periods", str(periods)]
                times[steps].append(run_clocked(command, cwd=ROOT, env=ENV, check=False)[1])
        gait = gait_from_document(document, f"wave-{N}")
        ref = statistics.median(reference_seconds(gait) for _ in range(repeat)) / 1000
    margin = (statistics.median(times[4000]) - statistics.median(times[1000])) / (3000 * periods)
    return margin, ref


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    subprocess.run([sys.executable, "-m", "crawlsim", "warmup"], check=True, capture_output=True, env=ENV)
    print(f"load average {os.getloadavg()[0]:.2f}; medians of {args.repeat} rounds")
    point, ref = sweep_point(args.repeat)
    print(
        f"  sweep point    {point * 1e3:8.3f} ms = {point / ref:5.1f} reference periods ({ref * 1e3:.3f} ms; bar <= 6)"
    )
    file, alone = files(args.repeat)
    print(f"  gait file      {file * 1e3:8.3f} ms = {file / alone:5.2f} x simulate ({alone * 1e3:.3f} ms; bar <= 2)")
    for way, (solver, iterate, periods) in newton(args.repeat).items():
        print(
            f"  Newton, {way:<18} {solver:7.3f} s = {solver / iterate:5.2f} x iterate "
            f"({iterate:.3f} s, {periods} periods; bar <= 0.5)"
        )
    for N in (64, 256):
        step, ref_step = catch_up_step(N, args.repeat)
        print(
            f"  catch-up N={N:<4}{step * 1e6:7.3f} us = {step / ref_step:5.1f} x reference step "
            f"({ref_step * 1e6:.3f} us; bar <= 5)"
        )
    print(f"load average after {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
