#!/usr/bin/env python
"""Benchmark: start-up cost of the `crawlsim` command, as ratios measured in one run.

* ``crawlsim --version`` and ``crawlsim --help`` against ``python -c pass`` (bar: at most 3x);
* ``crawlsim velocity gaits/inching-2.yaml``, with ``--integrator catch-up`` and ``exact``,
  against the bare import of what it truly needs,
  ``python -c "import numpy, scipy.sparse, clarabel, yaml"`` (bar: at most 1.3x).

Each command is a fresh process (wall time of `subprocess.run`); the commands are run in turns
(round-robin, each round starting one command later) so that a change of the machine's load
affects them alike, and the median of ``--repeat`` runs is reported. The last table lists the
heavy modules each velocity command imports beyond the baseline (``python -X importtime``), the
usual suspects when a ratio grows.

Bytecode: an installed package has its ``.pyc`` files (pip compiles them), so the commands run
with bytecode caching on (``PYTHONDONTWRITEBYTECODE`` removed from their environment; the warm-up
run writes crawlsim's ``__pycache__``, which git ignores), as numpy and the others have theirs.

Run it with the interpreter of a regular install (``pip install .`` in a fresh virtual
environment), what users run: an editable install adds its own import hook to every start-up
(pathlib, importlib machinery), which the installed package does not pay.

    python -m venv /tmp/inst && /tmp/inst/bin/pip install . &&
        /tmp/inst/bin/python scripts/bench-startup.py [--repeat 15]
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GAIT = ROOT / "gaits" / "inching-2.yaml"
NEEDED = "import numpy, scipy.sparse, clarabel, yaml"
HEAVY = ("jsonschema", "h5py", "matplotlib", "scipy.optimize", "tqdm", "distributed", "dask")


def crawlsim_command() -> list[str]:
    """The console script next to this interpreter (what users run), else ``python -m``."""
    script = Path(sys.executable).with_name("crawlsim")
    if script.exists():
        return [str(script)]
    found = shutil.which("crawlsim")
    return [found] if found else [sys.executable, "-m", "crawlsim"]


ENV = dict(os.environ)


def wall(argv: list[str]) -> float:
    began = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   cwd=ROOT, env=ENV)
    return time.perf_counter() - began


def imported(argv: list[str]) -> set[str]:
    """Top modules imported by ``argv`` (a Python command line), from ``-X importtime``."""
    if argv[0] != sys.executable:
        argv = [sys.executable, "-X", "importtime", "-m", "crawlsim", *argv[1:]]
    else:
        argv = [sys.executable, "-X", "importtime", *argv[1:]]
    err = subprocess.run(argv, capture_output=True, text=True, cwd=ROOT, env=ENV).stderr
    return {m.group(1).strip() for m in re.finditer(r"\|\s+\d+ \|\s*([\w.]+)", err)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=15, help="runs of each command (median)")
    args = ap.parse_args()
    ENV.pop("PYTHONDONTWRITEBYTECODE", None)
    crawlsim = crawlsim_command()
    commands = {
        "python -c pass": [sys.executable, "-c", "pass"],
        "crawlsim --version": [*crawlsim, "--version"],
        "crawlsim --help": [*crawlsim, "--help"],
        f"python -c '{NEEDED}'": [sys.executable, "-c", NEEDED],
        "crawlsim velocity inching-2 (catch-up)": [*crawlsim, "velocity", str(GAIT),
                                                   "--integrator", "catch-up"],
        "crawlsim velocity inching-2 (exact)": [*crawlsim, "velocity", str(GAIT),
                                                "--integrator", "exact"],
    }
    for argv in commands.values():  # warm the file cache and the .pyc files
        wall(argv)
    times: dict[str, list[float]] = {name: [] for name in commands}
    names = list(commands)
    for round_ in range(args.repeat):
        # each round starts one command later: a process run right after another pays for its
        # predecessor's exit (measured: up to 10%), and rotating spreads that over all commands
        for name in names[round_ % len(names):] + names[:round_ % len(names)]:
            times[name].append(wall(commands[name]))
    median = {name: statistics.median(t) for name, t in times.items()}

    print(f"start-up, median of {args.repeat} runs each (wall time of a fresh process, "
          "bytecode cached):")
    for name, t in median.items():
        print(f"  {name:<58} {t * 1e3:8.1f} ms")
    base, needed = median["python -c pass"], median[f"python -c '{NEEDED}'"]
    rows = [("crawlsim --version", base, 3.0), ("crawlsim --help", base, 3.0),
            ("crawlsim velocity inching-2 (catch-up)", needed, 1.3),
            ("crawlsim velocity inching-2 (exact)", needed, 1.3)]
    print("\nratios:")
    for name, reference, bar in rows:
        ratio = median[name] / reference
        against = "python -c pass" if reference is base else "the bare import"
        verdict = "met" if ratio <= bar else "NOT met"
        print(f"  {name:<40} {ratio:5.2f}x {against:<16} (bar {bar}x: {verdict})")

    baseline = imported([sys.executable, "-c", NEEDED])
    print("\nheavy modules imported beyond the bare import:")
    for name in ("crawlsim velocity inching-2 (catch-up)", "crawlsim velocity inching-2 (exact)"):
        extra = imported(commands[name]) - baseline
        heavy = sorted(m for m in HEAVY if m in extra)
        print(f"  {name:<40} {', '.join(heavy) or 'none'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
