#!/usr/bin/env python3
"""How the cost of a step and of an event grows with the number of blocks N.

The cosine wave of N blocks (link i: L_i = 1 + 0.3 cos 2 pi (t/T - phase_i), k = 10, friction
forward 1.0 / backward 2.13; phase_i = i/(N-1), or i/10 with ``--wave segments``, see `WAVES`),
for N = 4, 16, 64, 128, 256 and 1024, in one run:

* catch-up: microseconds per step at 400 steps per period (median over periods 1..P of a run,
  after a first period), and at 1000 steps per period for the ratio below;
* exact: milliseconds per period and events per period (median over periods 1..P);
* exact / catch-up time per period at 1000 steps per period;
* |v0(exact) - v0(catch-up)| at 400 steps per period against the first-order bound 1/400;
* peak memory of one period of each integrator (tracemalloc: numpy's allocations included),
  measured in a separate run, since tracing every allocation slows the stepping several-fold;
* the fitted exponent of cost against N between N = 64 and 1024 (least squares on log-log),
  and the N = 128 / N = 4 ratio of catch-up steps per second.

    python scripts/bench-scale.py [--periods 5] [--repeats 3] [--sizes 4,16,64,128,256,1024]
                                  [--wave body|segments] [--big] [--limit newton|iterate]

Each time is the median over ``--repeats`` runs of the median over their periods. A 1000-block
run of 20 periods at 400 steps per period is timed at the end (``--big``), with each integrator,
through the same library call as ``crawlsim run`` with an HDF5 file, which is then drawn by
``crawlsim plot``.
"""

from __future__ import annotations

import os

os.environ.setdefault("CRAWLSIM_KERNEL", "compiled")  # the compiled kernel's speed (crawlsim.kernel.jit)

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

from crawlsim.gait.document import gait_from_document
from crawlsim.integrate.stepping import make_stepper
from crawlsim.model.process import compile_gait

#: The waves the benchmark runs (``--wave``): ``body``, one wave over the whole body (link i at
#: phase i/(N-1), the workload the scaling work was specified on), and ``segments``, an
#: earthworm-like one ten links long (link i at phase i/10, as in
#: gaits/earthworm-100.yaml). Over a long body the first changes little from one link to the
#: next: the elastic forces on inner blocks, k times differences of neighbouring lengths, stay
#: far below their friction, so only the blocks near the ends slip and v0 tends to 0 as N grows.
#: The second moves every block at any N, so its cost is that of a crawler that crawls.
WAVES = ("body", "segments")


def wave_document(N: int, steps: int, periods: int = 1000, wave: str = "body") -> dict:
    def phase(i: int) -> float:
        return i / (N - 1) if wave == "body" else (i / 10) % 1

    return {
        "name": f"wave-{N}",
        "blocks": N,
        "period": 1.0,
        "stiffness": 10.0,
        "links": [{"kind": "cosine", "mean": 1.0, "amplitude": 0.3, "phase": phase(i)} for i in range(N - 1)],
        "friction": {"forward": 1.0, "backward": 2.13},
        "simulation": {"steps_per_period": steps, "max_periods": periods},
    }


def measure(N: int, integrator: str, steps: int, periods: int, repeats: int = 1, wave: str = "body"):
    """(seconds per period, events per period, v0): medians over the periods after the first of
    ``repeats`` fresh runs (the first period leaves the arbitrary initial state)."""
    gait = gait_from_document(wave_document(N, steps, wave=wave), f"wave-{N}")
    process = compile_gait(gait)
    times, events, v0 = [], [], []
    for _ in range(repeats):
        stepper = make_stepper(process, integrator)
        stepper.step_period()
        for _ in range(periods):
            began = time.perf_counter()
            record = stepper.step_period()
            times.append(time.perf_counter() - began)
            if record.events is not None:
                events.append(len(record.events.t))
            v0.append(float(np.mean(record.x[-1] - record.x[0])) / process.period)
    return statistics.median(times), (statistics.median(events) if events else None), v0[-1]


