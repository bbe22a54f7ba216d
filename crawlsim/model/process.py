"""Compile a validated gait into its shape-space polyhedral sweeping process (docs/model.md §1-2).

For a crawler of N blocks with link stiffnesses K = diag(k_i), shape z = D x and stress
sigma = K (L(t) - z), the variable w = -K z moves in

    K(t) = { w : B w <= c(t) },   B = [D^T ; -D^T],
    c(t) = [ mu^+(t) - D^T K L(t) ; mu^-(t) + D^T K L(t) ],

and catch-up stepping projects in the metric M = K^{-1}. The 2N multipliers
lambda = [lambda^+ ; lambda^-] of a step are the block slips: dx = lambda^+ - lambda^-
(docs/model.md §3), so the slip map is S = [I, -I].

A generic polyhedral sweeping process (docs/model.md §5, ``kind: sweeping-process``) compiles to the
same `SweepingProcess` with its own B, c(t), M and z(0) and no crawler fields, so it is stepped,
certified and analysed by the same code; `compile` dispatches on the kind.

B and M live in the process's `crawlsim.projection.kkt.Polyhedron`: for a crawler a `ChainPolyhedron`, which
never forms anything of size N^2, so compiling, like stepping, costs O(N) per grid time.
Everything time-dependent is tabulated once on the period's grid, vectorised over all times.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from crawlsim.gait.document import Gait, ProcessSpec
from crawlsim.gait.signals import Signal, evaluate_many
from crawlsim.model.crawler import Crawler, offsets_of, signals_of, slips
from crawlsim.model.offsets import PiecewiseOffsets
from crawlsim.projection.kkt import ChainPolyhedron, DensePolyhedron, Polyhedron

#: Grid times closer than this (in cycles) to a breakpoint are merged into the breakpoint.
GRID_MERGE = 1e-12


@dataclass(frozen=True, eq=False)
class SweepingProcess:
    """A T-periodic polyhedral sweeping process ``w' in -N_{K(t)}(w)``, tabulated on one period.

    ``crawler`` holds what is a crawler's only (`crawlsim.model.crawler.Crawler`: stiffness,
    stress, shape, block forces, stress bounds, dissipation, the signals' layout and the loads);
    it is ``None`` for a generic process, which has 0 ``blocks``.
    """

    name: str
    period: float
    polyhedron: Polyhedron  # B and the metric M: projections minimise 1/2 |w - w_trial|_M^2
    times: np.ndarray  # (G+1,) one period's grid: times[0] = 0, times[-1] = period
    offsets: np.ndarray  # c(t) on the grid (G+1, m)
    initial: np.ndarray  # w(0) (n,)
    crawler: Crawler | None = None  # the crawler's physics; None for a generic process
    # The closed form of c(t) piece by piece, for integrators that leave the grid (exact):
    offset_pieces: PiecewiseOffsets | None = None
    breakpoints: np.ndarray | None = None  # times in [0, T) where c has a kink or a jump

    @property
    def cycles(self) -> np.ndarray:
        """The grid in cycles t / T, exactly as built (breakpoints are grid points)."""
        return self._cycles if self._cycles is not None else self.times / self.period

    _cycles: np.ndarray | None = None

    @property
    def steps(self) -> int:
        return len(self.times) - 1

    @property
    def blocks(self) -> int:
        return 0 if self.crawler is None else self.crawler.blocks

    @property
    def scale(self) -> float:
        """A natural size of w and c, for relative tolerances."""
        return self.polyhedron.c_scale

    @property
    def normals(self) -> np.ndarray:
        """B as a dense (m, n) array (for files and figures; steps never form it)."""
        return self.polyhedron.dense_normals()

    @property
    def metric(self) -> np.ndarray:
        """M as a dense (n, n) array (for files and figures; steps never form it)."""
        return self.polyhedron.dense_metric()

    def slips(self, multipliers: np.ndarray) -> np.ndarray:
        """Block increments dx = lambda^+ - lambda^- of multipliers (..., 2N) (docs/model.md §3)."""
        return slips(multipliers)

    def describe_active(self, index) -> str:
        """Words for an active set: for crawlers, the set J of saturated blocks."""
        if self.crawler is None:
            index = np.asarray(index, dtype=int)
            return "active constraints {" + ", ".join(str(i) for i in index) + "}"
        return self.crawler.describe_active(index)


def period_grid(steps_per_period: int, breakpoints) -> np.ndarray:
    """One period's grid in cycles: ``steps_per_period`` uniform points plus every breakpoint.

    A uniform point within `GRID_MERGE` of a breakpoint is replaced by the breakpoint, so a
    jump of a `steps` signal is always exactly on the grid.
    """
    return _shared_grid(steps_per_period, breakpoints)[0]


GridKey = tuple[int, bytes]

#: Grids and signal values a sweep's points share (`_shared_grid`, `_on_grid`): at most `_KEPT`
#: of each, for grids of at most `_KEPT_SIZE` times.
_GRIDS: dict[GridKey, np.ndarray] = {}
_ON_GRID: dict[tuple[Signal, GridKey], np.ndarray] = {}
_KEPT = 64
_KEPT_SIZE = 1 << 14


def _shared_grid(steps_per_period: int, breakpoints) -> tuple[np.ndarray, GridKey]:
    """`period_grid` (a copy of its own) and the key of that grid: the last few are remembered
    (`_GRIDS`), since a sweep's points mostly share theirs."""
    bp = np.asarray(breakpoints, dtype=float)
    key = (int(steps_per_period), bp.tobytes())
    grid = _GRIDS.get(key)
    if grid is None:
        grid = _period_grid(steps_per_period, bp)
        if grid.size <= _KEPT_SIZE:
            if len(_GRIDS) >= _KEPT:
                _GRIDS.clear()
            _GRIDS[key] = grid
    return grid.copy(), key


