"""The stall force and the steepest climbable slope (docs/model.md §6).

v0 as a function of a load is only piecewise smooth: it can reach 0 smoothly (the stroke no
longer exceeds the elastic range), stay identically 0 on an interval of loads, and jump across 0
where the shifted thresholds violate the uniqueness condition. So the stall load is defined, and
found, as the boundary of the set of loads at which the crawler still moves its way:

    s* = sup { s : sign(v0(s')) = sign(v0(s0)) and v0(s') != 0 for all s' between s0 and s },

varying the load from the gait's value s0 in the direction that opposes the motion. A scan in
steps of `SCAN_STEPS`-ths of the load's natural range brackets the first load where the crawler
stops moving its way (or where the body can no longer hold, or the gait is refused); bisection
on the same predicate then shrinks the bracket to `RELATIVE_WIDTH` of the range. The predicate
is a sign, so bisection converges whatever v0 does inside the bracket: a smooth zero, a jump, or
an interval of v0 = 0 all leave a boundary point. The cause is read off the final bracket's
moving side: v0 within `SMOOTH` of its starting size there is a smooth zero, otherwise a jump,
and for a jump the subset J whose shifted uniqueness sum (docs/model.md §3, §6) vanishes at the
stall load is named.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from crawlsim.analysis.stall import MOVING, StallCause
from crawlsim.errors import CertificateError, GaitError, InputError
from crawlsim.gait.apriori import margin
from crawlsim.gait.docpaths import resolve_path, value_at
from crawlsim.gait.document import Gait, gait_from_document
from crawlsim.study.simulation import _as_spec, run

SMOOTH = 1e-6
"""A v0 below this fraction of |v0(s0)| on the moving side of the final bracket is a smooth zero."""

SCAN_STEPS = 64
"""Scan steps across the load's natural range (the loaded block's friction interval, or 90
degrees); beyond it the steps grow by 5 % each."""

RELATIVE_WIDTH = 1e-9
"""The final bracket's width relative to the natural range. Within about 1e-11 of a load where the
shifted uniqueness condition fails the active normals are nearly dependent, and a step's
certificate can fail at roundoff (`CertificateError`); such a load counts as not moving, which
moves the boundary by no more than that distance."""


@dataclass(frozen=True)
class StallResult:
    """The stall load and how it was found."""

    quantity: str  # "force" or "slope"
    path: str  # the document path varied
    value: float  # the stall load (force, or degrees)
    bracket: tuple[float, float]  # moving side, stopped side
    cause: StallCause
    v0_start: float  # v0 at the gait's own load
    v0_moving: float  # v0 at the bracket's moving side
    v0_stopped: float | None  # v0 at the stopped side (None where the gait is refused)
    start: float  # the gait's own load
    evaluations: int
    subset: tuple[int, ...] | None = None  # J (1-based blocks) of a jump, when one is found
    reason: str | None = None  # the refusal at the stopped side, if any
    unit: str = ""

    @property
    def error_estimate(self) -> float:
        """Half the bracket: the stall load is within it of ``value``."""
        return abs(self.bracket[1] - self.bracket[0]) / 2

    def summary(self) -> dict[str, Any]:
        """The numbers of ``crawlsim stall --json``, JSON-ready."""
        named = "steepest_slope" if self.quantity == "slope" else "stall_force"
        return {
            "quantity": self.quantity,
            "path": self.path,
            "stall": self.value,
            named: self.value,
            "error_estimate": self.error_estimate,
            "bracket": list(self.bracket),
            "cause": str(self.cause),
            "start": self.start,
            "v0_start": self.v0_start,
            "v0_moving_side": self.v0_moving,
            "v0_stopped_side": self.v0_stopped,
            "subset": None if self.subset is None else list(self.subset),
            "reason": self.reason,
            "unit": self.unit,
            "evaluations": self.evaluations,
        }


@dataclass
class _Probe:
    gait: Gait
    path: str
    evaluations: int = 0
    cache: dict[float, tuple[float | None, str | None, bool]] = field(default_factory=dict)

    def __call__(self, s: float) -> tuple[float | None, str | None, bool]:
        """(v0, refusal reason, refused because the body cannot hold) at load s."""
        if s in self.cache:
            return self.cache[s]
        self.evaluations += 1
        try:
            gait = self.gait.replace(self.path, float(s))
        except GaitError as error:
            out: tuple[float | None, str | None, bool] = (
                None,
                str(error),
                "too large for any quasistatic motion" in str(error),
            )
        else:
            try:
                result = run(gait, history=False)
            except CertificateError as error:  # at roundoff of a uniqueness failure (RELATIVE_WIDTH)
                out = (None, str(error), False)
                self.cache[s] = out
                return out
            if not result.converged:
                raise InputError(
                    self.gait.source,
                    self.path,
                    f"the run at {self.path} = {s:.12g} did not converge within max_periods; raise --max-periods",
                )
            out = (result.v0, None, False)
        self.cache[s] = out
        return out


def _natural_range(gait: Gait, quantity: str, path: str) -> float:
    """The size of the load's range: 90 degrees, or the friction interval mu+ + mu- at t = 0 of
    the loaded block (its mean over the blocks for one force on every block)."""
    if quantity == "slope":
        return 90.0
    zero = np.zeros(1)
    width = gait.mu_plus(zero)[0] + gait.mu_minus(zero)[0]
    last = path.rsplit(".", 1)[-1]
    return float(width[int(last)]) if last.isdigit() and int(last) < len(width) else float(np.mean(width))


def stall(gait: Gait | str, *, force: str | None = None, slope: bool = False) -> StallResult:
    """The stall force (``force=PATH``, a number in the ``loads:`` block such as
    ``"loads.force.0"``) or the steepest slope the gait still climbs (``slope=True``, varying
    ``loads.slope.angle``, in degrees), with its bracket and cause (module docstring)."""
    spec, path, quantity = _stall_problem(gait, force, slope)
    s0 = _start_load(spec, path)
    probe = _Probe(spec, path)
    v_start, why, _ = probe(s0)
    if v_start is None:  # pragma: no cover - the gait itself was validated
        raise InputError(spec.source, path, why or "refused")
    scale = _natural_range(spec, quantity, path)
    tolerance_v = MOVING * abs(v_start)
    if not abs(v_start) > 1e-12 * max(scale, 1.0):
        raise InputError(
            spec.source,
            path,
            f"the gait does not move at {path} = {s0:g} (v0 = {v_start:.3g}): there is no motion to stall",
        )
    sign = math.copysign(1.0, v_start)
    # a forward force helps forward motion; a steeper slope hinders climbing
    direction = -sign if quantity == "force" else sign

    def moving(s: float) -> bool:
        v, _, _ = probe(s)
        return v is not None and v * sign > tolerance_v

    lo, hi = _scan(moving, s0, direction, scale, quantity)
    if hi is None:
        raise InputError(
            spec.source,
            path,
            f"the gait still moves at {path} = {lo:.12g}, the end of the range searched: no stall load found",
        )
    lo, hi = _bisect(moving, lo, hi, RELATIVE_WIDTH * scale)
    v_lo, _, _ = probe(lo)
    v_hi, reason, no_hold = probe(hi)
    assert v_lo is not None
    subset = None
    value = 0.5 * (lo + hi)
    if no_hold:
        cause = StallCause.HOLD
    elif abs(v_lo) <= SMOOTH * abs(v_start):
        cause = StallCause.SMOOTH_ZERO
        value, hi = _smooth_zero(probe, lo, hi, v_lo, sign, direction, scale)
    else:
        cause = StallCause.JUMP
        nearest = margin(spec.replace(path, lo))  # the J whose g~_J vanishes at the jump
        subset = nearest.blocks if nearest.value <= 1e-6 * nearest.scale else None
    unit = "degree" if quantity == "slope" else spec.units.suffix("force").strip()
    return StallResult(
        quantity, path, value, (lo, hi), cause, v_start, v_lo, v_hi, s0, probe.evaluations, subset, reason, unit
    )


def _stall_problem(gait: Gait | str, force: str | None, slope: bool) -> tuple[Gait, str, str]:
    """(the gait, the path varied, "force" or "slope"): a force path gets zero forces on every
    block when the gait has none yet."""
    spec = _as_spec(gait)
    if not isinstance(spec, Gait):
        raise InputError(spec.source, "kind", "stall needs a crawler gait, not a sweeping process")
    if (force is None) == (not slope):
        raise InputError(spec.source, "", "give exactly one of force=PATH and slope=True")
    if slope:
        if spec.loads is None or spec.loads.weights is None:
            raise InputError(
                spec.source,
                "loads.slope",
                "the slope search needs the blocks' weights: add 'loads: {slope: {angle: 0.0, weight: W}}' to the gait",
            )
        return spec, "loads.slope.angle", "slope"
    assert force is not None
    path = force
    if not path.startswith("loads.force"):
        raise InputError(
            spec.source,
            path,
            "expected a path into loads.force, such as "
            "loads.force.0 (the force on block 1) or "
            "loads.force (one force on every block)",
        )
    loads = spec.document.get("loads") or {}
    if "force" not in loads:  # no force yet: start from zero forces on every block
        zero: Any = 0.0 if path == "loads.force" else [0.0] * spec.blocks
        document = {**spec.document, "loads": {**loads, "force": zero}}
        rebuilt = gait_from_document(document, spec.source, source_text=spec.source_text, default_name=spec.name)
        assert isinstance(rebuilt, Gait)
        spec = rebuilt
    if len(resolve_path(spec.document, path, spec.source)) != 1:
        raise InputError(spec.source, path, "expected a path to one number (no '*')")
    return spec, path, "force"


def _start_load(spec: Gait, path: str) -> float:
    """The gait's own load at ``path``: a constant number."""
    node = value_at(spec.document, resolve_path(spec.document, path, spec.source)[0])
    if not isinstance(node, (int, float)) or isinstance(node, bool):
        raise InputError(
            spec.source, path, f"expected a number at {path}, got {node!r}: the stall search varies a constant load"
        )
    return float(node)


