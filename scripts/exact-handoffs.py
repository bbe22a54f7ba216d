#!/usr/bin/env python3
"""Which periods of the exact integrator run in its Python event loop, and why; and whether v0
is the same in the compiled loop as in the Python loop.

For every example gait (gaits/*.yaml, gaits/paper/*.yaml) and the seeds of the random-gait
corpus (`crawlsim.gait.corpus`, as `scripts/random-gait-corpus.py` draws them), the gait runs
twice with the exact integrator (`crawlsim.analysis.run.simulate`): as it runs by default, and
with ``kernel=False`` (every period in the Python loop of `crawlsim.integrate.exact`). The first
run counts its periods by where they ran:

* ``compiled``: in the compiled event loop `crawlsim.kernel.eventloop`;
* ``generic``: a process that is not a crawler chain (the Python loop is its only path);
* ``no loop``: a crawler for which the stepper builds no compiled loop;
* ``handoff <reason>``: a period the compiled loop handed over (`eventloop.HANDOFF_REASONS`);
* ``abandoned``: a period after `exact.LOOP_HANDOFFS` handoffs, when the stepper stops trying.

and prints per gait |v0(default) - v0(Python loop)| (the bar: <= 1e-12; for a generic process,
which has no v0, the largest |w| of its limit period) and the CPU time of both runs (their
ratio: what the compiled loop saves). The summary gives the
counts per reason over all gaits. Exit status 1 when a v0 differs by more than ``--v0-tol``.

    python scripts/exact-handoffs.py --size 40
"""

from __future__ import annotations

import argparse
import collections
import functools
import math
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from crawlsim.analysis.run import simulate
from crawlsim.errors import CrawlsimError
from crawlsim.gait.corpus import random_gait
from crawlsim.gait.document import load_gait
from crawlsim.integrate import compiled, exact
from crawlsim.kernel import eventloop
from crawlsim.model.process import compile as compile_spec

ROOT = Path(__file__).resolve().parents[1]
COUNTS: collections.Counter[str] = collections.Counter()
FORCE_PYTHON = False


def _instrument() -> None:
    """Count the periods of every EventStepper by where they ran (module docstring)."""
    init, step, loop_period = (
        exact.EventStepper.__init__,
        exact.EventStepper._step_impl,
        compiled._CompiledLoop.period,
    )

    @functools.wraps(init)
    def __init__(self: Any, process: Any, **options: Any) -> None:
        if FORCE_PYTHON:
            options["kernel"] = False
        init(self, process, **options)
        if self._loop is not None:
            self._census_kind = "abandoned"
        else:
            self._census_kind = "generic" if process.crawler is None else "no loop"

    @functools.wraps(step)
    def _step_impl(self: Any) -> Any:
        had_loop = self._loop is not None
        self._census_reason = None
        record = step(self)
        if had_loop and self._census_reason is None:
            COUNTS["compiled"] += 1
        elif had_loop:
            COUNTS[f"handoff {self._census_reason}"] += 1
        else:
            COUNTS[self._census_kind] += 1
        return record

    @functools.wraps(loop_period)
    def period(self: Any, s: Any) -> Any:
        record = loop_period(self, s)
        if record is None:
            reason = int(self._scratch["report"][eventloop.R_REASON])
            s._census_reason = eventloop.HANDOFF_REASONS[reason]
        return record

    exact.EventStepper.__init__ = __init__  # type: ignore[method-assign]
    exact.EventStepper._step_impl = _step_impl  # type: ignore[method-assign]
    compiled._CompiledLoop.period = period  # type: ignore[method-assign]


def _v0(process: Any, max_periods: int, tolerance: float) -> tuple[float, str]:
    try:
        r = simulate(process, max_periods=max_periods, tolerance=tolerance, integrator="exact", history=False)
    except CrawlsimError as exc:
        return math.nan, f"{type(exc).__name__}: {str(exc)[:160]}"
    if r.v0 is not None:
        return r.v0, ""
    return float(np.max(np.abs(r.limit.w))), ""  # a generic process: its limit's size


