"""The terms of the implicit function theorem that are not walked along the period
(`crawlsim.analysis.sensitivity`, docs/sensitivity.md): the verified limit period, the offsets'
coefficients c(u) = phi(u) C_p with their derivatives in each number of the gait file, and the
friction's distance to the uniqueness boundary.

Every number of a gait file that is a mean, an amplitude, a Fourier coefficient, a knot value,
a friction coefficient or a stiffness enters C_p, the friction weights and K affinely, so one
difference quotient of the coefficients is exact to roundoff (eq. (parameters) of
docs/sensitivity.md); a phase rotates each harmonic pair, and the rotation is inverted exactly.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from crawlsim.analysis.energy import period_dissipation
from crawlsim.analysis.run import verified_limit_error
from crawlsim.errors import CrawlsimError, GaitError
from crawlsim.gait.docpaths import STRUCTURAL, explicit, set_value, value_at
from crawlsim.gait.settings import effective_tolerance
from crawlsim.gait.signals import Constant, Cosine, Fourier, parse_signal
from crawlsim.integrate.limit import PLAIN_PERIODS, relative_step, solve_limit
from crawlsim.integrate.stepping import make_stepper
from crawlsim.model.crawler import signal_columns, signals_of
from crawlsim.model.offsets import PiecewiseOffsets
from crawlsim.model.process import _scale, compile_gait

if TYPE_CHECKING:
    from crawlsim.gait.document import Gait
    from crawlsim.integrate.stepping import PeriodRecord
    from crawlsim.model.process import SweepingProcess

EPS = float(np.finfo(float).eps)
TWO_PI = 2.0 * math.pi
#: Relative step of the difference quotient of the offsets' coefficients (exact for affine
#: dependence, so only roundoff / h matters).
COEFFICIENT_STEP = 2.0**-10
#: Step in degrees of the central difference in a slope's angle (not affine: cos and sin).
ANGLE_STEP = 1e-3
#: Most blocks for which the uniqueness boundary is checked over every subset.
UNIQUENESS_BLOCKS = 12


# -- the limit period ------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Limit:
    process: SweepingProcess
    record: PeriodRecord
    v0: float
    v0_error: float
    displacement: float
    dissipation: float
    residual: float  # relative Poincare step of the verified period
    # the size of c that the walk's tolerances are relative to (the polyhedron's c_scale on
    # the grid the walk is defined on)
    scale: float


def find_limit(gait: Gait) -> Limit:
    """The verified limit period of ``gait`` with its own integrator (as `crawlsim velocity`
    finds it: plain periods, then the periodic-limit solver)."""
    process = compile_gait(gait)
    s = gait.simulation
    tol = effective_tolerance(s.tolerance)
    integrator = s.integrator
    stepper = make_stepper(process, integrator)
    record = None
    final = None
    periods = 0
    while periods < min(PLAIN_PERIODS, s.max_periods):
        record = stepper.step_period()
        periods += 1
        if relative_step(process, record.w[0], record.w[-1]) <= tol:
            final = record
            break
    if final is None:
        solution = solve_limit(
            process,
            make_stepper(process, integrator),
            tolerance=tol,
            first=record,
            max_periods=max(s.max_periods - periods, 1),
            plain=0,
        )
        if not solution.converged:
            raise CrawlsimError(
                f"{gait.source}: the periodic limit was not found within "
                f"max_periods = {s.max_periods}; sensitivities need it"
            )
        final = solution.record
    return limit_of(process, final)


def limit_of(
    process: SweepingProcess,
    final: PeriodRecord,
    scale: float | None = None,
    known: tuple[float, float, float | None] | None = None,
) -> Limit:
    """v0, its error and the period's displacement and dissipation of a verified limit period
    (the error as `crawlsim.analysis.run.simulate` bounds it: the steps' roundoff and the
    residual |P(w) - w| as a shape mismatch over the smallest stiffness). ``scale``: the size
    of c of the walk's grid where it is not ``process``'s (`breakpoint_scale`); the relative
    Poincare step is taken on it. ``known``: the period's displacement, dissipation and v0's
    error (None: not known) as the run that verified ``final`` measured them, with these
    formulas on this period (`crawlsim.analysis.run`), not measured again."""
    assert final.x is not None
    T = process.period
    if known is None:
        d = float(np.mean(final.x[-1] - final.x[0]))
        dissipation, err = period_dissipation(process, final), None
    else:
        d, dissipation, err = known
    if err is None:
        steps = len(final.w) - 1  # the run's grid (``process`` may be on a coarser one)
        err = verified_limit_error(process, final, steps)
    scale = process.scale if scale is None else scale
    # the relative Poincare step (`crawlsim.integrate.limit.relative_step`) on that scale
    step, end = final.w[-1] - final.w[0], final.w[-1]  # 2-norms, as np.linalg.norm forms them
    residual = math.sqrt(float(step.dot(step))) / max(math.sqrt(float(end.dot(end))), scale)
    return Limit(process, final, d / T, err, d, dissipation, residual, scale)


def breakpoint_scale(process: SweepingProcess) -> float:
    """The c_scale of ``process``'s gait compiled on the grid of its breakpoints alone (the
    exact walk's grid, `compile_gait` with one step): its offsets at the pieces' edges and
    its initial state, read off ``process``'s own grid, which holds every edge."""
    assert process.offset_pieces is not None
    edges = process.offset_pieces.edges
    if len(edges) == 2:  # one piece: the grid's first and last times are its edges, 0 and 1
        return _scale(process.offsets[[0, -1]], process.initial)
    cycles = process.cycles
    at = np.minimum(np.searchsorted(cycles, edges), len(cycles) - 1)
    return _scale(process.offsets[at[cycles[at] == edges]], process.initial)


