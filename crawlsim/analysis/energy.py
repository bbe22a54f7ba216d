"""The energy ledger of a crawler's period: actuator work, dissipation, jump losses
(docs/model.md §1-§4).

**Sign convention.** The stress is positive in compression, ``sigma = K (L(t) - z)`` (§1), and
the *actuator work* is the work done BY the actuators ON the body,

    W = sum_i  oint sigma_i dL_i,

positive when the actuators pay energy in: an actuator that lengthens against a compressed
spring (``sigma_i > 0``, ``dL_i > 0``) does positive work. For a crawler that moves, W > 0.

**The balance.** The elastic energy is ``E = sum_i sigma_i^2 / (2 k_i)``. Along the flow,

    dE/dt = sum_i sigma_i (Ldot_i - zdot_i) = sigma . Ldot - sigma . zdot,

and ``sigma . zdot = sigma . D xdot = (D^T sigma) . xdot = f . xdot``. A block moves forward
only at ``f_j = mu_j^+`` and backward only at ``f_j = -mu_j^-`` (§1), so ``f . xdot =
sum_j mu_j^+ (xdot_j)^+ + mu_j^- (xdot_j)^-``, the dissipation rate R(t, xdot) >= 0. Hence
``W = D + E(end) - E(start)`` over any interval on which the motion is continuous.

**Jumps.** Where a ``steps`` signal jumps (friction switched, or an actuator length that jumps),
the stress can lie outside the new admissible set C(t+); the blocks then slip instantaneously,
by the projection of the state onto K(t+) in the metric K^{-1} (§3, and `crawlsim.integrate.exact`). Let
``sigma^-`` be the stress just before, ``sigma^tr = sigma^- + K (L(t+) - L(t-))`` the stress with
the actuators moved and the blocks held (an actuator jump does the work ``E(sigma^tr) -
E(sigma^-)`` along that elastic path), and ``sigma^+`` the projected stress, with slips ``dx``
(the projection's multipliers) and ``z^+ - z^- = D dx``. Expanding the square,

    E(sigma^tr) - E(sigma^+) = sigma^+ . D dx + 1/2 |sigma^tr - sigma^+|^2_{K^-1}
                             = f^+ . dx + sum_i k_i (z^+_i - z^-_i)^2 / 2,

since ``sigma^tr - sigma^+ = -K (z^+ - z^-)``. The first term is the friction work of the slip
at the limits in force after the switch (complementarity, as in catch-up): crawlsim books it to
the dissipation, as ``dissipation_per_period`` always has. The second is the **jump loss**: the
elastic energy the instantaneous slip releases beyond any friction work, ``sum_i k_i
(Delta z_i)^2 / 2 >= 0``. Over one period of the periodic regime E is periodic, so

    W = D + J        (D: dissipation, J: jump losses),

and `PeriodEnergy.residual` ``W - D - J`` is the balance residual (it equals ``E(end) -
E(start)``, zero in the periodic regime, up to roundoff).

**The exact integrator** (`crawlsim.integrate.exact`) moves on pieces with a fixed active set A, on which
``w(u) = base + phi(u) @ Wc``, the slips ``Lambda_A(u) = lam0 - phi(u) @ Y`` and the signals
``L(u) = phi(u) @ Lc``, ``mu(u) = phi(u) @ Mc`` are combinations of one basis ``phi = [1, u,
cos 2 pi h u, sin 2 pi h u]`` of the cycle u = t/T (`crawlsim.model.offsets`). So on a piece

    W_piece = sum_i int sigma_i(u) L_i'(u) du = sum (Sc * (P @ Lc')),
    D_piece = sum_{r in A} int mu_r(u) lambda_r(u) du = -sum (Mc_A * (P @ Y')),

with ``Sc = Wc + Lc K`` (plus ``base`` in the constant row) the coefficients of sigma, primes
the exact derivative maps of the basis, and ``P[k, l] = int_{u0}^{u1} phi_k phi_l du`` the Gram
matrix of the basis on the piece, in closed form (`gram`). The two are computed independently
(D from the friction signals and the slip rates, W from the stresses and the actuators), so
their balance checks the trajectory: the active rows sit at their friction limits. The
integrals are exact up to roundoff: no quadrature, only the closed forms of ``int u^a``
(a <= 2), ``int u^a cos``, ``int u^a sin`` (a <= 1) and of products of harmonics.

**Catch-up** (`crawlsim.integrate.stepping`) moves on the grid by the elastic predictor (actuators to
``L^{n+1}``, blocks held: ``sigma^tr = sigma^n + K (L^{n+1} - L^n)``) and the friction corrector
(the K^{-1}-projection onto C(t_{n+1})), which is a jump of the kind above at every step. The
consistent discrete ledger is therefore

    W_h = sum_n (sigma^n + K Delta L^n / 2) . Delta L^n        (work along the predictor),
    D_h = sum_n lambda^{n+1} . mu(t_{n+1})                      (``dissipation_per_period``),
    J_h = sum_n sum_i k_i (z^{n+1}_i - z^n_i)^2 / 2,

and ``W_h = D_h + J_h + E^G - E^0`` holds exactly for the scheme (each step is the jump identity
above). Away from jumps ``Delta z = O(h)``, so J_h there is the scheme's numerical dissipation,
first order in h: it is reported apart, as the **discretisation loss**, and only the steps that
end at a jump of a ``steps`` signal are booked as jump losses, to which they converge; W_h and
D_h converge to W and D at first order.
(The right-endpoint sum ``sum_n sigma^{n+1} . Delta L^n`` balances too, with
``sum_n |sigma^{n+1} - sigma^n|^2_{K^-1} / 2`` in place of J_h, by ``|a|^2/2 - |b|^2/2 = <a, a -
b> - |a - b|^2/2``; but at a jump of an actuator length that term also holds the elastic work of
the jump, so it does not converge to the jump loss. The predictor form splits work and loss as
the exact integrator does.)

**The bound on the cost of transport.** Over a period of the periodic regime every block moves by
the period displacement d. A block that ends d > 0 ahead slipped forward by at least d, each
forward slip dissipating at least ``min_t mu_j^+(t)`` per length, so

    D >= sum_j min_t mu_j^+(t) * d   (d > 0),      D >= sum_j min_t mu_j^-(t) * |d|   (d < 0),

that is ``cost_of_transport >= cost_of_transport_bound``. The **efficiency** is their ratio,
``bound / cost_of_transport`` in (0, 1]: 1 for a gait whose blocks only ever slip one way at
constant friction (two-block inching). The minima are exact (`friction_minimum`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from crawlsim.gait.signals import (
    JUMP_TOLERANCE,
    Constant,
    Cosine,
    Fourier,
    PiecewiseLinear,
    Signal,
    Steps,
    union_breakpoints,
)
from crawlsim.integrate.ledger import PeriodEnergy
from crawlsim.integrate.stepping import PeriodRecord
from crawlsim.model.offsets import TWO_PI
from crawlsim.model.process import SweepingProcess


@dataclass(frozen=True)
class EnergyLedger:
    """What a run reports of its limit period's dissipation and energy (`ledger`)."""

    dissipation: float  # D, with its error estimate (None where v0's time-step error is unknown)
    dissipation_error_estimate: float | None
    cost_of_transport: float | None  # (D + W_load) / |displacement|; None without net motion
    actuator_work: float
    jump_loss: float
    balance_residual: float  # W - D - J - W_load (- the discretisation loss) on the limit period
    cost_of_transport_bound: float | None  # force; None without a direction of motion or with loads
    efficiency: float | None  # bound / cost of transport; with loads W_load / W
    load_work: float | None = None  # W_load; None without loads
    discretisation_loss: float | None = None  # catch-up's numerical loss; None for exact


