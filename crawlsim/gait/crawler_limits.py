"""The limits of double precision on a crawler's numbers: how wide its stiffnesses may range and
how stiff its links may be for its friction, for a step to be certified to roundoff
(docs/model.md §3).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from crawlsim.errors import GaitError
from crawlsim.gait.signals import Constant, Cosine, Fourier, Signal

STRESS_SCALE_LIMIT = 1e10
"""Largest stress scale max_i k_i |L_i| / min_j mu_j of a crawler (`stress_scale`). The offsets
c = [mu+ - D^T K L; mu- + D^T K L] hold the friction next to elastic forces that many times
larger, so in double precision (and under certificate tolerances of 1e-14 of |c|) the friction
is resolved only to about 1e-14 times this ratio of itself: at 1e12 the decisions of which block
slips err by a quarter of the friction, and v0 by many times its estimate (a two-block inching
gait, v0 = 0.6 - 2/k: 19x its estimate at k = 1e12; a Clarabel failure at 1e18). Up to 1e10
both integrators give the closed form to roundoff (tests/test_certificates.py)."""

STIFFNESS_CONDITION_LIMIT = 1e12
"""Largest estimated condition number (k_max / k_min) N^2 of the active-set Gram matrices
G_A = B_A K B_A^T. Beyond it an exact step cannot be certified in double precision: the
multipliers (the slips) would carry errors far above the certificates' roundoff tolerance."""


def stiffness_condition(stiffness: np.ndarray) -> float:
    """Estimated condition number (k_max / k_min) N^2 of the active-set Gram matrices.

    G_A = B_A K B_A^T with B = [D^T; -D^T]: its eigenvalues lie between k_min times those of
    B_A B_A^T and k_max times them, and those of D D^T (the path Laplacian of N blocks) span
    4 sin^2(pi/2N) ~ (pi/N)^2 to 4, so cond(G_A) <= (k_max / k_min) (2N/pi)^2 < (k_max/k_min) N^2.
    """
    k = np.asarray(stiffness, dtype=float)
    return float(np.max(k) / np.min(k)) * float(len(k) + 1) ** 2


def check_stiffness(k: np.ndarray, source: str) -> None:
    estimate = stiffness_condition(k)
    if estimate > STIFFNESS_CONDITION_LIMIT:
        ratio = float(np.max(k) / np.min(k))
        raise GaitError(
            source,
            "stiffness",
            f"the stiffness ratio k_max / k_min = {ratio:.3g} is too wide for "
            f"N = {len(k) + 1} blocks: a step's Gram matrices would have an estimated "
            f"condition number (k_max / k_min) N^2 = {estimate:.3g}, above the "
            f"{STIFFNESS_CONDITION_LIMIT:g} at which a step can still be certified in "
            "double precision (docs/model.md §3). Narrow the range of the stiffnesses "
            "(only their ratio matters for conditioning).",
        )


def _largest(signal: Signal) -> float:
    """A bound of max_t |s(t)| from the signal's coefficients (its mean and amplitudes, or its
    knot values)."""
    if isinstance(signal, Constant):
        return abs(signal.value)
    if isinstance(signal, Cosine):
        return abs(signal.mean) + abs(signal.amplitude)
    if isinstance(signal, Fourier):
        return abs(signal.mean) + float(np.sum(np.abs(signal.cos)) + np.sum(np.abs(signal.sin)))
    values = getattr(signal, "values", None)
    return float(np.max(np.abs(values))) if values is not None else float("inf")


def stress_scale(
    stiffness: np.ndarray, links: Sequence[Signal], initial_positions: np.ndarray, friction: Sequence[Signal]
) -> float:
    """max_i k_i max(|L_i(t)|, |z_i(0)|) / min_j min_t min(mu+_j(t), mu-_j(t)): how many times
    the largest elastic force of the offsets exceeds the smallest friction (`STRESS_SCALE_LIMIT`).
    Dimensionless: a change of units leaves it alone. ``friction`` holds every mu^+ and mu^-."""
    k = np.asarray(stiffness, dtype=float)
    lengths = np.array([_largest(s) for s in links])
    z0 = np.abs(np.diff(np.asarray(initial_positions, dtype=float)))
    force = float(np.max(k * np.maximum(lengths, z0)))
    least = min(s.minimum()[0] for s in friction)
    return force / least if least > 0 else float("inf")


def check_stress_scale(
    stiffness: np.ndarray,
    links: Sequence[Signal],
    initial_positions: np.ndarray,
    friction: Sequence[Signal],
    source: str,
) -> None:
    """Refuse links too stiff for the friction (`stress_scale` above `STRESS_SCALE_LIMIT`)."""
    ratio = stress_scale(stiffness, links, initial_positions, friction)
    if ratio > STRESS_SCALE_LIMIT:
        k = np.asarray(stiffness, dtype=float)
        raise GaitError(
            source,
            "stiffness",
            f"the links are too stiff for this friction: the largest elastic force "
            f"k L is {ratio:.3g} times the smallest friction, above the "
            f"{STRESS_SCALE_LIMIT:g} that crawlsim supports. In double precision the "
            f"friction would be resolved only to about {1e-14 * ratio:.1g} of itself, "
            "so which blocks slip, and v0, could be wrong beyond their error "
            "estimate. Lower the stiffness (here up to "
            f"{float(np.max(k)) * STRESS_SCALE_LIMIT / ratio:.3g}), or raise the "
            "friction (the ratio does not depend on the units)",
        )
