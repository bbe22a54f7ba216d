#!/usr/bin/env python
"""Gait design on the four-block wave (gaits/peristalsis-4.yaml): `crawlsim optimize` against a
brute-force grid, then the phase lags and the amplitude for v0 and for the cost of transport.

1. **Agreement with a grid** (the issue's done-when check). v0 on a 60 x 60 grid of the phase lags
   of links 1 and 2 over [0, 1] x [0, 1] (3,600 points, the sweep engine), against
   `crawlsim.design.optimize` on the same box with the default budget (150 (n + 1) = 450 points, within
   the allowed fifth of the grid, 720), for several seeds: the gap of each optimum to the grid's
   maximum (it must be > -1e-4), its evaluations and wall time (medians printed).
2. **--jobs**: one optimisation with 1 and with 2 local workers, in one run, as a ratio.
3. **Three parameters**: the lags and ``links.*.amplitude`` in [0.1, 0.4], maximising v0; then
   minimising the cost of transport subject to v0 >= 0.3.
4. **Figures** for docs/optimize.md, through the command line as a user draws
   them (`crawlsim optimize ... -o X.h5`, `crawlsim plot X.h5 -o docs/figures`): the convergence
   of the three-parameter v0 search, and the Pareto front of v0 against the cost of transport
   over the same three parameters (``--pareto``).

Every run uses the exact integrator with 20 output steps per period (the exact integrator's v0
does not depend on them).

    python scripts/optimize-four-block.py [--grid 60] [--seeds 5] [--jobs 2]
                                          [--no-figures | --figures-only]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from crawlsim.design import optimize as opt
from crawlsim.design.problem import Method, Objective, make_problem
from crawlsim.gait.document import load_gait, with_simulation
from crawlsim.study import sweep as sweeps

ROOT = Path(__file__).resolve().parents[1]
GAIT = ROOT / "gaits" / "peristalsis-4.yaml"
LAGS = ["links.1.phase=0:1", "links.2.phase=0:1"]
STEPS = 20


def base(path: Path = GAIT):
    return with_simulation(load_gait(path), integrator="exact", steps_per_period=STEPS)


def grid_maximum(n: int, jobs: int) -> tuple[float, tuple, float]:
    grid = sweeps.make_grid(base(), [f"links.1.phase=0:1:{n}", f"links.2.phase=0:1:{n}"])
    began = time.perf_counter()
    table = sweeps.run_sweep(grid, jobs=jobs)
    wall = time.perf_counter() - began
    v0 = table.columns()["v0"]
    k = int(np.nanargmax(v0))
    return float(v0[k]), grid.values(k), wall


def cli(*args: str) -> None:
    subprocess.run(["crawlsim", *args], check=True, stdout=subprocess.DEVNULL)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid", type=int, default=60)
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--no-figures", action="store_true")
    ap.add_argument("--figures-only", action="store_true")
    args = ap.parse_args()
    free = [*LAGS, "links.*.amplitude=0.1:0.4"]
    if not args.figures_only:
        measure(args, free)
    if not args.no_figures:
        figures(args, free)


def measure(args, free: list[str]) -> None:
    # 1. agreement with the grid
    grid_max, where, grid_wall = grid_maximum(args.grid, args.jobs)
    size = args.grid**2
    print(
        f"grid {args.grid} x {args.grid} ({size} points, -j {args.jobs}): max v0 "
        f"{grid_max!r} at links.1.phase = {where[0]:.6g}, links.2.phase = {where[1]:.6g}; "
        f"{grid_wall:.1f} s"
    )
    problem = make_problem(base(), LAGS)
    walls, counts, gaps = [], [], []
    for seed in range(args.seeds):
        result = opt.optimize(problem, Method(seed=seed))
        gap = result.value - grid_max
        walls.append(result.wall_time)
        counts.append(len(result.evaluations))
        gaps.append(gap)
        x = result.best_point.x
        print(
            f"  seed {seed}: v0 {result.value!r} at ({x[0]:.9f}, {x[1]:.9f}), "
            f"v0 - grid max = {gap:+.3e}, {len(result.evaluations)} evaluations "
            f"({result.stage_counts()['polish']} polish), {result.wall_time:.1f} s"
        )
    print(
        f"optimize: {sum(g > -1e-4 for g in gaps)} of {args.seeds} seeds within 1e-4 of the "
        f"grid maximum (or above it); median {statistics.median(counts):.0f} evaluations = "
        f"{statistics.median(counts) / size:.3f} of the grid's (allowed: 0.2); median wall "
        f"time {statistics.median(walls):.1f} s against {grid_wall:.1f} s for the grid "
        f"(ratio {statistics.median(walls) / grid_wall:.3f})"
    )

    # 2. --jobs
    if args.jobs > 1:
        one = opt.optimize(problem, Method(seed=0))
        many = opt.optimize(problem, Method(seed=0), jobs=args.jobs)
        assert many.best_point.x == one.best_point.x and many.value == one.value
        print(
            f"-j 1: {one.wall_time:.1f} s, -j {args.jobs}: {many.wall_time:.1f} s, ratio "
            f"{many.wall_time / one.wall_time:.2f} (same best point, bit for bit)"
        )

    # 3. phase lags and amplitude
    fast = opt.optimize(make_problem(base(), free), Method(seed=0), jobs=args.jobs)
    print(
        f"max v0 over lags and amplitude: v0 {fast.value!r}, cost of transport "
        f"{fast.best_point.row.cost_of_transport!r} at {fast.best_values}; "
        f"{len(fast.evaluations)} evaluations, {fast.wall_time:.1f} s"
    )
    cheap = opt.optimize(
        make_problem(base(), free, objective=Objective("cost_of_transport", "minimize"), constraints=["v0>=0.3"]),
        Method(seed=0),
        jobs=args.jobs,
    )
    row = cheap.best_point.row
    print(
        f"min cost of transport at v0 >= 0.3: {row.cost_of_transport!r} (v0 {row.v0!r}) at "
        f"{cheap.best_values}; {len(cheap.evaluations)} evaluations, "
        f"{cheap.wall_time:.1f} s; lower bound sum_j mu_j^+ = 4 (docs/optimize.md)"
    )


def figures(args, free: list[str]) -> None:
    out = ROOT / "docs" / "figures"
    with tempfile.TemporaryDirectory() as work:
        four = str(Path(work) / "optimize-four-block.h5")
        cli(
            "optimize",
            str(GAIT),
            *sum((["--free", f] for f in free), []),
            "--steps-per-period",
            str(STEPS),
            "-j",
            str(args.jobs),
            "-q",
            "-o",
            four,
        )
        cli("plot", four, "-o", str(out))
        front = str(Path(work) / "optimize-four-block-cost.h5")
        cli(
            "optimize",
            str(GAIT),
            *sum((["--free", f] for f in free), []),
            "--pareto",
            "--steps-per-period",
            str(STEPS),
            "-j",
            str(args.jobs),
            "-q",
            "-o",
            front,
        )
        cli("plot", front, "-o", str(out), "--only", "pareto-front")
    print(f"figures: {out}/optimize-four-block-objective.png, {out}/optimize-four-block-cost-pareto-front.png")


if __name__ == "__main__":
    sys.exit(main())