# -- the offsets' coefficients and their derivatives -----------------------------------------
@dataclass(frozen=True, eq=False)
class Coefficients:
    C: np.ndarray  # (P, nb, m) offsets c = phi @ C_p
    Mu: np.ndarray  # (P, nb, m) friction weights of the rows, mu = phi @ Mu_p
    k: np.ndarray  # (N-1,)
    edges: np.ndarray
    basis: Any
    pieces: Any  # the compiled `crawlsim.model.offsets.PiecewiseOffsets` they come from
    crawler: Any  # the `crawlsim.model.crawler.Crawler` whose signals they are


def coefficients_of(gait: Gait, process: SweepingProcess | None = None) -> Coefficients:
    """The offsets' coefficients as the integrator compiles them (every term of c(t), whatever
    the gait file adds to it) and the friction weights: those of ``process`` (the gait's,
    compiled on any grid) or of the gait compiled on a grid of its breakpoints only."""
    if process is None:
        process = compile_gait(gait, steps_per_period=1)
    assert process.offset_pieces is not None and process.crawler is not None
    return _assemble(process.offset_pieces, process.crawler)


def _signals(gait: Gait, fields: dict[str, Any] | None = None) -> tuple[Any, ...]:
    """The signals c(t) is combined from, in the order `compile_gait` takes them (with the
    gait's ``fields`` replaced by those given, `_moved_fields`)."""
    f = fields or {}
    forces = () if gait.loads is None else gait.loads.forces
    return signals_of(
        f.get("links", gait.links), f.get("forward", gait.forward), f.get("backward", gait.backward), forces
    )


def _assemble(pieces: Any, crawler: Any) -> Coefficients:
    """C_p of ``pieces`` and the friction weights Mu_p: the friction signals' own coefficients
    on each piece, times cos(angle) on a slope (docs/model.md §6)."""
    P = pieces.pieces
    C = np.array([pieces.coefficients(p) for p in range(P)])
    Mu = np.array([crawler.split(pieces.signal_coefficients(p))[1] for p in range(P)])
    k = np.array(crawler.stiffness, dtype=float)
    return Coefficients(C, Mu, k, pieces.edges, pieces.basis, pieces, crawler)


