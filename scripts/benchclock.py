"""The clock of the start-up benchmarks (`bench-startup.py`, `bench-study.py`): one fresh
process, its wall time and its own CPU time, both measured around the same run."""

from __future__ import annotations

import resource
import subprocess
import time
from pathlib import Path


def run_clocked(argv: list[str], *, cwd: Path, env: dict[str, str], check: bool = True) -> tuple[float, float]:
    """(wall seconds, user + system CPU seconds of the child) of running ``argv`` once; its
    output is discarded and a failure raises (unless ``check`` is False)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    began = time.perf_counter()
    subprocess.run(argv, check=check, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=cwd, env=env)
    wall = time.perf_counter() - began
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
