#!/usr/bin/env python3
"""The periodic limit directly: the periodic-limit solver against plain iteration, in one run.

For each gait, both integrators (exact, the default, and catch-up), `crawlsim.analysis.run.simulate`
with ``history=False`` (what ``crawlsim velocity`` and sweeps run) at tolerance 1e-12, once with
``limit="iterate"`` and once with ``limit="newton"``:

* periods simulated (``steps / steps_per_period``: the solver's periods included) and the
  ratio iterate / newton;
* wall time (median of ``--repeats`` runs) and the ratio iterate / newton;
* |v0(newton) - v0(iterate)| / |v0| and the distance of the two limit periods in the metric,
  ``max_t |w_newton(t) - w_iterate(t)|_M / max_t |w_iterate(t)|_M``, with the iterate's own
  error estimate of v0 for scale (plain iteration stopped at a Poincare step of 1e-12 is itself
  only that close to the limit: about 1e-12 / (1 - rate));
* |v0(newton) - v0| / |v0| against plain iteration run to the roundoff floor (1e-13), whose
  tail is ten times smaller;
* the contraction rate of the true iterates and the Jacobian's rate at the limit.

Gaits: the 20-block retrograde cosine wave (link i: L_i = 1 + 0.3 cos 2 pi (t/T - i/(N-1)),
k = 10, friction forward 1.0 / backward 2.13); the square-wave retrograde peristalsis for
N = 4..8 (link i contracted to 1 - 0.3 on [i/(N-1), (i+1)/(N-1)) of each period, at rest length
otherwise: it contracts by 1/4 at N = 4, 1/2 at N = 5, 3/4 at N = 7); the paper's acute angle at
alpha = 0.5 (rate 1/(1 + alpha^2) = 0.8); the two-block inching gait (finite-time, periodic
after one period); and a sweep of the phase lag lam of the 8-block wave (link i at phase i lam,
lam in [0, 1], ``--sweep-points`` points, default 1000, 100 steps per period) through
`crawlsim.study.sweep.sweep`, the library call of ``crawlsim velocity --sweep``, end to end, iterate
against newton (``--sweep-repeats`` runs, default 1: a run takes minutes).

    python scripts/bench-limit.py [--repeats 3] [--steps 400] [--integrators exact,catch-up]
        [--sweep-points 1000] [--sweep-blocks 8] [--sweep-steps 100] [--sweep-repeats 1]
        [--jobs 2] [--no-sweep | --only-sweep]

Done-when of the solver: >= 10x fewer periods where the contraction rate exceeds 0.5; the sweep
>= 3x faster end to end; gaits that converge in a period or two (finite-time) not slower by more
than 10%.
"""

from __future__ import annotations

import os

os.environ.setdefault("CRAWLSIM_KERNEL", "compiled")  # the compiled kernel's speed (crawlsim.kernel.jit)

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from crawlsim.analysis.run import simulate
from crawlsim.gait.document import gait_from_document, load_gait, with_simulation
from crawlsim.model.process import compile as compile_gait
from crawlsim.study import sweep as sweeps
from crawlsim.study.paper import acute_angle_document

ROOT = Path(__file__).resolve().parents[1]
TOLERANCE = 1e-12


def wave_document(N: int, steps: int) -> dict:
    """The retrograde cosine wave of N blocks (as in scripts/bench-scale.py)."""
    return {
        "name": f"wave-{N}",
        "blocks": N,
        "period": 1.0,
        "stiffness": 10.0,
        "links": [{"kind": "cosine", "mean": 1.0, "amplitude": 0.3, "phase": i / (N - 1)} for i in range(N - 1)],
        "friction": {"forward": 1.0, "backward": 2.13},
        "simulation": {"steps_per_period": steps, "max_periods": 5000},
    }


def square_document(N: int, steps: int, amplitude: float = 0.3) -> dict:
    """Square-wave retrograde peristalsis: one link contracted at a time, link i during
    [i/(N-1), (i+1)/(N-1)) of the period (a `steps` signal), the others at rest length."""
    width = 1.0 / (N - 1)
    return {
        "name": f"square-{N}",
        "blocks": N,
        "period": 1.0,
        "stiffness": 10.0,
        "links": [
            {"kind": "steps", "times": [0.0, width], "values": [1.0 - amplitude, 1.0], "phase": i * width}
            for i in range(N - 1)
        ],
        "friction": {"forward": 1.0, "backward": 2.13},
        "simulation": {"steps_per_period": steps, "max_periods": 5000},
    }