def _moved_coefficients(gait: Gait, base: Coefficients, keys: tuple[Any, ...], value: float) -> Coefficients:
    """The coefficients of the gait with one number moved. A signal's number (a link's, a
    friction's) changes the signals alone: they are combined by the base's own map into c
    (linear in them, docs/sensitivity.md), on the base's pieces when the breakpoints stay;
    anything else (the stiffness, which that map holds) is compiled anew."""
    moved = _moved(gait, keys, value)
    if keys[0] in ("links", "friction") and np.array_equal(moved.breakpoints(), gait.breakpoints()):
        pieces = PiecewiseOffsets(_signals(moved), base.pieces.combine, base.pieces.edges)
        return _assemble(pieces, base.crawler)
    return coefficients_of(moved)


def _smooth_derivative(signal: Any, inside: tuple[Any, ...], basis: Any) -> np.ndarray | None:
    """d/dtheta of the coefficients (nb,) of a constant, cosine or fourier signal
    (`crawlsim.model.offsets._smooth_coefficients`) for its number at ``inside`` (the path in
    its YAML form: ``()`` for a constant, ``("amplitude",)``, ``("cos", n - 1)``, ...), in
    closed form; None for anything else. With v = 2 pi (u - phase), harmonic n of
    a cos nv + b sin nv has the coefficients (a cos t_n - b sin t_n, a sin t_n + b cos t_n)
    of (cos 2 pi n u, sin 2 pi n u), t_n = 2 pi n phase, so d/dphase is 2 pi n times the quarter
    turn of them, d/da and d/db the columns of the rotation by t_n."""
    out = np.zeros(basis.size)
    h0 = basis.first_harmonic
    if isinstance(signal, Constant):
        if inside:
            return None
        out[0] = 1.0
        return out
    if not isinstance(signal, (Cosine, Fourier)) or signal.harmonics > basis.harmonics:
        return None
    if inside == ("mean",):
        out[0] = 1.0
        return out
    if isinstance(signal, Cosine):
        angle = TWO_PI * math.fmod(signal.phase, 1.0)
        ca, sa = math.cos(angle), math.sin(angle)
        if inside == ("amplitude",):
            out[h0], out[h0 + 1] = ca, sa
        elif inside == ("phase",):
            out[h0], out[h0 + 1] = -TWO_PI * signal.amplitude * sa, TWO_PI * signal.amplitude * ca
        else:
            return None
        return out
    phase = inside == ("phase",)
    which = inside[0] if len(inside) == 2 and isinstance(inside[1], int) else None
    if not phase and which not in ("cos", "sin"):
        return None
    for n in range(1, signal.harmonics + 1):
        angle = TWO_PI * math.fmod(n * math.fmod(signal.phase, 1.0), 1.0)
        ca, sa = math.cos(angle), math.sin(angle)
        at = h0 + 2 * (n - 1)
        if phase:
            a = signal.cos[n - 1] if n <= len(signal.cos) else 0.0
            b = signal.sin[n - 1] if n <= len(signal.sin) else 0.0
            out[at] = -TWO_PI * n * (a * sa + b * ca)
            out[at + 1] = TWO_PI * n * (a * ca - b * sa)
        elif inside[1] == n - 1:
            out[at], out[at + 1] = (ca, sa) if which == "cos" else (-sa, ca)
    if which is not None and not 0 <= inside[1] < signal.harmonics:
        return None
    return out


