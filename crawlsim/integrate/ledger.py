"""The exact integrator's energy ledger: actuator work, dissipation, jump losses and the loads'
work integrated in closed form on the pieces of one exact period (the balance and its terms are
derived in `crawlsim.analysis.energy`, which reports them; docs/model.md §1-§4).

It lives with the integrators because the exact stepper (`crawlsim.integrate.exact`) and its
compiled loop (`crawlsim.kernel.eventloop`) feed it piece by piece as the period is integrated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from crawlsim.model.crawler import elastic_energy
from crawlsim.model.offsets import TWO_PI, Basis
from crawlsim.model.process import SweepingProcess
from crawlsim.projection.certificate import Floats

#: Below this value of omega delta the closed form of int s sin(omega s) ds is summed as its
#: Taylor series (the closed form cancels there).
_SERIES = 0.1


@dataclass(frozen=True)
class PeriodEnergy:
    """The energy ledger of one period (module docstring); energies in force x length."""

    work: float  # W: actuator work on the body, sum_i oint sigma_i dL_i
    dissipation: float  # D: friction work, jump slips at the limits after the switch
    jump_loss: float  # J: energy released at jumps beyond friction work
    energy_start: float  # E at the period's start
    energy_end: float  # E at its end
    load_work: float = 0.0  # W_load: work against the loads, -oint F~ . dx (docs/model.md §6)
    # catch-up: the scheme's own numerical dissipation, first order in the step (the loss of
    # its steps but those across a jump); None for the exact integrator, which has none
    discretisation_loss: float | None = None

    @property
    def energy_change(self) -> float:
        return self.energy_end - self.energy_start

    @property
    def residual(self) -> float:
        """W - D - J - W_load (- the discretisation loss): zero in the periodic regime (it is
        E(end) - E(start), up to roundoff)."""
        return self.work - self.dissipation - self.jump_loss - self.load_work - (self.discretisation_loss or 0.0)

    @property
    def scale(self) -> float:
        """The size of the ledger's terms, for relative residuals."""
        return max(
            abs(self.work),
            abs(self.dissipation),
            abs(self.jump_loss),
            abs(self.load_work),
            abs(self.discretisation_loss or 0.0),
            self.energy_start,
            self.energy_end,
            1e-300,
        )


# -- closed-form integrals -----------------------------------------------------------------------
def _even_integral(nu: Floats, delta: Floats) -> np.ndarray:
    """int_{-delta}^{delta} cos(nu s) ds = 2 sin(nu delta)/nu (2 delta at nu = 0): the factor
    that `_cos_integral` and `_sin_integral` share, formed once where both are wanted."""
    with np.errstate(divide="ignore", invalid="ignore"):
        c: np.ndarray = np.where(nu == 0.0, 2.0 * delta, 2.0 * np.sin(nu * delta) / nu)
    return c


def _cos_integral(nu: Floats, m: Floats, delta: Floats, even: np.ndarray | None = None) -> np.ndarray:
    """int_{m-delta}^{m+delta} cos(nu u) du = cos(nu m) 2 sin(nu delta)/nu (2 delta at nu = 0);
    ``even`` is `_even_integral` (nu, delta) when already formed."""
    c = _even_integral(nu, delta) if even is None else even
    out: np.ndarray = np.cos(nu * m) * c
    return out


def _sin_integral(nu: Floats, m: Floats, delta: Floats, even: np.ndarray | None = None) -> np.ndarray:
    """int_{m-delta}^{m+delta} sin(nu u) du = sin(nu m) 2 sin(nu delta)/nu (0 at nu = 0);
    ``even`` as in `_cos_integral`."""
    c = _even_integral(nu, delta) if even is None else even
    out: np.ndarray = np.sin(nu * m) * c
    return out


def _s_sin(omega: Floats, delta: Floats) -> np.ndarray:
    """int_{-delta}^{delta} s sin(omega s) ds = 2 (sin x - x cos x)/omega^2, x = omega delta;
    for small x the series 2 delta^2 x (1/3 - x^2/30 + x^4/840 - x^6/45360)."""
    x = omega * delta
    with np.errstate(divide="ignore", invalid="ignore"):
        closed = 2.0 * (np.sin(x) - x * np.cos(x)) / (omega * omega)
    x2 = x * x
    series = 2.0 * delta * delta * x * (1 / 3 - x2 / 30 + x2 * x2 / 840 - x2**3 / 45360)
    return np.where(np.abs(x) < _SERIES, series, closed)