# -- a period's ledger, either integrator ----------------------------------------------------------
def catch_up_energy(process: SweepingProcess, record: PeriodRecord) -> PeriodEnergy:
    """The discrete ledger of a catch-up period (module docstring): W_h along the elastic
    predictor, D_h with the friction at the step's end, J_h = sum_n sum_i k_i (Delta z_i)^2/2."""
    crawler = process.crawler
    assert crawler is not None
    k = crawler.stiffness
    sigma = crawler.stress(record.w)
    dL = np.diff(crawler.lengths, axis=0)
    work = math.fsum(np.sum((sigma[:-1] + 0.5 * k * dL) * dL, axis=1))
    dissipation = period_dissipation(process, record)
    dw = np.diff(record.w, axis=0)
    loss = np.sum(dw * dw / (2.0 * k), axis=1)
    jumps = _jump_steps(process)
    return PeriodEnergy(
        work,
        dissipation,
        math.fsum(loss[jumps]),
        crawler.elastic_energy(sigma[0]),
        crawler.elastic_energy(sigma[-1]),
        crawler.load_work(record.multipliers),
        math.fsum(loss[~jumps]),
    )


def _jump_steps(process: SweepingProcess) -> np.ndarray:
    """The catch-up steps that end at a jump of a ``steps`` signal (a grid point, since the
    breakpoints are: `crawlsim.model.process.period_grid`), a mask over the steps."""
    assert process.offset_pieces is not None
    jumps = union_breakpoints([s.breakpoints() for s in process.offset_pieces.signals if isinstance(s, Steps)])
    ends = np.mod(process.cycles[1:], 1.0)  # a jump at u = 0 ends the period's last step
    gap = np.abs(ends[:, None] - jumps[None, :])
    return np.any(np.minimum(gap, 1.0 - gap) <= JUMP_TOLERANCE, axis=1)


