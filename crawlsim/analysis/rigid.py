"""The rigid limit k -> infinity of a crawler gait: v0 without stepping (docs/model.md §7).

Block j moves at u + c_j(t), c_j the rate of P_j = L_1 + ... + L_{j-1}, and in the order of
decreasing c_j the first block at which g_J = sum_J mu~^+ - sum_rest mu~^- turns positive rests
(u = -c_m). While it does, the integral of u is -(P_m(b) - P_m(a)), exact. It changes at
crossings of the c_j, at sign changes of the g_J of the order, and at jumps of the links; on each
piece between breakpoints every signal is phi(u) @ coef (`crawlsim.model.offsets`), and all the
pieces are searched together: zeros of an affine function or of one harmonic in closed form,
others by certified sampling (`_sampled`). The estimate adds the roundoff of the sum and, for
each event, its time's uncertainty times the jump of u there.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from crawlsim.errors import DegenerateModelError, ResourceError
from crawlsim.gait.crawler_spec import Gait
from crawlsim.gait.signals import Steps, union_breakpoints
from crawlsim.gait.uniqueness import TOLERANCE
from crawlsim.model.offsets import Basis, PiecewiseOffsets
from crawlsim.model.process import piece_edges
from crawlsim.status import RigidStatus

EPS = float(np.finfo(float).eps)
_CYCLE = np.array([0.0, 1.0])
TWO_PI = 2.0 * math.pi
SAMPLE_CELLS = 8
"""Cells per harmonic and cycle in which a sampled search starts."""
MAX_ENTRIES = 1 << 26
"""Most values of an array of the rigid limit (512 MiB of doubles)."""
NARROWEST = 1e-12
"""Cycles: a cell the sampled search does not split further; its width counts in the estimate."""


@dataclass(frozen=True, eq=False)
class RigidLimit:
    """The rigid limit of a gait: v0, its error estimate, and which block rests when.

    ``resting[i]`` (1-based) rests on ``[times[i], times[i+1])``; an interval of length zero is
    a jump of the links, made with that block at rest."""

    v0: float
    v0_error_estimate: float
    displacement_per_period: float
    period: float
    times: np.ndarray
    resting: np.ndarray
    status: RigidStatus
    message: str

    def summary(self) -> dict[str, Any]:
        """The JSON form: v0, its estimate, and the resting block's intervals."""
        return {
            "v0": self.v0,
            "v0_error_estimate": self.v0_error_estimate,
            "displacement_per_period": self.displacement_per_period,
            "status": str(self.status),
            "message": self.message,
            "resting": [
                {"start": float(a), "end": float(b), "block": int(m)}
                for a, b, m in zip(self.times[:-1], self.times[1:], self.resting)
            ],
        }


def rigid_limit(gait: Gait) -> RigidLimit:
    """v0 of ``gait`` as its links stiffen without bound (module docstring). Raises
    `DegenerateModelError` where the balance does not fix the motion (a g_J of the order is 0
    on an interval, or at a jump)."""
    n = gait.blocks
    loads = gait.loads
    scale = 1.0 if loads is None else loads.cos
    gravity = None if loads is None else loads.gravity
    signals = gait.links + gait.forward + gait.backward + (() if loads is None else loads.forces)
    distinct = {s: i for i, s in enumerate(dict.fromkeys(signals))}  # a chain repeats its friction
    kinks = [s.breakpoints() for s in distinct if not s.is_smooth]
    pieces = PiecewiseOffsets(
        list(distinct), lambda coef: coef, piece_edges(union_breakpoints(kinks)) if kinks else _CYCLE
    )
    # [P | mu~^+ | mu~^-] on every piece (docs/model.md §6): (basis, piece, 3N)
    coef = np.stack([pieces.signal_coefficients(p) for p in range(pieces.pieces)], axis=1)
    coef = coef[..., np.array([distinct[s] for s in signals])]
    positions = np.concatenate([np.zeros(coef.shape[:2] + (1,)), np.cumsum(coef[..., : n - 1], axis=-1)], axis=-1)
    plus, minus = scale * coef[..., n - 1 : 2 * n - 1], scale * coef[..., 2 * n - 1 : 3 * n - 1]
    if gravity is not None:
        force = coef[..., 3 * n - 1 :].copy()
        force[0] += gravity
        plus, minus = plus - force, minus + force
    walk = _Walk(gait, pieces.basis, np.concatenate([positions, plus, minus], axis=-1))
    if any(isinstance(s, Steps) for s in gait.links):
        walk.jumps(pieces.edges)
    walk.intervals(pieces.edges)
    return walk.result()


