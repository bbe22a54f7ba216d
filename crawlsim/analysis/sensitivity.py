"""Exact sensitivities of v0, the displacement per period, the dissipation and the cost of
transport with respect to the numbers of a gait file (docs/sensitivity.md).

At the periodic limit w* = P(w*, theta) the implicit function theorem gives

    dv0/dtheta = (1/T) [dY/dtheta + dY/dw (I - dP/dw)^+ dP/dtheta],

Y the displacement over one period. The partial derivatives come from one walk along the
verified limit period with an (n + p)-column tangent (`crawlsim.analysis.sensitivity_walk`): the
exact integrator's period map, piecewise smooth in (w, theta), or the catch-up scheme's own
discrete map, whose derivative is exact for that map (``method`` says which). The offsets'
derivatives in each number of the gait file come from `crawlsim.analysis.sensitivity_terms`. The
work is shared between parameters: one walk, one least-squares solve with p right-hand sides;
with ``run=`` (the `crawlsim velocity` run of the same gait) the limit period is not searched
again. The period enters through rate independence alone: Y does not depend on T, so
dv0/dT = -v0/T (for both integrators: the catch-up grid is in cycles).

Where the limit period sits on a kink of the period map (a hit at the same time as another event,
a hit with zero rate, a constraint touching zero gap without entering, a slip rate touching
zero without leaving, rows hit together whose times move differently, a catch-up step tight on
a row with a zero multiplier, or friction on the boundary of the uniqueness condition),
``smooth`` is False, and the left and right derivatives are measured by one-sided
perturbations of theta with the same integrator (Richardson extrapolated), or the reason why
they could not be.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from crawlsim.analysis.run import Settled, shape_mismatch
from crawlsim.analysis.sensitivity_terms import (
    EPS,
    Limit,
    Parameter,
    breakpoint_scale,
    coefficients_of,
    find_limit,
    limit_of,
    parameter_of,
    uniqueness_touch,
)
from crawlsim.analysis.sensitivity_walk import Prepared, Walk, prepare, walk_catch_up, walk_exact
from crawlsim.errors import CrawlsimError, GaitError
from crawlsim.gait.docpaths import check_number_paths, resolve_path
from crawlsim.gait.document import Gait
from crawlsim.kernel.jit import kernel
from crawlsim.status import Convergence, LimitMethod

if TYPE_CHECKING:
    from crawlsim.model.process import SweepingProcess

#: Relative step of the one-sided differences at a kink (h and 2 h, Richardson extrapolated).
ONE_SIDED_STEP = 1e-5

#: How a derivative was found: the exact integrator's period map, the catch-up scheme's own
#: discrete map, rate independence (the period), one-sided differences at a kink, or not at all.
Method = Literal["exact", "catch-up", "rate-independence", "one-sided", "unsupported"]


@dataclass(frozen=True)
class Derivative:
    """One derivative with its error estimate; None where it has no value (a kink)."""

    value: float | None
    error_estimate: float | None


@dataclass(frozen=True)
class ParameterSensitivity:
    """The derivatives of the run's outputs with respect to one number of the gait file."""

    path: str  # concrete dotted path (``*`` expanded)
    value: float  # the number in the gait
    v0: Derivative  # dv0/dtheta
    displacement_per_period: Derivative  # dY/dtheta
    dissipation_per_period: Derivative  # dD/dtheta
    cost_of_transport: Derivative  # d(D/|Y|)/dtheta
    smooth: bool
    method: Method
    reason: str | None = None  # why not smooth, or why not computed
    left: Derivative | None = None  # one-sided dv0/dtheta from below (smooth False)
    right: Derivative | None = None  # ... from above
    left_reason: str | None = None
    right_reason: str | None = None
    # dv0/dtheta on the limit period's own pieces (its visited active sets and event order
    # held): the derivative itself where smooth, one element of the generalized gradient at
    # a kink (which side is not known); what a gradient method can follow
    v0_on_pieces: float | None = None

    def summary(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "value": self.v0.value,
            "error_estimate": self.v0.error_estimate,
            "smooth": self.smooth,
            "method": self.method,
            "parameter_value": self.value,
        }
        for key in ("displacement_per_period", "dissipation_per_period", "cost_of_transport"):
            d: Derivative = getattr(self, key)
            out[f"d_{key}"] = d.value
            out[f"d_{key}_error_estimate"] = d.error_estimate
        if self.reason is not None:
            out["reason"] = self.reason
        if not self.smooth:
            for side in ("left", "right"):
                d_side: Derivative | None = getattr(self, side)
                out[side] = None if d_side is None else d_side.value
                out[f"{side}_error_estimate"] = None if d_side is None else d_side.error_estimate
                why = getattr(self, f"{side}_reason")
                if why is not None:
                    out[f"{side}_reason"] = why
        return out


