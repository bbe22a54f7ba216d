"""What a run's result says to a reader: the summary `crawlsim run` prints, the message of a run
that did not succeed, the note on a catch-up verdict that depends on the grid, and the short
``repr`` and HTML table of a result in a notebook.

Every number is printed with only the digits its error estimate supports
(`crawlsim.analysis.digits`); ``--json`` and `RunResult.summary` keep full precision.
"""

from __future__ import annotations

import html
import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from crawlsim.analysis.digits import counted, how_found, with_error
from crawlsim.status import Convergence, LimitMethod, RunStatus

if TYPE_CHECKING:
    from crawlsim.analysis.run import RunResult
    from crawlsim.gait.units import Units

#: The most lines a result's ``repr`` prints (the summary, never the arrays).
REPR_LINES = 25
#: Two contraction rates differ when they are further apart than this fraction of the larger.
RATE_AGREEMENT = 0.1

Row = tuple[str, str]
Unit = Callable[[str], str]


def run_message(result: RunResult, *, max_periods: int, tolerance: float, limit: str) -> str:
    """What happened and what to change, for a run whose `RunStatus` is not successful (in
    diffrax's manner): max_periods ran out before the limit was found."""
    steps = result.history.poincare_step
    step = float(steps[-1]) if len(steps) else math.nan
    advice = "raise `max_periods` (--max-periods)"
    if limit == LimitMethod.ITERATE:
        advice += " or let the periodic-limit solver find the limit (`--limit newton`)"
    return (
        f"the maximum number of periods was reached: max_periods = {max_periods} periods "
        f"ran out before the limit was found (final Poincare step {step:.3g}, tolerance "
        f"{tolerance:.3g} relative); {advice}"
    )


def not_converged_message(result: RunResult) -> str:
    """The one line on stderr of a run that ended without a verified limit (exit code 3): why,
    and what to change (its `RunResult.message`)."""
    return f"Not converged: {result.message}. The numbers printed are those of the last period."


def verdict_rate(result: RunResult) -> float | None:
    """The rate behind a verdict: the Jacobian's at the limit when formed, else the fitted."""
    if result.convergence == Convergence.FINITE_TIME:
        return None
    if result.solver.jacobian_rate is not None:
        return result.solver.jacobian_rate
    return None if result.rate is None else result.rate.rate


def grid_note(result: RunResult) -> str | None:
    """For a catch-up run measured against the exact integrator: None when both verdicts agree,
    else a sentence naming the exact integrator's verdict. Catch-up's verdict is that of the
    discretised process, whose contraction (and whether a finite-time jump happens at all)
    changes with the grid; the exact integrator's is the process's own."""
    if result.integrator == "exact" or result.exact is None:
        return None
    exact, rate = result.exact.convergence, result.exact.rate
    exact_text = f"{exact}" + ("" if rate is None else f", rate {rate:.2g}")
    mine = verdict_rate(result)
    if exact == result.convergence:
        if rate is None or mine is None:
            return None
        spread = RATE_AGREEMENT * max(abs(rate), abs(mine))
        if abs(mine - rate) <= spread + 3.0 * ((result.rate and result.rate.error) or 0.0):
            return None
    return (
        f"catch-up's verdict depends on the time grid ({result.steps_per_period} steps per "
        f"period); the exact integrator finds {exact_text}"
    )


def _error_parts(result: RunResult) -> str:
    """Where v0's error estimate comes from, after ``v0 ± estimate``."""
    e = result.estimate
    assert e is not None
    if e.error_estimate is None:
        return f" ({e.reason or 'no error estimate'})"
    if result.integrator == "exact":
        return " (period iteration; the exact integrator has no time-step error)"
    if e.time_step is None:
        return " (period iteration only)"
    return (
        f" (time step {e.time_step:.1g}, measured against the exact integrator; period iteration "
        f"{e.period_iteration:.1g})"
    )