class _Walk:
    """The resting block on every piece at once, and the displacement it makes."""

    def __init__(self, gait: Gait, basis: Basis, coef: np.ndarray):
        self.gait, self.basis, self.n, self.coef = gait, basis, gait.blocks, coef
        self.spans: list[np.ndarray] = []  # (start, end) of each interval, cycles
        self.resting: list[np.ndarray] = []
        self.displacement = 0.0
        self.error = 0.0
        self.sampled = 0

    def jumps(self, cuts: np.ndarray) -> None:
        """Jumps of the links at the pieces' starts (P from the piece before to this one): the
        block at rest is chosen by the rule of the velocities, with the jumps of P and the
        friction after."""
        n, coef = self.n, self.coef
        phi = self.basis.values(cuts[:-1])
        before = self.basis.values(np.append(1.0, cuts[1:-1]))
        step = np.einsum("pb,bpn->pn", phi, coef[..., :n]) - np.einsum(
            "pb,bpn->pn", before, np.roll(coef[..., :n], 1, 1)
        )
        size = np.einsum("pb,bpn->p", np.abs(phi), np.abs(coef[..., :n]))
        at = np.abs(step).max(axis=1) > 64 * EPS * size
        if not at.any():
            return
        step, size, u = step[at], size[at], cuts[:-1][at]
        friction = np.einsum("pb,bpn->pn", phi[at], coef[:, at, n:])
        m, _, _ = self._rank(np.round(step / (64 * EPS * size[:, None])), friction, None, u, u)
        self.spans.append(np.stack([u, u], 1))
        self.resting.append(m)
        self.displacement -= math.fsum(step[np.arange(len(m)), m])
        self.error += 8 * EPS * float(size.sum())

    def intervals(self, cuts: np.ndarray) -> None:
        """Every piece: its crossings, then its weight events, then the integral."""
        n, basis, coef = self.n, self.basis, self.coef
        c = basis.derivative(coef[..., :n])
        speed = max(float(np.abs(c).sum(axis=0).max()), 1e-300)
        self._bound(n * n * len(c) * (len(cuts) - 1), "differences of velocities")
        i, j = _pairs(n)
        owner = np.repeat(np.arange(len(cuts) - 1), len(i))
        roots, spread = self._zeros((c[..., i] - c[..., j]).reshape(len(c), -1), cuts[owner], cuts[owner + 1], speed)
        self.error += spread * speed * 16 * EPS
        edges = _distinct(np.concatenate([cuts, roots]))
        self._bound(len(edges) * n * len(c), "velocities between the crossings")
        varying = bool(coef[1:, :, n:].any())
        for _ in range(4 * n + 16):  # each round splits at the sign changes of two g_J
            mid = 0.5 * (edges[:-1] + edges[1:])
            piece = np.searchsorted(cuts, mid, side="right") - 1
            values = basis.values(np.concatenate([mid, edges]))  # at the midpoints, then the edges
            phi = values[: len(mid)]
            friction = coef[:, piece, n:]
            # velocities equal to roundoff (a link at rest, a wave summing to zero) tie
            key = np.round(np.einsum("mb,bmn->mn", phi, c[:, piece]) / (64 * EPS * speed))
            m, watched, owner = self._rank(
                key, np.einsum("mb,bmn->mn", phi, friction), friction if varying else None, edges[:-1], edges[1:]
            )
            if watched is None:
                break
            roots, spread = self._zeros(
                watched, edges[owner], edges[owner + 1], float(np.abs(friction).sum(axis=(0, 2)).max())
            )
            self.error += spread * 2.0 * speed
            split = _distinct(np.concatenate([edges, roots]))
            if len(split) == len(edges):  # none, or zeros at the edges they made
                break
            edges = split
        else:  # pragma: no cover - a round's zeros move the rank by one: n rounds suffice
            raise RuntimeError(f"{self.gait.source}: the weight events of the rigid limit did not settle")
        at = coef[:, piece, m]  # (basis, interval): the resting block's P
        left, right = values[len(mid) : -1], values[len(mid) + 1 :]
        moved = np.einsum("mb,bm->m", right, at) - np.einsum("mb,bm->m", left, at)
        self.spans.append(np.stack([edges[:-1], edges[1:]], 1))
        self.resting.append(m)
        self.displacement -= math.fsum(moved)
        self.error += 8 * EPS * float(np.einsum("mb,bm->", np.abs(left) + np.abs(right), np.abs(at)))

    def _rank(
        self, key: np.ndarray, values: np.ndarray, friction: np.ndarray | None, starts: np.ndarray, ends: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """The resting block of each interval, from its velocities (``key``, equal where they
        tie) and friction ``values`` [mu~^+ | mu~^-]; given the friction's coefficients on
        each interval (``friction``, where it varies), the g_J that keep it there (the one up to
        it and the one before, as coefficients), with the interval of each. Of blocks that move
        together the first is named (they all rest)."""
        n = self.n
        order = np.argsort(-key, axis=1, kind="stable")
        rows = np.arange(len(order))
        weights = values[:, :n] + values[:, n:]
        g = np.cumsum(np.take_along_axis(weights, order, axis=1), axis=1) - values[:, n:].sum(axis=1)[:, None]
        position = np.argmax(g > 0, axis=1)
        kept = [(position < n - 1, position), (position > 0, position - 1)]
        owner = np.concatenate([rows[k] for k, _ in kept])
        column = np.concatenate([p[k] for k, p in kept])
        band = TOLERANCE * weights.sum(axis=1)[owner]
        tied = np.abs(g[owner, column]) <= band
        watched = None
        if friction is not None:
            ordered = np.take_along_axis(friction[..., :n] + friction[..., n:], order[None], axis=2)
            watched = (np.cumsum(ordered, axis=2) - friction[..., n:].sum(axis=2)[..., None])[:, owner, column]
            tied &= np.all(np.abs(watched) <= band, axis=0)
        if tied.any():
            at = int(owner[np.argmax(tied)])
            self._degenerate(order[at], g[at], starts[at], ends[at])
        m = order[rows, position]
        return np.argmax(key == key[rows, m][:, None], axis=1), watched, owner

    def _bound(self, entries: int, what: str) -> None:
        """Refuse a rigid limit whose arrays would exceed `MAX_ENTRIES` (`ResourceError`)."""
        if entries > MAX_ENTRIES:
            raise ResourceError(
                self.gait.source,
                "blocks",
                f"the rigid limit of {self.n} blocks would hold {entries:,} values of its {what} at once, "
                f"more than {MAX_ENTRIES:,}: too many blocks and crossings for it",
            )

    def _degenerate(self, order: np.ndarray, g: np.ndarray, a: float, b: float) -> None:
        """Refuse a gait whose balance does not fix the motion: some g_J of the order is zero."""
        p = int(np.argmin(np.abs(g)))
        faster = ", ".join(str(int(j) + 1) for j in sorted(order[: p + 1]))
        period = self.gait.period
        when = f"t = {a * period:g}" if a == b else f"t in [{a * period:g}, {b * period:g}]"
        raise DegenerateModelError(
            self.gait.source,
            "loads" if self.gait.loads is not None else "friction",
            f"the rigid limit is not unique at {when}: the blocks J = {{{faster}}}, the fastest, "
            "forward and the rest backward balance exactly (sum mu+ over J - sum mu- over the "
            "rest = 0), so the balance does not fix which block rests (docs/model.md §7)",
        )

    def _zeros(self, z: np.ndarray, lo: Any, hi: Any, scale: float) -> tuple[np.ndarray, float]:
        """The sign changes of the columns f_i = phi @ z[:, i] in (lo_i, hi_i), and the sum of
        their times' uncertainties (cycles): affine columns and those of one harmonic in closed
        form, the others by `_sampled`. A column within roundoff of zero, relative to ``scale``
        (that of the functions it is a difference of), is zero: a tie, not a zero."""
        size = np.abs(z).sum(axis=0)
        lo, hi = np.broadcast_to(lo, size.shape), np.broadcast_to(hi, size.shape)
        basis = self.basis
        h0 = basis.first_harmonic
        slope = z[1] != 0 if basis.linear else np.zeros(len(size), dtype=bool)
        harmonic, higher = z[h0 : h0 + 2].any(axis=0), z[h0 + 2 :].any(axis=0)
        nonzero = size > 64 * EPS * scale
        groups = (
            (nonzero & ~harmonic & ~higher, _affine),
            (nonzero & harmonic & ~higher & ~slope, _harmonic),
            (nonzero & (higher | harmonic & slope), _sampled),
        )
        found, spread = [], 0.0
        for chosen, solve in groups:
            if chosen.any():
                roots, uncertain = solve(z[:, chosen], basis, lo[chosen], hi[chosen], 16 * EPS * size[chosen])
                found.append(roots)
                spread += uncertain
        self.sampled += int(groups[2][0].any())
        return np.concatenate(found) if found else np.empty(0), spread

    def result(self) -> RigidLimit:
        period = float(self.gait.period)
        spans, resting = np.concatenate(self.spans), np.concatenate(self.resting)
        order = np.lexsort((spans[:, 1], spans[:, 0]))  # a jump before the interval it starts
        spans, resting = spans[order], resting[order]
        point = spans[:, 0] == spans[:, 1]
        keep = np.concatenate([[True], (resting[1:] != resting[:-1]) | point[1:] | point[:-1]])
        error = self.error + 2 * EPS * len(spans) * abs(self.displacement)
        how = "every event in closed form"
        if self.sampled:
            how = "events in closed form and by certified sampling (several harmonics, or one and a linear part)"
        return RigidLimit(
            v0=self.displacement / period,
            v0_error_estimate=error / period,
            displacement_per_period=self.displacement,
            period=period,
            times=np.append(spans[keep, 0], 1.0) * period,
            resting=resting[keep] + 1,
            status=RigidStatus.SAMPLED if self.sampled else RigidStatus.CLOSED_FORM,
            message=how,
        )


@functools.lru_cache(maxsize=8)
def _pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Every pair j < l of n blocks."""
    return np.triu_indices(n, 1)


def _distinct(edges: np.ndarray) -> np.ndarray:
    """Sorted edges without those within a few ulps of the one before (the last kept)."""
    edges = np.sort(edges)
    keep = np.concatenate([np.diff(edges) > 4 * EPS, [True]])
    keep[0] = True
    return edges[keep]


def _affine(z: np.ndarray, basis: Basis, lo: np.ndarray, hi: np.ndarray, roundoff: np.ndarray) -> tuple:
    """Zeros of z0 + z1 u in (lo, hi), and the sum of their uncertainties."""
    slope = z[1] if basis.linear else np.zeros(z.shape[1])
    with np.errstate(divide="ignore", invalid="ignore"):
        u = -z[0] / slope
    keep = (slope != 0) & (u > lo) & (u < hi)
    return u[keep], float((roundoff[keep] / np.abs(slope[keep])).sum())


def _harmonic(z: np.ndarray, basis: Basis, lo: np.ndarray, hi: np.ndarray, roundoff: np.ndarray) -> tuple:
    """Sign changes of z0 + a cos 2 pi u + b sin 2 pi u = z0 + r cos(2 pi u - alpha) in (lo, hi):
    2 pi u = alpha +- arccos(-z0 / r) where r > |z0|; the uncertainty of each is the roundoff
    over the slope there, or at a near tangency sqrt(2 roundoff / f'')."""
    h0 = basis.first_harmonic
    radius = np.hypot(z[h0], z[h0 + 1])
    cross = radius > np.abs(z[0])
    delta = np.arccos(-z[0][cross] / radius[cross])
    alpha = np.arctan2(z[h0 + 1], z[h0])[cross]
    u = np.mod(np.concatenate([alpha - delta, alpha + delta]) / TWO_PI, 1.0)
    lo, hi, radius, r, delta = (
        np.concatenate([x, x]) for x in (lo[cross], hi[cross], radius[cross], roundoff[cross], delta)
    )
    keep = (u > lo) & (u < hi)
    rate = TWO_PI * radius * np.abs(np.sin(delta))
    with np.errstate(divide="ignore"):
        dt = np.minimum(r / rate, np.sqrt(2 * r / (TWO_PI**2 * radius)))
    return u[keep], float(dt[keep].sum())


def _at(z: np.ndarray, basis: Basis, owner: np.ndarray, u: np.ndarray) -> np.ndarray:
    """f_owner(u) for each pair of a function and a cycle."""
    return np.einsum("ij,ji->i", basis.values(u), z[:, owner])


def _sampled(z: np.ndarray, basis: Basis, lo: np.ndarray, hi: np.ndarray, roundoff: np.ndarray) -> tuple:
    """Sign changes of f_i = phi @ z[:, i] in (lo_i, hi_i) by certified sampling: on a cell of
    width h, |f''| <= M (`Basis.curvature_bound`) keeps f within M h^2 / 8 of its chord, and
    |f'(mid)| > M h / 2 makes it monotone. A cell whose ends have one sign holds no sign change
    if they exceed that bound or f is monotone; a monotone one whose ends differ holds one, found
    by Newton's method kept in the bracket. Other cells are split, down to `NARROWEST`; one left then counts its width
    as uncertainty."""
    derivative = basis.derivative(z)
    curve = basis.curvature_bound(z)
    cells = max(2, math.ceil(SAMPLE_CELLS * basis.harmonics * float(np.max(hi - lo))))
    owner = np.repeat(np.arange(z.shape[1]), cells)
    steps = np.tile(np.arange(cells + 1), (z.shape[1], 1)) / cells
    grid = lo[:, None] + (hi - lo)[:, None] * steps
    grid[:, -1] = hi
    x0, x1 = grid[:, :-1].ravel(), grid[:, 1:].ravel()
    found: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    uncertain = 0.0
    while owner.size:
        f0, f1 = _at(z, basis, owner, x0), _at(z, basis, owner, x1)
        h = x1 - x0
        rate = np.abs(_at(derivative, basis, owner, 0.5 * (x0 + x1)))
        change = np.signbit(f0) != np.signbit(f1)
        monotone = rate > curve[owner] * h / 2
        clear = ~change & (monotone | (np.minimum(np.abs(f0), np.abs(f1)) > curve[owner] * h * h / 8 + roundoff[owner]))
        narrow = h < NARROWEST
        solve = change & (monotone | narrow)
        uncertain += float(np.sum(h[narrow & ~clear & ~(change & monotone)]))
        if np.any(solve):
            found.append((owner[solve], x0[solve], x1[solve]))
        split = ~clear & ~solve & ~narrow
        owner, x0, x1 = owner[split], x0[split], x1[split]
        quarter = (x1 - x0) / 4
        owner = np.repeat(owner, 4)
        x0 = np.repeat(x0, 4) + np.tile(np.arange(4), len(quarter)) * np.repeat(quarter, 4)
        x1 = x0 + np.repeat(quarter, 4)
    if not found:
        return np.empty(0), uncertain
    owner = np.concatenate([f[0] for f in found])
    x0, x1 = np.concatenate([f[1] for f in found]), np.concatenate([f[2] for f in found])
    f0 = _at(z, basis, owner, x0)
    root = 0.5 * (x0 + x1)
    for _ in range(100):  # Newton's steps, kept in the bracket by bisection (cycles: <= 1)
        f, rate = _at(z, basis, owner, root), _at(derivative, basis, owner, root)
        same = np.signbit(f) == np.signbit(f0)
        x0, f0, x1 = np.where(same, root, x0), np.where(same, f, f0), np.where(same, x1, root)
        with np.errstate(divide="ignore", invalid="ignore"):
            newton = root - f / rate
        step = np.where((newton >= x0) & (newton <= x1), newton, 0.5 * (x0 + x1))
        root, moved = step, np.abs(step - root)
        if np.all((moved <= 4 * EPS) | (x1 - x0 <= 4 * EPS)):
            break
    rate = np.abs(_at(derivative, basis, owner, root))
    with np.errstate(divide="ignore"):
        dt = np.minimum(roundoff[owner] / rate, np.sqrt(2 * roundoff[owner] / np.maximum(curve[owner], 1e-300)))
    return root, uncertain + float(np.sum(dt + moved))
