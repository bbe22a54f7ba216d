#!/usr/bin/env python
"""Gradient-based gait design (`crawlsim.study.gradient.optimize_gradient`, exact sensitivities)
against `crawlsim optimize`'s derivative-free search, measured in one run.

1. **The README's two-lag example**: maximise v0 of gaits/peristalsis-4.yaml over
   ``links.1.phase`` and ``links.2.phase`` in [0, 1] (exact integrator, 20 output steps). For
   each method: the best v0, the evaluation at which the best v0 first came within 1e-6 of the
   known optimum 7/15 (= 0.4666..., phases (1/2, 0)), the evaluations the method spent in all,
   and its wall time.
2. **Ten lags**: an 11-block cosine wave, ``links.0.phase`` ... ``links.9.phase`` in [0, 1],
   the derivative-free search with its default budget, then the gradient method (a Latin
   hypercube of 40 points, a restart from each) with its evaluation budget raised until it uses
   about the same wall time or ends by itself (every restart converged or stalled): best v0 of
   each.

An evaluation of the gradient method is one verified limit with its gradient (at most
1 + 0.2 p times the cost of v0 alone, scripts/bench-sensitivity.py); a sample point is v0
alone.

    python scripts/optimize-gradient.py            # a few minutes
    python scripts/optimize-gradient.py --quick    # the two-lag example only
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import crawlsim
from crawlsim.gait.document import gait_from_document
from crawlsim.study.gradient import optimize_gradient
from crawlsim.study.optimize import make_problem, optimize

ROOT = Path(__file__).resolve().parents[1]
OPTIMUM = 7.0 / 15.0


def first_within(history, target: float, tol: float) -> int | None:
    return next((i + 1 for i, v in enumerate(history) if v >= target - tol), None)


def wave(blocks: int) -> crawlsim.Gait:
    links = [{"kind": "cosine", "mean": 1.0, "amplitude": 0.3, "phase": i / (blocks - 1)}
             for i in range(blocks - 1)]
    doc = {"name": f"wave-{blocks}", "blocks": blocks, "period": 1.0, "stiffness": 10.0,
           "links": links, "friction": {"forward": 1.0, "backward": 2.0},
           "simulation": {"steps_per_period": 20, "max_periods": 1000, "tolerance": 1e-12}}
    gait = gait_from_document(doc, f"wave-{blocks}")
    assert isinstance(gait, crawlsim.Gait)
    return gait


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    gait = crawlsim.load_gait(ROOT / "gaits" / "peristalsis-4.yaml")
    assert isinstance(gait, crawlsim.Gait)
    gait = gait.replace("simulation.steps_per_period", 20)
    assert isinstance(gait, crawlsim.Gait)
    free = [("links.1.phase", 0.0, 1.0), ("links.2.phase", 0.0, 1.0)]

    began = time.perf_counter()
    dfo = optimize(make_problem(gait, [f"{p}={lo}:{hi}" for p, lo, hi in free]))
    t_dfo = time.perf_counter() - began
    values = [e.row.v0 if e.row.v0 is not None else float("-inf") for e in dfo.evaluations]
    best, history = float("-inf"), []
    for v in values:
        best = max(best, v)
        history.append(best)
    print("two lags, peristalsis-4 (optimum 7/15 at phases (1/2, 0))")
    print(f"  derivative-free: v0 {dfo.value!r}, within 1e-6 at evaluation "
          f"{first_within(history, OPTIMUM, 1e-6)}, {len(values)} evaluations, {t_dfo:.2f} s")
    began = time.perf_counter()
    grad = optimize_gradient(gait, free)
    t_grad = time.perf_counter() - began
    print(f"  gradient:        v0 {grad.v0!r} at {grad.x}, within 1e-6 at evaluation "
          f"{first_within(grad.history, OPTIMUM, 1e-6)}, {grad.evaluations} evaluations "
          f"({grad.gradient_evaluations} with gradient), {t_grad:.2f} s")
    if args.quick:
        return 0

    big = wave(11)
    free10 = [(f"links.{i}.phase", 0.0, 1.0) for i in range(10)]
    began = time.perf_counter()
    dfo10 = optimize(make_problem(big, [f"{p}={lo}:{hi}" for p, lo, hi in free10]))
    t_dfo10 = time.perf_counter() - began
    print("ten lags, 11-block wave")
    print(f"  derivative-free: v0 {dfo10.value!r}, {len(dfo10.evaluations)} evaluations, "
          f"{t_dfo10:.1f} s")
    budget = 40
    while True:
        began = time.perf_counter()
        grad10 = optimize_gradient(big, free10, sample=4, restarts=64, max_evaluations=budget)
        t_grad10 = time.perf_counter() - began
        if t_grad10 >= 0.8 * t_dfo10 or grad10.evaluations < budget:
            break
        budget = int(budget * max(1.5, 0.9 * t_dfo10 / max(t_grad10, 1e-3)))
    print(f"  gradient:        v0 {grad10.v0!r}, {grad10.evaluations} evaluations "
          f"({grad10.gradient_evaluations} with gradient), {t_grad10:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
