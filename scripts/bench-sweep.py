#!/usr/bin/env python
"""Benchmark: gait-steps per second of a sweep against a loop of single `crawlsim velocity` runs.

The sweep is 1,000 points of the four-block wave (gaits/peristalsis-4.yaml) at 400 steps per
period, ``links.*.amplitude`` from 0.05 to 0.45, run with ``--jobs 2`` (validation of every point,
worker start-up and batched stepping included: the wall time of `crawlsim.study.sweep.sweep`).

The loop runs single `crawlsim velocity` computations in-process, as library calls (build and
validate the point's gait, compile, `crawlsim.analysis.run.simulate`): the honest comparison, with
no interpreter start-up per point. It runs every k-th point (``--loop-every``) and is compared
per gait-step. "gait-steps" = periods actually simulated x steps per period, summed over points.

    python scripts/bench-sweep.py [--repeat 3] [--points 1000] [--jobs 2] [--loop-every 10]

``--jobs-check`` measures instead whether ``-j 2`` is ever slower than ``-j 1`` (the sweep picks
its own parallelism, `crawlsim.study.executors.run_local`: the first task runs here and measures
the cost of a point, and the workers start only when they pay for their start-up): exact and
catch-up sweeps of peristalsis-4, small and large, each run with ``jobs=1`` and ``jobs=2``
alternately (interleaved), median wall times of ``--repeat`` runs and their ratio t(-j 1) /
t(-j 2) (>= 1: -j 2 is not slower).

    python scripts/bench-sweep.py --jobs-check [--repeat 5]

Measured (``--jobs-check --repeat 5``, medians of 5 interleaved runs, on the 2-core machine
with nothing else running, load average 0.8-1.2):

    sweep                                                  -j 1 s   -j 2 s  ratio
    exact, 20 steps, links.1.phase=0:1:12                   0.019    0.019   0.99
    exact, 20 steps, links.1.phase=0:1:120                  0.166    0.168   0.99
    catch-up, 400 steps, links.*.amplitude=0.05:0.45:40     0.057    0.057   1.00
    catch-up, 400 steps, links.*.amplitude=0.05:0.45:1000   1.372    1.378   1.00
    catch-up, 400 steps, links.*.amplitude=0.05:0.45:8000  11.139    6.687   1.67

The first four run in this process with ``-j 2`` too (two workers would not win back their
start-up and the kernel's load in each, `crawlsim.study.executors.worth_workers`): the same
computation twice, so their ratios are the run-to-run scatter (a second set of 7 runs: 1.00,
1.01, 0.97, 1.00). The 8000-point sweep (11 s of points) starts two workers and runs 1.67x
faster. Before issue 20 a catch-up sweep with ``-j 2`` always started two workers and ran at
0.72-0.82x of ``-j 1``.
"""

from __future__ import annotations

import os

os.environ.setdefault("CRAWLSIM_KERNEL", "compiled")  # the compiled kernel's speed (crawlsim.kernel.jit)

import argparse
import statistics
import time
from pathlib import Path

from crawlsim.analysis.run import simulate
from crawlsim.gait.document import load_gait, with_simulation
from crawlsim.model.process import compile_gait
from crawlsim.study import sweep as sweeps
from crawlsim.study.grid import parse_axis

GAIT = Path(__file__).resolve().parents[1] / "gaits" / "peristalsis-4.yaml"


#: The --jobs-check cases: (integrator, steps per period, axis).
JOB_CASES = (
    ("exact", 20, "links.1.phase=0:1:12"),
    ("exact", 20, "links.1.phase=0:1:120"),
    ("catch-up", 400, "links.*.amplitude=0.05:0.45:40"),
    ("catch-up", 400, "links.*.amplitude=0.05:0.45:1000"),
    ("catch-up", 400, "links.*.amplitude=0.05:0.45:8000"),
)


