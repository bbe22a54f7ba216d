#!/usr/bin/env python3
"""Run a seeded corpus of random valid gaits with both integrators and report what happened.

For each seed (`crawlsim.gait.corpus.random_gait`: every signal kind, per-link stiffness spread
over up to ``--stiffness-ratio``, per-block, time-varying and steps-switched friction with
forward/backward ratios up to ``--friction-ratio`` either way) the gait runs with catch-up and
with the exact integrator at ``--steps`` steps per period. The script prints one line per gait
and a summary:

* exits 1 (internal failures: certificates, events) per integrator, and runs over
  ``--timeout`` seconds (stopped there) -- the bar is zero of either;
* gaits refused at run time (exit 2: the model is degenerate at an instant of the grid);
* |v0(catch-up) - v0(exact)| against the first-order scale V / G, V the largest actuator
  stroke per period (max L - min L over the period, divided by T): the ratio is of order 1
  (catch-up's error is O(1/G)), with a constant that depends on the gait;
* the largest wall time of each integrator, and the ratio of exact to catch-up time for gaits
  with N <= 12.

The default ``--size`` is the CI size (about 1-2 minutes on one core); the full corpus is

    python scripts/random-gait-corpus.py --size 240

and ``--rough`` draws the rough classes instead (`crawlsim.gait.corpus`: jagged
piecewise-linear links of 100-1000 knots, steps in links and friction, stiffness spread up to
the accepted limits, 2 to ``--max-blocks`` blocks); CI runs ``--rough --size 10 --max-blocks
32``, and 500 gaits are

    python scripts/random-gait-corpus.py --rough --size 500 --first 1000 --max-blocks 64

Exit status: 1 when any run exits 1 or exceeds the time limit, else 0.
"""

from __future__ import annotations

import argparse
import json
import signal
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from crawlsim.analysis.run import simulate
from crawlsim.errors import CrawlsimError, InputError
from crawlsim.gait.corpus import random_gait
from crawlsim.kernel import jit
from crawlsim.model.process import compile_gait
from crawlsim.study.warmup import warmup

#: Gaits of the CI-size corpus.
CI_SIZE = 16
#: Exit code of a run stopped at the time limit.
TIMEOUT = 124


class _Overtime(Exception):
    pass


def _alarm(signum, frame):
    raise _Overtime


def run_one(gait, integrator: str, steps: int, timeout: float) -> dict:
    process = compile_gait(gait, steps)
    began = time.perf_counter()
    signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, timeout)
    try:
        r = simulate(
            process,
            max_periods=gait.simulation.max_periods,
            tolerance=gait.simulation.tolerance,
            integrator=integrator,
            history=False,
        )
    except _Overtime:
        return {"exit": TIMEOUT, "message": f"stopped after {timeout:g} s", "time": time.perf_counter() - began}
    except InputError as exc:
        return {"exit": 2, "message": str(exc), "time": time.perf_counter() - began}
    except CrawlsimError as exc:
        return {"exit": 1, "message": str(exc), "time": time.perf_counter() - began}
    except Exception as exc:  # a crash: the CLI would exit 1 with a traceback
        return {"exit": 1, "message": f"crash: {type(exc).__name__}: {exc}", "time": time.perf_counter() - began}
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
    return {
        "exit": 0 if r.converged else 3,
        "v0": r.v0,
        "periods": r.periods,
        "convergence": str(r.convergence),
        "time": time.perf_counter() - began,
    }


def corpus_gait(seed: int, args):
    """Three gaits in four have N <= 12, the rest up to ``--max-blocks`` (``--rough``: 2 to
    ``--max-blocks`` evenly)."""
    small = seed % 4 != 0 and not args.rough
    return random_gait(
        seed,
        blocks=(2, min(12, args.max_blocks)) if small else (2, args.max_blocks),
        loads=args.loads,
        stiffness_ratio=args.stiffness_ratio,
        friction_ratio=args.friction_ratio,
        rough=args.rough,
    )


