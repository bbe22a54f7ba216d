"""Seeded random valid gaits: the corpus that tests and `scripts/random-gait-corpus.py` run.

Every gait of the corpus is a valid gait file document (it passes `crawlsim.gait.document` validation):
N blocks with per-link stiffness (ratios up to ``stiffness_ratio``), actuated by signals of
every kind (constant, cosine, fourier, piecewise-linear, steps), and friction per block or
shared, constant, smoothly time-varying or switched by ``steps`` signals, with forward/backward
ratios between ``1 / friction_ratio`` and ``friction_ratio``. The initial state is the default
one (stress-free at t = 0, or with loads the held start of docs/model.md §6). Seeds make the
corpus reproducible. ``loads=True`` adds random loads (docs/model.md §6) drawn after everything
else, so the gait is the same one with loads on top: forces of every kind on some blocks, up to
a multiple of their friction (a block may be held by its links alone), and a slope of up to 30
degrees either way; a draw whose total load the body cannot hold is refused and redrawn by
`random_gait`.
"""

from __future__ import annotations

import math

import numpy as np

from crawlsim.errors import GaitError
from crawlsim.gait.crawler_limits import STIFFNESS_CONDITION_LIMIT, STRESS_SCALE_LIMIT
from crawlsim.gait.document import Gait, gait_from_document


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _link_signal(rng: np.random.Generator, mean: float, amplitude: float) -> dict | float:
    kind = rng.choice(["constant", "cosine", "cosine", "fourier", "piecewise-linear", "steps"])
    phase = float(rng.uniform(0, 1))
    if kind == "constant":
        return mean
    if kind == "cosine":
        return {"kind": "cosine", "mean": mean, "amplitude": amplitude, "phase": phase}
    if kind == "fourier":
        h = int(rng.integers(1, 4))
        scale = amplitude / h
        return {
            "kind": "fourier",
            "mean": mean,
            "cos": [float(v) for v in rng.uniform(-scale, scale, h)],
            "sin": [float(v) for v in rng.uniform(-scale, scale, h)],
            "phase": phase,
        }
    if kind == "piecewise-linear":
        knots = int(rng.integers(1, 4))
        times = sorted(float(t) for t in rng.uniform(0.05, 0.95, knots))
        values = [mean] + [mean + float(v) for v in rng.uniform(-amplitude, amplitude, knots)]
        return {"kind": "piecewise-linear", "times": [0.0, *times, 1.0], "values": [*values, mean], "phase": phase}
    steps = int(rng.integers(2, 4))
    times = [0.0, *sorted(float(t) for t in rng.uniform(0.05, 0.95, steps - 1))]
    return {
        "kind": "steps",
        "times": times,
        "values": [mean + float(v) for v in rng.uniform(-amplitude, amplitude, steps)],
        "phase": phase,
    }


def _friction_signal(rng: np.random.Generator, level: float) -> dict | float:
    kind = rng.choice(["constant", "constant", "cosine", "steps"])
    if kind == "constant":
        return level
    if kind == "cosine":
        return {
            "kind": "cosine",
            "mean": level,
            "amplitude": float(rng.uniform(0.1, 0.6)) * level,
            "phase": float(rng.uniform(0, 1)),
        }
    steps = int(rng.integers(2, 4))
    times = [0.0, *sorted(float(t) for t in rng.uniform(0.05, 0.95, steps - 1))]
    return {
        "kind": "steps",
        "times": times,
        "values": [level * _log_uniform(rng, 0.3, 3.0) for _ in range(steps)],
        "phase": float(rng.uniform(0, 1)),
    }


def _jagged_signal(rng: np.random.Generator) -> dict:
    """A piecewise-linear link of 100-1000 knots, evenly or randomly spaced, at random values
    within up to 45 % of the mean: many steep pieces whose crossings and kinks interleave."""
    knots = int(rng.integers(100, 1001))
    inner = np.sort(rng.uniform(0, 1, knots - 1)) if rng.uniform() < 0.5 else np.arange(1, knots) / knots
    drawn = 1.0 + rng.uniform(-1, 1, knots) * rng.uniform(0.1, 0.45)
    times, values = [0.0, *map(float, inner), 1.0], [*map(float, drawn), float(drawn[0])]
    return {"kind": "piecewise-linear", "times": times, "values": values, "phase": float(rng.uniform(0, 1))}


def _switched(rng: np.random.Generator, level: float, steps: int) -> dict | float:
    """``level``, or a steps signal of ``steps`` values around it."""
    if steps < 2:
        return level
    times = [0.0, *sorted(float(t) for t in rng.uniform(0.01, 0.99, steps - 1))]
    return {"kind": "steps", "times": times, "values": [level * _log_uniform(rng, 0.5, 2.0) for _ in range(steps)]}


