"""The kernel's two forms (`crawlsim.kernel.jit`): every command's path gives the same bits
interpreted and compiled, a small answer never loads numba, a long one switches to the compiled
kernel, and after ``crawlsim warmup`` nothing compiles.

The kernel is loops of IEEE arithmetic in a fixed order (no fast-math; numpy's reductions and
BLAS are not called from it, and math.hypot, which numba implements differently, is not used), so
the two forms must agree to the last bit, and a run may change form between periods.
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import crawlsim
from crawlsim.kernel import jit

ROOT = Path(__file__).resolve().parents[1]
GAITS = ROOT / "gaits"
TIMING = {"wall_time", "elapsed", "time"}


def _same(a, b, where: str) -> None:
    """a == b to the bit: numbers, arrays, and nested dicts and lists of them."""
    if isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for key in a:
            if key not in TIMING:
                _same(a[key], b[key], f"{where}.{key}")
    elif isinstance(a, list | tuple) and not isinstance(a, str):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, f"{where}[{i}]")
    elif isinstance(a, np.ndarray):
        np.testing.assert_array_equal(a, b, err_msg=where)
    elif isinstance(a, float) and math.isnan(a):
        assert isinstance(b, float) and math.isnan(b), where
    else:
        assert a == b, where


def _run(name: str, integrator: str):
    result = crawlsim.simulate(crawlsim.load_gait(GAITS / name).replace("simulation.integrator", integrator))
    return result.summary(), result.trajectory.columns() if result.trajectory else None


def _sensitivity(name: str, integrator: str):
    gait = crawlsim.load_gait(GAITS / name).replace("simulation.integrator", integrator)
    return crawlsim.sensitivity(gait, ["stiffness", "friction.forward", "links.*.phase"]).summary()


def _stall(name: str, integrator: str):
    from crawlsim.design.stall import stall

    gait = crawlsim.load_gait(GAITS / name).replace("simulation.integrator", integrator)
    return stall(gait, slope=True).summary()


def _sweep(name: str, integrator: str):
    gait = crawlsim.load_gait(GAITS / name).replace("simulation.integrator", integrator)
    table = crawlsim.sweep(gait, {"links.0.amplitude": [0.1, 0.2, 0.3]})
    return {name: np.asarray(table[name].values) for name in table.data_vars}


PATHS = [
    (_run, "peristalsis-4.yaml", "exact"),
    (_run, "peristalsis-4.yaml", "catch-up"),
    (_run, "anchoring-2.yaml", "exact"),  # steps: jumps
    (_run, "smooth-friction-3.yaml", "exact"),  # Fourier links: certified sampling
    (_run, "climbing-3.yaml", "catch-up"),  # a slope
    (_run, "inching-2-towing.yaml", "exact"),  # a force
    (_run, "paper/triangle.yaml", "exact"),  # a generic process, Newton
    (_run, "paper/acute-angle.yaml", "catch-up"),
    (_sensitivity, "peristalsis-4.yaml", "exact"),
    (_sensitivity, "peristalsis-4.yaml", "catch-up"),
    (_stall, "climbing-3.yaml", "exact"),
    (_sweep, "peristalsis-4.yaml", "exact"),
    (_run, "terrain/patch-4.yaml", "exact"),  # terrain: boundaries, holds and slides
    (_run, "terrain/step-up-2.yaml", "catch-up"),  # terrain: the factors at each step's start
]


@pytest.mark.parametrize("path, gait, integrator", PATHS, ids=[f"{p.__name__[1:]}-{g}-{i}" for p, g, i in PATHS])
def test_interpreted_and_compiled_give_the_same_bits(path, gait, integrator):
    with jit.forced("python"):
        interpreted = path(gait, integrator)
    with jit.forced("compiled"):
        compiled = path(gait, integrator)
    _same(interpreted, compiled, f"{path.__name__} {gait} {integrator}")


def test_a_run_may_change_form_between_periods(monkeypatch):
    """The auto form switches after `SWITCH_SECONDS` of interpreted work (here at once): the run
    that started interpreted ends compiled, with the bits of a run in either form alone."""
    gait = crawlsim.load_gait(GAITS / "peristalsis-4.yaml").replace("simulation.limit", "iterate")
    with jit.forced("python"):
        alone = crawlsim.simulate(gait).summary()
    jit.compiled()  # in the cache from here on, as the stamp says in a real switch
    monkeypatch.setattr(jit, "ready", lambda: True)
    monkeypatch.setattr(jit, "SWITCH_SECONDS", 0.0)
    calls = []
    getattr_ = jit.World.__getattr__

    def counting(world, name):
        calls.append(world.compiled)
        return getattr_(world, name)

    monkeypatch.setattr(jit.World, "__getattr__", counting)
    with jit.forced("auto"):
        monkeypatch.setitem(jit._state, "started", None)
        monkeypatch.setattr(jit, "_compiled", None)
        mixed = crawlsim.simulate(gait).summary()
    assert calls[0] is False and calls[-1] is True, calls
    _same(alone, mixed, "switched run")


def _crawlsim(*args: str, cache: Path | None = None, **env: str) -> subprocess.CompletedProcess:
    """``crawlsim ARGS`` in a fresh interpreter (with ``-X importtime``), on ``cache`` (None: this
    session's numba cache)."""
    environment = {k: v for k, v in os.environ.items() if k not in ("NUMBA_DISABLE_JIT", "CRAWLSIM_KERNEL")}
    environment.update(env)
    if cache is not None:
        environment["NUMBA_CACHE_DIR"] = str(cache)
    return subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "crawlsim", *args],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=environment,
        timeout=600,
    )