def summary(rows: list[dict], steps: int, timeout: float) -> int:
    """Print the summary; the number of runs that exit 1 or time out."""
    print()
    bad = 0
    for integrator in ("catch-up", "exact"):
        exits = [r[integrator]["exit"] for r in rows]
        slowest = max(r[integrator]["time"] for r in rows)
        print(
            f"{integrator:9s}: {exits.count(0)} converged, {exits.count(3)} not converged, "
            f"{exits.count(2)} refused (exit 2), {exits.count(1)} internal failures (exit 1), "
            f"{exits.count(TIMEOUT)} over {timeout:g} s; slowest run {slowest:.2f} s"
        )
        bad += exits.count(1) + exits.count(TIMEOUT)
        for r in rows:
            if r[integrator]["exit"] in (1, 2, TIMEOUT):
                print(f"    seed {r['seed']} (N {r['blocks']}): {r[integrator]['message'][:300]}")
    both = [r for r in rows if "v0" in r["catch-up"] and "v0" in r["exact"]]
    if both:
        ratio = [abs(r["catch-up"]["v0"] - r["exact"]["v0"]) * steps / max(r["stroke_velocity"], 1e-300) for r in both]
        above = sum(q > 1.0 for q in ratio)
        print(
            f"|dv0| G / V over {len(both)} gaits: max {max(ratio):.3f}, median "
            f"{statistics.median(ratio):.3f} (catch-up's error is first order in 1/G, so "
            f"this stays of order 1; above 1 on {above})"
        )
    timed = [r["exact"]["time"] / r["catch-up"]["time"] for r in both if r["blocks"] <= 12]
    if timed:
        print(
            f"exact / catch-up time, N <= 12, {len(timed)} gaits: max {max(timed):.2f}, "
            f"median {statistics.median(timed):.2f}"
        )
    return bad


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--size",
        "--count",
        dest="size",
        type=int,
        default=CI_SIZE,
        help=f"number of gaits (default {CI_SIZE}, the CI size)",
    )
    parser.add_argument("--first", type=int, default=0, help="first seed")
    parser.add_argument("--steps", type=int, default=1000, help="steps per period")
    parser.add_argument("--max-blocks", type=int, default=40)
    parser.add_argument(
        "--stiffness-ratio", type=float, default=1e6, help="largest ratio of a link's stiffness to the smallest draw"
    )
    parser.add_argument(
        "--friction-ratio", type=float, default=1e3, help="largest forward/backward friction ratio, either way"
    )
    parser.add_argument(
        "--timeout", type=float, default=60.0, help="seconds after which a run is stopped and counted as a failure"
    )
    parser.add_argument(
        "--rough",
        action="store_true",
        help="the rough classes: jagged piecewise-linear links of 100-1000 knots, steps in links and friction, "
        "stiffness spreads up to the accepted limit (crawlsim.gait.corpus)",
    )
    parser.add_argument("--jsonl", help="also write one JSON line per gait to this file")
    parser.add_argument(
        "--loads", action="store_true", help="add random loads and slopes (docs/model.md §6) to every gait"
    )
    args = parser.parse_args()
    out = open(args.jsonl, "w") if args.jsonl else None
    # the kernel compiled and loaded before any run is timed: an alarm inside numba breaks it
    if not jit.ready():
        warmup()
    warm = compile_gait(random_gait(0, blocks=(2, 3)), 50)
    with jit.forced("compiled"):
        for integrator in ("catch-up", "exact"):
            simulate(warm, max_periods=2, integrator=integrator, history=False)
    rows = []
    for seed in range(args.first, args.first + args.size):
        gait = corpus_gait(seed, args)
        row: dict = {"seed": seed, "blocks": gait.blocks}
        for integrator in ("catch-up", "exact"):
            row[integrator] = run_one(gait, integrator, args.steps, args.timeout)
        L = compile_gait(gait, args.steps).crawler.lengths
        row["stroke_velocity"] = float(np.max(L.max(axis=0) - L.min(axis=0), initial=0.0) / gait.period)
        rows.append(row)
        a, b = row["catch-up"], row["exact"]
        dv = abs(a["v0"] - b["v0"]) if "v0" in a and "v0" in b else float("nan")
        print(
            f"seed {seed:4d}  N {gait.blocks:3d}  catch-up exit {a['exit']} "
            f"{a['time']:7.3f} s   exact exit {b['exit']} {b['time']:7.3f} s   "
            f"|dv0| {dv:.2e}",
            flush=True,
        )
        if out:
            out.write(json.dumps(row) + "\n")
            out.flush()
    return 1 if summary(rows, args.steps, args.timeout) else 0


if __name__ == "__main__":
    sys.exit(main())
