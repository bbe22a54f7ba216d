#!/usr/bin/env python
"""Cost of the exact integrator's energy ledger (crawlsim/analysis/energy.py).

In one run, for each example crawler gait and for a long peristaltic wave (--blocks), it times
periods of the exact integrator with the ledger (as crawlsim runs) and without it (the stepper's
ledger switched off), and prints the median times, their ratio, and the ledger's balance
residual |W - D - J - (E(end) - E(start))| / max(W, D).

Usage: python scripts/bench-energy.py [--repeats 5] [--periods 3] [--blocks 200]
"""

import os

os.environ.setdefault("CRAWLSIM_KERNEL", "compiled")  # the compiled kernel's speed (crawlsim.kernel.jit)

import argparse
import statistics
import time
from pathlib import Path

import yaml

from crawlsim.analysis import energy
from crawlsim.gait.document import load_gait, parse_gait
from crawlsim.integrate.stepping import make_stepper
from crawlsim.model.process import compile_gait

ROOT = Path(__file__).resolve().parents[1]


def wave(blocks: int):
    """A peristaltic wave of ``blocks`` blocks: link i lags link i-1 by 1/3 of a period."""
    doc = {
        "name": f"wave-{blocks}",
        "blocks": blocks,
        "period": 1.0,
        "stiffness": 10.0,
        "links": [{"kind": "cosine", "mean": 1.0, "amplitude": 0.3, "phase": (i / 3) % 1} for i in range(blocks - 1)],
        "friction": {"forward": 1.0, "backward": 2.0},
    }
    return parse_gait(yaml.safe_dump(doc), source="<wave>")


def timed(process, periods: int, ledger: bool) -> tuple[float, float]:
    stepper = make_stepper(process, "exact")
    if not ledger:
        stepper._ledger = None
    began = time.perf_counter()
    records = [stepper.step_period() for _ in range(periods)]
    seconds = time.perf_counter() - began
    worst = 0.0
    if ledger:
        for record in records:
            e = energy.period_energy(process, record)
            worst = max(worst, abs(e.residual - e.energy_change) / e.scale)
    return seconds, worst


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--periods", type=int, default=3)
    parser.add_argument("--blocks", type=int, default=200)
    args = parser.parse_args()
    gaits = [load_gait(p) for p in sorted((ROOT / "gaits").glob("*.yaml"))]
    gaits.append(wave(args.blocks))
    print(f"{'gait':22s} {'with ledger':>12s} {'without':>12s} {'ratio':>7s} {'residual':>10s}")
    for gait in gaits:
        process = compile_gait(gait)
        with_, without, worst = [], [], 0.0
        for _ in range(args.repeats):
            seconds, residual = timed(process, args.periods, True)
            with_.append(seconds)
            worst = max(worst, residual)
            without.append(timed(process, args.periods, False)[0])
        a, b = statistics.median(with_), statistics.median(without)
        print(f"{gait.name:22s} {a:11.4f}s {b:11.4f}s {a / b:7.3f} {worst:10.1e}")


if __name__ == "__main__":
    main()
