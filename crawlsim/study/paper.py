"""Reproduce the paper's convergence results with crawlsim: each claim, what was measured, pass/fail.

The claims (the paper of Colombo, Gidoni & Vilches; docs/model.md §4-5):

* **Theorem th:1dim / Corollary cor:cell.** Every solution of a sweeping process on a periodic
  n-cell (a product of intervals) is T-periodic on [T, oo), whatever its start; Theorem th:1dim
  applied to a two-block crawler says the same of its motion.
* **Acute angle (Section 5.2, ex:small).** With C(t) = C0 - l(t), C0 = {0 <= z2 <= alpha z1,
  z1 <= beta}, the corrected l(t) = (0, t) on [0, T/2] and (0, T - t) on [T/2, T] (docs/model.md,
  Correction 2), and alpha gamma = T/2, the Poincare map on the edge z2 = 0 is
  ``z1 -> (alpha^2 gamma + z1) / (alpha^2 + 1)`` for z1 < gamma and the identity for
  z1 >= gamma. It contracts by 1/(1 + alpha^2), so the convergence is only asymptotic.
* **Triangle (Section 5.3, ex:large).** C(t) = PQR - F(t), with F the primitive of
  f = alpha nu_k on the k-th third of the period. For alpha T large the point is carried from
  edge to edge, PQ -> QR -> RP -> PQ, each time by ``phi(s) = (1 - s)/2`` in the edges' arc
  parameter s in [0, 1]; one period is phi^3(s) = (3 - s)/8, which contracts by 1/8 towards its
  unique fixed point s = 1/3.
* **Theorem th:speed.** A crawler's average velocity v0 does not depend on the start, its
  periods converge in W^{1,2}, and all its periodic solutions share one derivative.

Each check function returns `Check` rows; ``python -m crawlsim.study.paper`` prints them as a table
(``scripts/reproduce-paper.sh``) and the tests assert the same numbers.

Why catch-up stepping reproduces the closed forms to roundoff here: in every example the point is
pushed by one translating face at a time, whose offset is linear between breakpoints, and the
breakpoints are on the grid. The exact solution then is the projection of the point onto the
face's current position (the face moves along its own normal), which is what a catch-up step
computes, whether or not the first contact falls on a grid point. The iterates therefore agree
with the paper's maps to a few ulps, on any grid.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from crawlsim.gait.crawler_spec import admissibility_violation
from crawlsim.gait.document import Gait, ProcessSpec, gait_from_document, load_gait, with_simulation
from crawlsim.integrate.stepping import STEPPERS, make_stepper
from crawlsim.model.process import compile
from crawlsim.study.simulation import SimulationResult, run

#: Where the paper's example files live: ``gaits/paper`` of the repository, relative to the
#: working directory (``scripts/reproduce-paper.sh`` runs from the repository's root).
PAPER_GAITS = Path("gaits") / "paper"

#: Agreement with a closed form that only roundoff separates from the computation, relative to
#: the problem's size (a few thousand ulps over a hundred periods).
ROUNDOFF_MATCH = 1e-12


@dataclass(frozen=True)
class Check:
    """One row of the reproduction table. ``error`` is the measured deviation from the claim
    (0 when the claim is exact), ``tolerance`` what is accepted."""

    claim: str
    measured: str
    error: float
    tolerance: float

    @property
    def ok(self) -> bool:
        return bool(self.error <= self.tolerance)


# --------------------------------------------------------------------------------------------
# Example documents


def acute_angle_document(
    alpha: float = 1.0,
    period: float = 1.0,
    start: float = 0.1,
    beta: float | None = None,
    steps: int = 64,
    max_periods: int = 400,
) -> dict:
    """The process of Section 5.2 with the corrected l(t) (docs/model.md, Correction 2).

    C0 = {0 <= z2 <= alpha z1, z1 <= beta} has rows b = (0, -1), (-alpha, 1), (1, 0) with
    offsets (0, 0, beta). z in C0 - l(t) iff z + l(t) in C0 iff <b_i, z> <= c0_i - <b_i, l(t)>,
    so with l = (0, l2): c = (l2, -l2, beta), l2 rising from 0 to T/2 at mid-period and back.
    beta defaults to twice the larger of gamma and T alpha / 2 (the paper needs beta > gamma and
    2 beta > T alpha; the face z1 <= beta only makes C0 compact, and is never touched then).
    The start is (start, 0).
    """
    gamma = period / (2 * alpha)
    beta = 2 * max(gamma, period * alpha / 2) if beta is None else beta
    l2 = {"kind": "piecewise-linear", "times": [0, 0.5, 1], "values": [0, period / 2, 0]}
    minus_l2 = {"kind": "piecewise-linear", "times": [0, 0.5, 1], "values": [0, -period / 2, 0]}
    return {
        "kind": "sweeping-process",
        "name": f"acute-angle-alpha-{alpha:g}",
        "description": f"paper Section 5.2: acute angle, alpha = {alpha:g}, T = {period:g}",
        "period": period,
        "normals": [[0.0, -1.0], [-alpha, 1.0], [1.0, 0.0]],
        "offsets": [l2, minus_l2, beta],
        "initial": [start, 0.0],
        "simulation": {"steps_per_period": steps, "max_periods": max_periods, "tolerance": 1e-12},
    }


def acute_angle_map(z1: float, alpha: float, period: float = 1.0) -> float:
    """The paper's Poincare map on the edge z2 = 0 (Section 5.2)."""
    gamma = period / (2 * alpha)
    return (alpha**2 * gamma + z1) / (alpha**2 + 1) if z1 < gamma else z1