def convergence_text(result: RunResult) -> str:
    """The verdict with its evidence: the rate, its standard error and the periods fitted."""
    if result.convergence == Convergence.FINITE_TIME:
        return f"finite-time: periodic from period {result.periodic_from}"
    if result.convergence == Convergence.ASYMPTOTIC:
        fit, solver = result.rate, result.solver
        jacobian = None if solver is None else solver.jacobian_rate
        if fit is None and jacobian is None:
            return "asymptotic, contraction rate n/a per period"
        fitted = "" if fit is None else f"fitted on {fit.periods} periods"
        if fit is not None and fit.error is not None:
            fitted = f"± {fit.error:.1g}, {fitted}"
        if fit is not None and (jacobian is None or abs(fit.rate - jacobian) <= 3 * (fit.error or 0.0)):
            return f"asymptotic, contraction rate {fit.rate:.4g} per period ({fitted})"
        # the solver's limit: the history stops after a few periods, whose fit need not be the
        # asymptotic rate yet; the Jacobian's at the limit is
        seen = "" if fit is None else f"; the history's {fit.rate:.4g} {fitted}"
        return f"asymptotic, contraction rate {jacobian:.4g} per period (the Jacobian's at the limit{seen})"
    return f"NOT converged: final Poincare step {result.history.poincare_step[-1]:.3g}. Try increasing max_periods."


def summary_rows(result: RunResult, units: Units | None = None) -> list[Row]:
    """The labelled values of the summary, in order (`summary_text`, `result_html`), with the
    units of the gait file."""

    def unit(quantity: str) -> str:
        return "" if units is None else str(units.suffix(quantity))

    rows: list[Row] = []
    e, energy, solver = result.estimate, result.energy, result.solver
    if e is not None:
        rows.append(("v0", with_error(e.value, e.error_estimate, unit("velocity")) + _error_parts(result)))
    rows.append(("convergence", convergence_text(result)))
    if result.exact is not None and result.exact.note:
        rows.append(("grid", result.exact.note))
    rows.append(("limit found by", how_found(solver.method, solver.newton_steps, solver.periods, solver.jacobian_rate)))
    if e is not None and energy is not None:
        d_err = None if e.error_estimate is None else e.error_estimate * result.period
        rows.append(("displacement per period", with_error(e.displacement, d_err, unit("length"))))
        D, D_err = energy.dissipation, energy.dissipation_error_estimate
        rows.append(("dissipation per period", with_error(D, D_err, unit("dissipation"))))
        cot = energy.cost_of_transport
        shown = "n/a (no net motion)" if cot is None else with_error(cot, _cot_error(result), unit("force"))
        rows.append(("cost of transport", shown))
        rows.extend(energy_rows(result, unit))
    return rows


def quotient_error(cot: float | None, d: float | None, dD: float | None, dd: float | None) -> float | None:
    """The error of the cost of transport cot = D/|d| from those of D and d: first-order
    propagation through the quotient (|d(D/d)| <= dD/|d| + D dd/d^2), widened by 1 % for the
    second-order term, which is below that wherever the cost of transport is printed at all."""
    if cot is None or d is None or dD is None or dd is None or d == 0:
        return None
    return 1.01 * (dD / abs(d) + cot * dd / abs(d))


def _cot_error(result: RunResult) -> float | None:
    """`quotient_error` of the run's dissipation over its displacement."""
    e, energy = result.estimate, result.energy
    assert e is not None and energy is not None
    dd = None if e.error_estimate is None else e.error_estimate * result.period
    return quotient_error(energy.cost_of_transport, e.displacement, energy.dissipation_error_estimate, dd)


def headline(result: RunResult) -> str:
    what = "gait" if result.v0 is not None else "process"  # a generic process has no v0
    return f"{what} {result.name}: {counted(result.periods, 'period')} of {counted(result.steps_per_period, 'step')}"


def _line(row: Row) -> str:
    return f"  {row[0]:<24} {row[1]}"


def summary_text(result: RunResult, output: str | None = None, units: Units | None = None) -> str:
    """The short human summary printed by ``crawlsim run``: each number with only the digits
    its error estimate supports (`crawlsim.analysis.digits`); ``--json`` keeps full precision."""
    rows = summary_rows(result, units)
    if output:
        rows.append(("written", output))
    return "\n".join([headline(result), *map(_line, rows)])


