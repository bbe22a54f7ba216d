#!/usr/bin/env python
"""Benchmark: exact sweeps and `crawlsim optimize` end to end, before the kernel and now.

The bars of issue 20: an exact 1-D sweep of 120 points (``-j 1``) runs at least 30x faster than
before the compiled kernel, a 2-D sweep of 120 points (12 x 10 over links.1.phase and
links.2.phase) the same, and the optimize example of docs/optimize.md at least 20x faster.
"Before" is commit 3423cad (the last commit before the kernel; its 1-D sweep took 3.21 s, measured
under load). This script measures both in one run: it extracts that commit with ``git archive``
into a temporary directory and runs the same commands there with ``PYTHONPATH=<that dir>`` (the
same interpreter and the same installed dependencies; 3423cad needs nothing that the current
tree does not), and here with ``PYTHONPATH=<this tree>``.

Every command is a fresh ``python -m crawlsim`` process, its output written to a temporary
directory; before and now are run in turns (round-robin, each round starting one command later),
``--repeat`` times, and the median is reported with the load average. ``--clock cpu`` reports the
child's user+system CPU time instead of the wall time (steadier on a shared machine; every
command here runs in one process, ``-j 1``). The per-point cost is the sweep's time minus the same
command on a 1-point sweep (start-up, gait loading and writing the table excluded), divided by the
number of points; as the difference of two processes of a second or more it is noisy on a
loaded machine, so it is also measured in-process (the sweeps as library calls, no start-up,
CPU time, in turns before/now). The numba cache of the current tree is warmed first (a cold cache is
`scripts/bench-startup.py --cold`'s business).

The end-to-end bars include the start-up of the process: importing numpy, scipy, clarabel, numba
and loading the cached kernel costs about a second (`scripts/bench-startup.py`), more than 1/30 of
the before figure, so the 30x end-to-end bar cannot be met by any per-point speed; the script
prints that floor (the 1-point sweep now) against the bar's budget.

    python scripts/bench-study.py [--repeat 3] [--clock cpu] [--skip-optimize]

The in-process figures are also read against the bars per point: the 30x bar leaves a point
1/30 of its in-process cost before the kernel, and the optimize example called in the process
(its whole search, no start-up) 1/20 of its time; these are not the issue's bars (those are end
to end, above) and are reported apart from them.

Measured (``--repeat 5 --clock cpu``, on the 2-core machine shared with other jobs at a load
average of 1.3-3.9, after the per-point cuts of the sweep-point work, at ac109a2):

    command                       before s    now s   ratio  bar
    1-D sweep, 120 points            2.776    1.259    2.2x  >= 30x: NOT met
    2-D sweep, 12 x 10 points        2.725    1.227    2.2x  >= 30x: NOT met
    1-point sweep                    0.368    1.100    0.3x
    optimize example                 6.912    1.765    3.9x  >= 20x: NOT met
    per point (processes)           20.1 / 19.6 ms   1.33 / 1.06 ms   15.1x / 18.5x
    in-process, per point           18.25 / 18.15 ms   1.67 / 1.53 ms   10.9x / 11.9x
                                    (30x budget 0.61 / 0.60 ms: NOT met in-process)
    in-process, optimize example     5.959 s   0.321 s   18.6x  (20x: NOT met in-process)

At 2bc9b42, before those cuts (load 1.3-3.7), the in-process figures were 20.47 / 20.20 ms
before and 2.70 / 2.62 ms now (7.6x / 7.7x). The per-point figure from processes is the
difference of two processes of a second or more and swings with the load (7.3x, 9.2x and
15.1x in three runs at this work's last three commits, whose in-process figures were 10.0x,
11.2x and 10.9x); the in-process one is the steadier. The 1-point sweep is the floor: 1.10 s now
(0.37 s before the kernel: numba's import and its first cache load are most of the
difference, `scripts/bench-startup.py`), twelve times the 0.093 s that the 30x bar leaves for
the whole 120-point sweep. The optimize example now runs the gradient search (48 evaluations,
the default method since) where 3423cad ran differential evolution (360 evaluations).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tarfile
import tempfile
from io import BytesIO
from pathlib import Path

from benchclock import run_clocked  # scripts/benchclock.py

ROOT = Path(__file__).resolve().parents[1]
BEFORE = "3423cad"
GAIT = "gaits/peristalsis-4.yaml"
SWEEP_POINTS = 120

#: name -> crawlsim arguments ({out} is the output directory of the run); the bar of each.
COMMANDS: dict[str, list[str]] = {
    "1-D sweep, 120 points": ["velocity", GAIT, "--sweep", "links.1.phase=0:1:120", "-j", "1", "-o", "{out}/sweep.csv"],
    "2-D sweep, 12 x 10 points": [
        "velocity",
        GAIT,
        "--sweep",
        "links.1.phase=0:1:12",
        "--sweep",
        "links.2.phase=0:1:10",
        "-j",
        "1",
        "-o",
        "{out}/sweep.csv",
    ],
    "1-point sweep": ["velocity", GAIT, "--sweep", "links.1.phase=0:1:1", "-j", "1", "-o", "{out}/sweep.csv"],
    "optimize example": [
        "optimize",
        GAIT,
        "--free",
        "links.1.phase=0:1",
        "--free",
        "links.2.phase=0:1",
        "--steps-per-period",
        "20",
        "--write-best",
        "{out}/best.yaml",
        "-o",
        "{out}/optimize.h5",
    ],
}
BARS = {"1-D sweep, 120 points": 30.0, "2-D sweep, 12 x 10 points": 30.0, "optimize example": 20.0}


#: The per-point cost in-process (no start-up in it): the sweeps as library calls, and the
#: optimize example as the command called in the process (``sys.argv[2]``: its output
#: directory), timed with the process's CPU clock after a warm-up; prints one line of JSON,
#: {name: [seconds per round]}.
IN_PROCESS = """
import json, sys, time
try:
    from crawlsim.study.sweep import sweep
