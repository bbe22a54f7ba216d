"""Shared fixtures: the example gaits and small helpers to build gaits in tests."""

from pathlib import Path

import pytest
import yaml

from crawlsim.gait import parse_gait

ROOT = Path(__file__).resolve().parents[1]
GAITS = ROOT / "gaits"


def make_gait(doc: dict, source: str = "<test>"):
    """A validated gait from a Python mapping (the same path as a file)."""
    return parse_gait(yaml.safe_dump(doc), source=source)


def two_block(amplitude=0.3, k=10.0, friction=None, steps=200, max_periods=20, **extra):
    """Two blocks, one link L(t) = 1 + amplitude cos(2 pi t / T)."""
    doc = {
        "blocks": 2, "period": 1.0, "stiffness": k,
        "links": [{"kind": "cosine", "mean": 1.0, "amplitude": amplitude}],
        "friction": friction or {"forward": 1.0, "backward": 2.0},
        "simulation": {"steps_per_period": steps, "max_periods": max_periods},
    }
    doc.update(extra)
    return make_gait(doc)


@pytest.fixture
def gaits_dir():
    return GAITS