def period_energy(process: SweepingProcess, record: PeriodRecord) -> PeriodEnergy | None:
    """The ledger of one period: the exact integrator's (carried by its record), else the
    catch-up ledger on the grid; None for a generic sweeping process."""
    if process.crawler is None:
        return None
    energy = getattr(record, "energy", None)
    return energy if energy is not None else catch_up_energy(process, record)


def period_dissipation(process: SweepingProcess, record: PeriodRecord) -> float:
    """The friction dissipation of one period (exact for the exact integrator, whose record
    carries it; the grid sum ``sum_n lambda^{n+1} . mu(t_{n+1})`` for catch-up)."""
    energy = getattr(record, "energy", None)
    if energy is not None:
        return float(energy.dissipation)
    assert process.crawler is not None
    return process.crawler.dissipation(record.multipliers)


# -- friction minima and the bound ---------------------------------------------------------------
def _trig_minimum(mean: float, a: np.ndarray, b: np.ndarray) -> float:
    """min over v of mean + sum_n a_n cos(n v) + b_n sin(n v).

    The minimum is at a zero of the derivative ``sum_n n (b_n cos n v - a_n sin n v)``; with
    ``z = e^{iv}`` that is ``z^{-H} p(z)`` for a polynomial p of degree 2H, whose roots on the unit
    circle give every critical point (numpy's companion-matrix roots, polished by Newton steps
    on the derivative). Every candidate value is a value of the function, so the result is
    never below the true minimum, and it is the minimum up to roundoff.
    """
    H = len(a)
    n = np.arange(1, H + 1)

    def f(v):
        v = np.atleast_1d(v)[:, None]
        return mean + np.cos(n * v) @ a + np.sin(n * v) @ b

    # derivative coefficients: n (b_n cos n v - a_n sin n v) = sum_n c_n z^n + conj(c_n) z^-n,
    # c_n = n (b_n + i a_n) / 2
    # (scaled by the largest coefficient, which moves no critical point: subnormal coefficients
    # would overflow the companion matrix)
    size = float(np.max(np.abs(np.concatenate([a, b])), initial=0.0)) or 1.0
    c = n * (b / size + 1j * a / size) / 2.0
    candidates: list[np.ndarray] = [np.linspace(0.0, TWO_PI, 8 * H + 1)]
    # harmonics below roundoff of the largest only make the companion matrix singular: the
    # critical points are those of the rest, polished below on the whole derivative
    big = np.flatnonzero(np.abs(c) > 1e-13 * np.max(np.abs(c), initial=0.0))
    if big.size:
        K = int(n[big[-1]])
        poly = np.zeros(2 * K + 1, dtype=complex)  # z^K * derivative, ascending powers 0..2K
        poly[K + n[:K]] = c[:K]
        poly[K - n[:K]] = np.conj(c[:K])
        roots = np.roots(poly[::-1])
        v = np.angle(roots)
        for _ in range(3):  # Newton on the derivative
            d1 = -np.sin(n * v[:, None]) @ (n * a) + np.cos(n * v[:, None]) @ (n * b)
            d2 = -np.cos(n * v[:, None]) @ (n * n * a) - np.sin(n * v[:, None]) @ (n * n * b)
            with np.errstate(divide="ignore", invalid="ignore"):
                step = np.where(d2 != 0.0, d1 / d2, 0.0)
            v = v - np.where(np.abs(step) < 0.1, step, 0.0)
        candidates.append(v)
    return float(np.min(f(np.concatenate(candidates))))


