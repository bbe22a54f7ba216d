#!/usr/bin/env python
"""Benchmark: the cost of exact sensitivities against v0 alone, measured in one run.

For each gait and each number of parameters p, prints the median wall time of
``crawlsim.api.run(gait, history=False)`` (what ``crawlsim velocity GAIT`` computes), of
``crawlsim.sensitivity(gait, paths)`` with p parameters (its own verified limit included), their
ratio, and the bar 1 + 0.2 p of issue 22; the two are interleaved, repeat by repeat, so that a
change of load on the machine hits both alike. The tangents of all p parameters are carried
together through one walk along the limit period, so the ratio grows slowly with p; each parameter costs
one validated copy of the gait (its coefficients' derivative).

    python scripts/bench-sensitivity.py              # about a minute
    python scripts/bench-sensitivity.py --repeats 3
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import crawlsim
from crawlsim import api
from crawlsim.gait.document import gait_from_document

ROOT = Path(__file__).resolve().parents[1]


def wave(blocks: int) -> crawlsim.Gait:
    """A cosine wave of blocks - 1 links, a lag of 1/(blocks - 1) period each."""
    links = [{"kind": "cosine", "mean": 1.0, "amplitude": 0.3, "phase": i / (blocks - 1)}
             for i in range(blocks - 1)]
    doc = {"name": f"wave-{blocks}", "blocks": blocks, "period": 1.0, "stiffness": 10.0,
           "links": links, "friction": {"forward": 1.0, "backward": 2.0},
           "simulation": {"steps_per_period": 1000, "max_periods": 1000, "tolerance": 1e-12}}
    gait = gait_from_document(doc, f"wave-{blocks}")
    assert isinstance(gait, crawlsim.Gait)
    return gait


def median_time(call, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        began = time.perf_counter()
        call()
        times.append(time.perf_counter() - began)
    return statistics.median(times)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    peristalsis = crawlsim.load_gait(ROOT / "gaits" / "peristalsis-4.yaml")
    assert isinstance(peristalsis, crawlsim.Gait)
    cases = [(peristalsis, ["links.1.phase"], ["links.*.phase", "links.*.amplitude"],
              ["links.*.phase", "links.*.amplitude", "links.*.mean", "stiffness",
               "friction.forward", "friction.backward"]),
             (wave(11), ["links.1.phase"], ["links.*.phase"],
              ["links.*.phase", "links.*.amplitude"])]
    print(f"{'gait':16s} {'p':>3s} {'v0 alone':>10s} {'sensitivity':>12s} {'ratio':>7s} "
          f"{'bar':>6s}")
    for gait, *path_sets in cases:
        for paths in path_sets:
            result = crawlsim.api.sensitivity(gait, paths)
            p = len(result.parameters)
            # interleaved, so that a change of load on the machine hits both alike
            base, sens = [], []
            for _ in range(args.repeats):
                base.append(median_time(lambda g=gait: api.run(g, history=False), 1))
                sens.append(median_time(lambda g=gait, ps=paths: crawlsim.api.sensitivity(g, ps),
                                        1))
            b, t = statistics.median(base), statistics.median(sens)
            print(f"{gait.name:16s} {p:3d} {b:9.4f}s {t:11.4f}s {t / b:7.2f} "
                  f"{1 + 0.2 * p:6.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