@dataclass(frozen=True)
class SensitivityResult:
    """`sensitivity`'s answer: the run's values and one `ParameterSensitivity` per number."""

    name: str
    period: float
    v0: float
    v0_error_estimate: float
    displacement_per_period: float
    dissipation_per_period: float
    cost_of_transport: float | None
    parameters: tuple[ParameterSensitivity, ...]
    kinks: tuple[str, ...] = field(default=())  # the kinks of the limit period found

    def __getitem__(self, path: str) -> ParameterSensitivity:
        for p in self.parameters:
            if p.path == path:
                return p
        raise KeyError(path)

    @property
    def smooth(self) -> bool:
        """True when v0 is differentiable in every parameter (no kink of the contact sequence)."""
        return all(p.smooth for p in self.parameters)

    def summary(self) -> dict[str, Any]:
        """The ``sensitivity`` mapping of ``crawlsim velocity --json``: path -> its derivatives."""
        return {p.path: p.summary() for p in self.parameters}


# -- the public function ---------------------------------------------------------------------
def sensitivity(
    gait: Gait, paths: Sequence[str] | str, *, one_sided: bool = True, run: Settled | None = None
) -> SensitivityResult:
    """dv0/dtheta (and of the displacement, dissipation and cost of transport per period) for
    every number ``paths`` name in ``gait`` (dotted paths with ``*``, as ``--sweep``; each
    ``*`` expands to one parameter per element), at the verified limit of the gait's own
    integrator: the exact integrator's derivatives, or those of the catch-up scheme's discrete
    map.

    ``run``: what a run of this gait settled on (`crawlsim.analysis.run.Settled`: a
    ``crawlsim.api.run`` result's ``settled``), whose limit period is used instead of searching
    it again. ``one_sided=False`` skips the one-sided
    differences at a kink (left and right are then None with the reason)."""
    if not isinstance(gait, Gait):
        raise GaitError(
            getattr(gait, "source", "<gait>"), "", "sensitivities are defined for crawler gaits (kind: crawler)"
        )
    lim = _limit_of_run(gait, run)
    st = _static_of(gait, lim.process, paths)
    co, params, active, dMu = st.co, st.params, st.active, st.dMu
    catch_up = gait.simulation.integrator != "exact"
    walk = (walk_catch_up if catch_up else walk_exact)(lim, co, st.dC, dMu, st.dk, st.prep)
    ift = _Ift(lim, walk, st, gait.blocks)
    friction_kink = st.friction_kink
    T = lim.process.period
    Y, D = lim.displacement, lim.dissipation
    cot = D / abs(Y) if abs(Y) > 10 * lim.v0_error * T + 1e-300 else None
    out: list[ParameterSensitivity] = []
    for i, prm in enumerate(params):
        if prm.period:
            out.append(_period_entry(prm, lim, cot))
        elif prm.dC is None:
            none = Derivative(None, None)
            out.append(
                ParameterSensitivity(prm.path, prm.value, none, none, none, none, False, "unsupported", prm.reason)
            )
        else:
            col = active.index(i)
            reasons = ift.kinks(col)
            if friction_kink is not None and np.any(dMu[..., col] != 0.0):
                reasons.append(friction_kink)
            out.append(_entry(gait, prm, lim, ift, col, cot, reasons, "catch-up" if catch_up else "exact", one_sided))
    return SensitivityResult(
        gait.name, T, lim.v0, lim.v0_error, Y, D, cot, tuple(out), tuple(dict.fromkeys(walk.kinks))
    )