_NU = np.array([[0.0, -1.0], [math.sqrt(3) / 2, 0.5], [-math.sqrt(3) / 2, 0.5]])
"""Outward unit normals nu_1, nu_2, nu_3 of the edges PQ, QR, RP (Section 5.3)."""


def triangle_vertices(side: float = 1.0) -> np.ndarray:
    """P, Q, R of the equilateral triangle with its centroid at 0 and PQ horizontal at the bottom."""
    r = side / (2 * math.sqrt(3))  # inradius: every edge is at distance r from the centroid
    return np.array([[-side / 2, -r], [side / 2, -r], [0.0, 2 * r]])


def triangle_document(
    alpha: float = 3.0,
    period: float = 1.0,
    side: float = 1.0,
    start=(0.1, 0.05),
    steps: int = 60,
    max_periods: int = 100,
) -> dict:
    """The process of Section 5.3 as a moving set C(t) = PQR - F(t).

    PQR = {z : <nu_i, z> <= r} (r the inradius), so z in C(t) iff <nu_i, z> <= r - <nu_i, F(t)>.
    F is the primitive of f = alpha nu_k on the k-th third, F(0) = 0; with a = alpha T / 3 and
    <nu_i, nu_j> = -1/2 for i != j, F = a nu_1 at T/3, a (nu_1 + nu_2) = -a nu_3 at 2T/3 and 0
    at T, so the offsets are piecewise linear with knots at thirds:
    c_1 = r - (0, a, a/2, 0), c_2 = r - (0, -a/2, a/2, 0), c_3 = r - (0, -a/2, -a, 0).
    A third's travel a must exceed the triangle's height for "alpha T sufficiently large".
    """
    r = side / (2 * math.sqrt(3))
    a = alpha * period / 3
    knots = [0, 1 / 3, 2 / 3, 1]
    shifts = ([0, a, a / 2, 0], [0, -a / 2, a / 2, 0], [0, -a / 2, -a, 0])
    return {
        "kind": "sweeping-process",
        "name": "equilateral-triangle",
        "description": f"paper Section 5.3: equilateral triangle of side {side:g} swept by "
        f"f = alpha nu_k on each third, alpha = {alpha:g}, T = {period:g}",
        "period": period,
        "normals": _NU.tolist(),
        "offsets": [{"kind": "piecewise-linear", "times": knots, "values": [r - s for s in shift]} for shift in shifts],
        "initial": [float(x) for x in start],
        "simulation": {"steps_per_period": steps, "max_periods": max_periods, "tolerance": 1e-12},
    }


