#!/usr/bin/env python3
"""The bar of the compiled kernel: crawlsim's certified steps against a compact compiled step.

The reference (`reference_period` below) is the catch-up step of the chain as plainly as it can
be written: a numba loop that, at every step, factors the padded tridiagonal system of the
current active set (the Thomas algorithm), solves it, and moves the set (drop the blocks whose
slip has the wrong sign, add the violated limits) until none is left, with no certificate,
tolerance policy, refinement, fallback or record. It follows crawlsim's trajectory to roundoff
(the script prints the largest difference of the states).

Printed, for the ``--wave segments`` and ``--wave body`` gaits of scripts/bench-scale.py at 1000
steps per period and N = 4, 16, 64, 256, 1024, each a median over ``--repeats`` interleaved
runs of ``--periods`` periods (after ``--skip-periods`` periods from the initial state, one by
default, and after compiling):

* catch-up: crawlsim's certified step (`crawlsim.integrate.stepping.CatchUpStepper.step_period`, per
  step) / the reference step (bar: <= 5);
* exact: one period of the exact integrator / one period of the reference (bar: <= 3).

    python scripts/bench-kernel.py [--sizes 4,16,64,256,1024] [--waves segments,body]
                                   [--periods 3] [--repeats 3] [--skip-periods 1] [--sweep]
                                   [--clock wall|cpu]

``--sweep`` also times the exact 1-D sweep of the bar (120 points, -j 1) and divides the figure
measured before the compiled kernel by it (bar: >= 30):

    crawlsim velocity gaits/peristalsis-4.yaml --sweep 'links.1.phase=0:1:120' -j 1 -o OUT.csv

The exact integrator's period against the reference (exact/ref, bar <= 3), medians of three runs
of this script on a 2-core machine shared with other jobs (load 9-13; "start": load 0.5-3,
"fused": five runs at load 2-3, ``--clock cpu``; "2bc9b42" and "local": three runs each of the
code before local events (below) and of this code, ``--repeats 3 --clock cpu``, load 2.2-2.5):

    wave       N  before (b994998, wall)  compiled loop (wall / cpu)  now (cpu)  start  fused  2bc9b42  local
    segments    4          67.7             3.3 / 3.7                     3.1    3.7    2.0      1.8    2.0
    segments   16          55.0             2.6 / 2.4                     1.8    2.2    1.7      1.4    1.4
    segments   64          57.0            13.9 / 3.3 (wall: preempted)   2.5    2.8    2.2      1.8    1.6
    segments  256          29.1             4.1 / 4.5                     3.5    5.2    2.3      2.3    1.7
    segments 1024          10.0             4.0 / 3.8                     3.2    4.3    2.6      2.2    1.4
    body        4          62.3             3.6 / 3.3                     3.0    4.9    1.7      1.6    1.8
    body       16          64.4             2.4 / 2.5                     2.2    2.8    1.6      1.5    1.6
    body       64           9.4             1.3 / 1.3                     1.0    1.4    0.8      0.7    0.7
    body      256           3.3             1.3 / 1.3                     0.9    1.2    0.7      0.6    0.6
    body     1024           5.6             1.1 / 1.0                     0.9    1.2    0.6      0.5    0.5

"now": the record's slips and positions in one compiled pass, the closed-form crossings only for
rows that can cross before the earliest event so far, contiguous phi @ coef, the energy terms of
the slipping blocks only (medians of three runs, load 2-5). "start": one run of that code
(f702eb5) before the work of "fused", load 0.5-3. "fused" (medians of five runs at load 2-3 with
the test suite on one core, each figure scattering by up to +-0.5; five earlier runs at load
3-9, before the last two changes below, gave segments 2.2, 1.7, 2.0, 2.5, 2.3 and body 2.0, 1.7,
0.9, 0.7, 0.7): a grid sample formed and certified in one pass over the blocks, which also forms
the record's slips and positions; an event's velocity problems on the period's scratch, the
first one from the warm set with the rows the event hit, the piece on the factor of the last
velocity problem; the slope bound of every row before its crossing, the row it lets cross first
sought first; the offsets' size once per piece; the load products of the ledger only with loads;
the record's W, MU and X written into the arrays of a record nobody holds any more. Outputs are
the same bits (every example gait and the scaled waves, three periods; v0 of the 40-gait random
corpus unchanged).

These are periods 2 to 16. The segments wave's events per period keep growing after them (N =
256: about 420 there, 533 from period 30; N = 1024: about 300, then 840-900), and at 2bc9b42 an
event cost several O(N) passes (the piece's factor and solves, the gaps and rates of every row,
the velocity problems over the whole chain, the energy terms of every link). In that regime,
``--sizes 256,1024 --waves segments --skip-periods 30 --repeats 5 --clock cpu`` (periods 31-45,
medians of three interleaved runs, load 1.7-2.3):

    N      2bc9b42 exact ms/period   exact/ref     local exact ms/period   exact/ref
    256          21.4                   3.8                11.4                 2.0
    1024        134.4                   5.7                52.0                 2.2

"local": an event touches what can change. The piece is kept per run of active blocks: only the
ranges of blocks whose sign changed (each ended by blocks free in both sets) are factored and
solved again (`crawlsim.kernel.piece.rebuild`), the other runs go on with their own closed form
and their slips so far; the chain's factor and solves skip the l = 0 terms between runs (the same
numbers, no recurrence across the whole chain; the catch-up step gains too). With closed-form
crossings each row keeps its crossing until its function or tolerance changes
(`crawlsim.kernel.events.next_event_kept`), so an event seeks the rows of the blocks it changed.
The velocity problems are solved only on the runs of candidate blocks that can change
(`crawlsim.kernel.eventloop.decide_local`: a run of the piece's set with no hit row, no other
tight row and every slip rate above 1e3 times any dual tolerance keeps its set; the same sets as
`decide` at every event checked, 4320 at N = 1024 and 857 at N = 16 to 64), and the energy terms
are summed by chunks of 32 links, only the chunks an event rebuilt again. Outputs change only by
roundoff (the example gaits and the scaled waves, three periods: states within 6e-14, the same
events; v0 of the example gaits and the 40 corpus seeds of scripts/exact-handoffs.py within
1e-13 of 2bc9b42's, but seed 29, 12 blocks with stiffness spread 6e5: 2.6e-10, relative 9e-11,
where 2bc9b42's own compiled and Python loops differ by 9.1e-11); gaits whose zeros need
sampling rebuild the whole piece at every event as before, so that they stay the Python loop's
to roundoff. Where an event's time goes now at N = 1024 (periods 31-35, 885 events a period; a
copy of the loop with timers): the velocity problems 19 us, the next event 12 us (4 of it the
rows sought again when the rate tolerance changes, 37 times a period), the ranges rebuilt 4 us,
the dual tolerance's scale 4.4 us, the energy terms 3.8 us, the event's record 2.7 us, the state
2.2 us; the 1000 grid samples 11.4 ms a period (11 us each, as the reference's steps are O(N)
each).

The catch-up step against the reference (catch-up/ref, bar <= 5; in brackets the certified step
in us), medians of five interleaved runs of this script at f702eb5 and now, ``--clock cpu``, on a
2-core machine shared with other jobs (load 3.8-5):

    wave       N    before (f702eb5)    now
    segments   4      7.2 (0.53)        2.9 (0.21)
    segments  16      2.7 (0.82)        1.2 (0.38)
    segments  64      2.3 (3.18)        1.0 (1.30)
    segments 256      2.4 (13.2)        1.1 (5.89)
    segments 1024     2.2 (50.6)        0.9 (21.0)
    body       4      6.6 (0.48)        2.8 (0.20)
    body      16      2.8 (0.87)        1.2 (0.37)
    body      64      2.1 (2.53)        0.7 (0.92)
    body     256      2.1 (10.3)        0.8 (3.98)
    body    1024      2.0 (42.6)        0.7 (14.7)

(the largest of the five runs now: 3.0 and 2.9 at N = 4, 1.5 at N = 16; with the factor and
solves that skip the l = 0 terms between runs, three runs at load 2.2-2.3: segments 3.0, 1.1,
0.8, 1.2, 0.8 and body 2.8, 1.1, 0.7, 0.7, 0.8). "now": after the solve,
one pass forms the point, multipliers, slack and the certificate's three numbers; the small
functions of the step are inlined into the loop; each row's own dual tolerance is formed only
where a multiplier's sign is in doubt; no allocation or slice copy per step; the period's block
positions and visited sets are compiled passes rather than numpy temporaries. The trajectory is
the same bit for bit.

Before the kernel (commit 3423cad, 2-core machine shared with other jobs): 3.29, 3.21, 3.04 s,
median 3.21 s (37 points/s). The catch-up step on the segments wave at 1000 steps per period was
then 3.09, 10.1 and 24.2 us at N = 4, 16 and 64 (median of 3 runs of 3 periods, the in-process
timer of scripts/bench-scale.py).
"""