# -- what depends on the gait alone, built once per gait ----------------------------------------
#: Per gait (a frozen value, compared by identity): what a call derives from the gait and the
#: grid its limit process is compiled on, not from the limit period; keyed by the kind of entry,
#: the integrator, the grid's steps and (for `_Static`) the paths asked for.
_CACHE: weakref.WeakKeyDictionary[Gait, dict[tuple[Any, ...], Any]] = weakref.WeakKeyDictionary()
#: Most entries kept per gait (a long sweep of paths on one gait starts again when it is full).
CACHE_ENTRIES = 32


def _cached(gait: Gait, key: tuple[Any, ...], build: Callable[[], Any]) -> Any:
    """``build()``, kept on ``gait`` under ``key``: a repeated `sensitivity` call on the same
    `Gait` object (a notebook or a script that asks again, with other paths or after another
    run) does not derive again what its limit period does not change. A first call builds it."""
    store = _CACHE.setdefault(gait, {})
    if key not in store:
        if len(store) >= CACHE_ENTRIES:
            store.clear()
        store[key] = build()
    return store[key]


@dataclass(frozen=True, eq=False)
class _Static:
    """The offsets' coefficients, the parameters with their columns dC, dMu (P, nb, m, p) and
    dk (n, p) (`crawlsim.analysis.sensitivity_terms`), the friction's uniqueness touch, the
    walk's `Prepared` data and each column's relative move of the slips (`_Ift`'s roundoff
    floor): everything of a call that the limit period does not enter."""

    co: Any
    params: tuple[Parameter, ...]
    active: tuple[int, ...]
    dC: np.ndarray
    dMu: np.ndarray
    dk: np.ndarray
    friction_kink: str | None
    prep: Prepared
    moved: np.ndarray  # (p,)


def _static_of(gait: Gait, process: SweepingProcess, paths: Sequence[str] | str) -> _Static:
    """`_Static` of ``gait`` on ``process``'s grid for ``paths``, built once."""
    integrator = gait.simulation.integrator
    key = ("static", integrator, process.steps, (paths,) if isinstance(paths, str) else tuple(paths))
    return _cached(gait, key, lambda: _build_static(gait, process, paths))


def _build_static(gait: Gait, process: SweepingProcess, paths: Sequence[str] | str) -> _Static:
    co = coefficients_of(gait, process)
    params = tuple(parameter_of(gait, co, keys) for keys in _expand(gait, paths))
    active = tuple(i for i, prm in enumerate(params) if prm.dC is not None)
    dC, dMu, dk = _stack(co, [params[i] for i in active])
    prep = prepare(process, co, dC, dMu, gait.simulation.integrator != "exact")
    moved = kernel().implicit.column_moves(co.C, dC, np.ascontiguousarray(co.k, dtype=float), dk)
    # the friction's uniqueness touch matters only to a column that moves the friction
    touch = uniqueness_touch(gait, co) if dMu.any() else None
    return _Static(co, params, active, dC, dMu, dk, touch, prep, moved)


def _limit_of_run(gait: Gait, run: Settled | None) -> Limit:
    """The limit period ``run`` settled on when it is this gait's, else found. The exact walk
    needs the closed form of c only, not the run's grid: its tolerances are relative to c's
    size at the pieces' edges (`breakpoint_scale`)."""
    if run is None or not run.result.converged or run.result.integrator != gait.simulation.integrator:
        return find_limit(gait)
    process = run.process
    exact = gait.simulation.integrator == "exact"
    scale = _cached(gait, ("scale", process.steps), lambda: breakpoint_scale(process)) if exact else None
    return limit_of(process, run.record, scale, _known(run))