def gram(basis: Basis, a: npt.ArrayLike, b: npt.ArrayLike) -> np.ndarray:
    """P[k, l] = int_a^b phi_k(u) phi_l(u) du for the basis of `crawlsim.model.offsets`, in closed form:
    (nb, nb) for scalars a, b, (K, nb, nb) for arrays of K intervals.

    With m = (a + b)/2, delta = (b - a)/2 and u = m + s: ``int 1 = 2 delta``, ``int u = 2 delta
    m``, ``int u^2 = 2 delta m^2 + 2 delta^3/3``; ``cos(w u) = cos w m cos w s - sin w m sin w s``
    (and sin likewise), whose odd parts in s integrate to zero, so ``int u cos w u = m cos(w m)
    C(w) - sin(w m) S(w)`` and ``int u sin w u = m sin(w m) C(w) + cos(w m) S(w)``, with
    ``C(w) = 2 sin(w delta)/w`` and ``S(w) = int s sin w s``; products of harmonics are sums of
    harmonics (``cos a cos b = (cos(a-b) + cos(a+b))/2`` and so on). Centring on m keeps every
    term free of cancellation for short pieces: each entry is correct to a few ulps of the
    integrand's size times the piece length.
    """
    scalar = np.ndim(a) == 0
    a = np.atleast_1d(np.asarray(a, dtype=float))
    b = np.atleast_1d(np.asarray(b, dtype=float))
    m, delta = 0.5 * (a + b), 0.5 * (b - a)
    nb, K = basis.size, a.size
    P = np.zeros((K, nb, nb))
    P[:, 0, 0] = 2.0 * delta
    lin = 1 if basis.linear else None
    if lin is not None:
        P[:, 0, lin] = P[:, lin, 0] = 2.0 * delta * m
        P[:, lin, lin] = 2.0 * delta * m * m + 2.0 * delta**3 / 3.0
    H = basis.harmonics
    if H:
        h0 = basis.first_harmonic
        w = TWO_PI * np.arange(1, H + 1)
        ci = h0 + 2 * np.arange(H)  # columns of cos(w_h u)
        si = ci + 1
        m1, d1 = m[:, None], delta[:, None]  # (K, 1) against (H,)
        even = _even_integral(w, d1)
        P[:, 0, ci] = P[:, ci, 0] = _cos_integral(w, m1, d1, even)
        P[:, 0, si] = P[:, si, 0] = _sin_integral(w, m1, d1, even)
        if lin is not None:
            cw = 2.0 * np.sin(w * d1) / w
            ss = _s_sin(w, d1)
            P[:, lin, ci] = P[:, ci, lin] = m1 * np.cos(w * m1) * cw - np.sin(w * m1) * ss
            P[:, lin, si] = P[:, si, lin] = m1 * np.sin(w * m1) * cw + np.cos(w * m1) * ss
        m2, d2 = m[:, None, None], delta[:, None, None]  # (K, 1, 1) against (H, H)
        diff = w[:, None] - w[None, :]  # alpha - beta
        total = w[:, None] + w[None, :]
        even_d, even_t = _even_integral(diff, d2), _even_integral(total, d2)
        cd, ct = _cos_integral(diff, m2, d2, even_d), _cos_integral(total, m2, d2, even_t)
        # cos(alpha u) sin(beta u) = (sin((alpha + beta) u) - sin((alpha - beta) u)) / 2
        cs = 0.5 * (_sin_integral(total, m2, d2, even_t) - _sin_integral(diff, m2, d2, even_d))
        P[:, ci[:, None], ci[None, :]] = 0.5 * (cd + ct)
        P[:, si[:, None], si[None, :]] = 0.5 * (cd - ct)
        P[:, ci[:, None], si[None, :]] = cs
        P[:, si[:, None], ci[None, :]] = np.swapaxes(cs, 1, 2)
    return P[0] if scalar else P


def _identity(coef: np.ndarray) -> np.ndarray:
    return coef


