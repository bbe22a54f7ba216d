"""What a run's result says to a reader: the summary `crawlsim run` prints, the message of a run
that did not succeed, the note on a catch-up verdict that depends on the grid, and the short
``repr`` and HTML table of a result in a notebook.

Every number is printed with only the digits its error estimate supports
(`crawlsim.analysis.digits`); ``--json`` and `RunResult.summary` keep full precision.
"""

from __future__ import annotations

import html
import math
from collections.abc import Callable
from typing import TYPE_CHECKING

from crawlsim.analysis.digits import counted, how_found, with_error
from crawlsim.status import Convergence, LimitMethod, RunStatus

if TYPE_CHECKING:
    from crawlsim.analysis.run import RunResult

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


def not_converged_message(result: RunResult, max_periods: int, tolerance: float, limit: str) -> str:
    """The one line on stderr of a run that ended without a verified limit (exit code 3): why,
    and what to change (`run_message`)."""
    why = run_message(result, max_periods=max_periods, tolerance=tolerance, limit=limit)
    return f"Not converged: {why}. The numbers printed are those of the last period."


def verdict_rate(result: RunResult) -> float | None:
    """The rate behind a verdict: the Jacobian's at the limit when formed, else the fitted."""
    if result.convergence == Convergence.FINITE_TIME:
        return None
    return result.jacobian_rate if result.jacobian_rate is not None else result.contraction_rate


def grid_note(result: RunResult) -> str | None:
    """For a catch-up run measured against the exact integrator: None when both verdicts agree,
    else a sentence naming the exact integrator's verdict. Catch-up's verdict is that of the
    discretised process, whose contraction (and whether a finite-time jump happens at all)
    changes with the grid; the exact integrator's is the process's own."""
    exact = result.exact_convergence
    if result.integrator == "exact" or exact is None:
        return None
    rate = result.exact_rate
    exact_text = f"{exact}" + ("" if rate is None else f", rate {rate:.2g}")
    mine = verdict_rate(result)
    if exact == result.convergence:
        if rate is None or mine is None:
            return None
        spread = RATE_AGREEMENT * max(abs(rate), abs(mine))
        if abs(mine - rate) <= spread + 3.0 * (result.contraction_rate_error or 0.0):
            return None
    return (
        f"catch-up's verdict depends on the time grid ({result.steps_per_period} steps per "
        f"period); the exact integrator finds {exact_text}"
    )


def _error_parts(result: RunResult) -> str:
    """Where v0's error estimate comes from, after ``v0 ± estimate``."""
    if result.v0_error_estimate is None:
        return f" ({result.v0_error_reason or 'no error estimate'})"
    quasi = result.terrain is not None and result.terrain.regime == "quasi-periodic"
    if quasi and result.integrator == "exact":
        return " (the long-run average's estimate, docs/model.md §8)"
    if result.integrator == "exact":
        return " (period iteration; the exact integrator has no time-step error)"
    step = result.v0_error_time_step
    if step is None:
        return " (period iteration only)"
    return (
        f" (time step {step:.1g}, measured against the exact integrator; period iteration "
        f"{result.v0_error_period_iteration:.1g})"
    )


def convergence_text(result: RunResult) -> str:
    """The verdict with its evidence: the rate, its standard error and the periods fitted."""
    if result.convergence == Convergence.FINITE_TIME:
        return f"finite-time: periodic from period {result.periodic_from}"
    if result.convergence == Convergence.ASYMPTOTIC:
        rate = result.contraction_rate
        if rate is None:
            return "asymptotic, contraction rate n/a per period"
        error = result.contraction_rate_error
        spread = "" if error is None else f"± {error:.1g}, "
        return (
            f"asymptotic, contraction rate {rate:.4g} per period ({spread}fitted on "
            f"{result.contraction_rate_periods} periods)"
        )
    if result.convergence == Convergence.QUASI_PERIODIC:
        return f"quasi-periodic: not locked to the ground over {result.periods} periods (docs/model.md §8)"
    return f"NOT converged: final Poincare step {result.history.poincare_step[-1]:.3g}. Try increasing max_periods."


def _units_of(result: RunResult) -> Unit:
    units = getattr(result, "units", None)  # the gait file's units (crawlsim.api results)

    def unit(quantity: str) -> str:
        return "" if units is None else str(units.suffix(quantity))

    return unit


def summary_rows(result: RunResult) -> list[Row]:
    """The labelled values of the summary, in order (`summary_text`, `result_html`)."""
    unit = _units_of(result)
    rows: list[Row] = []
    if result.v0 is not None:
        rows.append(("v0", with_error(result.v0, result.v0_error_estimate, unit("velocity")) + _error_parts(result)))
    rows.append(("convergence", convergence_text(result)))
    if result.terrain is not None:
        rows.extend(result.terrain.text(result.period))
    if result.grid_note:
        rows.append(("grid", result.grid_note))
    rows.append(
        (
            "limit found by",
            how_found(result.limit_method, result.limit_newton_steps, result.limit_periods, result.jacobian_rate),
        )
    )
    if result.displacement_per_period is not None:
        assert result.dissipation_per_period is not None
        rows.append(
            (
                "displacement per period",
                with_error(result.displacement_per_period, result.displacement_error_estimate, unit("length")),
            )
        )
        rows.append(
            (
                "dissipation per period",
                with_error(result.dissipation_per_period, result.dissipation_error_estimate, unit("dissipation")),
            )
        )
        cot = (
            "n/a (no net motion)"
            if result.cost_of_transport is None
            else with_error(result.cost_of_transport, result.cost_of_transport_error_estimate, unit("force"))
        )
        rows.append(("cost of transport", cot))
        rows.extend(energy_rows(result, unit))
    return rows