def _on_grid(signals: Sequence[Signal], u: np.ndarray, key: GridKey) -> np.ndarray:
    """``evaluate_many(signals, u)``, each distinct signal evaluated once on the grid ``u``
    (`_shared_grid`'s ``key``) and remembered: a sweep point changes one signal or two.
    Columns holding a zero are not kept: signals equal as values may differ in the sign of a
    zero (0.0 == -0.0), and only columns that no such sign can change are shared."""
    columns: dict[Signal, np.ndarray] = {}
    missing = []
    for s in dict.fromkeys(signals):
        kept = _ON_GRID.get((s, key))  # one look-up: another thread may empty the table
        if kept is None:
            missing.append(s)
        else:
            columns[s] = kept
    fresh = evaluate_many(missing, u)
    for i, s in enumerate(missing):
        columns[s] = fresh[:, i]
        if u.size <= _KEPT_SIZE and np.all(fresh[:, i]):
            if len(_ON_GRID) >= _KEPT:
                _ON_GRID.clear()
            _ON_GRID[(s, key)] = fresh[:, i].copy()
    return np.column_stack([columns[s] for s in signals]) if signals else np.empty((u.size, 0))


def _period_grid(steps_per_period: int, bp: np.ndarray) -> np.ndarray:
    uniform = np.linspace(0.0, 1.0, steps_per_period + 1)
    bp = bp[(bp > GRID_MERGE) & (bp < 1.0 - GRID_MERGE)]
    if bp.size:
        near = np.min(np.abs(uniform[:, None] - bp[None, :]), axis=1) <= GRID_MERGE
        uniform = uniform[~near]
    u = np.sort(np.concatenate([uniform, bp]))  # np.union1d, but without importing numpy.ma
    keep = np.concatenate([[True], np.diff(u) > GRID_MERGE])
    u = u[keep]
    u[0], u[-1] = 0.0, 1.0
    return u


def _scale(offsets: np.ndarray, initial: np.ndarray) -> float:
    """A natural size of w and c, the floor of every certificate tolerance."""
    return float(max(np.abs(offsets).max(), np.abs(initial).max(), 1e-300))