def main() -> int:
    global FORCE_PYTHON
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=40, help="corpus gaits")
    parser.add_argument("--first", type=int, default=0, help="first seed")
    parser.add_argument("--steps", type=int, default=1000, help="steps per period (corpus)")
    parser.add_argument("--max-blocks", type=int, default=40)
    parser.add_argument("--stiffness-ratio", type=float, default=1e6)
    parser.add_argument("--friction-ratio", type=float, default=1e3)
    parser.add_argument("--no-examples", action="store_true")
    parser.add_argument("--v0-tol", type=float, default=1e-12)
    parser.add_argument("--no-compare", action="store_true", help="count the periods only (no run in the Python loop)")
    parser.add_argument("--loads", action="store_true", help="random loads and slopes on every corpus gait")
    args = parser.parse_args()
    _instrument()
    gaits: list[tuple[str, Any]] = []
    if not args.no_examples:
        for path in sorted(ROOT.glob("gaits/*.yaml")) + sorted(ROOT.glob("gaits/paper/*.yaml")):
            gaits.append((path.relative_to(ROOT).as_posix(), load_gait(path)))
    for seed in range(args.first, args.first + args.size):
        small = seed % 4 != 0
        gait = random_gait(
            seed,
            blocks=(2, min(12, args.max_blocks)) if small else (2, args.max_blocks),
            loads=args.loads,
            stiffness_ratio=args.stiffness_ratio,
            friction_ratio=args.friction_ratio,
        )
        gaits.append((f"seed {seed}", gait))
    total: collections.Counter[str] = collections.Counter()
    worst, bad = 0.0, 0
    ratios: list[float] = []
    for name, gait in gaits:
        process = compile_spec(gait, None if name.startswith("gaits") else args.steps)
        sim = gait.simulation
        COUNTS.clear()
        FORCE_PYTHON = False
        began = time.process_time()
        v0, err = _v0(process, sim.max_periods, sim.tolerance)
        seconds = time.process_time() - began
        counts = dict(COUNTS)
        if args.no_compare:
            v0_py, err_py, ratio = v0, err, math.nan
        else:
            FORCE_PYTHON = True
            began = time.process_time()
            v0_py, err_py = _v0(process, sim.max_periods, sim.tolerance)
            ratio = (time.process_time() - began) / max(seconds, 1e-9)
            FORCE_PYTHON = False
            if not (err or err_py):
                ratios.append(ratio)
        total.update(counts)
        diff = abs(v0 - v0_py)
        if err or err_py:
            same = err.split(":")[0] == err_py.split(":")[0]
            note = f"error (same in both: {same}): {err or err_py}"
            bad += not same
        else:
            worst = max(worst, diff)
            bad += not diff <= args.v0_tol
            note = f"|dv0| {diff:.2e} rel {diff / max(abs(v0), 1e-300):.1e}"
        basis = process.offset_pieces.basis if process.offset_pieces is not None else None
        shape = "" if basis is None else f"linear {int(basis.linear)} H {basis.harmonics}"
        if process.crawler is not None:
            k = np.asarray(process.crawler.stiffness, dtype=float)
            shape += f" k ratio {np.max(k) / np.min(k):.0e}"
        print(
            f"{name:36s} N {process.blocks if process.crawler else '-':>3} {shape:28s} "
            f"{note}  cpu {seconds:.2f} s (Python loop / default {ratio:.1f})  "
            f"{dict(sorted(counts.items()))}",
            flush=True,
        )
    print()
    print(f"periods by where they ran, {len(gaits)} gaits: {dict(sorted(total.items()))}")
    if ratios:
        print(
            f"largest |v0(default) - v0(Python loop)|: {worst:.2e}; gaits over "
            f"{args.v0_tol:g}: {bad}; CPU time of a run, Python loop / default: median "
            f"{statistics.median(ratios):.1f} (min {min(ratios):.1f}, max {max(ratios):.1f})"
        )
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
