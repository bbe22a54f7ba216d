#!/usr/bin/env python
"""Benchmark: v0 of the four-block wave (gaits/peristalsis-4.yaml) to 1e-9, exact vs catch-up.

Prints, in one run:

* the exact integrator's v0 and its wall time (median of ``--repeats`` runs, compile included),
  with a small output grid and with the default one (the grid only samples the solution);
* the exact v0's own consistency: other bracketing grids and output grids;
* catch-up at a sequence of step counts: the error against the exact v0, error * G (first
  order: bounded), the least-squares extrapolation v(G) = v_inf + C/G and the last Richardson
  value 2 v(2G) - v(G), which cross-check the reference;
* the step count catch-up needs for an error of 1e-9 (max |error| G / 1e-9: its error is
  irregular in G, so the envelope, not a fit, decides), its time at the measured cost per step,
  and the ratio of the two times.

Catch-up at that step count (~3e8 steps per period) cannot be run here: one period's arrays
alone would take tens of GB. Its time is extrapolated linearly from the largest measured run,
which is stated in the output.

    python scripts/bench-exact.py            # about half a minute
    python scripts/bench-exact.py --quick    # a few seconds, shorter catch-up sequence
"""

from __future__ import annotations

import os

os.environ.setdefault("CRAWLSIM_KERNEL", "compiled")  # the compiled kernel's speed (crawlsim.kernel.jit)

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from crawlsim.analysis.run import simulate
from crawlsim.gait.document import load_gait
from crawlsim.integrate.exact import EventStepper
from crawlsim.model.process import compile_gait

GAIT = Path(__file__).resolve().parents[1] / "gaits" / "peristalsis-4.yaml"
TARGET = 1e-9
BAR = 0.2  # seconds


def timed(fn, repeats):
    times, value = [], None
    for _ in range(repeats):
        began = time.perf_counter()
        value = fn()
        times.append(time.perf_counter() - began)
    return value, statistics.median(times)


def exact_v0(gait, steps):
    result = simulate(
        compile_gait(gait, steps),
        max_periods=gait.simulation.max_periods,
        tolerance=gait.simulation.tolerance,
        integrator="exact",
    )
    return result


def catch_up_v0(gait, steps):
    result = simulate(
        compile_gait(gait, steps), max_periods=gait.simulation.max_periods, tolerance=gait.simulation.tolerance
    )
    return result


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    gait = load_gait(GAIT)

    exact_small, t_small = timed(lambda: exact_v0(gait, 16), args.repeats)
    exact_default, t_default = timed(lambda: exact_v0(gait, 1000), args.repeats)
    v0 = exact_small.v0
    print(f"gait {gait.name}: T = {gait.period:g}, target |error in v0| <= {TARGET:g}")
    print(f"exact     v0 = {v0:.16f}  ({exact_small.periods} periods, {exact_small.convergence})")
    print(f"          time, output grid 16 steps     {t_small * 1e3:8.2f} ms  (median of {args.repeats})")
    print(f"          time, output grid 1000 steps   {t_default * 1e3:8.2f} ms")
    print(
        f"          bar: v0 to 9 digits in < {BAR:g} s: "
        f"{'met' if t_small < BAR else 'NOT met'} ({t_small / BAR:.2f} of the bar)"
    )

    spread = [abs(exact_default.v0 - v0)]
    for cells in (64, 8192):
        stepper = EventStepper(compile_gait(gait, 16), bracket_cells=cells)
        for _ in range(exact_small.periods):
            rec = stepper.step_period()
        spread.append(abs(np.mean(rec.x[-1] - rec.x[0]) / gait.period - v0))
    print(
        f"          consistency over output grids 16/1000 and bracketing grids 64/1024/8192: "
        f"max |dv0| = {max(spread):.2g}"
    )

    steps = (
        [1009, 2003, 4001, 8009, 16001] if args.quick else [1009, 2003, 4001, 8009, 16001, 32003, 64007, 128021, 256019]
    )
    print("\ncatch-up      G          v0                    error         error*G    time")
    values, costs = [], []
    for G in steps:
        result, seconds = timed(lambda G=G: catch_up_v0(gait, G), 1 if G > 20000 else 3)
        error = result.v0 - v0
        values.append(result.v0)
        costs.append(seconds / (result.periods * G))
        print(f"         {G:8d}   {result.v0:.15f}   {error:+.3e}   {error * G:+.4f}   {seconds * 1e3:8.1f} ms")
    G = np.array(steps, dtype=float)
    values = np.array(values)
    tail = slice(-5, None)  # the asymptotic end of the sequence, weighted by G (error ~ C/G)
    design = np.column_stack([np.ones_like(G[tail]), 1 / G[tail]]) * G[tail, None]
    (v_inf, C), *_ = np.linalg.lstsq(design, values[tail] * G[tail], rcond=None)
    richardson = (steps[-1] * values[-1] - steps[-2] * values[-2]) / (steps[-1] - steps[-2])
    inside = bool(np.all(np.abs(values - v0) <= 0.3 / G))
    print(
        f"cross-check: weighted least squares v_inf + C/G on the last 5: v_inf = {v_inf:.12f}"
        f" (C = {C:+.4f}), |v_inf - v0_exact| = {abs(v_inf - v0):.2g}"
    )
    print(f"             Richardson on the last pair: {richardson:.12f}, |. - v0_exact| = {abs(richardson - v0):.2g}")
    print(f"             v0_exact within 0.3/G of every catch-up value: {inside}")

    envelope = float(np.max(np.abs(values - v0) * G))
    needed = envelope / TARGET
    per_step = costs[-1]
    t_catch_up = per_step * needed * exact_small.periods
    print(f"\ncatch-up needs G ~ {needed:.2g} steps per period for {TARGET:g} (envelope |error| <= {envelope:.3f}/G)")
    print(
        f"         at {per_step * 1e9:.1f} ns per step (measured at G = {steps[-1]}): "
        f"{t_catch_up:.3g} s for {exact_small.periods} periods (extrapolated)"
    )
    print(f"ratio catch-up / exact time for v0 to {TARGET:g}: {t_catch_up / t_small:.3g}")


if __name__ == "__main__":
    main()