def _known(run: Settled) -> tuple[float, float, float | None] | None:
    """What ``run`` measured of its limit period with `limit_of`'s own formulas: the
    displacement and dissipation of the period (`crawlsim.analysis.run`'s motion), and v0's
    error where the run took it as `verified_limit_error` does here, or all but its residual
    term (the periodic-limit solver's period, or a finite-time limit, on the grid of the
    record: else None, measured again)."""
    result, process, final = run.result, run.process, run.record
    if result.estimate is None or result.energy is None:
        return None
    d, dissipation, err = result.estimate.displacement, result.energy.dissipation, result.estimate.period_iteration
    if len(final.w) - 1 != process.steps:
        return d, dissipation, None
    if result.solver.method == LimitMethod.NEWTON:
        return d, dissipation, err
    if result.convergence == Convergence.FINITE_TIME:
        # the period iteration's error is then the displacement's roundoff over T alone, to
        # which `verified_limit_error` adds the period's residual
        return d, dissipation, err + shape_mismatch(process, final) / process.period
    return d, dissipation, None


def _expand(gait: Gait, paths: Sequence[str] | str) -> list[tuple[Any, ...]]:
    """The concrete key paths of ``paths`` (each ``*`` expanded), each once, in order."""
    paths = check_number_paths(gait, [paths] if isinstance(paths, str) else paths)
    keys_list: list[tuple[Any, ...]] = []
    for path in paths:
        for keys in resolve_path(gait.document, path, gait.source):
            if keys not in keys_list:
                keys_list.append(keys)
    return keys_list