def gaits(steps: int) -> list[tuple[str, object]]:
    out = [("wave-20", gait_from_document(wave_document(20, steps), "wave-20"))]
    out += [(f"square-{N}", gait_from_document(square_document(N, steps), f"square-{N}")) for N in range(4, 9)]
    acute = acute_angle_document(alpha=0.5, steps=64, max_periods=5000)
    out.append(("acute-angle-0.5", gait_from_document(acute, "acute-angle-0.5")))
    out.append(("inching-2 (finite)", load_gait(ROOT / "gaits" / "inching-2.yaml")))
    return out


def metric_norm(process, W: np.ndarray) -> np.ndarray:
    """|w|_M of each row of W."""
    MW = process.polyhedron.metric_times(W)
    return np.sqrt(np.sum(W * MW, axis=-1))


def timed(process, integrator: str, repeats: int):
    """(iterate result, newton result, median wall of each): the two methods alternate, so
    that a change of the machine's load hits both; runs under 0.2 s are repeated at least 15
    times (their medians are otherwise noise)."""
    walls: dict[str, list[float]] = {"iterate": [], "newton": []}
    results = {}
    count = 0
    while count < repeats or (count < 15 and sum(walls["iterate"] + walls["newton"]) < 0.2 * count):
        for limit in ("iterate", "newton"):
            began = time.perf_counter()
            results[limit] = simulate(
                process, max_periods=5000, tolerance=TOLERANCE, integrator=integrator, limit=limit, history=False
            )
            walls[limit].append(time.perf_counter() - began)
        count += 1
    return (
        results["iterate"],
        results["newton"],
        statistics.median(walls["iterate"]),
        statistics.median(walls["newton"]),
    )


def compare_gaits(args) -> list[str]:
    missed = []
    header = (
        f"{'gait':<19} {'integrator':<9} {'rate':>6} {'J rate':>6} {'periods it/nt':>14} "
        f"{'ratio':>6} {'wall it/nt s':>15} {'ratio':>6} {'|dv0|/v0':>9} {'v0 err it':>9} "
        f"{'limit dist':>10} {'|dv0| 1e-13':>11}"
    )
    print(header)
    print("-" * len(header))
    for name, gait in gaits(args.steps):
        for integrator in args.integrators:
            process = compile_gait(with_simulation(gait, integrator=integrator))
            it, nt, t_it, t_nt = timed(process, integrator, args.repeats)
            G = process.steps
            p_it, p_nt = it.steps // G, nt.steps // G
            dv = (abs(nt.v0 - it.v0) / abs(it.v0)) if it.v0 else float("nan")
            err = (it.estimate.error_estimate / abs(it.v0)) if it.v0 else float("nan")
            dist = float(
                np.max(metric_norm(process, nt.limit.w - it.limit.w))
                / max(float(np.max(metric_norm(process, it.limit.w))), 1e-300)
            )
            # plain iteration to the roundoff floor: the reference for the v0 of both
            tight = simulate(
                process, max_periods=5000, tolerance=1e-13, integrator=integrator, limit="iterate", history=False
            )
            dv_tight = (abs(nt.v0 - tight.v0) / abs(tight.v0)) if tight.v0 else float("nan")
            rate = None if it.rate is None else it.rate.rate
            jrate = nt.solver.jacobian_rate
            print(
                f"{name:<19} {integrator:<9} {_f(rate, 4):>6} {_f(jrate, 4):>6} "
                f"{p_it:>6} / {p_nt:<5} {p_it / p_nt:>6.1f} {t_it:>7.3f}/{t_nt:<7.3f} "
                f"{t_it / t_nt:>6.2f} {dv:>9.1e} {err:>9.1e} {dist:>10.1e} {dv_tight:>11.1e}",
                flush=True,
            )
            if rate is not None and rate > 0.5 and p_it < 10 * p_nt:
                missed.append(f"{name} {integrator}: {p_it / p_nt:.1f}x fewer periods (< 10x)")
            if p_it <= 3 and t_nt > 1.1 * t_it:
                missed.append(f"{name} {integrator}: finite-time gait {t_nt / t_it:.2f}x slower")
    return missed


