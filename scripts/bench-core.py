#!/usr/bin/env python
"""Benchmark of exact catch-up stepping on the four-block wave (issue: core simulator).

In one run it measures, at 1000 steps per period:
  * crawlsim's steps per second (persistent Clarabel solver, certified fast paths);
  * the steps per second of a naive loop that builds a fresh Clarabel solver at every step and
    projects every step exactly (same KKT solve and certificate);
  * their ratio, and the largest difference in block positions between the two.

Usage: python scripts/bench-core.py [--repeats 5] [--periods 20] [--naive-periods 2]
"""

import os

os.environ.setdefault("CRAWLSIM_KERNEL", "compiled")  # the compiled kernel's speed (crawlsim.kernel.jit)

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from crawlsim.gait.document import load_gait, with_simulation
from crawlsim.integrate.stepping import CatchUpStepper
from crawlsim.model.process import compile_gait

GAIT = Path(__file__).resolve().parents[1] / "gaits" / "peristalsis-4.yaml"


def run(process, periods, **options):
    stepper = CatchUpStepper(process, **options)
    began = time.perf_counter()
    records = [stepper.step_period() for _ in range(periods)]
    return time.perf_counter() - began, records


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--periods", type=int, default=20)
    parser.add_argument("--naive-periods", type=int, default=2)
    parser.add_argument("--steps-per-period", type=int, default=1000)
    args = parser.parse_args()
    gait = with_simulation(load_gait(GAIT), steps_per_period=args.steps_per_period)
    process = compile_gait(gait)
    G = process.steps
    fast_rates, naive_rates, diffs = [], [], []
    for _ in range(args.repeats):
        t_fast, fast = run(process, args.periods)
        t_naive, naive = run(process, args.naive_periods, check_every_step=True, persistent_solver=False)
        fast_rates.append(args.periods * G / t_fast)
        naive_rates.append(args.naive_periods * G / t_naive)
        diffs.append(max(float(np.max(np.abs(a.x - b.x))) for a, b in zip(fast, naive)))
    fast_med, naive_med = statistics.median(fast_rates), statistics.median(naive_rates)
    print(f"gait: {GAIT.name}, {G} steps per period, {args.repeats} repeats (median)")
    print(f"crawlsim (persistent solver, certified fast paths): {fast_med:12,.0f} steps/s ({args.periods} periods)")
    print(
        f"naive loop (fresh Clarabel solver every step):      {naive_med:12,.0f} steps/s ({args.naive_periods} periods)"
    )
    print(f"ratio: {fast_med / naive_med:.1f}x")
    print(f"largest difference in block positions: {max(diffs):.3g}")


if __name__ == "__main__":
    main()
