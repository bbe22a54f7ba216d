#!/usr/bin/env python
"""Benchmark: start-up cost of the `crawlsim` command, as ratios measured in one run.

* ``crawlsim --version`` and ``crawlsim --help`` against ``python -c pass`` (bar: at most 3x);
* ``crawlsim validate gaits/peristalsis-4.yaml`` against ``python -c "import numpy, yaml"``
  (bar: at most 1.5x; it must load neither scipy nor numba);
* ``crawlsim velocity gaits/peristalsis-4.yaml`` (the exact integrator, the default) and
  ``gaits/inching-2.yaml`` (catch-up and exact) against the import of what the command needs
  (bar: at most 1.3x).

What "what it needs" means (the honest reading of the bar): numpy, scipy.sparse, clarabel, yaml
*and the compiled module*, i.e. importing numba and crawlsim's kernel modules and loading, from
numba's cache, the machine code of exactly the kernel entry points (dispatchers and signatures)
that the command calls. A probe runs each velocity command once in-process and lists the
dispatchers that got an overload; the denominator is then a ``python -c`` that imports the four
libraries and the kernel modules and calls ``dispatcher.compile(signature)`` for those
signatures only (found in the dispatcher's cache index, so it is a cache load, never a
compilation). Loading a cached overload is not free: numba refreshes its target context
(its typing and lowering registries, numba.np.arraymath, whose BLAS check imports
scipy.linalg), and that is part of the cost of the compiled module. The strict ratio against the
bare ``python -c "import numpy, scipy.sparse, clarabel, yaml"`` is printed too, and so are the
modules of the bar's list that a command does not import at all (a crawler's velocity needs
neither clarabel nor scipy.sparse: its compiled kernel solves every step).

Each command is a fresh process; ``--clock wall`` (default) times ``subprocess.run``,
``--clock cpu`` the child's user+system CPU time (steadier on a shared machine). The commands
are run in turns (round-robin, each round starting one command later) so that a change of the
machine's load affects them alike, and the median of ``--repeat`` runs is reported, with the
load average. The last table lists the heavy modules each command imports beyond its
denominator (``python -X importtime``), the usual suspects when a ratio grows.

``--cold N`` also times N first runs of ``crawlsim velocity gaits/peristalsis-4.yaml`` with an
empty numba cache (``NUMBA_CACHE_DIR`` a fresh temporary directory each time), median, against
``COLD_SECONDS`` (crawlsim/kernel/catchup.py), the figure the command prints on a cold cache.

Bytecode: an installed package has its ``.pyc`` files (pip compiles them), so the commands run
with bytecode caching on (``PYTHONDONTWRITEBYTECODE`` removed from their environment; the warm-up
run writes crawlsim's ``__pycache__``, which git ignores), as numpy and the others have theirs.

Run it with the interpreter of a regular install (``pip install .`` in a fresh virtual
environment), what users run: an editable install adds its own import hook to every start-up
(pathlib, importlib machinery), which the installed package does not pay.

    python -m venv /tmp/inst && /tmp/inst/bin/pip install . &&
        /tmp/inst/bin/python scripts/bench-startup.py [--repeat 15] [--clock cpu] [--cold 3]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from benchclock import run_clocked  # scripts/benchclock.py

ROOT = Path(__file__).resolve().parents[1]
PERISTALSIS = ROOT / "gaits" / "peristalsis-4.yaml"
INCHING = ROOT / "gaits" / "inching-2.yaml"
NEEDED = "import numpy, scipy.sparse, clarabel, yaml"
VALIDATE_NEEDS = "import numpy, yaml"
HEAVY = (
    "jsonschema",
    "h5py",
    "matplotlib",
    "scipy.optimize",
    "scipy.linalg",
    "scipy.sparse",
    "scipy",
    "numba",
    "tqdm",
    "distributed",
    "dask",
    "xarray",
    "pandas",
)

#: Run one crawlsim command in-process and print, on the last line, the kernel dispatchers that
#: got a compiled overload and their signatures.
PROBE = """
import gc, json, sys
from crawlsim.cli import main
try:
    main(sys.argv[1:], standalone_mode=False)
except SystemExit:
    pass
from numba.core.registry import CPUDispatcher
used = {f"{d.py_func.__module__}:{d.py_func.__name__}": [str(s) for s in d.signatures]
        for d in gc.get_objects() if isinstance(d, CPUDispatcher) and d.overloads}
print("\\nPROBE " + json.dumps(used))
"""

#: The denominator: the libraries, numba, the kernel modules, and the cached machine code of
#: the given dispatchers' given signatures (argv[1], the probe's JSON).
LOAD = (
    NEEDED
    + """