from __future__ import annotations

import os

os.environ.setdefault("CRAWLSIM_KERNEL", "compiled")  # the compiled kernel's speed (crawlsim.kernel.jit)

import argparse
import importlib.util
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from numba import njit

from crawlsim.gait.document import gait_from_document
from crawlsim.integrate.stepping import make_stepper
from crawlsim.model.process import compile_gait

ROOT = Path(__file__).resolve().parents[1]
SWEEP_BEFORE = 3.21  # seconds, median of the three runs in the docstring


def _bench_scale():
    spec = importlib.util.spec_from_file_location("bench_scale", ROOT / "scripts" / "bench-scale.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@njit
def reference_period(k, C, w0, signs, W):
    """Catch-up steps w_j -> w_{j+1} onto {B w <= C[j+1]} (crawlsim.projection.kkt's chain), the active
    set of each step found from the previous one; W (G+1, N-1) receives the states."""
    N = signs.shape[0]
    G = C.shape[0] - 1
    D = np.empty(N)
    y = np.empty(N)
    f = np.empty(N)
    W[0] = w0
    for j in range(G):
        w = W[j]
        c = C[j + 1]
        f[0] = -w[0]
        for i in range(1, N - 1):
            f[i] = w[i - 1] - w[i]
        f[N - 1] = w[N - 2]
        for _ in range(4 * N + 4):
            # Thomas algorithm on the padded system of the saturated blocks
            for i in range(N):
                s = signs[i]
                D[i] = ((k[i - 1] if i > 0 else 0.0) + (k[i] if i < N - 1 else 0.0)) if s else 1.0
                y[i] = (f[i] - c[i] if s > 0 else f[i] + c[N + i]) if s else 0.0
            for i in range(1, N):
                e = -k[i - 1] if (signs[i - 1] != 0 and signs[i] != 0) else 0.0
                li = e / D[i - 1]
                D[i] -= li * e
                y[i] -= li * y[i - 1]
            y[N - 1] /= D[N - 1]
            for i in range(N - 2, -1, -1):
                e = -k[i] if (signs[i] != 0 and signs[i + 1] != 0) else 0.0
                y[i] = (y[i] - e * y[i + 1]) / D[i]
            changed = False
            for i in range(N):
                s = signs[i]
                if s and s * y[i] < -1e-13:  # a slip against its limit: release
                    signs[i] = 0
                    changed = True
            if not changed:
                prev = 0.0
                for i in range(N):
                    nxt = y[i + 1] if i < N - 1 else 0.0
                    fi = (
                        f[i]
                        - (k[i - 1] * (y[i] - prev) if i > 0 else 0.0)
                        + (k[i] * (nxt - y[i]) if i < N - 1 else 0.0)
                    )
                    prev = y[i]
                    if signs[i] == 0:
                        if fi - c[i] > 1e-13:
                            signs[i] = 1
                            changed = True
                        elif -fi - c[N + i] > 1e-13:
                            signs[i] = -1
                            changed = True
            if not changed:
                break
        for i in range(N - 1):
            W[j + 1, i] = w[i] - (y[i + 1] - y[i]) * k[i]
    return W


def _process(N: int, wave: str):
    scale = _bench_scale()
    doc = scale.wave_document(N, 1000, wave=wave)
    return compile_gait(gait_from_document(doc, f"wave-{N}"))


#: The clock of the measurements (``--clock``): wall time, or the process's CPU time, which a
#: machine shared with other jobs does not inflate by preemption.
CLOCK = time.perf_counter


def measure(N: int, wave: str, periods: int, repeats: int, skip: int = 0):
    """(reference s/period, catch-up s/period, exact s/period, max |w - w_reference|), the
    periods timed after ``skip`` untimed ones of each integrator (the segments wave's events
    per period grow over its first 30 periods: ``--skip-periods 30`` times the regime it
    settles in)."""
    process = _process(N, wave)
    k = np.ascontiguousarray(process.polyhedron.stiffness)
    C = np.ascontiguousarray(process.offsets)
    G = process.steps
    catch_up = make_stepper(process, "catch-up")
    exact = make_stepper(process, "exact")
    for _ in range(max(skip, 1)):
        catch_up.step_period()
        exact.step_period()
    ref_w = catch_up.w.copy()
    signs = np.zeros(N, dtype=np.int8)
    W = np.empty((G + 1, N - 1))
    reference_period(k, C, ref_w, signs, W)  # warm: settles the set at the period start
    ref, cu, ex = [], [], []
    diff = 0.0
    for _ in range(repeats):
        for _ in range(periods):
            start = catch_up.w.copy()
            began = CLOCK()
            record = catch_up.step_period()
            cu.append(CLOCK() - began)
            began = CLOCK()
            reference_period(k, C, start, signs, W)
            ref.append(CLOCK() - began)
            diff = max(diff, float(np.max(np.abs(W - record.w))))
            began = CLOCK()
            exact.step_period()
            ex.append(CLOCK() - began)
    return statistics.median(ref), statistics.median(cu), statistics.median(ex), diff


def sweep(repeats: int) -> float:
    times = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(repeats):
            out = Path(tmp) / f"sweep{i}.csv"
            began = time.perf_counter()
            subprocess.run(
                [
                    sys.executable,
                    "-m",
                    "crawlsim",
                    "velocity",
                    str(ROOT / "gaits" / "peristalsis-4.yaml"),
                    "--sweep",
                    "links.1.phase=0:1:120",
                    "-j",
                    "1",
                    "-o",
                    str(out),
                ],
                check=True,
                capture_output=True,
            )
            times.append(time.perf_counter() - began)
    return statistics.median(times)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="4,16,64,256,1024")
    parser.add_argument("--waves", default="segments,body")
    parser.add_argument("--periods", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument(
        "--skip-periods", type=int, default=1, help="untimed periods of each integrator before the timed ones"
    )
    parser.add_argument("--sweep", action="store_true")
    parser.add_argument("--clock", choices=("wall", "cpu"), default="wall")
    args = parser.parse_args()
    global CLOCK
    CLOCK = time.process_time if args.clock == "cpu" else time.perf_counter
    sizes = [int(s) for s in args.sizes.split(",") if s]
    print(
        f"1000 steps per period; medians of {args.repeats} x {args.periods} interleaved periods "
        f"after {args.skip_periods} ({args.clock} clock)"
    )
    print(
        f"{'wave':>9} {'N':>5} {'reference us/step':>18} {'catch-up us/step':>17} "
        f"{'catch-up/ref':>13} {'exact ms/period':>16} {'exact/ref period':>17} "
        f"{'max|dw|':>9}"
    )
    for wave in args.waves.split(","):
        for N in sizes:
            ref, cu, ex, diff = measure(N, wave, args.periods, args.repeats, args.skip_periods)
            print(
                f"{wave:>9} {N:>5} {ref / 1000 * 1e6:>18.3f} {cu / 1000 * 1e6:>17.3f} "
                f"{cu / ref:>13.1f} {ex * 1e3:>16.2f} {ex / ref:>17.1f} {diff:>9.2g}",
                flush=True,
            )
    print("bars: catch-up/ref <= 5, exact/ref period <= 3")
    if args.sweep:
        t = sweep(args.repeats)
        print(
            f"exact sweep of 120 points, -j 1: {t:.2f} s; before the kernel {SWEEP_BEFORE} s: "
            f"{SWEEP_BEFORE / t:.2f}x faster (bar: >= 30)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
