"""Gradient-based gait design: maximise v0 in a box of gait parameters with the exact
sensitivities of `crawlsim.sensitivity` (docs/sensitivity.md).

The method: a coarse sample of the box (``sample`` points per free parameter, a grid, or a Latin
hypercube when the grid would be large; each a run of v0 alone), then L-BFGS-B
(`scipy.optimize.minimize`, bounds = the box) from the best ``restarts`` sample points, each
step one evaluation of v0 with its gradient at the gait's integrator's verified limit. v0 is
only piecewise smooth: at a kink the gradient used is the derivative on the limit period's own
pieces (one element of the generalized gradient), and the restarts from distinct sample points
keep one kink from ending the search. A free path with ``*`` ties every element to one value,
so its derivative is the sum over the elements.

``crawlsim optimize --method gradient`` runs it (maximise v0 in a box; no constraints, Pareto
front or results file yet).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from crawlsim.errors import CrawlsimError
from crawlsim.gait.document import Gait

#: The largest coarse grid; beyond, the sample is a Latin hypercube.
GRID_POINTS = 64


def _sample(lo: np.ndarray, hi: np.ndarray, sample: int, seed: int) -> list[np.ndarray]:
    n = len(lo)
    if sample ** n <= GRID_POINTS:
        axes = [np.linspace(a, b, sample) for a, b in zip(lo, hi)]
        return [np.array(corner) for corner in itertools.product(*axes)]
    from scipy.stats import qmc

    unit = qmc.LatinHypercube(d=n, seed=seed).random(sample * n)
    return [lo + u * (hi - lo) for u in unit]


@dataclass(frozen=True)
class GradientResult:
    """The best point found, its v0, and what the search cost."""

    x: tuple[float, ...]
    v0: float
    evaluations: int  # v0 runs: sample points plus gradient evaluations
    gradient_evaluations: int
    history: tuple[float, ...]  # best v0 after each evaluation


def optimize_gradient(gait: Gait, free: Sequence[tuple[str, float, float]], *,
                      sample: int = 4, restarts: int = 2, max_evaluations: int = 200,
                      gtol: float = 1e-10, stall: int = 8, seed: int = 0) -> GradientResult:
    """Maximise v0 over the box ``free`` = [(path, lo, hi), ...] (module docstring). The
    sample is the grid of ``sample`` points per parameter while it has at most `GRID_POINTS`
    points, else a Latin hypercube of ``sample * n`` points seeded by ``seed``. A restart
    ends when L-BFGS-B converges or when ``stall`` evaluations in a row improve its best v0 by
    less than 1e-13 relative (a line search stuck on a kink)."""
    from scipy.optimize import minimize

    from crawlsim.analysis.sensitivity import sensitivity
    from crawlsim.study.simulation import run

    paths = [f[0] for f in free]
    lo = np.array([f[1] for f in free], dtype=float)
    hi = np.array([f[2] for f in free], dtype=float)
    count = 0
    grads = 0
    best = (-math.inf, tuple(lo))
    history: list[float] = []

    def moved(x: np.ndarray) -> Gait:
        g = gait.replace({p: float(v) for p, v in zip(paths, x)})
        assert isinstance(g, Gait)
        return g

    def note(x: np.ndarray, v0: float) -> None:
        nonlocal best, count
        count += 1
        if v0 > best[0]:
            best = (v0, tuple(float(v) for v in x))
        history.append(best[0])

    samples = []
    for x in _sample(lo, hi, sample, seed):
        try:
            v0 = run(moved(x), history=False).v0
        except CrawlsimError:
            note(x, -math.inf)
            continue
        assert v0 is not None
        note(x, v0)
        samples.append((v0, x))
    samples.sort(key=lambda s: -s[0])

    class Budget(Exception):
        pass

    run_best = [-math.inf, 0]  # this restart's best v0, evaluations since it improved

    def fun(x: np.ndarray) -> tuple[float, np.ndarray]:
        nonlocal grads
        if count >= max_evaluations or run_best[1] >= stall:
            raise Budget
        x = np.clip(x, lo, hi)
        try:
            r = sensitivity(moved(x), paths, one_sided=False)
        except CrawlsimError:
            note(x, -math.inf)
            return math.inf, np.zeros(len(x))
        grads += 1
        note(x, r.v0)
        if r.v0 > run_best[0] + 1e-13 * max(abs(run_best[0]), 1e-300):
            run_best[:] = [r.v0, 0]
        else:
            run_best[1] += 1
        grad = np.zeros(len(x))
        for i, path in enumerate(paths):
            prefix = path.split(".")
            for p in r.parameters:
                parts = p.path.split(".")
                if len(parts) == len(prefix) and all(a in ("*", b) for a, b in
                                                     zip(prefix, parts)):
                    grad[i] += p.v0_on_pieces or 0.0
        return -r.v0, -grad

    for _, x0 in samples[:restarts]:
        run_best[:] = [-math.inf, 0]
        if count >= max_evaluations:
            break
        try:
            minimize(fun, x0, jac=True, method="L-BFGS-B", bounds=list(zip(lo, hi)),
                     options={"gtol": gtol, "ftol": 1e-15, "maxiter": 100})
        except Budget:
            continue
    return GradientResult(best[1], best[0], count, grads, tuple(history))