def peak_memory(N: int, integrator: str, steps: int, wave: str = "body") -> int:
    """Peak bytes allocated while compiling the gait and stepping two periods (tracemalloc)."""
    gait = gait_from_document(wave_document(N, steps, wave=wave), f"wave-{N}")
    tracemalloc.start()
    try:
        stepper = make_stepper(compile_gait(gait), integrator)
        stepper.step_period()
        stepper.step_period()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def exponent(sizes, costs, lo=64, hi=1024) -> float:
    pick = [(n, c) for n, c in zip(sizes, costs) if lo <= n <= hi]
    if len(pick) < 2:
        return float("nan")
    n, c = np.array(pick).T
    return float(np.polyfit(np.log(n), np.log(c), 1)[0])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--periods", type=int, default=5)
    parser.add_argument(
        "--repeats", type=int, default=1, help="fresh runs per measurement; times are medians over all of them"
    )
    parser.add_argument("--sizes", default="4,16,64,128,256,1024")
    parser.add_argument(
        "--wave",
        choices=WAVES,
        default="body",
        help="body: phase i/(N-1) (one wave over the body); segments: phase "
        "i/10 (a wave ten links long, every block slips)",
    )
    parser.add_argument(
        "--big", action="store_true", help="also time the 1000-block, 20-period run with its results file"
    )
    parser.add_argument(
        "--limit",
        choices=("newton", "iterate"),
        default="newton",
        help="how the --big run finds its periodic limit (the gait setting)",
    )
    args = parser.parse_args()
    sizes = [int(s) for s in args.sizes.split(",") if s]  # --sizes "" --big: the big run alone
    if sizes:
        table(sizes, args.periods, args.repeats, args.wave)
    if args.big:
        for integrator in ("exact", "catch-up"):
            big(integrator, args.wave, args.limit)
    return 0


def table(sizes: list[int], periods: int, repeats: int, wave: str) -> None:
    """The per-N table, the fitted exponents and the bars of the scaling work."""
    rows = []
    print(f"wave: {wave}; medians of {repeats} run(s) x {periods} periods")
    print(
        f"{'N':>5} {'catch-up us/step':>17} {'exact ms/period':>16} {'events/period':>14} "
        f"{'exact/catch-up @1000':>21} {'|dv0|*400':>10} {'peak MB':>8}"
    )
    for N in sizes:
        cu, _, v_cu = measure(N, "catch-up", 400, periods, repeats, wave)
        ex, ev, v_ex = measure(N, "exact", 400, periods, repeats, wave)
        cu1000, _, _ = measure(N, "catch-up", 1000, periods, repeats, wave)
        ex1000, _, _ = measure(N, "exact", 1000, periods, repeats, wave)
        mem_cu = peak_memory(N, "catch-up", 400, wave)
        mem_ex = peak_memory(N, "exact", 400, wave)
        rows.append(
            (N, cu / 400 * 1e6, ex * 1e3, ev, ex1000 / cu1000, abs(v_ex - v_cu) * 400, max(mem_cu, mem_ex) / 2**20)
        )
        r = rows[-1]
        print(
            f"{r[0]:>5} {r[1]:>17.2f} {r[2]:>16.2f} {r[3]:>14.0f} {r[4]:>21.2f} {r[5]:>10.3g} {r[6]:>8.1f}", flush=True
        )
    Ns = [r[0] for r in rows]
    print()
    print(
        f"fitted exponent of cost in N, N = 64..1024: catch-up "
        f"{exponent(Ns, [r[1] for r in rows]):.2f}, exact "
        f"{exponent(Ns, [r[2] for r in rows]):.2f} (bar: <= 1.2)"
    )
    by_n = {r[0]: r for r in rows}
    if 4 in by_n and 128 in by_n:
        print(f"catch-up steps per second, N = 128 / N = 4: {by_n[4][1] / by_n[128][1]:.3f} (bar: >= 0.1)")
    for n in (64, 256):
        if n in by_n:
            print(
                f"N = {n}: |v0 exact - v0 catch-up| x 400 = {by_n[n][5]:.3g} (bar: <= 1); "
                f"exact / catch-up at 1000 steps per period = {by_n[n][4]:.2f} (bar: <= 3)"
            )


def big(integrator: str, wave: str, limit: str = "newton") -> None:
    """The 1000-block run of 20 periods at 400 steps per period, file written and plotted."""
    from crawlsim import api

    doc = wave_document(1000, 400, periods=20, wave=wave)
    # Run all 20 periods, following the iterates as `crawlsim run` does when it writes a file.
    doc["simulation"].update(tolerance=1e-300, integrator=integrator, limit=limit)
    gait = gait_from_document(doc, "wave-1000")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "wave-1000.h5"
        began = time.perf_counter()
        result = api.run(gait, output=out)
        seconds = time.perf_counter() - began
        size = out.stat().st_size / 2**20
        began = time.perf_counter()
        plot = subprocess.run(
            [sys.executable, "-m", "crawlsim", "plot", str(out), "-o", tmp], capture_output=True, text=True
        )
        plot_seconds = time.perf_counter() - began
    print(
        f"\n1000 blocks ({wave} wave), 20 periods x 400 steps, {integrator}, limit {limit}, "
        "with its results file: "
        f"{seconds:.1f} s (bar: < 60 s), file {size:.1f} MB, v0 {result.v0:.6g}; "
        f"crawlsim plot: exit {plot.returncode} in {plot_seconds:.1f} s "
        f"({len(plot.stdout.split())} figures)",
        flush=True,
    )
    if plot.returncode:
        print(plot.stderr)


if __name__ == "__main__":
    sys.exit(main())
