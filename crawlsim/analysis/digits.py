"""Printing a value with only the digits its error estimate supports (and the one line saying
how a run's periodic limit was found, for the summaries: no numerical module is imported).

A summary that prints ``0.370883735228`` for a v0 whose error is 3e-4 invites a reader to copy
nine wrong digits. `supported` rounds the value at the leading digit of its error estimate and
widens the printed estimate by what that rounding moved, so that the printed pair keeps the
promise of the unrounded one: the true value lies within the printed estimate of the printed
value, ``|printed - true| <= |printed - value| + error <= printed error``.
"""

from __future__ import annotations

import math
from decimal import ROUND_CEILING, ROUND_HALF_EVEN, Decimal


def supported(value: float, error: float | None) -> tuple[str, str | None]:
    """``(value, error)`` as text: the value rounded at the decimal place of the error's leading
    digit, and the error rounded up to one significant digit after adding the rounding. A zero
    error (a gait whose blocks never slip moves by exactly 0) keeps every digit; without a
    finite error the value keeps 12 significant digits and the error is None."""
    if error == 0 and math.isfinite(value):
        return f"{value:.17g}", "0"
    if error is None or not math.isfinite(error) or error <= 0 or not math.isfinite(value):
        return f"{value:.12g}", None
    place = math.floor(math.log10(error))
    unit = Decimal(1).scaleb(place)
    exact = Decimal(repr(float(value)))
    shown = exact.quantize(unit, rounding=ROUND_HALF_EVEN) if place > -300 else exact
    total = Decimal(repr(float(error))) + abs(shown - exact)
    bound = (total / unit).to_integral_value(rounding=ROUND_CEILING) * unit
    text = f"{shown:f}" if place < 0 else f"{int(shown)}"
    if text in ("-0", "-0." + "0" * (len(text) - 3)):
        text = text[1:]  # a rounded zero has no sign
    return text, f"{float(bound):.1g}"


def with_error(value: float, error: float | None, unit: str = "") -> str:
    """``value ± error`` with the supported digits (`supported`), each with its unit suffix."""
    text, bound = supported(value, error)
    return f"{text}{unit}" if bound is None else f"{text}{unit} ± {bound}{unit}"


def counted(n: int | None, noun: str) -> str:
    """``n`` and ``noun``, plural but for one: "1 period", "2 periods"."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


def how_found(
    method: str | None, newton_steps: int | None, periods: int | None, jacobian_rate: float | None = None
) -> str:
    """One line saying how a run's limit was found (``crawlsim run`` and ``crawlsim info``)."""
    if method == "newton":
        rate = "" if jacobian_rate is None else f", Jacobian rate {jacobian_rate:.4g}"
        steps, simulated = counted(newton_steps, "Newton step"), counted(periods, "period")
        return f"Newton on the period map: {steps} in {simulated}, verified by a plain period{rate}"
    if method == "iterate":
        return "plain iteration of the periods"
    return "n/a (older file)"