def _scan(
    moving: Callable[[float], bool], s0: float, direction: float, scale: float, quantity: str
) -> tuple[float, float | None]:
    """(the last load still moving, the first load stopped or None): uniform steps of
    `SCAN_STEPS`-ths of the range, then 5 % longer each (a force on one block of many may have
    to reach the whole body's friction), up to 90 degrees for a slope."""
    step = scale / SCAN_STEPS
    lo = s0
    limit = 90.0 if quantity == "slope" else math.inf
    offset = 0.0
    for k in itertools.count(1):
        offset += step * (1.05 ** max(0, k - SCAN_STEPS))
        s = s0 + direction * offset
        if abs(s) >= limit:
            s = direction * (limit - 1e-9)
            return lo, (None if moving(s) else s)
        if not moving(s):
            return lo, s
        lo = s
        if k > 10 * SCAN_STEPS:  # pragma: no cover - the body cannot hold past the friction
            break
    return lo, None


def _bisect(moving: Callable[[float], bool], lo: float, hi: float, width: float) -> tuple[float, float]:
    """The bracket (moving, stopped) shrunk to ``width`` by bisection on the predicate."""
    while abs(hi - lo) > width:
        middle = 0.5 * (lo + hi)
        if middle in (lo, hi):
            break
        if moving(middle):
            lo = middle
        else:
            hi = middle
    return lo, hi


def _smooth_zero(
    probe: _Probe, lo: float, hi: float, v_lo: float, sign: float, direction: float, scale: float
) -> tuple[float, float]:
    """(the stall load, the bracket's stopped side) of a smooth zero: the predicate stopped
    where |v0| fell to its tolerance, so the zero is the secant root through lo and a point
    farther back on the moving side."""
    value = 0.5 * (lo + hi)
    back = lo - direction * max(1e3 * abs(hi - lo), 1e-6 * scale)
    v_back, _, _ = probe(back)
    if v_back is not None and v_back * sign > abs(v_lo) and v_back != v_lo:
        root = lo - v_lo * (lo - back) / (v_lo - v_back)
        if abs(root - lo) <= 1e3 * abs(hi - lo):
            value = root
            hi = lo + 2 * (root - lo) if abs(root - lo) > abs(hi - lo) / 2 else hi
    return value, hi