import importlib, json, sys
wanted = json.loads(sys.argv[1])
for name, signatures in wanted.items():
    module, attribute = name.split(":")
    dispatcher = getattr(importlib.import_module(module), attribute)
    keys = [key[0] for key in dispatcher._cache._cache_file._load_index()
            if str(key[0]) in signatures]
    if len(keys) != len(signatures):
        sys.exit(f"{name}: {len(signatures)} signatures wanted, {len(keys)} in the cache")
    for key in keys:
        dispatcher.compile(key)
    if dispatcher._cache_hits.total() != len(keys) or dispatcher._cache_misses.total():
        sys.exit(f"{name}: not loaded from the cache")
"""
)


def crawlsim_command() -> list[str]:
    """The console script next to this interpreter (what users run), else ``python -m``."""
    script = Path(sys.executable).with_name("crawlsim")
    if script.exists():
        return [str(script)]
    found = shutil.which("crawlsim")
    return [found] if found else [sys.executable, "-m", "crawlsim"]


ENV = dict(os.environ)


def timed(argv: list[str], clock: str, env: dict[str, str] | None = None) -> float:
    """Seconds of one fresh process: wall time, or its user+system CPU time."""
    wall, cpu = run_clocked(argv, cwd=ROOT, env=env or ENV)
    return wall if clock == "wall" else cpu


def probe(arguments: list[str]) -> dict[str, list[str]]:
    """The kernel dispatchers and signatures the command ``crawlsim arguments`` calls."""
    out = subprocess.run(
        [sys.executable, "-c", PROBE, *arguments], capture_output=True, text=True, cwd=ROOT, env=ENV, check=True
    ).stdout
    line = [row for row in out.splitlines() if row.startswith("PROBE ")][-1]
    used: dict[str, list[str]] = json.loads(line[len("PROBE ") :])
    return used


def imported(argv: list[str]) -> set[str]:
    """Modules imported by ``argv`` (a crawlsim or Python command line), from ``-X importtime``."""
    if argv[0] != sys.executable:
        argv = [sys.executable, "-X", "importtime", "-m", "crawlsim", *argv[1:]]
    else:
        argv = [sys.executable, "-X", "importtime", *argv[1:]]
    err = subprocess.run(argv, capture_output=True, text=True, cwd=ROOT, env=ENV).stderr
    return {m.group(1).strip() for m in re.finditer(r"\|\s+\d+ \|\s*([\w.]+)", err)}


def cold_runs(crawlsim: list[str], count: int) -> list[tuple[float, float]]:
    """(wall, CPU) seconds of ``count`` velocity runs of peristalsis-4, each with an empty
    numba cache."""
    seconds = []
    for _ in range(count):
        with tempfile.TemporaryDirectory(prefix="crawlsim-cold-") as cache:
            env = {**ENV, "NUMBA_CACHE_DIR": cache}
            seconds.append(run_clocked([*crawlsim, "velocity", str(PERISTALSIS)], cwd=ROOT, env=env))
    return seconds


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=15, help="runs of each command (median)")
    ap.add_argument(
        "--clock",
        choices=("wall", "cpu"),
        default="wall",
        help="wall time of each process, or its CPU time (user + system)",
    )
    ap.add_argument(
        "--cold", type=int, default=0, metavar="N", help="also time N first runs with an empty numba cache (median)"
    )
    args = ap.parse_args()
    ENV.pop("PYTHONDONTWRITEBYTECODE", None)
    crawlsim = crawlsim_command()
    velocity = {
        "crawlsim velocity peristalsis-4 (exact)": ["velocity", str(PERISTALSIS)],
        "crawlsim velocity inching-2 (catch-up)": ["velocity", str(INCHING), "--integrator", "catch-up"],
        "crawlsim velocity inching-2 (exact)": ["velocity", str(INCHING), "--integrator", "exact"],
    }
    for arguments in velocity.values():  # warm numba's cache (a cold one is --cold's business)
        subprocess.run([*crawlsim, *arguments], check=True, capture_output=True, cwd=ROOT, env=ENV)
    loads = {name: probe(arguments) for name, arguments in velocity.items()}
    needs = {
        name: "libraries + numba + cached " + ", ".join(sorted(entry.split(".")[-1] for entry in loads[name]))
        for name in velocity
    }
    commands = {
        "python -c pass": [sys.executable, "-c", "pass"],
        "crawlsim --version": [*crawlsim, "--version"],
        "crawlsim --help": [*crawlsim, "--help"],
        f"python -c '{VALIDATE_NEEDS}'": [sys.executable, "-c", VALIDATE_NEEDS],
        "crawlsim validate peristalsis-4": [*crawlsim, "validate", str(PERISTALSIS)],
        f"python -c '{NEEDED}'": [sys.executable, "-c", NEEDED],
    }
    for name, arguments in velocity.items():
        commands[name] = [*crawlsim, *arguments]
        commands[needs[name]] = [sys.executable, "-c", LOAD, json.dumps(loads[name])]
    for argv in commands.values():  # warm the file cache and the .pyc files
        timed(argv, args.clock)
    times: dict[str, list[float]] = {name: [] for name in commands}
    names = list(commands)
    load_before = os.getloadavg()
    for round_ in range(args.repeat):
        # each round starts one command later: a process run right after another pays for its
        # predecessor's exit (measured: up to 10%), and rotating spreads that over all commands
        for name in names[round_ % len(names) :] + names[: round_ % len(names)]:
            times[name].append(timed(commands[name], args.clock))
    median = {name: statistics.median(t) for name, t in times.items()}

    print(
        f"start-up, median of {args.repeat} runs each ({args.clock} time of a fresh process, "
        f"bytecode cached); load average {load_before[0]:.2f} before, "
        f"{os.getloadavg()[0]:.2f} after:"
    )
    for name, t in median.items():
        print(f"  {name:<72} {t * 1e3:8.1f} ms")
    base = median["python -c pass"]
    rows = [
        ("crawlsim --version", "python -c pass", 3.0),
        ("crawlsim --help", "python -c pass", 3.0),
        ("crawlsim validate peristalsis-4", f"python -c '{VALIDATE_NEEDS}'", 1.5),
    ]
    for name in velocity:
        rows.append((name, needs[name], 1.3))
    print("\nratios:")
    for name, reference, bar in rows:
        ratio = median[name] / median[reference]
        against = (
            "python -c pass"
            if reference == "python -c pass"
            else "the libraries + cached kernel"
            if reference in needs.values()
            else "python -c 'import numpy, yaml'"
        )
        verdict = "met" if ratio <= bar else "NOT met"
        print(f"  {name:<42} {ratio:5.2f}x {against:<30} (bar {bar}x: {verdict})")
    print("\nstrict ratios against the bare import of the libraries (no numba, no kernel):")
    for name in velocity:
        print(f"  {name:<42} {median[name] / median[f'python -c {NEEDED!r}']:5.2f}x")
    print(
        f"  (the libraries + cached kernel of peristalsis-4 alone: "
        f"{median[needs['crawlsim velocity peristalsis-4 (exact)']] / median[f'python -c {NEEDED!r}']:.2f}x"
        f"; python -c pass {base * 1e3:.1f} ms)"
    )

    print("\nheavy modules imported beyond the denominator:")
    baseline = imported([sys.executable, "-c", VALIDATE_NEEDS])
    extra = imported(commands["crawlsim validate peristalsis-4"]) - baseline
    heavy = sorted(m for m in HEAVY if m in extra)
    print(f"  {'crawlsim validate peristalsis-4':<42} {', '.join(heavy) or 'none'}")
    unused = {}
    for name in velocity:
        baseline = imported([sys.executable, "-c", LOAD, json.dumps(loads[name])])
        mine = imported(commands[name])
        heavy = sorted(m for m in HEAVY if m in mine - baseline)
        print(f"  {name:<42} {', '.join(heavy) or 'none'}")
        unused[name] = sorted(m for m in ("clarabel", "scipy.sparse") if m not in mine)
    print("\nmodules of the bar's denominator that the command does not import at all:")
    for name, modules in unused.items():
        print(f"  {name:<42} {', '.join(modules) or 'none'}")

    if args.cold:
        from crawlsim.kernel.catchup import COLD_SECONDS

        cold = cold_runs(crawlsim, args.cold)
        walls, cpus = [w for w, _ in cold], [c for _, c in cold]
        print(
            f"\ncold first run (empty numba cache), crawlsim velocity peristalsis-4: wall "
            f"median {statistics.median(walls):.1f} s of {', '.join(f'{s:.1f}' for s in walls)}"
            f"; CPU median {statistics.median(cpus):.1f} s of "
            f"{', '.join(f'{s:.1f}' for s in cpus)} (load average {os.getloadavg()[0]:.2f}; "
            f"the compilation is one thread, so on an idle machine the wall time is the CPU "
            f"time); COLD_SECONDS prints ~{COLD_SECONDS} s"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