def friction_minimum(signal: Signal) -> float:
    """min over the cycle of a friction signal, exactly: the least value of a constant, a
    ``steps`` or a ``piecewise-linear`` signal (linear pieces attain their minimum at a knot),
    ``mean - |amplitude|`` for a cosine, and the critical points of a Fourier series."""
    if isinstance(signal, Constant):
        return signal.value
    if isinstance(signal, (Steps, PiecewiseLinear)):
        return float(min(signal.values))
    if isinstance(signal, Cosine):
        return signal.mean - abs(signal.amplitude)
    if isinstance(signal, Fourier):
        H = signal.harmonics
        a = np.zeros(H)
        b = np.zeros(H)
        a[: len(signal.cos)] = signal.cos
        b[: len(signal.sin)] = signal.sin
        return signal.mean if H == 0 else _trig_minimum(signal.mean, a, b)
    raise TypeError(f"no exact minimum for the signal {signal!r}")  # pragma: no cover


def friction_minima(process: SweepingProcess) -> tuple[np.ndarray, np.ndarray]:
    """(min_t mu_j^+(t), min_t mu_j^-(t)) for every block j of a compiled crawler."""
    crawler, pieces = process.crawler, process.offset_pieces
    assert crawler is not None and pieces is not None
    forward = np.array([friction_minimum(s) for s in pieces.signals[crawler.columns["forward"]]])
    backward = np.array([friction_minimum(s) for s in pieces.signals[crawler.columns["backward"]]])
    return crawler.friction_scale * forward, crawler.friction_scale * backward


def cost_of_transport_bound(process: SweepingProcess, displacement: float) -> float | None:
    """The least cost of transport of any gait with this friction moving this way (module
    docstring): sum_j min_t mu_j^+ for d > 0, sum_j min_t mu_j^- for d < 0; None for d = 0."""
    if displacement == 0.0 or not math.isfinite(displacement):
        return None
    forward, backward = friction_minima(process)
    return float(math.fsum(forward if displacement > 0 else backward))


def ledger(
    process: SweepingProcess,
    record: PeriodRecord,
    displacement: float,
    cost_of_transport: float | None,
    dissipation_error: float | None,
) -> EnergyLedger | None:
    """The ledger of the limit period ``record`` and the bound on the cost of transport; None
    for a generic sweeping process."""
    energy = period_energy(process, record)
    if energy is None:
        return None
    head = (energy.dissipation, dissipation_error, cost_of_transport, energy.work, energy.jump_loss, energy.residual)
    if process.crawler is not None and process.crawler.load is not None:
        # with loads (docs/model.md §6): the efficiency is the share of the actuator work that
        # goes into the load, and the friction-only bound does not bound the cost of transport
        efficiency = energy.load_work / energy.work if energy.work > 0 else None
        return EnergyLedger(*head, None, efficiency, energy.load_work, energy.discretisation_loss)
    bound = cost_of_transport_bound(process, displacement)
    efficiency = None
    if bound is not None and cost_of_transport is not None and cost_of_transport > 0:
        efficiency = bound / cost_of_transport
    return EnergyLedger(*head, bound, efficiency, None, energy.discretisation_loss)