def _imported(stderr: str, module: str) -> bool:
    return any(line.rstrip().endswith(f"| {module}") for line in stderr.splitlines())


def test_a_small_answer_on_an_empty_cache_loads_no_numba(tmp_path):
    """The README's first command on a fresh install: the answer, no compile, no numba, no
    background compile (the run is shorter than `SWITCH_SECONDS`)."""
    done = _crawlsim("run", "gaits/peristalsis-4.yaml", "-o", str(tmp_path / "r.h5"), cache=tmp_path / "cache")
    assert done.returncode == 0, done.stderr
    assert "v0                       0.3711554676647" in done.stdout
    assert not _imported(done.stderr, "numba") and "compiling" not in done.stderr
    assert not (tmp_path / "cache").exists() or not any((tmp_path / "cache").rglob("*.nbi"))


def test_a_long_answer_starts_one_background_compile(tmp_path):
    """Past `SWITCH_SECONDS` of interpreted work on an empty cache, `crawlsim warmup --background`
    starts (it takes the cache's lock at once); the run itself goes on interpreted. The compile is
    stopped here: its result is the warmup test's."""
    cache = tmp_path / "cache"
    code = (
        "import crawlsim, time\n"
        "from crawlsim.kernel import jit\n"
        "jit.SWITCH_SECONDS = 0.0\n"
        "g = crawlsim.load_gait('gaits/peristalsis-4.yaml')\n"
        "crawlsim.simulate(g); crawlsim.simulate(g)\n"
        "p = jit._state['background']\n"
        "lock = jit.stamp().with_suffix('.lock')\n"
        "for _ in range(600):\n"
        "    if lock.exists() or p.poll() is not None: break\n"
        "    time.sleep(0.05)\n"
        "print(p.args, lock.exists(), jit._compiled is None)\n"
        "import os, signal; os.killpg(p.pid, signal.SIGKILL); p.wait()\n"
    )
    environment = {k: v for k, v in os.environ.items() if k not in ("NUMBA_DISABLE_JIT", "CRAWLSIM_KERNEL")}
    done = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env={**environment, "NUMBA_CACHE_DIR": str(cache)},
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.split("]")[1].split() == ["True", "True"], done.stdout
    assert "'warmup', '--background'" in done.stdout


