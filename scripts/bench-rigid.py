#!/usr/bin/env python
"""Benchmark: ``crawlsim velocity GAIT --rigid`` against ``crawlsim velocity GAIT``, measured in
one run (issue 34's bar: the rigid limit costs at most 1/20 of an elastic velocity).

``library`` is the ratio of ``crawlsim.api.run(gait, history=False)`` (what ``crawlsim velocity``
runs) to ``crawlsim.rigid_limit(gait)``, each on a fresh copy of the validated gait (nothing of
it cached), interleaved repeat by repeat so that a change of load hits both alike: the median of
the repeats' ratios, beside the median times. ``command`` is the literal measure, the two
commands run in this process through click's test runner (the file read and validated, the
result printed; the interpreter's start-up, the same for both, left out). The bar is met where a
ratio is at least 20.

    python scripts/bench-rigid.py                    # a minute or two
    python scripts/bench-rigid.py --repeats 21 --clock cpu
"""

from __future__ import annotations

import argparse
import copy
import shutil
import statistics
import tempfile
import time
from pathlib import Path

import yaml
from click.testing import CliRunner

import crawlsim
from crawlsim.cli import main as cli
from crawlsim.gait.corpus import random_gait

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = [
    "inching-2",
    "anchoring-2",
    "climbing-3",
    "peristalsis-3",
    "smooth-friction-3",
    "peristalsis-4",
    "earthworm-100",
]


def measure(gait, folder: Path, repeats: int, clock) -> tuple[float, float, float, float]:
    """(elastic seconds, rigid seconds, library ratio, command ratio), medians."""
    crawlsim.run(gait, history=False)  # warm
    crawlsim.rigid_limit(gait)
    elastic, rigid = [], []
    for _ in range(repeats):
        fresh = copy.copy(gait)
        began = clock()
        crawlsim.run(fresh, history=False)
        middle = clock()
        crawlsim.rigid_limit(copy.copy(gait))
        rigid.append(clock() - middle)
        elastic.append(middle - began)
    path = folder / f"{gait.name}.yaml"
    path.write_text(yaml.safe_dump(gait.document, sort_keys=False))
    runner = CliRunner()
    commands = []
    for _ in range(repeats):
        began = clock()
        runner.invoke(cli, ["velocity", str(path)])
        middle = clock()
        runner.invoke(cli, ["velocity", str(path), "--rigid"])
        commands.append((middle - began) / (clock() - middle))
    library = statistics.median(e / r for e, r in zip(elastic, rigid))
    return statistics.median(elastic), statistics.median(rigid), library, statistics.median(commands)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument("--repeats", type=int, default=9)
    parser.add_argument("--corpus", type=int, default=12, help="random gaits (seeds 0, 1, ...) after the examples")
    parser.add_argument("--clock", choices=("wall", "cpu"), default="wall")
    args = parser.parse_args()
    clock = time.perf_counter if args.clock == "wall" else time.process_time
    gaits = [crawlsim.load_gait(ROOT / "gaits" / f"{name}.yaml") for name in EXAMPLES]
    gaits += [random_gait(seed, loads=seed % 3 == 0) for seed in range(args.corpus)]
    folder = Path(tempfile.mkdtemp(prefix="bench-rigid-"))
    print(f"{'gait':18s} {'N':>3s} {'velocity':>10s} {'--rigid':>10s} {'library':>8s} {'command':>8s} {'bar':>4s}")
    ratios = []
    for gait in gaits:
        elastic, rigid, library, command = measure(gait, folder, args.repeats, clock)
        ratios.append(library)
        print(
            f"{gait.name:18s} {gait.blocks:3d} {elastic * 1e3:8.3f}ms {rigid * 1e3:8.3f}ms "
            f"{library:8.1f} {command:8.1f} {'met' if library >= 20 else 'no':>4s}"
        )
    print(f"median library ratio {statistics.median(ratios):.1f} (bar 20)")
    shutil.rmtree(folder, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