def triangle_shift(t: np.ndarray, alpha: float = 3.0, period: float = 1.0) -> np.ndarray:
    """F(t), the primitive of f with F(0) = 0, at times t (shape (k, 2))."""
    u = np.mod(np.asarray(t, dtype=float) / period, 1.0)
    a = alpha * period / 3
    knots = np.array([0.0, 1 / 3, 2 / 3, 1.0])
    values = np.array([[0.0, 0.0], a * _NU[0], -a * _NU[2], [0.0, 0.0]])
    return np.column_stack([np.interp(u, knots, values[:, 0]), np.interp(u, knots, values[:, 1])])


def edge_parameter(p: np.ndarray, edge: int, side: float = 1.0) -> tuple[float, float]:
    """Arc parameter s in [0, 1] of point p (in the triangle's own frame) along edge PQ, QR or
    RP (edge 0, 1, 2, each run from its first vertex), and p's distance from that edge's line."""
    V = triangle_vertices(side)
    a, b = V[edge], V[(edge + 1) % 3]
    s = float(np.dot(p - a, b - a) / np.dot(b - a, b - a))
    return s, float(np.dot(p - a, _NU[edge]))


def phi(s):
    """The edge-to-edge map of Section 5.3."""
    return (1 - s) / 2


def _with(spec, **changes):
    """A copy of a validated file with top-level keys changed, validated again."""
    doc = copy.deepcopy(spec.document)
    doc.update(changes)
    return gait_from_document(doc, spec.source, default_name=spec.name)


def _steps(spec, steps):
    return spec if steps is None else with_simulation(spec, steps_per_period=steps)


def _periods(spec, count: int, integrator: str = "catch-up"):
    """The first ``count`` period records of ``spec``'s process, from the stepping engine."""
    stepper = make_stepper(compile(spec), integrator)
    return [stepper.step_period() for _ in range(count)]


def _exact_available() -> bool:
    if "exact" not in STEPPERS:
        return False
    module = STEPPERS["exact"].target.split(":")[0]
    try:
        __import__(module)
    except ModuleNotFoundError as exc:
        if exc.name == module:
            return False
        raise
    return True


# --------------------------------------------------------------------------------------------
# Theorem th:1dim / Corollary cor:cell


def cell_checks(path: Path | None = None, starts=None, steps: int | None = None, periods: int = 4) -> list[Check]:
    """Periodic after one period from several starts: every later period's trajectory equals
    period 1's (sup distance 0), while period 0 moved the point; `crawlsim run` calls it
    finite-time from period 1 at the latest."""
    spec = _steps(load_gait(path or PAPER_GAITS / "cell-3.yaml"), steps)
    starts = (
        starts if starts is not None else [spec.initial.tolist(), [0.1, -0.9, 0.0], [0.45, 0.9, -0.5], [0.35, 0.0, 0.5]]
    )
    rows = []
    for start in starts:
        started = _with(spec, initial=list(start))
        records = _periods(started, periods)
        moved = float(np.linalg.norm(records[0].w[-1] - records[0].w[0]))
        later = max(float(np.max(np.abs(r.w - records[1].w))) for r in records[2:])
        result = run(started)
        verdict = result.periodic_from is not None and result.periodic_from <= 1
        rows.append(
            Check(
                f"cor:cell ({spec.name}, z(0) = {_vec(start)}): T-periodic on [T, oo)",
                f"|z(T) - z(0)| = {moved:.3g}; sup |z(t + qT) - z(t + T)| over periods q = "
                f"2..{periods - 1} = {later:.3g}; crawlsim run: {result.convergence} from period "
                f"{result.periodic_from}",
                later + (0.0 if verdict else math.inf),
                ROUNDOFF_MATCH * _size(result),
            )
        )
    return rows