def jobs_check(repeat: int) -> None:
    """Median wall times of -j 1 and -j 2, interleaved, for each of `JOB_CASES`."""
    print(f"{'sweep':<52} {'-j 1 s':>8} {'-j 2 s':>8} {'ratio':>6}")
    for integrator, steps, axis in JOB_CASES:
        gait = with_simulation(load_gait(GAIT), steps_per_period=steps, integrator=integrator)
        walls: dict[int, list[float]] = {1: [], 2: []}
        tables = {}
        for _ in range(repeat):
            for jobs in (1, 2):
                began = time.perf_counter()
                tables[jobs] = sweeps.sweep(gait, [axis], jobs=jobs)
                walls[jobs].append(time.perf_counter() - began)
        assert tables[1].to_csv() == tables[2].to_csv()  # the same rows, bit for bit
        one, two = statistics.median(walls[1]), statistics.median(walls[2])
        print(
            f"{integrator + ', ' + str(steps) + ' steps, ' + axis:<52} {one:>8.3f} {two:>8.3f} {one / two:>6.2f}",
            flush=True,
        )


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs-check", action="store_true")
    ap.add_argument("--points", type=int, default=1000)
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--loop-every", type=int, default=10)
    ap.add_argument("--path", default="links.*.amplitude=0.05:0.45")
    args = ap.parse_args()
    if args.jobs_check:
        jobs_check(args.repeat)
        return
    gait = with_simulation(load_gait(GAIT), steps_per_period=args.steps)
    axis = f"{args.path}:{args.points}"
    grid = sweeps.make_grid(gait, [parse_axis(axis)])

    sweep_rates, loop_rates, walls = [], [], []
    for rep in range(args.repeat):
        began = time.perf_counter()
        table = sweeps.sweep(gait, [axis], jobs=args.jobs)
        wall = time.perf_counter() - began
        steps = sum(r.steps for r in table.rows)
        sweep_rates.append(steps / wall)
        walls.append(wall)

        began = time.perf_counter()
        loop_steps = 0
        for i in range(0, grid.size, args.loop_every):
            point = grid.gait(i)
            s = point.simulation
            result = simulate(compile_gait(point), max_periods=s.max_periods, tolerance=s.tolerance)
            assert abs(result.v0 - table.rows[i].v0) <= 1e-12
            loop_steps += result.steps
        loop_rates.append(loop_steps / (time.perf_counter() - began))
        print(
            f"run {rep + 1}: sweep {steps} gait-steps in {wall:.3f} s = "
            f"{sweep_rates[-1]:,.0f} gait-steps/s; loop of single runs "
            f"{loop_rates[-1]:,.0f} gait-steps/s",
            flush=True,
        )

    counts = table.counts()
    sweep_rate, loop_rate = statistics.median(sweep_rates), statistics.median(loop_rates)
    print(
        f"\nsweep: {args.points} points of {GAIT.name}, {axis}, {args.steps} steps/period, "
        f"--jobs {args.jobs}: {counts['ok']} ok, {counts['not-converged']} not converged, "
        f"{counts['failed']} failed; {steps} gait-steps "
        f"(mean {steps / args.points / args.steps:.2f} periods per point)"
    )
    print(f"median of {args.repeat} runs:")
    print(
        f"  sweep (--jobs {args.jobs})                 {sweep_rate:>14,.0f} gait-steps/s "
        f"(wall {statistics.median(walls):.3f} s)"
    )
    print(
        f"  loop of single runs (in-process)   {loop_rate:>14,.0f} gait-steps/s "
        f"(every {args.loop_every}th point, extrapolated per gait-step)"
    )
    print(f"  ratio                              {sweep_rate / loop_rate:>14.1f} x")
    print(
        f"bar: >= 1,000,000 gait-steps/s and >= 10x: "
        f"{'met' if sweep_rate >= 1e6 and sweep_rate >= 10 * loop_rate else 'NOT met'}"
    )


if __name__ == "__main__":
    main()