def headline(result: RunResult) -> str:
    what = "gait" if result.v0 is not None else "process"  # a generic process has no v0
    return f"{what} {result.name}: {counted(result.periods, 'period')} of {counted(result.steps_per_period, 'step')}"


def _line(row: Row) -> str:
    return f"  {row[0]:<24} {row[1]}"


def summary_text(result: RunResult, output: str | None = None) -> str:
    """The short human summary printed by ``crawlsim run``: each number with only the digits
    its error estimate supports (`crawlsim.analysis.digits`); ``--json`` keeps full precision."""
    rows = summary_rows(result)
    if output:
        rows.append(("written", output))
    return "\n".join([headline(result), *map(_line, rows)])


def energy_lines(result: RunResult, unit: Unit) -> list[str]:
    """The energy ledger's lines of the summary (`crawlsim.analysis.energy`)."""
    return [_line(row) for row in energy_rows(result, unit)]


def energy_rows(result: RunResult, unit: Unit) -> list[Row]:
    """The energy ledger's rows of the summary (`crawlsim.analysis.energy`)."""
    if result.actuator_work_per_period is None:
        return []
    work = result.actuator_work_per_period
    loss = result.jump_loss_per_period or 0.0
    numerical = result.discretisation_loss_per_period
    residual = result.energy_balance_residual or 0.0
    relative = abs(residual) / max(abs(work), 1e-300)
    # W = D + J (+ catch-up's numerical loss, first order in the step): the work is as accurate
    # as the dissipation, and for catch-up its losses are those of the step too
    err = result.dissipation_error_estimate
    if err is not None and numerical is not None:
        err += abs(loss) + abs(numerical)
    terms = ("" if numerical is None else " - discretisation loss") + (
        " - load work" if result.load_work_per_period is not None else ""
    )
    rows = [
        ("actuator work per period", with_error(work, err, unit("dissipation"))),
        ("jump losses per period", f"{loss:.3g}{unit('dissipation')}"),
        (
            "energy balance residual",
            f"{residual:.3g}{unit('dissipation')} (work - dissipation - jump losses{terms}; {relative:.1g} relative)",
        ),
    ]
    if numerical is not None:
        rows[2:2] = [
            (
                "discretisation loss",
                f"{numerical:.3g}{unit('dissipation')} per period (catch-up's own, first order in the step)",
            )
        ]
    if result.load_work_per_period is not None:
        rows[2:2] = [_load_row(result, err, unit)]
        if result.efficiency is not None:
            load = result.load_work_per_period
            eff_err = (
                None if err is None or load == 0 else result.efficiency * 1.01 * (err / abs(load) + err / abs(work))
            )
            rows.append(("efficiency", f"{with_error(result.efficiency, eff_err)} (load work / actuator work)"))
    if result.cost_of_transport_bound is not None:
        rows.append(_bound_row(result, unit))
    return rows


def _load_row(result: RunResult, err: float | None, unit: Unit) -> Row:
    # W_load carries the error of the work it is part of (W = D + J + W_load, §6)
    assert result.load_work_per_period is not None
    return (
        "load work per period",
        f"{with_error(result.load_work_per_period, err, unit('dissipation'))} (against the loads, docs/model.md §6)",
    )


def _bound_row(result: RunResult, unit: Unit) -> Row:
    cot_err = result.cost_of_transport_error_estimate
    eff = (
        "n/a"
        if result.efficiency is None or result.cost_of_transport is None
        else (
            with_error(
                result.efficiency,
                None if cot_err is None else 1.01 * result.efficiency * cot_err / result.cost_of_transport,
            )
        )
    )
    return ("cost of transport bound", f"{result.cost_of_transport_bound:.12g}{unit('force')} (efficiency {eff})")


def _extra_rows(result: RunResult) -> list[Row]:
    """What a notebook result holds besides the summary: its status and message, the
    trajectory kept and the file written (`crawlsim.api.SimulationResult`)."""
    rows: list[Row] = [
        ("status", str(result.status) + ("" if result.status == RunStatus.SUCCESSFUL else f": {result.message}"))
    ]
    trajectory = getattr(result, "trajectory", None)
    if trajectory is not None:
        names = list(trajectory.columns())
        events = "" if trajectory.events is None else (f", {len(trajectory.events['t'])} events")
        rows.append(("trajectory", f"{len(trajectory.t)} saved points ({', '.join(names)}){events}"))
    output = getattr(result, "output", None)
    if output is not None:
        rows.append(("written", str(output)))
    return rows


def result_repr(result: RunResult) -> str:
    """A result's ``repr``: its type and the summary, at most `REPR_LINES` lines."""
    lines = [f"<{type(result).__name__}> {headline(result)}", *map(_line, summary_rows(result) + _extra_rows(result))]
    if len(lines) > REPR_LINES:
        lines = lines[: REPR_LINES - 1] + ["  ... (result.summary() has every number)"]
    return "\n".join(lines)


def result_html(result: RunResult) -> str:
    """A result as an HTML table for notebooks: the headline as caption, one row per value."""
    cells = "".join(
        f'<tr><th style="text-align:left">{html.escape(label)}</th>'
        f'<td style="text-align:left">{html.escape(value)}</td></tr>'
        for label, value in summary_rows(result) + _extra_rows(result)
    )
    caption = html.escape(f"{type(result).__name__}: {headline(result)}")
    return f"<table><caption>{caption}</caption>{cells}</table>"