def _signal_columns(gait: Gait, keys: tuple[Any, ...]) -> tuple[list[tuple[int, Any, float]], tuple[Any, ...]] | None:
    """The signals a number at ``keys`` of a link, a friction or a force belongs to, each with
    its column in `_signals`' order (links, mu^+ per block, mu^- per block, forces per block)
    and the derivative of its number by the one at ``keys``, and the path inside them; None for
    other numbers. A wave's number moves every link's (``links.wave...``: by 1; the
    ``phase_step``: link i's phase by i, `crawlsim.gait.docpaths.wave_links`)."""
    columns = signal_columns(gait.blocks)
    if keys[0] == "links" and len(keys) >= 2 and isinstance(keys[1], int):
        return [(keys[1], gait.links[keys[1]], 1.0)], keys[2:]
    if keys[:2] == ("links", "wave"):
        return [(i, link, 1.0) for i, link in enumerate(gait.links)], keys[2:]
    if keys == ("links", "phase_step"):
        return [(i, link, float(i)) for i, link in enumerate(gait.links)], ("phase",)
    if keys[0] == "loads" and len(keys) >= 2 and keys[1] == "force" and gait.loads is not None:
        each = len(keys) >= 3 and isinstance(keys[2], int)  # one signal per block
        forced: Sequence[int] = [keys[2]] if each else range(gait.blocks)
        first = columns["forces"].start
        return ([(first + j, gait.loads.forces[j], 1.0) for j in forced], keys[3:] if each else keys[2:])
    friction = _friction_keys(gait, keys) if keys[0] == "friction" else None
    if friction is None:
        return None
    side, blocks, rest = friction
    first, signals = columns[side].start, gait.forward if side == "forward" else gait.backward
    ground = gait.terrain  # uniform ground scales the friction it compiles to (docs/model.md §8)
    scale = 1.0 if ground is None else float((ground.forward if side == "forward" else ground.backward)[0])
    return [(first + j, signals[j], scale) for j in blocks], rest[1:]


def _friction_keys(gait: Gait, keys: tuple[Any, ...]) -> tuple[str, Sequence[int], tuple[Any, ...]] | None:
    """The side (``forward``/``backward``), the blocks and the keys from the side on of a
    friction number: ``friction.forward...`` is every block's, ``friction.I.forward...`` block
    I's; None for another form."""
    if len(keys) < 2:
        return None
    shared = isinstance(keys[1], str)
    rest = keys[1:] if shared else keys[2:]
    if not rest or rest[0] not in ("forward", "backward"):
        return None
    return rest[0], range(gait.blocks) if shared else [keys[1]], rest


def _closed_form_change(gait: Gait, base: Coefficients, keys: tuple[Any, ...]) -> tuple[np.ndarray, np.ndarray] | None:
    """dC and the friction weights' dMu (P, nb, m) for a number of a constant, cosine or
    fourier signal (a link's, a friction's, a force's), in closed form (`_smooth_derivative`): c is
    combined from the signals by the base's own map, affine in them, so dC is that map's
    linear part applied to the signals' derivative, the same on every piece; None for other
    numbers and signals (`parameter_of` then differences the coefficients)."""
    found = _signal_columns(gait, keys)
    if found is None:
        return None
    columns, inside = found
    basis = base.basis
    # a zero row first: ``combine`` adds its constant term (the loads') to row 0, the
    # coefficient of phi_0 = 1, so the rows after it are the linear part alone
    dS = np.zeros((basis.size + 1, len(_signals(gait))))
    for column, signal, weight in columns:
        d = _smooth_derivative(signal, inside, basis)
        if d is None:
            return None
        dS[1:, column] = weight * d
    dC = base.pieces.combine(dS)[1:]
    dMu = base.crawler.split(dS[1:])[1]
    P = base.C.shape[0]
    out_C, out_Mu = np.empty((P, *dC.shape)), np.empty((P, *dMu.shape))
    out_C[:], out_Mu[:] = dC, dMu
    return out_C, out_Mu


@dataclass(frozen=True, eq=False)
class Parameter:
    path: str
    keys: tuple[Any, ...]
    value: float
    dC: np.ndarray | None = None
    dMu: np.ndarray | None = None
    dk: np.ndarray | None = None
    reason: str | None = None  # not computed: why
    period: bool = False


def _moved(gait: Gait, keys: tuple[Any, ...], value: float) -> Gait:
    """The gait with the number at ``keys`` set to ``value``, for a difference quotient of the
    coefficients: the fields of `_moved_fields` rebuilt alone, anything else through
    `Gait.replace`, validated like a file."""
    fields = _moved_fields(gait, keys, value)
    if fields is None:
        return gait.replace(".".join(str(k) for k in keys), value)
    return dataclasses.replace(gait, **fields)