def two_block_checks(path: Path | None = None, shapes=(1.2, 1.25, 1.3, 1.4), steps: int | None = None) -> list[Check]:
    """Theorem th:1dim for a two-block crawler (one link): periodic from T for several starts,
    given as the initial link length z = x2 - x1 (admissible: |k (L(0) - z)| within friction)."""
    gait = _steps(load_gait(path or PAPER_GAITS.parent / "inching-2.yaml"), steps)
    rows = []
    for z in shapes:
        result = run(_with(gait, initial={"positions": [0.0, float(z)]}))
        steps_ = result.history.poincare_step
        error = float(steps_[1]) if len(steps_) > 1 else 0.0
        rows.append(
            Check(
                f"th:1dim ({gait.name}, two blocks, z(0) = {z:g}): periodic from T",
                f"|w(T) - w(0)| = {steps_[0]:.3g}, |w(2T) - w(T)| = {error:.3g}; "
                f"{result.convergence} from period "
                f"{result.periodic_from}; v0 = {result.v0:.12g}",
                error + (0.0 if result.periodic_from is not None and result.periodic_from <= 1 else math.inf),
                ROUNDOFF_MATCH * _size(result),
            )
        )
    return rows


# --------------------------------------------------------------------------------------------
# Section 5.2: the acute angle


def acute_angle_iterates(
    alpha: float, start: float, periods: int, period: float = 1.0, steps: int = 64, integrator: str = "catch-up"
) -> np.ndarray:
    """z(qT), q = 0..periods, computed by crawlsim (shape (periods + 1, 2))."""
    spec = gait_from_document(acute_angle_document(alpha, period, start, steps=steps), "<acute-angle>")
    records = _periods(spec, periods, integrator)
    return np.vstack([records[0].w[0]] + [r.w[-1] for r in records])


def acute_angle_checks(
    alphas=(0.5, 1.0, 2.0),
    fractions=(0.0, 0.4, 0.9, 1.5),
    periods: int = 12,
    period: float = 1.0,
    steps: int = 64,
    integrator: str = "catch-up",
) -> list[Check]:
    """Iterate by iterate against the paper's map, for several alpha and starts z1 = f gamma
    (f >= 1: a fixed point), and the contraction rate 1/(1 + alpha^2)."""
    rows = []
    for alpha in alphas:
        gamma = period / (2 * alpha)
        worst, worst_z2 = 0.0, 0.0
        for f in fractions:
            z = acute_angle_iterates(alpha, f * gamma, periods, period, steps, integrator)
            expected = [f * gamma]
            for _ in range(periods):
                expected.append(acute_angle_map(expected[-1], alpha, period))
            worst = max(worst, float(np.max(np.abs(z[:, 0] - expected))))
            worst_z2 = max(worst_z2, float(np.max(np.abs(z[:, 1]))))
        label = "" if integrator == "catch-up" else f" [integrator {integrator}]"
        rows.append(
            Check(
                f"acute angle alpha = {alpha:g}, T = {period:g}{label}: z1(qT) = P^q(z1(0)) with "
                f"P(z1) = (alpha^2 gamma + z1)/(alpha^2 + 1), z2(qT) = 0; {periods} iterates from "
                f"z1(0)/gamma = {', '.join(f'{f:g}' for f in fractions)}",
                f"max |z1 - P^q| = {worst:.2g}, max |z2| = {worst_z2:.2g}",
                max(worst, worst_z2),
                ROUNDOFF_MATCH * max(gamma, 1.0),
            )
        )
        if integrator != "catch-up":
            continue
        result = acute_angle_run(alpha, 0.0, period, steps)
        poincare = result.history.poincare_step
        usable = poincare[poincare > 1e-6 * poincare[0]]
        ratios = usable[1:] / usable[:-1]
        rate = 1 / (1 + alpha**2)
        rows.append(
            Check(
                f"acute angle alpha = {alpha:g}: the Poincare step contracts by 1/(1 + alpha^2) = "
                f"{rate:.6g} per period (z1(0) = 0)",
                f"ratios of successive Poincare steps {np.min(ratios):.12g}..{np.max(ratios):.12g} "
                f"({len(ratios)} periods)",
                float(np.max(np.abs(ratios - rate))),
                1e-8,
            )
        )
        fitted = None if result.rate is None else result.rate.rate
        rows.append(
            Check(
                f"acute angle alpha = {alpha:g}: convergence is asymptotic only, rate {rate:.6g}",
                f"crawlsim run: {result.convergence} after {result.periods} periods, reported "
                f"contraction rate {_num(fitted)}",
                (math.inf if fitted is None or result.convergence != "asymptotic" else abs(fitted - rate) / rate),
                1e-3,
            )
        )
    return rows


