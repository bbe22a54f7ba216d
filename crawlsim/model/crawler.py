"""The crawler of a compiled process: its stress, shape, block forces, stress bounds and
dissipation, computed in one place (docs/model.md §1-§3, §6).

A crawler of N blocks with link stiffnesses K = diag(k_i) moves in the variable w = -K z
(z = D x the shape, docs/model.md §2), so that

    z = -K^{-1} w,            sigma = K (L(t) - z) = w + K L(t),        f = D^T sigma,

with (D^T v)_j = v_{j-1} - v_j and v_0 = v_N = 0. The 2N multipliers lambda = [lambda^+ ;
lambda^-] of a step are the block slips dx = lambda^+ - lambda^- (§3), each paid at its friction
threshold: the dissipation of a step is lambda . [mu^+ ; mu^-] (§4), and with loads the work
against them lambda . [-F~ ; F~] (§6).

The module-level functions take plain arrays, so a results file's arrays (the figures read
those) are treated by the same code as a compiled process's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


def block_forces(stress: np.ndarray) -> np.ndarray:
    """The net elastic force on each block, f = D^T sigma: f_j = sigma_{j-1} - sigma_j with
    sigma_0 = sigma_N = 0 (docs/model.md §1). ``stress`` is (..., N-1); the result (..., N)."""
    stress = np.asarray(stress, dtype=float)
    padded = np.zeros(stress.shape[:-1] + (stress.shape[-1] + 2,))
    padded[..., 1:-1] = stress
    return padded[..., :-1] - padded[..., 1:]


def offsets_of(KL: np.ndarray, plus: np.ndarray, minus: np.ndarray, force: np.ndarray | None) -> np.ndarray:
    """c = [mu~^+ - D^T K L; mu~^- + D^T K L] with mu~^+ = mu^+ cos - F~ and mu~^- = mu^- cos + F~
    (docs/model.md §2, §6), from K L, the friction ``plus`` and ``minus`` (already times cos) and
    F~ (None without loads): the same on the grid (values) and on a piece (coefficients)."""
    DtKL = block_forces(KL)
    if force is None:
        return np.hstack([plus - DtKL, minus + DtKL])
    return np.hstack([plus - force - DtKL, minus + force + DtKL])


def stress_bounds(friction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The range of each link stress sigma_i over the admissible set C(t), (..., N-1) each, from
    the friction thresholds ``[mu^+, mu^-]`` (..., 2N).

    With f = D^T sigma we have sigma_i = -(f_1 + ... + f_i) = f_{i+1} + ... + f_N (the forces sum
    to zero), and the f_j range independently over [-mu_j^-, mu_j^+]. So sigma_i ranges exactly
    over

        [ -min(sum_{j<=i} mu_j^+, sum_{j>i} mu_j^-),  min(sum_{j<=i} mu_j^-, sum_{j>i} mu_j^+) ]:

    a link in compression sigma_i > 0 pushes the blocks behind it backward and those ahead
    forward, and it reaches its bound when one of the two groups slips as a whole. These are
    necessary limits for a stress; the exact ones are the block limits -mu^- <= f <= mu^+.
    """
    friction = np.asarray(friction, dtype=float)
    N = friction.shape[-1] // 2
    plus, minus = friction[..., :N], friction[..., N:]
    behind_plus = np.cumsum(plus, axis=-1)[..., :-1]
    behind_minus = np.cumsum(minus, axis=-1)[..., :-1]
    ahead_plus = plus.sum(axis=-1, keepdims=True) - behind_plus
    ahead_minus = minus.sum(axis=-1, keepdims=True) - behind_minus
    return -np.minimum(behind_plus, ahead_minus), np.minimum(behind_minus, ahead_plus)


def elastic_energy(stress: np.ndarray, stiffness: np.ndarray) -> float:
    """E = sum_i sigma_i^2 / (2 k_i), the energy stored in the links (docs/model.md §4)."""
    return float(np.sum(stress * stress / (2.0 * stiffness)))


def slips(multipliers: np.ndarray) -> np.ndarray:
    """Block increments dx = lambda^+ - lambda^- of multipliers (..., 2N) (docs/model.md §3)."""
    N = multipliers.shape[-1] // 2
    return multipliers[..., :N] - multipliers[..., N:]


def signal_columns(blocks: int) -> dict[str, slice]:
    """Where each signal a crawler's offsets c(t) are combined from sits in the signals' table
    (`crawlsim.model.offsets.PiecewiseOffsets`, `signals_of`): the links' lengths L, mu^+ and
    mu^- per block, and the loads' forces per block (docs/model.md §2, §6)."""
    N = blocks
    return {
        "links": slice(0, N - 1),
        "forward": slice(N - 1, 2 * N - 1),
        "backward": slice(2 * N - 1, 3 * N - 1),
        "forces": slice(3 * N - 1, 4 * N - 1),
    }


def signals_of(links: Sequence, forward: Sequence, backward: Sequence, forces: Sequence = ()) -> tuple:
    """The signals of c(t) in the order of `signal_columns`."""
    return (*links, *forward, *backward, *forces)