# -- the exact integrator's ledger ---------------------------------------------------------------
class ExactLedger:
    """Accumulates `PeriodEnergy` over the pieces and jumps of one exact period (module
    docstring); `crawlsim.integrate.exact.EventStepper` feeds it.

    A piece contributes ``sum(P * G)`` with P its Gram matrix and ``G = Sc @ Lc'^T`` (work) or
    ``-Mc_A @ Y'^T`` (dissipation), both (nb, nb): pieces keep only these, and the Gram matrices
    of all pieces are formed at once at the end of the period.
    """

    def __init__(self, process: SweepingProcess):
        pieces, crawler = process.offset_pieces, process.crawler
        assert pieces is not None and crawler is not None
        self.basis: Basis = pieces.basis
        self.crawler = crawler
        self.k = np.asarray(crawler.stiffness, dtype=float)
        self.pieces = pieces.pieces
        # the signals themselves (`crawlsim.model.crawler.signal_columns`), in the basis and on
        # the pieces of c(t)
        self.signals = pieces.recombined(_identity)
        # per piece of c: L, K L, dL/du and mu coefficients (a period revisits every piece)
        self._cache: dict[int, tuple[np.ndarray, ...]] = {}
        self.start()

    def start(self) -> None:
        self._bounds: list[tuple[float, float]] = []
        self._products: list[np.ndarray] = []  # (2 or 3, nb, nb): work, dissipation, load work
        self._jumps: dict[str, list[float]] = {"work": [], "dissipation": [], "jump_loss": [], "load_work": []}

    def _split(self, p: int) -> tuple[np.ndarray, ...]:
        """(Lc, K Lc, Lc', Mc, lc) of piece p: Mc the friction of the 2N rows (mu cos(angle) on a
        slope), lc the load's share l = [-F~ ; F~] (zero without loads, docs/model.md §6)."""
        cached = self._cache.get(p)
        if cached is None:
            Lc, Mc, force = self.crawler.split(self.signals.coefficients(p))
            lc = np.zeros_like(Mc) if force is None else np.hstack([-force, force])
            cached = (Lc, Lc * self.k, self.basis.derivative(Lc), Mc, lc)
            if len(self._cache) > 256:
                self._cache.clear()
            self._cache[p] = cached
        return cached

    @property
    def products(self) -> int:
        """Products a piece keeps: work and dissipation, and the load's work with loads."""
        return 2 if self.crawler.load is None else 3

    def terms(self, p: int) -> tuple[np.ndarray, ...]:
        """(Lc, K Lc, Lc', Mc, lc) of piece p of c(t), as `piece` uses them."""
        return self._split(p)

    def add_pieces(self, bounds: np.ndarray, products: np.ndarray) -> None:
        """Add pieces [u0, u1] (rows of ``bounds``) whose products (K, `products`, nb, nb)
        were formed elsewhere (the compiled event loop, `crawlsim.kernel.eventloop`)."""
        self._bounds.extend((float(a), float(b)) for a, b in bounds)
        self._products.extend(products)

    def piece(
        self, p: int, u0: float, u1: float, base: np.ndarray, Wc: np.ndarray, active: np.ndarray, Y: np.ndarray
    ) -> None:
        """Add the piece [u0, u1] of piece p of c(t): w(u) = base + phi(u) @ Wc, slips of the
        active rows Lambda(u) = lam0 - phi(u) @ Y."""
        if not u1 > u0:
            return
        _, KLc, dLc, Mc, lc = self._split(p)
        Sc = Wc + KLc
        Sc[0] = Sc[0] + base
        loaded = self.crawler.load is not None  # a third product only with loads (§6)
        G = np.empty((3 if loaded else 2,) + (self.basis.size,) * 2)
        G[0] = Sc @ dLc.T
        dY = self.basis.derivative(Y).T
        G[1] = -(Mc[:, active] @ dY) if active.size else 0.0
        if loaded:
            G[2] = -(lc[:, active] @ dY) if active.size else 0.0
        self._bounds.append((u0, u1))
        self._products.append(G)

    def _signals_at(self, u: float, p: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        Lc, _, _, Mc, lc = self._split(p)
        phi = self.basis.values(u)[0]
        return phi @ Lc, phi @ Mc, phi @ lc

    def jump(self, p_before: int, u: float, w_before: np.ndarray, w_after: np.ndarray, multipliers: np.ndarray) -> None:
        """Add the jump at the end u of piece ``p_before`` (at u = 1 the signals after it are
        those of u = 0): the actuators' jump work, the slip's friction work and the jump loss."""
        p_after = (p_before + 1) % self.pieces
        L_before, _, _ = self._signals_at(u, p_before)
        L_after, mu_after, load_after = self._signals_at(u if p_before + 1 < self.pieces else 0.0, p_after)
        dL = L_after - L_before
        sigma = w_before + self.k * L_before
        self._jumps["work"].append(float(np.sum((sigma + 0.5 * self.k * dL) * dL)))
        self._jumps["dissipation"].append(float(multipliers @ mu_after))
        self._jumps["load_work"].append(float(multipliers @ load_after))
        dw = w_after - w_before
        self._jumps["jump_loss"].append(float(np.sum(dw * dw / (2.0 * self.k))))

    def finish(self, w_start: np.ndarray, w_end: np.ndarray) -> PeriodEnergy:
        """The period's ledger; both ends are at u = 0 of the cycle (L(1) = L(0))."""
        work, dissipation = list(self._jumps["work"]), list(self._jumps["dissipation"])
        load_work = list(self._jumps["load_work"])
        if self._bounds:
            bounds = np.array(self._bounds)
            P = gram(self.basis, bounds[:, 0], bounds[:, 1])  # (K, nb, nb)
            terms = np.einsum("kab,kjab->jk", P, np.array(self._products))
            work.extend(terms[0].tolist())
            dissipation.extend(terms[1].tolist())
            if len(terms) > 2:
                load_work.extend(terms[2].tolist())
        L0, _, _ = self._signals_at(0.0, 0)
        return PeriodEnergy(
            math.fsum(work),
            math.fsum(dissipation),
            math.fsum(self._jumps["jump_loss"]),
            elastic_energy(w_start + self.k * L0, self.k),
            elastic_energy(w_end + self.k * L0, self.k),
            math.fsum(load_work),
        )