def acute_angle_run(alpha: float, start: float = 0.0, period: float = 1.0, steps: int = 64) -> SimulationResult:
    spec = gait_from_document(acute_angle_document(alpha, period, start, steps=steps), "<acute-angle>")
    return run(spec)


# --------------------------------------------------------------------------------------------
# Section 5.3: the triangle


def triangle_edges(
    spec: ProcessSpec, periods: int, alpha: float, side: float = 1.0, integrator: str = "catch-up"
) -> np.ndarray:
    """Arc parameters and distances on the edge reached at the end of each third:
    rows (s, distance) at T/3 on PQ, 2T/3 on QR, T on RP, then the next period..."""
    records = _periods(spec, periods, integrator)
    T = spec.period
    times = compile(spec).times
    out = []
    for rec in records:
        for edge, third in enumerate((1 / 3, 2 / 3, 1.0)):
            j = int(np.argmin(np.abs(times - third * T)))
            p = rec.w[j] + triangle_shift(np.array([third * T]), alpha, T)[0]
            out.append(edge_parameter(p, edge, side))
    return np.array(out)


def triangle_checks(
    path: Path | None = None, starts=None, periods: int = 10, steps: int | None = None, integrator: str = "catch-up"
) -> list[Check]:
    """phi on every third, the 1/8 contraction of phi^3 and its unique fixed point 1/3."""
    spec = _steps(load_gait(path or PAPER_GAITS / "triangle.yaml"), steps)
    alpha = _triangle_alpha(spec)
    starts = starts if starts is not None else [spec.initial.tolist(), [-0.3, -0.2], [0.0, 0.5], [0.45, -0.25]]
    label = "" if integrator == "catch-up" else f" [integrator {integrator}]"
    phi_error, on_edge, contraction = 0.0, 0.0, 0.0
    ratios = []
    for start in starts:
        edges = triangle_edges(_with(spec, initial=list(start)), periods, alpha, integrator=integrator)
        s = edges[:, 0]
        on_edge = max(on_edge, float(np.max(np.abs(edges[:, 1]))))
        phi_error = max(phi_error, float(np.max(np.abs(s[1:] - phi(s[:-1])))))
        pq = s[0::3]
        dev = np.abs(pq - 1 / 3)
        good = dev[:-1] > 1e-6 * dev[0]
        if np.any(good):
            r = dev[1:][good] / dev[:-1][good]
            ratios.extend(r.tolist())
            contraction = max(contraction, float(np.max(np.abs(r - 1 / 8))))
    rows = [
        Check(
            f"triangle{label}: edge map phi(s) = (1 - s)/2 at every third, the point on the "
            f"edge ({len(starts)} starts, {periods} periods)",
            f"max |s' - phi(s)| = {phi_error:.2g}, max distance to the edge = {on_edge:.2g}",
            max(phi_error, on_edge),
            ROUNDOFF_MATCH,
        ),
        Check(
            f"triangle{label}: one period is phi^3, |s - 1/3| contracts by 1/8",
            f"ratios {min(ratios):.12g}..{max(ratios):.12g} ({len(ratios)} periods)",
            contraction,
            1e-8,
        ),
    ]
    if integrator != "catch-up":
        return rows
    limits, converged = [], True
    for start in starts:
        result = run(_with(spec, initial=list(start)))
        converged &= result.convergence == "asymptotic"
        limits.append(result.limit.w[-1])
        rate = None if result.rate is None else result.rate.rate
    s_limit = edge_parameter(limits[0], 2)[0]
    spread = float(max(np.linalg.norm(w - limits[0]) for w in limits))
    rows.append(
        Check(
            "triangle: phi^3 has the unique fixed point s = 1/3; every start converges to it, only asymptotically",
            f"limit s on RP = {s_limit:.15g} (|s - 1/3| = {abs(s_limit - 1 / 3):.2g}), spread of "
            f"the limits over starts = {spread:.2g}; fitted rate {_num(rate)}; all asymptotic: "
            f"{converged}",
            max(abs(s_limit - 1 / 3), spread) + (0.0 if converged else math.inf),
            1e-10,
        )
    )
    return rows