def test_no_background_compile_when_turned_off(tmp_path):
    code = (
        "import crawlsim\nfrom crawlsim.kernel import jit\njit.SWITCH_SECONDS = 0.0\n"
        "g = crawlsim.load_gait('gaits/peristalsis-4.yaml')\ncrawlsim.simulate(g); crawlsim.simulate(g)\n"
        "print(jit._state['background'], jit._compiled)\n"
    )
    environment = {k: v for k, v in os.environ.items() if k not in ("NUMBA_DISABLE_JIT", "CRAWLSIM_KERNEL")}
    environment.update(NUMBA_CACHE_DIR=str(tmp_path / "cache"), CRAWLSIM_BACKGROUND_COMPILE="0")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, env=environment)
    assert done.returncode == 0 and done.stdout.split() == ["None", "None"], done.stdout + done.stderr


@pytest.mark.slow
def test_after_warmup_nothing_compiles(tmp_path):
    """`crawlsim warmup` compiles every path, once: afterwards each command in the compiled form
    loads the kernel from the cache and prints no compile line. The cache starts empty, as a new
    user's: a cache that earlier tests filled would hide an entry point warmup misses (the
    triangle's linear closed form was one).

    Warmup's processes compile the crawlsim that started them, whose sources numba caches apart
    from any other copy's: here a copy that shadows the installed one (as a checkout does for
    ``python -m pytest``, or a user working inside it), and, afterwards, a folder holding a
    ``crawlsim/`` that is not the one running (``-m`` would put it first)."""
    copy = tmp_path / "copy"
    shutil.copytree(ROOT / "crawlsim", copy / "crawlsim", ignore=shutil.ignore_patterns("__pycache__"))
    cache = tmp_path / "cache"
    environment = {k: v for k, v in os.environ.items() if k not in ("NUMBA_DISABLE_JIT", "CRAWLSIM_KERNEL")}
    environment["NUMBA_CACHE_DIR"] = str(cache)

    def crawlsim_in(folder: Path, *args: str, **env: str) -> subprocess.CompletedProcess:
        argv = [sys.executable, "-X", "importtime", "-m", "crawlsim", *args]
        return subprocess.run(argv, capture_output=True, text=True, cwd=folder, env={**environment, **env}, timeout=600)

    done = crawlsim_in(copy, "warmup")
    assert done.returncode == 0, done.stderr
    assert "the kernel is compiled" in done.stdout
    assert (cache / jit.stamp().name).exists()
    commands = [
        ["velocity", "gaits/peristalsis-4.yaml"],
        ["velocity", "gaits/peristalsis-4.yaml", "--integrator", "catch-up"],
        ["velocity", "gaits/peristalsis-4.yaml", "--sensitivity", "stiffness", "--sensitivity", "links.*.phase"],
        ["velocity", "gaits/inching-2.yaml", "--integrator", "catch-up", "--sensitivity", "friction.forward"],
        ["velocity", "gaits/smooth-friction-3.yaml"],
        ["velocity", "gaits/anchoring-2.yaml"],
        ["stall", "gaits/inching-2-towing.yaml", "--force", "loads.force.0"],
        ["stall", "gaits/climbing-3.yaml", "--slope"],
        ["run", "gaits/paper/triangle.yaml", "-o", str(tmp_path / "t.h5")],
        ["velocity", "gaits/terrain/patch-4.yaml"],
        ["velocity", "gaits/terrain/patch-4.yaml", "--integrator", "catch-up"],
        ["run", "gaits/terrain/step-up-2.yaml", "-o", str(tmp_path / "s.h5")],
    ]
    for args in commands:
        absolute = [str(ROOT / a) if a.startswith("gaits/") else a for a in args]
        done = crawlsim_in(copy, *absolute, CRAWLSIM_KERNEL="compiled")
        assert done.returncode == 0, (args, done.stderr)
        assert _imported(done.stderr, "numba"), args
        assert "compiling the kernel" not in done.stderr, args
    decoy = tmp_path / "checkout"
    (decoy / "crawlsim").mkdir(parents=True)
    (decoy / "crawlsim" / "__init__.py").write_text("raise SystemExit(5)\n")
    argv = [sys.executable, "-P", "-m", "crawlsim", "warmup"]
    done = subprocess.run(argv, capture_output=True, text=True, cwd=decoy, env={**environment, "PYTHONPATH": str(copy)})
    assert done.returncode == 0, done.stderr