def _moved_fields(gait: Gait, keys: tuple[Any, ...], value: float) -> dict[str, Any] | None:
    """The fields of the gait that setting the number at ``keys`` to ``value`` changes, when it
    is a link's signal, a friction signal or the stiffness (``parse_signal`` checks a signal);
    None for anything else: the gait is then not compiled anew where only its signals move
    (a number of a smooth signal needs neither: `_closed_form_change`)."""
    if keys[0] == "links" and len(keys) >= 2 and isinstance(keys[1], int):
        i = keys[1]
        links = list(gait.links)
        links[i] = _moved_signal(gait, explicit(gait.document)["links"][i], keys[2:], value, f"links[{i}]")
        return {"links": tuple(links)}
    if keys[0] == "friction" and value > 0:
        friction = _moved_friction(gait, keys, value)
        if friction is not None:
            return {"forward": friction[0], "backward": friction[1]}
    if keys[0] == "stiffness" and len(keys) <= 2 and value > 0:
        k = np.array(gait.stiffness, dtype=float)
        if len(keys) == 1:
            k[:] = value
        else:
            k[keys[1]] = value
        return {"stiffness": k}
    return None


def _moved_signal(gait: Gait, node: Any, inside: tuple[Any, ...], value: float, keypath: str) -> Any:
    """The signal of the document ``node`` with the number at ``inside`` it set to ``value``
    (the node itself when ``inside`` is empty: a constant), parsed and checked."""
    if inside:
        node = copy.deepcopy(node)
        set_value(node, inside, value)
    else:
        node = value
    return parse_signal(node, keypath, gait.source)


def _moved_friction(gait: Gait, keys: tuple[Any, ...], value: float) -> tuple[tuple[Any, ...], tuple[Any, ...]] | None:
    """mu^+ and mu^- per block with one friction number moved (``friction.forward...``, shared
    by every block, or ``friction.I.forward...``); None for another form of the block."""
    friction = _friction_keys(gait, keys)
    if friction is None:
        return None
    side, blocks, rest = friction
    node: Any = gait.document["friction"]
    node = node if isinstance(keys[1], str) else node[keys[1]]
    signal = _moved_signal(gait, node[side], rest[1:], value, ".".join(map(str, keys[: len(keys) - len(rest) + 1])))
    sides = {"forward": list(gait.forward), "backward": list(gait.backward)}
    for j in blocks:
        sides[side][j] = signal
    return tuple(sides["forward"]), tuple(sides["backward"])


def parameter_of(gait: Gait, base: Coefficients, keys: tuple[Any, ...]) -> Parameter:
    path = ".".join(str(k) for k in keys)
    node = value_at(gait.document, keys)
    if node is None and keys[-1] == "phase":
        node = 0.0
    if isinstance(node, bool) or not isinstance(node, (int, float)):
        raise GaitError(gait.source, path, f"a sensitivity needs a number, found {node!r}")
    value = float(node)
    if keys == ("period",):
        return Parameter(path, keys, value, period=True)
    if keys[0] in STRUCTURAL:
        return Parameter(path, keys, value, reason=f"{path} is not a continuous parameter of the gait")
    if keys[-1] == "angle":
        return _angle(gait, keys, path, value)
    closed = _closed_form_change(gait, base, keys)
    if closed is not None:
        return Parameter(path, keys, value, closed[0], closed[1], np.zeros_like(base.k))
    moves = f"moving {path} moves the breakpoints of c(t) or changes its form: not differentiated"
    if keys[-1] in ("phase", "phase_step"):  # a smooth signal's is closed above, a piecewise
        return Parameter(path, keys, value, reason=moves)  # one's moves its breakpoints
    h = COEFFICIENT_STEP * max(abs(value), 1.0)
    try:
        change = _change(gait, base, keys, value, h)
    except CrawlsimError as exc:
        try:
            h = -h
            change = _change(gait, base, keys, value, h)
        except CrawlsimError:
            return Parameter(path, keys, value, reason=f"the gait with {path} moved is refused: {exc}")
    if change is None:
        return Parameter(path, keys, value, reason=moves)
    dC, dMu, dk = change
    return Parameter(path, keys, value, dC / h, dMu / h, dk / h)