def energy_rows(result: RunResult, unit: Unit) -> list[Row]:
    """The energy ledger's rows of the summary (`crawlsim.analysis.energy`)."""
    energy = result.energy
    if energy is None:
        return []
    work, loss, residual, load = energy.actuator_work, energy.jump_loss, energy.balance_residual, energy.load_work
    numerical = energy.discretisation_loss
    relative = abs(residual) / max(abs(work), 1e-300)
    # W = D + J (+ catch-up's numerical loss, first order in the step): the work is as accurate
    # as the dissipation, and for catch-up its losses are those of the step too
    err = energy.dissipation_error_estimate
    if err is not None and numerical is not None:
        err += abs(loss) + abs(numerical)
    terms = ("" if numerical is None else " - discretisation loss") + (" - load work" if load is not None else "")
    rows = [
        ("actuator work per period", with_error(work, err, unit("dissipation"))),
        ("jump losses per period", f"{loss:.3g}{unit('dissipation')}"),
        (
            "energy balance residual",
            f"{residual:.3g}{unit('dissipation')} (work - dissipation - jump losses{terms}; {relative:.1g} relative)",
        ),
    ]
    if numerical is not None:
        loss_text = f"{numerical:.3g}{unit('dissipation')} per period (catch-up's own, first order in the step)"
        rows[2:2] = [("discretisation loss", loss_text)]
    if load is not None:
        # W_load carries the error of the work it is part of (W = D + J + W_load, §6)
        against = f"{with_error(load, err, unit('dissipation'))} (against the loads, docs/model.md §6)"
        rows[2:2] = [("load work per period", against)]
        eff = energy.efficiency
        if eff is not None:
            eff_err = None if err is None or load == 0 else eff * 1.01 * (err / abs(load) + err / abs(work))
            rows.append(("efficiency", f"{with_error(eff, eff_err)} (load work / actuator work)"))
    if energy.cost_of_transport_bound is not None:
        cot, cot_err, efficiency = energy.cost_of_transport, _cot_error(result), energy.efficiency
        shown = "n/a"
        if efficiency is not None and cot is not None:
            shown = with_error(efficiency, None if cot_err is None else 1.01 * efficiency * cot_err / cot)
        bound = f"{energy.cost_of_transport_bound:.12g}{unit('force')} (efficiency {shown})"
        rows.append(("cost of transport bound", bound))
    return rows


def _notebook_rows(result: RunResult, units: Units | None, extra: Sequence[Row]) -> list[Row]:
    """The summary's rows, the status and message, and what the holder of the result adds
    (`crawlsim.api.SimulationResult`: the trajectory kept, the file written)."""
    status = str(result.status) + ("" if result.status == RunStatus.SUCCESSFUL else f": {result.message}")
    return [*summary_rows(result, units), ("status", status), *extra]


def result_repr(result: RunResult, units: Units | None = None, extra: Sequence[Row] = (), kind: str = "") -> str:
    """A result's ``repr``: its type (``kind``) and the summary, at most `REPR_LINES` lines."""
    head = f"<{kind or type(result).__name__}> {headline(result)}"
    lines = [head, *map(_line, _notebook_rows(result, units, extra))]
    if len(lines) > REPR_LINES:
        lines = lines[: REPR_LINES - 1] + ["  ... (result.summary() has every number)"]
    return "\n".join(lines)


def result_html(result: RunResult, units: Units | None = None, extra: Sequence[Row] = (), kind: str = "") -> str:
    """A result as an HTML table for notebooks: the headline as caption, one row per value."""
    cells = "".join(
        f'<tr><th style="text-align:left">{html.escape(label)}</th>'
        f'<td style="text-align:left">{html.escape(value)}</td></tr>'
        for label, value in _notebook_rows(result, units, extra)
    )
    caption = html.escape(f"{kind or type(result).__name__}: {headline(result)}")
    return f"<table><caption>{caption}</caption>{cells}</table>"