except ImportError:  # 3423cad: one module
    from crawlsim.sweep import sweep
from crawlsim.api import load_gait
from crawlsim.cli import main
gait = load_gait("gaits/peristalsis-4.yaml")
cases = {"1-D": ["links.1.phase=0:1:120"], "2-D": ["links.1.phase=0:1:12", "links.2.phase=0:1:10"],
         "1-point": ["links.1.phase=0:1:1"]}
optimize = ["optimize", "gaits/peristalsis-4.yaml", "--free", "links.1.phase=0:1", "--free",
            "links.2.phase=0:1", "--steps-per-period", "20", "--quiet", "--write-best",
            sys.argv[2] + "/best.yaml", "-o", sys.argv[2] + "/optimize.h5"]
sweep(gait, ["links.1.phase=0:1:5"])  # warm: imports, numba's cache
out = {name: [] for name in [*cases, "optimize"]}
for _ in range(int(sys.argv[1])):
    for name, axes in cases.items():
        began = time.process_time()
        sweep(gait, axes)
        out[name].append(time.process_time() - began)
    if sys.argv[3] == "1":
        began = time.process_time()
        main(optimize, standalone_mode=False)
        out["optimize"].append(time.process_time() - began)
print(json.dumps(out))
"""


def in_process(tree: Path, rounds: int, env: dict[str, str], optimize: bool) -> dict[str, list[float]]:
    """CPU seconds of each in-process sweep of `IN_PROCESS` (and of the optimize example),
    ``rounds`` times, in ``tree``."""
    with tempfile.TemporaryDirectory(prefix="crawlsim-bench-") as out_dir:
        out = subprocess.run(
            [sys.executable, "-c", IN_PROCESS, str(rounds), out_dir, str(int(optimize))],
            cwd=tree,
            check=True,
            capture_output=True,
            text=True,
            env={**env, "PYTHONPATH": str(tree)},
        )
    result: dict[str, list[float]] = json.loads(out.stdout.splitlines()[-1])
    return result


def extract(commit: str, into: Path) -> Path:
    """The tree of ``commit`` (crawlsim, gaits) written into ``into``."""
    archive = subprocess.run(
        ["git", "archive", commit, "crawlsim", "gaits"], cwd=ROOT, check=True, capture_output=True
    ).stdout
    with tarfile.open(fileobj=BytesIO(archive)) as tar:
        tar.extractall(into, filter="data")
    return into


def timed(tree: Path, arguments: list[str], clock: str, env: dict[str, str]) -> float:
    """Seconds of ``python -m crawlsim arguments`` run in ``tree``, in a fresh output dir."""
    with tempfile.TemporaryDirectory(prefix="crawlsim-bench-") as out:
        argv = [sys.executable, "-m", "crawlsim", *(a.format(out=out) for a in arguments)]
        wall, cpu = run_clocked(argv, cwd=tree, env={**env, "PYTHONPATH": str(tree)})
    return wall if clock == "wall" else cpu


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3, help="runs of each command (median)")
    ap.add_argument("--clock", choices=("wall", "cpu"), default="wall")
    ap.add_argument(
        "--skip-optimize", action="store_true", help="leave out the optimize example (about 25 s before, per run)"
    )
    args = ap.parse_args()
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # an installed package has its .pyc files
    names = [n for n in COMMANDS if not (args.skip_optimize and n == "optimize example")]
    with tempfile.TemporaryDirectory(prefix="crawlsim-before-") as old:
        trees = {"before": extract(BEFORE, Path(old)), "now": ROOT}
        runs = [(when, name) for name in names for when in trees]
        for when, name in runs:  # warm .pyc files and, now, numba's cache
            timed(trees[when], COMMANDS[name], args.clock, env)
        times: dict[tuple[str, str], list[float]] = {run: [] for run in runs}
        load = os.getloadavg()[0]
        for round_ in range(args.repeat):
            shift = round_ % len(runs)
            for run in runs[shift:] + runs[:shift]:
                times[run].append(timed(trees[run[0]], COMMANDS[run[1]], args.clock, env))
                print(".", end="", file=sys.stderr, flush=True)
        print(file=sys.stderr)
        inside: dict[str, dict[str, list[float]]] = {when: {} for when in trees}
        for _ in range(args.repeat):  # in turns, a process of a few rounds each
            for when, tree in trees.items():
                for name, seconds in in_process(tree, 3, env, not args.skip_optimize).items():
                    inside[when].setdefault(name, []).extend(seconds)
    median = {run: statistics.median(t) for run, t in times.items()}

    print(
        f"{args.clock} time of `python -m crawlsim ...`, median of {args.repeat} interleaved "
        f"runs; load average {load:.2f} before, {os.getloadavg()[0]:.2f} after; before = "
        f"{BEFORE}"
    )
    print(f"  {'command':<28} {'before s':>9} {'now s':>8} {'ratio':>7}  bar")
    for name in names:
        b, n = median[("before", name)], median[("now", name)]
        bar = BARS.get(name)
        verdict = "" if bar is None else f">= {bar:.0f}x: {'met' if b / n >= bar else 'NOT met'}"
        print(f"  {name:<28} {b:>9.3f} {n:>8.3f} {b / n:>6.1f}x  {verdict}")
    print(f"\nper point (the sweep minus the 1-point sweep, / {SWEEP_POINTS}):")
    for name in names[:2]:
        per = {when: (median[(when, name)] - median[(when, "1-point sweep")]) / SWEEP_POINTS for when in trees}
        print(
            f"  {name:<28} {per['before'] * 1e3:>7.2f} ms {per['now'] * 1e3:>7.2f} ms "
            f"{per['before'] / per['now']:>6.1f}x"
        )
    print(
        f"\nIN-PROCESS, per point (library calls, no start-up, CPU time, median of "
        f"{3 * args.repeat} rounds; the sweep minus the 1-point sweep, / {SWEEP_POINTS}), "
        "against the 30x bar read per point (the end-to-end bars above are the issue's):"
    )
    print(f"  {'sweep':<28} {'before':>10} {'now':>10} {'ratio':>7}  {'30x budget':>10}")
    for name in ("1-D", "2-D"):
        per = {
            when: (statistics.median(inside[when][name]) - statistics.median(inside[when]["1-point"])) / SWEEP_POINTS
            for when in trees
        }
        ratio = per["before"] / per["now"]
        print(
            f"  {name + ' sweep':<28} {per['before'] * 1e3:>7.2f} ms {per['now'] * 1e3:>7.2f} ms "
            f"{ratio:>6.1f}x  {per['before'] / 30 * 1e3:>7.2f} ms: "
            f"{'met' if ratio >= 30 else 'NOT met'} in-process"
        )
    if not args.skip_optimize:
        whole = {when: statistics.median(inside[when]["optimize"]) for when in trees}
        ratio = whole["before"] / whole["now"]
        print(
            f"  {'optimize example (whole)':<28} {whole['before']:>8.3f} s {whole['now']:>8.3f} s "
            f"{ratio:>6.1f}x  {whole['before'] / 20:>8.3f} s: "
            f"{'met' if ratio >= 20 else 'NOT met'} in-process (20x)"
        )
    floor = median[("now", "1-point sweep")]
    budget = median[("before", "1-D sweep, 120 points")] / 30
    print(
        f"\nfloor: a 1-point sweep now costs {floor:.3f} s (start-up, the cached kernel, the "
        f"gait, the table); the 30x bar leaves {budget:.3f} s for the whole 120-point sweep"
        f" ({floor / budget:.1f}x the budget before any point runs)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