def _stack(co: Any, params: list[Parameter]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The parameters' dC, dMu (P, nb, m, p) and dk (n, p), one column each."""
    P, nb, m = co.C.shape
    if len(params) == 1:  # one column: the parameter's own arrays, viewed as (..., 1)
        prm = params[0]
        assert prm.dC is not None and prm.dMu is not None and prm.dk is not None
        return prm.dC[..., None], prm.dMu[..., None], prm.dk[:, None]
    dC = np.zeros((P, nb, m, len(params)))
    dMu = np.zeros((P, nb, m, len(params)))
    dk = np.zeros((len(co.k), len(params)))
    for col, prm in enumerate(params):
        assert prm.dC is not None and prm.dMu is not None and prm.dk is not None
        dC[..., col], dMu[..., col], dk[:, col] = prm.dC, prm.dMu, prm.dk
    return dC, dMu, dk


class _Ift:
    """(ift) solved for every parameter column at once: dw* = (I - dP/dw)^+ dP/dtheta (one
    least-squares solve, p right-hand sides), dY and dD with their error estimates."""

    def __init__(self, lim: Limit, walk: Walk, st: _Static, blocks: int):
        n = len(st.co.k)
        self.n, self.walk, self.scale_c = n, walk, lim.scale
        # error: roundoff of every term (pieces x eps x their sizes, times the conditioning of
        # the least-squares solve) plus the verified limit's distance, relative, on the same
        # sizes (`crawlsim.kernel.implicit.implicit` gives the sizes and the conditioning)
        self.dw, self.dY, self.dD, magY, magD, cond = kernel().implicit.implicit(walk.W, walk.L, walk.D, blocks)
        rel = 64 * EPS * (walk.pieces + n) * cond + lim.residual
        # a floor at the roundoff of the slips themselves: a derivative that cancels to ~0 (a
        # common phase shift) is zero to eps times the sizes the period's slips are made of
        # (``st.moved``: each column's largest relative move of c and k)
        floor = 64 * EPS * walk.pieces * st.moved
        self.errY = rel * magY + floor * (float(np.abs(walk.lam).sum()) / blocks)
        self.errD = rel * magD + floor * abs(lim.dissipation)

    def kinks(self, col: int) -> list[str]:
        """Why the period map is not smooth in parameter ``col`` at the limit: the walk's kinks,
        and the touches that the parameter moves off zero."""
        n, dw = self.n, self.dw[:, col]
        reasons = list(self.walk.kinks)
        for message, tangent in self.walk.touches:
            total = tangent[:, :n] @ dw + tangent[:, n + col]
            size = np.abs(tangent[:, :n]) @ np.abs(dw) + np.abs(tangent[:, n + col])
            if np.any(np.abs(total) > 1e-7 * np.max(size) + 1e3 * EPS * self.scale_c):
                reasons.append(message)
        column_kinks = self.walk.column_kinks
        if column_kinks is not None and column_kinks[n + col] and not reasons:
            reasons.append("constraints reached together move apart")
        return reasons


def _period_entry(prm: Parameter, lim: Limit, cot: float | None) -> ParameterSensitivity:
    """dv0/dT = -v0/T by rate independence; Y, D and the cost of transport do not move."""
    T = lim.process.period
    dv = Derivative(-lim.v0 / T, lim.v0_error / T)
    zero = Derivative(0.0, 0.0)
    return ParameterSensitivity(
        prm.path,
        prm.value,
        dv,
        zero,
        zero,
        zero if cot is not None else Derivative(None, None),
        True,
        "rate-independence",
        v0_on_pieces=dv.value,
    )


def _entry(
    gait: Gait,
    prm: Parameter,
    lim: Limit,
    ift: _Ift,
    col: int,
    cot: float | None,
    reasons: list[str],
    method: Method,
    one_sided: bool,
) -> ParameterSensitivity:
    """One parameter's derivatives: the walked ones where smooth, else one-sided values."""
    T = lim.process.period
    Y, D = lim.displacement, lim.dissipation
    y, ey = float(ift.dY[col]), float(ift.errY[col])
    dd, ed = float(ift.dD[col]), float(ift.errD[col])
    dcot_d = Derivative(None, None)
    if cot is not None:
        dcot = dd / abs(Y) - D * math.copysign(1.0, Y) * y / (Y * Y)
        ecot = ed / abs(Y) + abs(D) * ey / (Y * Y) + abs(dcot) * lim.v0_error * T / abs(Y)
        dcot_d = Derivative(dcot, ecot)
    if not reasons:
        return ParameterSensitivity(
            prm.path,
            prm.value,
            Derivative(y / T, ey / T),
            Derivative(y, ey),
            Derivative(dd, ed),
            dcot_d,
            True,
            method,
            v0_on_pieces=y / T,
        )
    left = right = None
    lr: str | None = "one-sided differences not requested"
    rr: str | None = lr
    if one_sided:
        left, lr = _one_sided(gait, prm, lim.v0, -1)
        right, rr = _one_sided(gait, prm, lim.v0, +1)
    none = Derivative(None, None)
    return ParameterSensitivity(
        prm.path,
        prm.value,
        none,
        none,
        none,
        none,
        False,
        "one-sided",
        "; ".join(dict.fromkeys(reasons)),
        left,
        right,
        None if left is not None else lr,
        None if right is not None else rr,
        y / T,
    )


def _one_sided(gait: Gait, prm: Parameter, v0: float, side: int) -> tuple[Derivative | None, str | None]:
    """The one-sided derivative of v0 from the integrator's v0 at theta + side h and
    theta + 2 side h: D(h) = (v(theta + s h) - v0) / (s h), extrapolated 2 D(h) - D(2 h); its
    error: the extrapolation's change |D(h) - D(2h)| plus the runs' roundoff over h."""
    h = ONE_SIDED_STEP * max(abs(prm.value), 1.0)
    values = []
    try:
        for mult in (1, 2):
            lim = find_limit(gait.replace(prm.path, prm.value + side * mult * h))
            values.append((lim.v0, lim.v0_error))
    except CrawlsimError as exc:
        return None, f"{prm.path} = {prm.value + side * h:g}: {exc}"
    d1 = (values[0][0] - v0) / (side * h)
    d2 = (values[1][0] - v0) / (side * 2 * h)
    err = abs(d1 - d2) + 3 * (values[0][1] + values[1][1]) / h
    return Derivative(2 * d1 - d2, err), None