def _rough_document(rng: np.random.Generator, N: int, friction_ratio: float) -> dict:
    """The rough classes (``random_document(rough=True)``): one to three jagged links
    (`_jagged_signal`), the others steps (2-30 values) or smooth; friction pairs constant or
    switched by steps, up to 12 distinct ones among the blocks; stiffnesses spread up to the
    accepted limits (`crawlsim.gait.crawler_limits`)."""
    jagged = set(rng.choice(N - 1, size=min(N - 1, int(rng.integers(1, 4))), replace=False).tolist())
    links = [_jagged_signal(rng) if i in jagged else _link_signal(rng, 1.0, 0.45) for i in range(N - 1)]
    for i, link in enumerate(links):
        if isinstance(link, dict) and link["kind"] == "steps":
            links[i] = _switched(rng, 1.0, int(rng.integers(2, 31)))
    mu0 = _log_uniform(rng, 0.2, 5.0)
    palette = []  # a few distinct friction pairs, shared by the blocks
    for _ in range(int(rng.integers(1, min(N, 12) + 1))):
        level = mu0 * _log_uniform(rng, 0.3, 3.0)
        sides = (level, level * _log_uniform(rng, 1 / friction_ratio, friction_ratio))
        pair = [_switched(rng, side, int(rng.integers(0, 5))) for side in sides]
        palette.append({"forward": pair[0], "backward": pair[1]})
    friction = [palette[i] for i in rng.integers(len(palette), size=N)]
    least = min(min(v["values"]) if isinstance(v, dict) else v for f in friction for v in f.values())
    spread = _log_uniform(rng, 1.0, 0.9 * STIFFNESS_CONDITION_LIMIT / N**2)
    k = _log_uniform(rng, 1.0, 100.0) * spread ** rng.uniform(0, 1, N - 1)
    k[rng.integers(N - 1)] = k.min() * spread  # the whole spread
    k *= min(1.0, 0.5 * STRESS_SCALE_LIMIT * least / (2 * k.max()))  # values <= 2 L
    return {"blocks": N, "stiffness": [float(v) for v in k], "links": links, "friction": friction}


def random_document(
    seed: int,
    *,
    blocks: tuple[int, int] = (2, 12),
    stiffness_ratio: float = 1e3,
    friction_ratio: float = 1e2,
    steps_per_period: int = 1000,
    max_periods: int = 300,
    tolerance: float = 1e-11,
    loads: bool = False,
    rough: bool = False,
) -> dict:
    """A random gait document (not yet validated) from ``seed``; ``rough``: of the rough
    classes (`_rough_document`; ``stiffness_ratio`` is then the accepted limit's)."""
    rng = np.random.default_rng(seed)
    N = int(rng.integers(blocks[0], blocks[1] + 1))
    if rough:
        simulation = {"steps_per_period": steps_per_period, "max_periods": max_periods, "tolerance": tolerance}
        period = _log_uniform(rng, 0.5, 5.0)
        return {
            "name": f"rough-{seed}",
            "period": period,
            **_rough_document(rng, N, friction_ratio),
            "simulation": simulation,
        }
    k0 = _log_uniform(rng, 1.0, 100.0)
    stiffness = [k0 * _log_uniform(rng, 1.0, stiffness_ratio) for _ in range(N - 1)]
    mu0 = _log_uniform(rng, 0.2, 5.0)
    amplitude = float(rng.uniform(0.05, 0.5))
    links = [_link_signal(rng, 1.0, amplitude * float(rng.uniform(0.3, 1.0))) for _ in range(N - 1)]
    levels: list[tuple[float, float]] = []  # (forward, backward) level of each block
    # the draws keep their order (forward signal, ratio, backward signal): a seed's gait is the
    # same as before loads existed
    if rng.uniform() < 0.3:
        forward = _friction_signal(rng, mu0)
        backward = mu0 * _log_uniform(rng, 1 / friction_ratio, friction_ratio)
        friction: dict | list = {"forward": forward, "backward": _friction_signal(rng, backward)}
        levels = [(mu0, backward)] * N
    else:
        friction = []
        for _ in range(N):
            level = mu0 * _log_uniform(rng, 0.3, 3.0)
            forward = _friction_signal(rng, level)
            backward = level * _log_uniform(rng, 1 / friction_ratio, friction_ratio)
            friction.append({"forward": forward, "backward": _friction_signal(rng, backward)})
            levels.append((level, backward))
    doc = {
        "name": f"random-{seed}",
        "blocks": N,
        "period": _log_uniform(rng, 0.5, 5.0),
        "stiffness": stiffness,
        "links": links,
        "friction": friction,
        "simulation": {"steps_per_period": steps_per_period, "max_periods": max_periods, "tolerance": tolerance},
    }
    if loads:
        doc["loads"] = _random_loads(rng, levels)
    return doc


def _random_loads(rng: np.random.Generator, levels: list[tuple[float, float]]) -> dict:
    """Forces on some blocks (constant, cosine or steps, forward or backward, up to 1.5 times the
    block's smaller friction level) and, half the time, a slope of up to 30 degrees with weights
    up to the friction levels."""
    out: dict = {}
    if rng.uniform() < 0.8:
        forces: list = []
        for forward, backward in levels:
            size = 1.5 * min(forward, backward) * float(rng.uniform(-1.0, 1.0))
            kind = rng.choice(["zero", "constant", "constant", "cosine", "steps"])
            if kind == "zero":
                forces.append(0.0)
            elif kind == "constant":
                forces.append(size)
            elif kind == "cosine":
                forces.append(
                    {"kind": "cosine", "mean": size / 2, "amplitude": size / 2, "phase": float(rng.uniform(0, 1))}
                )
            else:
                forces.append(
                    {
                        "kind": "steps",
                        "times": [0.0, float(rng.uniform(0.1, 0.9))],
                        "values": [size, float(rng.uniform(-0.5, 0.5)) * size],
                    }
                )
        out["force"] = forces
    if not out or rng.uniform() < 0.5:
        out["slope"] = {
            "angle": float(rng.uniform(-30.0, 30.0)),
            "weight": [float(rng.uniform(0.0, 1.0)) * min(f, b) for f, b in levels],
        }
    return out


def random_gait(seed: int, **options) -> Gait:
    """The first valid gait from seeds ``seed``, ``seed + 10**6``, ... (a random document is
    occasionally refused, for instance by the uniqueness condition)."""
    for attempt in range(100):
        doc = random_document(seed + attempt * 10**6, **options)
        try:
            gait = gait_from_document(doc, f"random gait {seed}", default_name=doc["name"])
        except GaitError:
            continue
        assert isinstance(gait, Gait)
        return gait
    raise RuntimeError(f"no valid random gait from seed {seed}")  # pragma: no cover
