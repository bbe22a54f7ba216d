#!/usr/bin/env python
"""Benchmark: what a user waits for before an answer, as ratios measured in one run.

* ``crawlsim --version`` and ``crawlsim --help`` against ``python -c pass`` (bar: at most 3x);
* ``crawlsim validate gaits/peristalsis-4.yaml`` against ``python -c "import numpy, yaml"``
  (bar: at most 1.5x);
* ``crawlsim velocity gaits/peristalsis-4.yaml`` (warm: numba's cache holds the kernel) against
  ``python -c "import numpy, yaml"`` (bar: at most 3x). A run this small stays interpreted and
  loads no numba (`crawlsim.kernel.jit`).

Each command is a fresh process; ``--clock cpu`` (default) takes the child's user+system CPU
time, ``--clock wall`` its wall time. The commands run in turns (each round starting one command
later), and the median of ``--repeat`` runs is reported with the load average.

``--cold N`` also times, N times each with an empty numba cache (a fresh ``NUMBA_CACHE_DIR``):
the README's first command, ``crawlsim run gaits/peristalsis-4.yaml`` (bar: at most 5 s of wall
time to its answer), then ``crawlsim warmup`` on every core (bar: at most 30 s of wall time),
then the commands of tests/test_jit.py in the compiled form, which must compile nothing.

Run it with the interpreter of a regular install (``pip install .`` in a fresh virtual
environment): an editable install adds its own import hook to every start-up.

    python -m venv /tmp/inst && /tmp/inst/bin/pip install . &&
        /tmp/inst/bin/python scripts/bench-startup.py [--repeat 15] [--cold 3]
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from benchclock import run_clocked  # scripts/benchclock.py

ROOT = Path(__file__).resolve().parents[1]
PERISTALSIS = str(ROOT / "gaits" / "peristalsis-4.yaml")
LIBRARIES = "import numpy, yaml"
ENV = {k: v for k, v in os.environ.items() if k not in ("PYTHONDONTWRITEBYTECODE", "CRAWLSIM_KERNEL")}
#: Commands that must load the warm kernel and compile nothing (``CRAWLSIM_KERNEL=compiled``).
COMPILED = [
    ["velocity", PERISTALSIS],
    ["velocity", PERISTALSIS, "--integrator", "catch-up"],
    ["velocity", PERISTALSIS, "--sensitivity", "stiffness"],
    ["velocity", PERISTALSIS, "--integrator", "catch-up", "--sensitivity", "stiffness"],
    ["stall", str(ROOT / "gaits" / "climbing-3.yaml"), "--slope"],
]


def crawlsim_command() -> list[str]:
    """The console script next to this interpreter (what users run), else ``python -m``."""
    script = Path(sys.executable).with_name("crawlsim")
    if script.exists():
        return [str(script)]
    found = shutil.which("crawlsim")
    return [found] if found else [sys.executable, "-m", "crawlsim"]


def cold(crawlsim: list[str], folder: str) -> tuple[float, float, list[str]]:
    """On an empty cache in ``folder``: the first run's wall time, warmup's wall time, and the
    compiled commands that printed a compile line afterwards."""
    env = {**ENV, "NUMBA_CACHE_DIR": folder}
    first, _ = run_clocked([*crawlsim, "run", PERISTALSIS, "-o", f"{folder}/p.h5"], cwd=ROOT, env=env)
    warm, _ = run_clocked([*crawlsim, "warmup"], cwd=ROOT, env=env)
    compiled = {**env, "CRAWLSIM_KERNEL": "compiled"}
    again = [
        " ".join(args)
        for args in COMPILED
        if "compiling" in subprocess.run([*crawlsim, *args], capture_output=True, text=True, env=compiled).stderr
    ]
    return first, warm, again


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=15, help="runs of each command (median)")
    ap.add_argument("--clock", choices=("wall", "cpu"), default="cpu")
    ap.add_argument("--cold", type=int, default=0, metavar="N", help="also N runs on an empty numba cache")
    args = ap.parse_args()
    crawlsim = crawlsim_command()
    commands = {
        "python -c pass": [sys.executable, "-c", "pass"],
        f"python -c '{LIBRARIES}'": [sys.executable, "-c", LIBRARIES],
        "crawlsim --version": [*crawlsim, "--version"],
        "crawlsim --help": [*crawlsim, "--help"],
        "crawlsim validate peristalsis-4": [*crawlsim, "validate", PERISTALSIS],
        "crawlsim velocity peristalsis-4": [*crawlsim, "velocity", PERISTALSIS],
    }
    for argv in commands.values():  # warm the file cache and the .pyc files
        run_clocked(argv, cwd=ROOT, env=ENV)
    times: dict[str, list[float]] = {name: [] for name in commands}
    names = list(commands)
    load = os.getloadavg()[0]
    for round_ in range(args.repeat):
        for name in names[round_ % len(names) :] + names[: round_ % len(names)]:
            wall, cpu = run_clocked(commands[name], cwd=ROOT, env=ENV)
            times[name].append(cpu if args.clock == "cpu" else wall)
    median = {name: statistics.median(t) for name, t in times.items()}
    print(
        f"start-up, median of {args.repeat} runs ({args.clock}); load average {load:.2f}, then {os.getloadavg()[0]:.2f}"
    )
    for name, t in median.items():
        print(f"  {name:<40} {t * 1e3:8.1f} ms")
    print("ratios:")
    for name, reference, bar in (
        ("crawlsim --version", "python -c pass", 3.0),
        ("crawlsim --help", "python -c pass", 3.0),
        ("crawlsim validate peristalsis-4", f"python -c '{LIBRARIES}'", 1.5),
        ("crawlsim velocity peristalsis-4", f"python -c '{LIBRARIES}'", 3.0),
    ):
        ratio = median[name] / median[reference]
        print(f"  {name:<40} {ratio:5.2f}x {reference:<30} (bar {bar}x: {'met' if ratio <= bar else 'NOT met'})")
    if args.cold:
        runs = []
        for _ in range(args.cold):
            with tempfile.TemporaryDirectory(prefix="crawlsim-cold-") as folder:
                runs.append(cold(crawlsim, folder))
        first, warm = [r[0] for r in runs], [r[1] for r in runs]
        print(
            f"empty cache (load average {os.getloadavg()[0]:.2f}): crawlsim run peristalsis-4 "
            f"{statistics.median(first):.2f} s wall (median of {', '.join(f'{s:.2f}' for s in first)}; bar 5 s); "
            f"crawlsim warmup {statistics.median(warm):.1f} s wall (median of {', '.join(f'{s:.1f}' for s in warm)}"
            f"; bar 30 s); compiled afterwards: {sorted({c for r in runs for c in r[2]}) or 'nothing'}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
