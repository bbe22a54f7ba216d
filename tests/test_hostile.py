"""Hostile and extreme gait files through the real command line, under a memory limit.

Every file of the corpus (tests/hostile/, plus files too large to commit, made here at run
time) goes through ``python -m crawlsim run FILE -o OUT`` in a subprocess limited to 1 GiB of
address space (RLIMIT_AS). Each must be refused with exit code 2 and a one-line
message that names the file and what is wrong (the key where there is one), with no
traceback and no output file. ``blocks: 10000`` is a valid request: it must run within its own
memory estimate or be refused by it, and the test decides which from the estimate.

No test asserts a time: a loaded machine makes any limit flaky. A child still running after
`HANG_GUARD` seconds is killed, so a hang fails (exit code -9) instead of blocking the suite;
how fast each refusal is belongs to scripts/hostile-corpus.py, which prints the exit code, time
and peak memory of each file and its time as a ratio to a valid two-block run's, measured in
the same run. `run_limited` and `corpus` are shared with it.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

HOSTILE = Path(__file__).parent / "hostile"
GAITS = Path(__file__).resolve().parents[1] / "gaits"
# 1 GiB: the compiled kernel's LLVM (numba) maps about 300 MB of address space before any work,
# and OpenBLAS's thread buffers come on top of it
LIMIT_BYTES = 1 << 30
#: Seconds after which a child is killed: a hang guard, never a speed requirement.
HANG_GUARD = 300.0

#: file -> a phrase of crawlsim's own refusal (the key, or what crawlsim's YAML guard says),
#: never another library's wording: PyYAML and Python change theirs between releases (PyYAML
#: 6.0.3 refuses deep nesting itself, with its own words, before crawlsim's guard would)
EXPECTED = {
    "alias-bomb.yaml": "once its aliases are expanded",
    "alias-bomb-description.yaml": "once its aliases are expanded",
    "amplitude-inf.yaml": "links[0].amplitude: expected a finite number",
    "blocks-10e12.yaml": "blocks: expected an integer from 2 to 100,000",
    "blocks-1e308.yaml": "blocks: expected a number of magnitude at most",
    "forward-1e-308.yaml": "friction: uniqueness condition violated: for J = {1, 2, 3}",
    "integer-5000-digits.yaml": "an integer of 5,000 digits; at most 4,300 are read",
    "mean-1e200.yaml": "links[0].mean: expected a number of magnitude at most",
    "nested-1000.yaml": "nesting deeper than 32 levels",
    "nested-block-100.yaml": "nesting deeper than 32 levels",
    "period-1e308.yaml": "period: expected a number of magnitude at most",
    "phase-1e308.yaml": "links[0].phase: expected a number of magnitude at most",
    "recursive-alias.yaml": "recursive alias",
    "steps-1e9.yaml": "simulation.steps_per_period: expected an integer from 1 to 100,000,000",
    "stiffness-wide.yaml": "stiffness: the stiffness ratio k_max / k_min = 1e+16",
    "wave-21.yaml": "friction: uniqueness condition violated: for J = {1, 2, 3, 4, 5, 6, 7, 8, 9, "
    "10, 11, 12, 13, 14} (forward) and the rest {15, 16, 17, 18, 19, 20, 21}",
    "wave-30.yaml": "(forward) and the rest {21, 22, 23, 24, 25, 26, 27, 28, 29, 30} (backward)",
    "wave-60.yaml": "(forward) and the rest {41, 42, 43, 44, 45, 46, 47, 48, 49, 50, 51, 52, 53, 54, "
    "55, 56, 57, 58, 59, 60} (backward)",
    "wave-120.yaml": "uniqueness condition violated: for J = {1, 2, 3",
    # made at run time
    "huge-file.yaml": "is larger than 1,048,576 bytes",
    "fourier-100000.yaml": "links[0].cos: expected at most 1,000 entries",
    "steps-1e7.yaml": "more than the memory limit",
    "/dev/zero": "is a device, not a gait file",
    "fifo-endless.yaml": "is larger than 1,048,576 bytes",
    "fifo-no-writer.yaml": "the document is empty",
}

GAIT_TAIL = "period: 1.0\nstiffness: 10.0\nfriction: {forward: 1.0, backward: 2.0}\n"


def corpus(folder: Path) -> list[tuple[str, Path]]:
    """(name, path) of every hostile file, the generated ones written into ``folder``."""
    files = [(p.name, p) for p in sorted(HOSTILE.glob("*.yaml"))]
    made = {
        "huge-file.yaml": "description: '" + "x" * (1 << 20) + "'\n",
        "fourier-100000.yaml": "blocks: 2\n"
        + GAIT_TAIL
        + "links: [{kind: fourier, mean: 1.0, cos: ["
        + ",".join(["0"] * 100_000)
        + "]}]\n",
        "steps-1e7.yaml": "blocks: 4\n" + GAIT_TAIL + "links: [{kind: cosine, mean: 1.0, amplitude: "
        "0.3}, 1.0, 1.0]\nsimulation: {steps_per_period: 10000000}\n",
        "blocks-10000.yaml": "blocks: 10000\n"
        + GAIT_TAIL.replace("backward: 2.0", "backward: 2.5")
        + "links: ["
        + ",".join(["1.0"] * 9999)
        + "]\nsimulation: {steps_per_period: 10, max_periods: 3}\n",
    }
    for name, text in made.items():
        path = folder / name
        path.write_text(text)
        if name in EXPECTED:
            files.append((name, path))
    files.append(("/dev/zero", Path("/dev/zero")))
    for name in ("fifo-endless.yaml", "fifo-no-writer.yaml"):
        path = folder / name
        os.mkfifo(path)
        files.append((name, path))
    return files


def _limit():
    resource.setrlimit(resource.RLIMIT_AS, (LIMIT_BYTES, LIMIT_BYTES))


def _endless_writer(path: Path, stop: threading.Event):
    """Write to a FIFO until the reader goes away (it stops after its size limit)."""
    try:
        with open(path, "wb") as fifo:
            chunk = b"# " + b"x" * 65533 + b"\n"
            while not stop.is_set():
                fifo.write(chunk)
    except (BrokenPipeError, OSError):
        pass


def run_limited(args: list[str], cwd: Path, timeout: float = HANG_GUARD) -> dict:
    """Run ``python -m crawlsim ARGS`` under RLIMIT_AS = 1 GiB; exit code, seconds, peak RSS
    (from wait4, in bytes), stdout and stderr."""
    out, err = cwd / ".stdout", cwd / ".stderr"
    with open(out, "w") as o, open(err, "w") as e:
        began = time.perf_counter()
        child = subprocess.Popen(
            [sys.executable, "-m", "crawlsim", *args],
            cwd=cwd,
            stdout=o,
            stderr=e,
            stdin=subprocess.DEVNULL,
            preexec_fn=_limit,
        )
        while True:
            pid, status, usage = os.wait4(child.pid, os.WNOHANG)
            if pid:
                break
            if time.perf_counter() - began > timeout:
                child.kill()
                pid, status, usage = os.wait4(child.pid, 0)
                break
            time.sleep(0.01)
        seconds = time.perf_counter() - began
    child.returncode = os.waitstatus_to_exitcode(status)
    return {
        "code": child.returncode,
        "seconds": seconds,
        "peak": usage.ru_maxrss * 1024,
        "stdout": out.read_text(),
        "stderr": err.read_text(),
    }


def run_hostile(name: str, path: Path, cwd: Path) -> dict:
    stop = threading.Event()
    writer = None
    if name == "fifo-endless.yaml":
        writer = threading.Thread(target=_endless_writer, args=(path, stop), daemon=True)
        writer.start()
    try:
        return run_limited(["run", str(path), "-o", "out.h5"], cwd)
    finally:
        stop.set()
        if writer is not None:
            try:  # unblock a writer still waiting for a reader
                os.close(os.open(path, os.O_RDONLY | os.O_NONBLOCK))
            except OSError:
                pass
            writer.join(5)


@pytest.fixture(scope="module")
def hostile_files(tmp_path_factory):
    return corpus(tmp_path_factory.mktemp("made"))


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_hostile_file_is_refused_cleanly(name, hostile_files, tmp_path):
    path = dict(hostile_files)[name]
    result = run_hostile(name, path, tmp_path)
    message = result["stderr"].strip()
    assert result["code"] == 2, (name, result)
    assert "Traceback" not in result["stderr"] + result["stdout"]
    assert len(message.splitlines()) == 1, message
    assert message.startswith(f"Error: {path}"), message
    assert EXPECTED[name] in message, message
    assert result["peak"] < LIMIT_BYTES
    assert not (tmp_path / "out.h5").exists()
    assert not list(tmp_path.glob(".out.h5*"))


def test_the_corpus_is_complete(hostile_files):
    assert sorted(name for name, _ in hostile_files) == sorted(EXPECTED)


@pytest.mark.slow  # a 10,000-block run
def test_ten_thousand_blocks_run_within_their_own_estimate(tmp_path_factory, tmp_path):
    """blocks: 10000 is a valid request: with the O(N) chain kernel it runs under the corpus's
    1 GiB address-space limit, and the memory it needs beyond an interpreter's
    (a two-block run's peak) stays within the estimate made before it started."""
    from crawlsim.gait.document import load_gait
    from crawlsim.integrate.resources import gait_memory

    folder = tmp_path_factory.mktemp("valid")
    path = folder / "blocks-10000.yaml"
    path.write_text(
        "blocks: 10000\n"
        + GAIT_TAIL.replace("backward: 2.0", "backward: 2.5")
        + "links: ["
        + ",".join(["1.0"] * 9999)
        + "]\nsimulation: {steps_per_period: 10, max_periods: 3}\n"
    )
    big = run_limited(["run", str(path), "-o", "out.h5"], tmp_path)
    assert big["code"] == 0, big
    assert "Traceback" not in big["stderr"]
    assert big["peak"] < LIMIT_BYTES
    small = run_limited(["run", str(GAITS / "inching-2.yaml"), "-o", "small.h5"], tmp_path)
    assert small["code"] == 0, small
    estimate = gait_memory(load_gait(path))
    assert big["peak"] - small["peak"] <= estimate.total, (big["peak"], small["peak"], estimate)
