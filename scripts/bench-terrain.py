#!/usr/bin/env python
"""Benchmark: the exact integrator's cost per period on terrain against the same gait on uniform
ground (docs/model.md §8; the bar of issue 33: at most 1.5 where the crawler crosses ground that
changes, its events at a boundary a few per crossing), compiled kernel.

For each case, in one run: the same periods from the same start stepped on uniform ground and on
the terrain, each the median over ``--repeats`` runs after one run to warm the kernel; printed
with the ground events per period and the ratio terrain / uniform. The uniform gait runs through
the same stepper, so the ratio is what the ground costs: tracking positions, seeking boundaries,
holds, slides and their events, and the uniqueness condition on each new ground.

* crossings (the bar): a step (gaits/terrain/step-up-2.yaml, the periods until it settles) and
  a patch (gaits/terrain/patch-4.yaml, likewise);
* dense stripes, where every block crosses two boundaries a period (each crossing is an event
  uniform ground does not have): two and four blocks, and earthworm-100, whose 101 blocks cross
  some 70 boundaries a period (reported, not held to the bar).

    python scripts/bench-terrain.py            # about half a minute
    python scripts/bench-terrain.py --quick
"""

from __future__ import annotations

import os

os.environ.setdefault("CRAWLSIM_KERNEL", "compiled")  # the compiled kernel's speed (crawlsim.kernel.jit)

import argparse
import statistics
import time
from pathlib import Path

import yaml

from crawlsim.gait.document import parse_gait
from crawlsim.integrate.exact import EventStepper
from crawlsim.model.process import compile_gait

GAITS = Path(__file__).resolve().parents[1] / "gaits"
#: Case: (gait file, the terrain (None: the file's own), periods, whether the bar applies).
STRIPES = {"repeat": 1.0, "patches": [{"from": 0.3, "to": 0.6, "forward": 0.7, "backward": 1.3}]}
CASES = {
    "step (step-up-2)": ("terrain/step-up-2", None, 8, True),
    "patch (patch-4)": ("terrain/patch-4", None, 23, True),
    "stripes, 2 blocks": (
        "inching-2",
        {"repeat": 1.0, "patches": [{"from": 0.0, "to": 0.4, "forward": 1.5, "backward": 1.5}]},
        40,
        False,
    ),
    "stripes, 4 blocks": ("peristalsis-4", STRIPES, 40, False),
    "stripes, 101 blocks": (
        "earthworm-100",
        {**STRIPES, "patches": [{**STRIPES["patches"][0], "forward": 0.7071, "backward": 1.3183}]},
        6,
        False,
    ),
}
BAR = 1.5


def per_period(gait, periods: int, repeats: int) -> tuple[float, float]:
    """(median seconds per period, ground events per period) of ``periods`` exact periods."""
    process = compile_gait(gait)
    times, events = [], 0.0
    for r in range(repeats + 1):
        stepper = EventStepper(process)
        began = time.perf_counter()
        count = 0
        for _ in range(periods):
            record = stepper.step_period()
            count += 0 if record.ground is None else len(record.ground)
        if r:  # the first run warms the kernel and the caches
            times.append((time.perf_counter() - began) / periods)
        events = count / periods
    return statistics.median(times), events


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    repeats = 2 if args.quick else args.repeats
    worst = 0.0
    print(f"{'case':22} {'periods':>7} {'uniform ms':>11} {'terrain ms':>11} {'events':>7} {'ratio':>6}")
    for name, (path, terrain, periods, bar) in CASES.items():
        document = yaml.safe_load((GAITS / f"{path}.yaml").read_text())
        flat = {key: value for key, value in document.items() if key != "terrain"}
        uniform = parse_gait(yaml.safe_dump(flat), source=name)
        ground = parse_gait(yaml.safe_dump({**flat, "terrain": terrain or document["terrain"]}), source=name)
        t_uniform, _ = per_period(uniform, periods, repeats)
        t_ground, events = per_period(ground, periods, repeats)
        ratio = t_ground / t_uniform
        if bar:
            worst = max(worst, ratio)
        print(f"{name:22} {periods:7} {1e3 * t_uniform:11.3f} {1e3 * t_ground:11.3f} {events:7.1f} {ratio:6.2f}")
    print(f"largest ratio where the crawler crosses {worst:.2f} (bar {BAR}): {'met' if worst <= BAR else 'NOT met'}")


if __name__ == "__main__":
    main()