def _triangle_alpha(spec: ProcessSpec) -> float:
    """alpha from the offsets: c_1 falls by a = alpha T / 3 over the first third."""
    c = spec.offset_values(np.array([0.0, spec.period / 3]))
    return float(3 * (c[0, 0] - c[1, 0]) / spec.period)


# --------------------------------------------------------------------------------------------
# Theorem th:speed


def admissible_starts(gait: Gait, count: int, seed: int = 5) -> list[np.ndarray]:
    """The file's start and random admissible ones: stresses drawn inside C(0), kept when
    `admissibility_violation` accepts them."""
    rng = np.random.default_rng(seed)
    zero = np.zeros(1)
    L0 = gait.lengths(zero)[0]
    mu = min(float(gait.mu_plus(zero).min()), float(gait.mu_minus(zero).min()))
    starts = [np.asarray(gait.initial_positions, dtype=float)]
    while len(starts) < count:
        sigma = rng.uniform(-mu, mu, size=gait.blocks - 1)
        z = L0 - sigma / gait.stiffness
        x = np.concatenate([[0.0], np.cumsum(z)])
        if admissibility_violation(gait, x) is None:
            starts.append(x)
    return starts


def w12_distances(records, times: np.ndarray) -> np.ndarray:
    """W^{1,2}(0, T) distance of each period's w to the last one's, on the grid ``times``.

    As in `crawlsim.analysis.run`: with e = w_q - w_last, ||e||_{L2}^2 by the trapezoidal rule and
    ||e'||_{L2}^2 = sum |e_{j+1} - e_j|^2 / h_j (the catch-up interpolant is piecewise linear).
    """
    h = np.diff(times)
    last = records[-1].w
    out = []
    for rec in records:
        e = rec.w - last
        e2 = np.sum(e * e, axis=1)
        l2 = float(np.sum(h * (e2[1:] + e2[:-1]) / 2))
        h1 = float(np.sum(np.sum(np.diff(e, axis=0) ** 2, axis=1) / h))
        out.append(math.sqrt(l2 + h1))
    return np.array(out)


