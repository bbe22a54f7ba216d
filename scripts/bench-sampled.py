#!/usr/bin/env python3
"""Benchmark: a period of the exact integrator on gaits whose zeros need sampling (offsets with
several harmonics, or one harmonic and a linear part), in the compiled event loop against the
Python loop (``EventStepper(kernel=False)``, which decides with Clarabel's projector and the
kernel's velocity problems; both find sampled zeros with `crawlsim.kernel.sampling`).

Before the compiled loop took these gaits, every one of their periods ran in the Python loop
(and its sampling in Python and scipy), so the ratio printed is a lower bound of the gain.

For each gait: ``--periods`` periods stepped by each loop in turn (after one warm-up period),
``--repeats`` times interleaved; the median time of a period and the ratio of the medians.

    python scripts/bench-sampled.py --clock cpu
"""

from __future__ import annotations

import os

os.environ.setdefault("CRAWLSIM_KERNEL", "compiled")  # the compiled kernel's speed (crawlsim.kernel.jit)

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from crawlsim.gait.corpus import random_gait
from crawlsim.gait.document import load_gait
from crawlsim.integrate.exact import EventStepper
from crawlsim.model.process import compile_gait

ROOT = Path(__file__).resolve().parents[1]


def gaits(steps: int) -> list[tuple[str, object]]:
    """smooth-friction-3 and corpus gaits of 5 to 36 blocks (`crawlsim.gait.corpus`)."""
    out: list[tuple[str, object]] = [
        ("smooth-friction-3", compile_gait(load_gait(ROOT / "gaits" / "smooth-friction-3.yaml"), steps))
    ]
    for seed, blocks in ((18, (2, 5)), (5, (2, 5)), (13, (2, 12)), (20, (2, 40))):
        gait = random_gait(seed, blocks=blocks, stiffness_ratio=1e6, friction_ratio=1e3)
        out.append((f"corpus seed {seed} (N {gait.blocks})", compile_gait(gait, steps)))
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clock", choices=("cpu", "wall"), default="wall")
    parser.add_argument("--steps", type=int, default=1000, help="steps per period")
    parser.add_argument("--periods", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    clock = time.process_time if args.clock == "cpu" else time.perf_counter
    print(f"{'gait':28s} {'basis':>22s} {'compiled ms':>12s} {'Python ms':>10s} {'ratio':>7s}")
    for name, process in gaits(args.steps):
        steppers = {"compiled": EventStepper(process), "python": EventStepper(process, kernel=False)}
        for s in steppers.values():
            s.step_period()  # warm-up (compilation, caches)
        times: dict[str, list[float]] = {key: [] for key in steppers}
        for _ in range(args.repeats):
            for key, s in steppers.items():
                began = clock()
                for _ in range(args.periods):
                    s.step_period()
                times[key].append((clock() - began) / args.periods)
        loop = steppers["compiled"]._loop
        assert loop is not None and loop.handoffs == 0, name
        fast, slow = (statistics.median(times[k]) for k in ("compiled", "python"))
        b = steppers["compiled"].basis
        print(
            f"{name:28s} {f'linear {int(b.linear)} harmonics {b.harmonics}':>22s} "
            f"{1e3 * fast:12.3f} {1e3 * slow:10.2f} {slow / fast:7.1f}",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
