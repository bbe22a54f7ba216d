"""Shared fixtures: the example gaits and small helpers to build gaits in tests.

Hypothesis profiles: ``ci`` (the default) is derandomized, so the suite is the same on every
machine and every run; ``explore`` draws fresh examples and more of them. Search with, say,
``HYPOTHESIS_PROFILE=explore python -m pytest tests --hypothesis-seed=7``, and keep every
counterexample found as an ``@example``.
"""

import os
import sys
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, settings

from crawlsim.gait.document import parse_gait

settings.register_profile(
    "ci", derandomize=True, database=None, deadline=None, print_blob=True, suppress_health_check=[HealthCheck.too_slow]
)
# "seeded": Hypothesis's own example count, drawn from --hypothesis-seed (the check that the
# suite holds under any seed: pytest --hypothesis-seed=N with HYPOTHESIS_PROFILE=seeded)
settings.register_profile(
    "seeded", derandomize=False, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow]
)
settings.register_profile(
    "explore", derandomize=False, deadline=None, max_examples=400, suppress_health_check=[HealthCheck.too_slow]
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


ROOT = Path(__file__).resolve().parents[1]
GAITS = ROOT / "gaits"
#: Example gaits whose iterates settle only slowly (earthworm-100 contracts by 0.995 a period,
#: about 5,500 periods to 1e-12), so their periodic limit comes from the solver: the tests that
#: iterate every example period by period leave them out, and tests/test_earthworm.py runs them.
SOLVER_GAITS = frozenset({"earthworm-100"})


def iterated_examples() -> list[Path]:
    """The example gaits of gaits/ (top level) that converge by iteration in seconds."""
    return sorted(p for p in GAITS.glob("*.yaml") if p.stem not in SOLVER_GAITS)


def make_gait(doc: dict, source: str = "<test>"):
    """A validated gait from a Python mapping (the same path as a file)."""
    return parse_gait(yaml.safe_dump(doc), source=source)


def two_block(amplitude=0.3, k=10.0, friction=None, steps=200, max_periods=20, **extra):
    """Two blocks, one link L(t) = 1 + amplitude cos(2 pi t / T)."""
    doc = {
        "blocks": 2,
        "period": 1.0,
        "stiffness": k,
        "links": [{"kind": "cosine", "mean": 1.0, "amplitude": amplitude}],
        "friction": friction or {"forward": 1.0, "backward": 2.0},
        "simulation": {"steps_per_period": steps, "max_periods": max_periods},
    }
    doc.update(extra)
    return make_gait(doc)


def console_env(env: dict[str, str] | None = None) -> dict[str, str]:
    """The environment (``os.environ`` by default) of a subprocess that calls ``crawlsim`` from
    PATH (the scripts of scripts/, documented commands): the console scripts of this
    interpreter's environment first, so that ``venv/bin/python -m pytest tests`` needs no
    activated venv and runs its own crawlsim."""
    env = dict(os.environ if env is None else env)
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    return env


@pytest.fixture
def gaits_dir():
    return GAITS


def pytest_sessionfinish(session, exitstatus):
    """No stray process after the tests: a background compile of the kernel (`crawlsim warmup
    --background`, started by a long run on a cold cache) that is still running is stopped; the
    functions it finished stay in numba's cache."""
    import signal

    from crawlsim.kernel import jit

    lock = jit.stamp().with_suffix(".lock")
    try:
        os.killpg(int(lock.read_text()), signal.SIGTERM)
    except (OSError, ValueError):
        pass
    background = jit._state["background"]
    if background is not None and background.poll() is None:
        os.killpg(background.pid, signal.SIGTERM)
        background.wait()