def piece_edges(breakpoints) -> np.ndarray:
    """Edges of the pieces of one cycle between breakpoints: exactly the grid's breakpoints."""
    bp = np.asarray(breakpoints, dtype=float)
    bp = np.unique(bp[(bp > GRID_MERGE) & (bp < 1.0 - GRID_MERGE)])
    return np.concatenate([[0.0], bp, [1.0]])


def compile_gait(gait: Gait, steps_per_period: int | None = None) -> SweepingProcess:
    """The shape-space sweeping process of a crawler gait on its time grid (docs/model.md §2)."""
    G = steps_per_period or gait.simulation.steps_per_period
    breakpoints = gait.breakpoints()  # the union of every signal's: computed once
    u, key = _shared_grid(G, breakpoints)
    k = np.asarray(gait.stiffness, dtype=float)
    L = _on_grid(gait.links, u, key)  # (G+1, N-1)
    loads = gait.loads
    scale = 1.0 if loads is None else loads.cos
    mu_f = _on_grid(gait.forward, u, key) * scale  # (G+1, N): friction mu cos(angle), §6
    mu_b = _on_grid(gait.backward, u, key) * scale
    KL = L * k  # K L on the grid
    total = None if loads is None else loads.total(u)  # F~ = F - W sin(angle)
    offsets = offsets_of(KL, mu_f, mu_b, total)
    x0 = np.asarray(gait.initial_positions, dtype=float)
    w0 = -k * np.diff(x0)  # w = -K z, z = D x
    crawler = Crawler(
        stiffness=k,
        initial_positions=x0,
        stress_offset=KL,
        friction=np.hstack([mu_f, mu_b]),
        lengths=L,
        load=None if total is None else np.hstack([-total, total]),
        friction_scale=scale,
        load_constant=None if loads is None else loads.gravity,
        slope_angle=None if loads is None or loads.weights is None else float(loads.angle),
    )
    signals = signals_of(gait.links, gait.forward, gait.backward, () if loads is None else loads.forces)
    pieces = PiecewiseOffsets(signals, crawler.offsets, piece_edges(breakpoints))
    return SweepingProcess(
        name=gait.name,
        period=float(gait.period),
        polyhedron=ChainPolyhedron(k, _scale(offsets, w0)),
        times=u * gait.period,
        offsets=offsets,
        initial=w0,
        crawler=crawler,
        offset_pieces=pieces,
        breakpoints=np.asarray(breakpoints, dtype=float) * gait.period,
        _cycles=u,
    )


def compile_process(spec: ProcessSpec, steps_per_period: int | None = None) -> SweepingProcess:
    """The tabulated sweeping process ``z' in -N_{C(t)}(z)`` of a generic process file (docs/model.md §5).

    No change of variables: w is z, B and M are the file's normals and metric, c(t) its offsets.
    """
    G = steps_per_period or spec.simulation.steps_per_period
    breakpoints = spec.breakpoints()
    u = period_grid(G, breakpoints)
    T = float(spec.period)
    offsets = evaluate_many(spec.offsets, u)
    initial = np.array(spec.initial, dtype=float)
    return SweepingProcess(
        name=spec.name,
        period=T,
        polyhedron=DensePolyhedron(spec.normals, spec.metric, _scale(offsets, initial)),
        times=u * T,
        offsets=offsets,
        initial=initial,
        offset_pieces=PiecewiseOffsets(spec.offsets, lambda coef: coef, piece_edges(breakpoints)),
        breakpoints=np.asarray(breakpoints, dtype=float) * T,
        _cycles=u,
    )


def compile(spec: Gait | ProcessSpec, steps_per_period: int | None = None) -> SweepingProcess:
    """Compile a crawler gait or a generic process file, whichever ``spec`` is."""
    if isinstance(spec, ProcessSpec):
        return compile_process(spec, steps_per_period)
    return compile_gait(spec, steps_per_period)