def describe_subset(rows, N: int) -> str:
    """Words for the active rows of a crawler of N blocks: the set J of saturated blocks,
    rows 0..N-1 at the forward limit and N..2N-1 at the backward one."""
    fwd = [int(i) + 1 for i in rows if i < N]
    bwd = [int(i) - N + 1 for i in rows if i >= N]
    return (
        f"J = {{{', '.join(map(str, sorted(fwd + bwd)))}}}: blocks "
        f"{fwd or 'none'} at their forward friction limit, "
        f"{bwd or 'none'} at their backward limit"
    )


@dataclass(frozen=True, eq=False)
class Crawler:
    """What a compiled process knows of its crawler, tabulated on the period's grid (G+1 rows).

    Every quantity of the crawler that follows from the state w is computed here: the
    process's files, analysis and figures ask it instead of recomputing.
    """

    stiffness: np.ndarray  # k (N-1,): M = K^{-1}
    initial_positions: np.ndarray  # x(0) (N,)
    stress_offset: np.ndarray  # K L(t) on the grid (G+1, N-1): stress = w + K L
    friction: np.ndarray  # [mu^+, mu^-] on the grid (G+1, 2N), scaled by cos(angle) (§6)
    lengths: np.ndarray  # L(t) on the grid (G+1, N-1)
    # Loads (docs/model.md §6): the load's share l = [-F~ ; F~] of the offsets on the grid
    # (G+1, 2N), so that c's thresholds are friction + l; None without loads.
    load: np.ndarray | None = None
    friction_scale: float = 1.0  # cos(angle): the signals' mu scaled to the slope's friction
    load_constant: np.ndarray | None = None  # -W sin(angle) (N,): F~ = F(t) + load_constant
    slope_angle: float | None = None  # degrees, None without a slope

    @property
    def blocks(self) -> int:
        return len(self.stiffness) + 1

    @property
    def columns(self) -> dict[str, slice]:
        """The signals' columns (`signal_columns`)."""
        return signal_columns(self.blocks)

    def split(self, table: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """A table of the signals' coefficients (nb, S), columns as `signal_columns`, split into
        the lengths L (nb, N-1), the friction [mu^+, mu^-] cos(angle) (nb, 2N) and the loads'
        F~ = F - W sin(angle) (nb, N; None without loads), whose constant is added to row 0,
        the coefficient of phi_0 = 1 (docs/model.md §6)."""
        c = self.columns
        friction = self.friction_scale * table[:, c["forward"].start : c["backward"].stop]
        force = None
        if self.load_constant is not None:
            force = table[:, c["forces"]].copy()
            force[0] += self.load_constant
        return table[:, c["links"]], friction, force

    def offsets(self, table: np.ndarray) -> np.ndarray:
        """The coefficients (nb, 2N) of c = [mu~^+ - D^T K L; mu~^- + D^T K L] from those of the
        signals (`split`): the map `crawlsim.model.offsets.PiecewiseOffsets` combines them with."""
        L, friction, force = self.split(table)
        N = self.blocks
        return offsets_of(L * self.stiffness, friction[:, :N], friction[:, N:], force)

    def stress(self, w: np.ndarray, rows=slice(None)) -> np.ndarray:
        """sigma = w + K L(t) at the grid rows ``rows`` of the states ``w`` (§2)."""
        return w + self.stress_offset[rows]

    def shape(self, w: np.ndarray) -> np.ndarray:
        """The link lengths z = -K^{-1} w of the states ``w`` (§2)."""
        return -w / self.stiffness

    def positions(self, w: np.ndarray, barycentre: float) -> np.ndarray:
        """Block positions in the state ``w`` with the given barycentre: z = D x = -K^{-1} w,
        so x_i = x_1 + z_1 + ... + z_{i-1}."""
        x = np.concatenate([[0.0], np.cumsum(self.shape(np.asarray(w, dtype=float)))])
        return x - np.mean(x) + barycentre

    def block_forces(self, w: np.ndarray, rows=slice(None)) -> np.ndarray:
        """f = D^T sigma of the states ``w`` at grid rows ``rows`` (§1)."""
        return block_forces(self.stress(w, rows))

    def stress_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The range of each link stress over C(t) on the grid (`stress_bounds`)."""
        return stress_bounds(self.friction)

    def elastic_energy(self, stress: np.ndarray) -> float:
        """E = sum_i sigma_i^2 / (2 k_i)."""
        return elastic_energy(stress, self.stiffness)

    def slips(self, multipliers: np.ndarray) -> np.ndarray:
        """dx = lambda^+ - lambda^- (§3)."""
        return slips(multipliers)

    def dissipation(self, multipliers: np.ndarray) -> float:
        """The friction work of a catch-up period's steps, sum_n lambda^{n+1} . mu(t_{n+1})
        (multipliers (G, 2N), one row per step, paid at the step's end)."""
        return float(np.sum(multipliers * self.friction[1:]))

    def load_work(self, multipliers: np.ndarray) -> float:
        """The work against the loads of a catch-up period's steps, sum_n lambda^{n+1} .
        l(t_{n+1}) (§6); 0 without loads."""
        if self.load is None:
            return 0.0
        return math.fsum(np.sum(multipliers * self.load[1:], axis=1))

    def describe_active(self, index) -> str:
        """Words for an active set: the set J of saturated blocks."""
        return describe_subset(np.asarray(index, dtype=int), self.blocks)