def speed_checks(path: Path | None = None, count: int = 4, steps: int | None = None, periods: int = 6) -> list[Check]:
    """Theorem th:speed: one v0 from several starts; the periods converge in W^{1,2}; the limit
    periods from different starts share their derivative."""
    gait = _steps(load_gait(path or PAPER_GAITS / "speed-peristalsis-4.yaml"), steps)
    results = [run(_with(gait, initial={"positions": x.tolist()})) for x in admissible_starts(gait, count)]
    v0 = np.array([r.v0 for r in results])
    bound = max(max(r.estimate.error_estimate or 0.0 for r in results), ROUNDOFF_MATCH * np.max(np.abs(v0)))
    spread = float(np.ptp(v0))
    h = np.diff(results[0].limit.t)
    dw = [np.diff(r.limit.w, axis=0) for r in results]
    derivative = max(math.sqrt(float(np.sum(np.sum((d - dw[0]) ** 2, axis=1) / h))) for d in dw)
    scale = math.sqrt(float(np.sum(np.sum(dw[0] ** 2, axis=1) / h)))
    times = compile(gait).times
    distances = np.array(
        [
            w12_distances(_periods(_with(gait, initial={"positions": x.tolist()}), periods), times)
            for x in admissible_starts(gait, count)
        ]
    )  # (starts, periods)
    tail = float(np.max(distances[:, -2]))
    shown = ", ".join(f"{d:.3g}" for d in np.max(distances, axis=0))
    return [
        Check(
            f"th:speed ({gait.name}): v0 does not depend on the start ({count} admissible starts)",
            f"v0 = {', '.join(f'{v:.12g}' for v in v0)}; spread {spread:.2g} (error estimate {bound:.2g})",
            spread,
            2 * bound + ROUNDOFF_MATCH * np.max(np.abs(v0)),
        ),
        Check(
            f"th:speed ({gait.name}): w(. + qT) converges in W^{{1,2}}(0, T)",
            f"W12 distance of periods q = 0..{periods - 1} to period {periods - 1}, worst over the starts: {shown}",
            tail,
            ROUNDOFF_MATCH * max(float(np.max(distances[:, 0])), 1.0),
        ),
        Check(
            f"th:speed ({gait.name}): all periodic solutions share one derivative",
            f"max ||d/dt (wbar_i - wbar_0)||_L2 = {derivative:.2g} (||d/dt wbar_0||_L2 = {scale:.3g})",
            derivative,
            1e-9 * max(scale, 1.0),
        ),
    ]


# --------------------------------------------------------------------------------------------
# The table


def all_checks(quick: bool = False, folder: Path = PAPER_GAITS) -> list[Check]:
    """Every row of the reproduction, from the files in ``folder`` (and ``folder/../inching-2``).
    ``quick`` uses coarser grids (the tests' setting)."""
    folder = Path(folder)
    steps = 120 if quick else None
    rows = cell_checks(folder / "cell-3.yaml", steps=steps)
    rows += two_block_checks(folder.parent / "inching-2.yaml", steps=steps)
    rows += acute_angle_checks()
    rows += triangle_checks(folder / "triangle.yaml", steps=steps)
    if _exact_available():
        rows += acute_angle_checks(integrator="exact")
        rows += triangle_checks(folder / "triangle.yaml", steps=steps, integrator="exact")
    rows += speed_checks(folder / "speed-peristalsis-4.yaml", steps=steps)
    return rows


def format_table(rows: list[Check]) -> str:
    """A Markdown table: claim, measured, pass/fail (a ``|`` inside a cell is escaped)."""
    lines = ["| paper's claim | crawlsim measured | result |", "|---|---|---|"]
    for row in rows:
        claim, measured = (text.replace("|", "\\|") for text in (row.claim, row.measured))
        lines.append(f"| {claim} | {measured} | {'pass' if row.ok else 'FAIL'} |")
    passed = sum(row.ok for row in rows)
    lines.append("")
    lines.append(f"{passed} of {len(rows)} checks pass.")
    if not _exact_available():
        lines.append(
            "The event-driven integrator (`integrator: exact`) is not available; its comparison rows were skipped."
        )
    return "\n".join(lines)


def _vec(v) -> str:
    return "(" + ", ".join(f"{x:g}" for x in v) + ")"


def _num(x) -> str:
    return "n/a" if x is None else f"{x:.8g}"


def _size(result: SimulationResult) -> float:
    return max(float(np.max(np.abs(result.limit.w))), 1.0)


def main(argv=None) -> int:
    import argparse

    parser = argparse.ArgumentParser(
        prog="python -m crawlsim.study.paper",
        description="Reproduce the paper's Section 5 and Theorem th:speed; print the table.",
    )
    parser.add_argument("--quick", action="store_true", help="coarser grids (seconds)")
    parser.add_argument(
        "--gaits", type=Path, default=PAPER_GAITS, help="folder of the paper's example files (default: gaits/paper)"
    )
    args = parser.parse_args(argv)
    rows = all_checks(quick=args.quick, folder=args.gaits)
    print(format_table(rows))
    return 0 if all(row.ok for row in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