def _f(value, digits: int) -> str:
    return "-" if value is None else f"{value:.{digits}g}"


def compare_sweep(args) -> list[str]:
    """The phase lag lam of the retrograde cosine wave of ``--sweep-blocks`` blocks (link i at
    phase i lam: linked paths, one grid dimension), end to end through `crawlsim.study.sweep.sweep`."""
    N, steps, P = args.sweep_blocks, args.sweep_steps, args.sweep_points
    gait = gait_from_document(wave_document(N, steps), f"wave-{N}")
    axes = [[f"links.{i}.phase=0:{i}:{P}" for i in range(1, N - 1)]]
    missed = []
    for integrator in args.integrators:
        walls: dict[str, list[float]] = {"iterate": [], "newton": []}
        tables = {}
        for _ in range(args.sweep_repeats):
            for limit in ("iterate", "newton"):
                g = with_simulation(gait, integrator=integrator, limit=limit)
                began = time.perf_counter()
                tables[limit] = sweeps.sweep(g, axes, jobs=args.jobs)
                walls[limit].append(time.perf_counter() - began)
        it, nt = tables["iterate"].rows, tables["newton"].rows
        v_it = np.array([np.nan if r.v0 is None else r.v0 for r in it])
        v_nt = np.array([np.nan if r.v0 is None else r.v0 for r in nt])
        p_it = sum(r.steps for r in it) / steps
        p_nt = sum(r.steps for r in nt) / steps
        t_it, t_nt = statistics.median(walls["iterate"]), statistics.median(walls["newton"])
        # plain iteration stopped at a Poincare step of 1e-12 is off by its own error estimate
        # (the geometric tail): |dv0| is measured against it (exact rows; catch-up sweep rows
        # carry no estimate), and against the sweep's largest |v0| (v0 crosses 0 near lag 0)
        e_it = np.array([np.nan if r.estimate.error_estimate is None else r.estimate.error_estimate for r in it])
        dv = float(np.nanmax(np.abs(v_nt - v_it)) / np.nanmax(np.abs(v_it)))
        ratio = np.abs(v_nt - v_it) / e_it
        dv_err = float(np.nanmax(ratio)) if np.any(np.isfinite(ratio)) else float("nan")
        counts = tables["newton"].counts()
        print(
            f"sweep of the phase lag of wave-{N} ({P} points, {steps} steps, {integrator}, "
            f"--jobs {args.jobs}, median of {args.sweep_repeats}): periods "
            f"{p_it:.0f} / {p_nt:.0f} ({p_it / p_nt:.1f}x fewer), wall {t_it:.1f} / "
            f"{t_nt:.1f} s ({t_it / t_nt:.2f}x faster), max |dv0| / max |v0| {dv:.1e}, max |dv0| / "
            f"(error estimate of the iterate's v0) {dv_err:.2f}; newton "
            f"points: {counts}",
            flush=True,
        )
        if t_it < 3 * t_nt:
            missed.append(f"sweep {integrator}: {t_it / t_nt:.2f}x faster end to end (< 3x)")
    return missed


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--steps", type=int, default=400, help="steps per period of the crawlers")
    ap.add_argument("--sweep-points", type=int, default=1000)
    ap.add_argument("--sweep-blocks", type=int, default=8)
    ap.add_argument("--sweep-steps", type=int, default=100)
    ap.add_argument("--sweep-repeats", type=int, default=1)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--integrators", default="exact,catch-up")
    ap.add_argument("--no-sweep", action="store_true")
    ap.add_argument("--only-sweep", action="store_true")
    args = ap.parse_args()
    args.integrators = [s for s in args.integrators.split(",") if s]
    print(
        f"iterate (it) against newton (nt), tolerance {TOLERANCE:g}, median wall of "
        f"{args.repeats} runs; rate: fitted to the true iterates, J rate: Jacobian at the "
        "limit; v0 err it: the iterate's own error estimate of v0, relative\n"
    )
    missed = [] if args.only_sweep else compare_gaits(args)
    if not args.no_sweep:
        print()
        missed += compare_sweep(args)
    print()
    print("done-when: " + ("met" if not missed else "MISSED: " + "; ".join(missed)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
