#!/usr/bin/env python
"""The gradient search of `crawlsim optimize --method gradient` (a coarse sample, then
quasi-Newton runs on the exact sensitivities, `crawlsim.study.descent`) against the evolution
search (differential evolution + pattern search), measured in one run.

1. **The README's two-lag example**: maximise v0 of gaits/peristalsis-4.yaml over
   ``links.1.phase`` and ``links.2.phase`` in [0, 1] (exact integrator, 20 output steps). For
   each method: the best v0, the evaluation at which the best v0 first came within 1e-6 of the
   known optimum 7/15 (phases (1/2, 0)), the evaluations the method spent in all, and its wall
   time. The bar: the gradient search gets within 1e-6 in at most 1/5 of the evolution search's
   evaluations.
2. **Ten lags**: an 11-block cosine wave, ``links.0.phase`` ... ``links.9.phase`` in [0, 1]:
   the evolution search with its default budget, then the gradient search with as many
   restarts as its Latin-hypercube sample has points and its evaluation budget raised until it
   uses about the same wall time (or ends by itself): best v0 of each. The bar: the gradient
   search reaches a better v0 in the same wall time.

An evaluation of the gradient search's local runs is one verified limit with its gradient (at
most 1 + 0.2 p times the cost of v0 alone, scripts/bench-sensitivity.py); a sample point is v0
alone.

Measured on the 2-core machine shared with other jobs (one run each; the evaluation counts do
not depend on the load, the wall times do):

    two lags, peristalsis-4 (optimum 7/15 at phases (1/2, 0))
      evolution: v0 0.46666666666653356, within 1e-6 at evaluation 279, 360 evaluations
      gradient:  v0 0.46666666666666673, within 1e-6 at evaluation 25, 48 evaluations
    ten lags, 11-block wave: see the handoff (filled in by the run below)

    python scripts/optimize-gradient.py            # several minutes
    python scripts/optimize-gradient.py --quick    # the two-lag example only
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import crawlsim
from crawlsim.gait.document import gait_from_document
from crawlsim.study.optimize import Method, OptimizationResult, make_problem, optimize

ROOT = Path(__file__).resolve().parents[1]
OPTIMUM = 7.0 / 15.0


def first_within(result: OptimizationResult, target: float, tol: float) -> int | None:
    """The number of evaluations after which the best v0 was within ``tol`` of ``target``."""
    best = -math.inf
    for e in result.evaluations:
        if e.row.v0 is not None:
            best = max(best, e.row.v0)
        if best >= target - tol:
            return e.index + 1
    return None


def wave(blocks: int) -> crawlsim.Gait:
    links = [{"kind": "cosine", "mean": 1.0, "amplitude": 0.3, "phase": i / (blocks - 1)}
             for i in range(blocks - 1)]
    doc = {"name": f"wave-{blocks}", "blocks": blocks, "period": 1.0, "stiffness": 10.0,
           "links": links, "friction": {"forward": 1.0, "backward": 2.0},
           "simulation": {"steps_per_period": 20, "max_periods": 1000, "tolerance": 1e-12}}
    gait = gait_from_document(doc, f"wave-{blocks}")
    assert isinstance(gait, crawlsim.Gait)
    return gait


def timed(problem, method: Method) -> tuple[OptimizationResult, float]:
    began = time.perf_counter()
    result = optimize(problem, method)
    return result, time.perf_counter() - began


def two_lags() -> None:
    gait = crawlsim.load_gait(ROOT / "gaits" / "peristalsis-4.yaml")
    assert isinstance(gait, crawlsim.Gait)
    gait = gait.replace("simulation.steps_per_period", 20)
    problem = make_problem(gait, ["links.1.phase=0:1", "links.2.phase=0:1"])
    print("two lags, peristalsis-4 (optimum 7/15 at phases (1/2, 0))")
    counts = {}
    for search in ("evolution", "gradient"):
        result, wall = timed(problem, Method(search=search))
        counts[search] = first_within(result, OPTIMUM, 1e-6)
        print(f"  {search:<10} v0 {result.value!r} at {tuple(result.best_point.x)}, within 1e-6 "
              f"at evaluation {counts[search]}, {len(result.evaluations)} evaluations, "
              f"{wall:.2f} s")
    if counts["evolution"] and counts["gradient"]:
        print(f"  evaluations to 1e-6: gradient / evolution = "
              f"{counts['gradient'] / counts['evolution']:.3f} (bar <= 0.2)")


def ten_lags() -> None:
    problem = make_problem(wave(11), [f"links.{i}.phase=0:1" for i in range(10)])
    print("ten lags, 11-block wave")
    evolution, t_evolution = timed(problem, Method())
    print(f"  evolution  v0 {evolution.value!r}, {len(evolution.evaluations)} evaluations, "
          f"{t_evolution:.1f} s")
    budget = 100
    while True:
        gradient, t_gradient = timed(problem, Method(search="gradient", restarts=40,
                                                     max_evaluations=budget))
        if t_gradient >= 0.8 * t_evolution or len(gradient.evaluations) < budget:
            break
        budget = int(budget * max(1.5, 0.9 * t_evolution / max(t_gradient, 1e-3)))
    print(f"  gradient   v0 {gradient.value!r}, {len(gradient.evaluations)} evaluations, "
          f"{t_gradient:.1f} s ({gradient.runs[0].stop})")
    print(f"  gradient - evolution v0 = {gradient.value - evolution.value:.3e} (bar > 0), wall "
          f"time ratio {t_gradient / t_evolution:.2f}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    two_lags()
    if not args.quick:
        ten_lags()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