def _change(
    gait: Gait, base: Coefficients, keys: tuple[Any, ...], value: float, h: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The change of C, of the friction weights and of k when the number at ``keys`` moves
    from ``value`` by h; None when that moves the breakpoints of c or changes its form."""
    moved = _moved_coefficients(gait, base, keys, value + h)
    if moved.C.shape != base.C.shape or not np.array_equal(moved.edges, base.edges) or moved.basis != base.basis:
        return None
    return moved.C - base.C, moved.Mu - base.Mu, moved.k - base.k


def _angle(gait: Gait, keys: tuple[Any, ...], path: str, value: float) -> Parameter:
    """A slope's angle enters c and the friction weights through its cosine and sine, not
    affinely: a central difference of the coefficients, h = ANGLE_STEP degrees (its error
    h^2 (pi/180)^2 / 6 relative, below 1e-12; its roundoff eps |C| / h)."""
    try:
        plus = coefficients_of(gait.replace(path, value + ANGLE_STEP))
        minus = coefficients_of(gait.replace(path, value - ANGLE_STEP))
    except CrawlsimError as exc:
        return Parameter(path, keys, value, reason=f"the gait with {path} moved is refused: {exc}")
    h2 = 2 * ANGLE_STEP
    return Parameter(path, keys, value, (plus.C - minus.C) / h2, (plus.Mu - minus.Mu) / h2, (plus.k - minus.k) / h2)


def uniqueness_touch(gait: Gait, co: Coefficients) -> str | None:
    """Friction on the boundary of the uniqueness condition: some g_J(t) (docs/model.md §3)
    reaches zero without changing sign (a tangency), so that moving the friction creates or
    removes instants where the slips are not unique."""
    N = gait.blocks
    if N > UNIQUENESS_BLOCKS or not np.any(co.Mu[:, 1:, :]):
        return None  # friction constant on each piece: g_J = 0 there is refused by validation
    total = np.zeros(N)
    J = ((np.arange(2**N)[:, None] >> np.arange(N)[None, :]) & 1).astype(float)  # (2^N, N)
    for p in range(co.Mu.shape[0]):
        Mu = co.Mu[p]
        if co.basis.size == 1:
            x = np.array([0.5 * (co.edges[p] + co.edges[p + 1])])
        else:
            x = np.linspace(co.edges[p], co.edges[p + 1], 513)
        vals = co.basis.values(x) @ Mu  # (s, 2N)
        plus, minus = vals[:, :N], vals[:, N:]
        total = np.maximum(total, np.max(plus + minus, axis=0))
        g = J @ (plus + minus).T - np.sum(minus, axis=1)[None, :]  # (2^N, s)
        tol = 1e-9 * float(np.max(np.sum(plus + minus, axis=1)))
        low = np.min(np.abs(g), axis=1)
        for r in np.flatnonzero(low <= 1e-3 * tol / 1e-9):
            gr = g[r]
            i = int(np.argmin(np.abs(gr)))
            if np.all(gr >= -tol) or np.all(gr <= tol):
                # refine the minimum of |g| near sample i on the closed form
                from scipy.optimize import minimize_scalar

                coefs = (J[r] @ (Mu[:, :N] + Mu[:, N:]).T) - np.sum(Mu[:, N:], axis=1)
                lo, hi = x[max(i - 1, 0)], x[min(i + 1, len(x) - 1)]
                if hi > lo:
                    res = minimize_scalar(
                        lambda v, z=coefs: abs(co.basis.scalar(v, z)),
                        bounds=(lo, hi),
                        method="bounded",
                        options={"xatol": 1e-12},
                    )
                    val = float(res.fun)
                else:
                    val = abs(float(gr[i]))
                if val <= tol:
                    blocks = [j + 1 for j in range(N) if J[r, j]]
                    return (
                        f"the friction is on the boundary of the uniqueness condition: "
                        f"g_J touches zero at t/T = {x[i]:.6g} for J = {blocks}"
                    )
    return None
