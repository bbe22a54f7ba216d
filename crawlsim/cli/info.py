"""``crawlsim info``: what a results file holds, run or sweep, in a few lines."""

from __future__ import annotations

import math

import click

from crawlsim.analysis.digits import counted, how_found, with_error
from crawlsim.analysis.report import quotient_error
from crawlsim.cli import library_errors, main, to_json
from crawlsim.status import Convergence


def _g(value, digits: int = 12) -> str:
    return "n/a" if value is None else f"{value:.{digits}g}"


def _run_lines(d: dict) -> list[str]:
    """The lines of a run's file: the summary of ``crawlsim run``, from the attributes."""
    what = "gait" if d["kind"] == "crawler" else d["kind"]
    lines = [f"{d['file']}: run of {what} {d['name']}", f"  integrator               {d['integrator'] or 'n/a'}"]
    if d["v0"] is not None:
        lines.append(f"  v0                       {with_error(d['v0'], d['v0_error_estimate'])}")
    conv = d["convergence"]
    if conv == Convergence.FINITE_TIME:
        conv += f": periodic from period {d['periodic_from']}"
    elif conv == Convergence.ASYMPTOTIC:
        conv += f", contraction rate {_g(d['contraction_rate'], 4)} per period"
        if d.get("contraction_rate_periods"):
            error = d.get("contraction_rate_error")
            spread = "" if error is None else f"± {error:.1g}, "
            conv += f" ({spread}fitted on {d['contraction_rate_periods']} periods)"
    lines.append(f"  convergence              {conv}")
    if d.get("grid_note"):
        lines.append(f"  grid                     {d['grid_note']}")
    found = how_found(
        d.get("limit_method"), d.get("limit_newton_steps"), d.get("limit_periods"), d.get("jacobian_rate")
    )
    lines.append(f"  limit found by           {found}")
    lines.append(
        f"  periods                  {d['periods']} of {counted(d['steps_per_period'], 'step')} "
        f"(period {_g(d['period'])})"
    )
    if d["displacement_per_period"] is not None:  # as `crawlsim run` prints them
        d_err = None if d["v0_error_estimate"] is None else d["v0_error_estimate"] * d["period"]
        dD_err = d["dissipation_error_estimate"]
        cot_err = quotient_error(d["cost_of_transport"], d["displacement_per_period"], dD_err, d_err)
        lines.append(f"  displacement per period  {with_error(d['displacement_per_period'], d_err)}")
        lines.append(f"  dissipation per period   {with_error(d['dissipation_per_period'], dD_err)}")
        if d["cost_of_transport"] is not None:
            lines.append(f"  cost of transport        {with_error(d['cost_of_transport'], cot_err)}")
    if d.get("rigid_v0") is not None:
        lines.append(
            f"  rigid limit v0           {with_error(d['rigid_v0'], d['rigid_v0_error_estimate'])} (k -> infinity)"
        )
    if d.get("uniqueness_margin"):
        lines.append(f"  uniqueness margin        {d['uniqueness_margin']['text']}")
    return lines


def summary_lines(d: dict) -> list[str]:
    """The text of ``crawlsim info`` for `crawlsim.io.describe.describe`'s dict."""
    lines = []
    if d["file_kind"] == "run":
        lines.extend(_run_lines(d))
    elif d["file_kind"] == "optimization":
        lines.append(f"{d['file']}: optimisation of gait {d['name']}, from {d['source']}: {d['objective']}")
        for c in d["constraints"]:
            lines.append(f"  subject to               {c}")
        for free in d["free"]:
            lines.append(
                f"  free                     {free['path']} in [{_g(free['lo'])}, "
                f"{_g(free['hi'])}]: best {_g(d['best'].get(free['path']))}"
            )
        lines.append(
            f"  best v0                  {_g(d['v0'])} (cost of transport "
            f"{_g(d['cost_of_transport'], 6)})" + ("" if d["best_feasible"] else ", infeasible")
        )
        counts = ", ".join(f"{v} {k}" for k, v in sorted(d["statuses"].items()))
        lines.append(f"  evaluations              {d['evaluations']} of {d['max_evaluations']} allowed: {counts}")
        if d["front_points"] is not None:
            lines.append(f"  Pareto front             {d['front_points']} points")
        lines.append(f"  integrator, seed         {d['integrator']}, {d['seed']}")
    else:
        shard = f" (shard {d['shard']})" if d["shard"] else ""
        if [dim["paths"] for dim in d["grid"]] == [["gait"]]:  # crawlsim velocity A.yaml B.yaml ...
            lines.append(f"{d['file']}: v0 of {d['source']}{shard}")
        else:
            lines.append(f"{d['file']}: sweep of gait {d['name']}{shard}, from {d['source']}")
        for n, dim in enumerate(d["grid"], 1):
            paths = " with ".join(dim["paths"])
            lines.append(
                f"  dimension {n}              {paths}: {dim['values']} values"
                + ("" if dim["min"] is None else f" in [{_g(dim['min'])}, {_g(dim['max'])}]")
            )
        counts = ", ".join(f"{v} {k}" for k, v in sorted(d["statuses"].items()))
        lines.append(f"  points                   {d['points']}: {counts}")
        lines.append(f"  integrator               {d['integrator'] or 'n/a (older file)'}")
        if d["v0_min"] is not None:
            lines.append(f"  v0 of the ok points      {_g(d['v0_min'])} to {_g(d['v0_max'])}")
    lines.append(f"  written by               crawlsim {d['crawlsim_version']} (format {d['format_version']})")
    for key, value in sorted(d["attributes"].items()):
        if not (isinstance(value, float) and math.isnan(value)):  # NaN: does not apply to this run
            lines.append(f"  {key:<24} {value}")
    return lines


@main.command()
@click.argument("results_file", type=click.Path(dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
def info(results_file, as_json):
    """Summarise a results file, of a run, a sweep or an optimisation.

    RESULTS_FILE is written by crawlsim run, or by crawlsim velocity --sweep ... -o OUT.h5 and
    crawlsim merge. A file that is not a crawlsim results file is refused (exit code 2).

    For a run: gait, integrator, v0 and its error, convergence, periods. For a sweep: the grid,
    the counts of statuses, the range of v0. Both: the crawlsim version that wrote the file and
    its other attributes (provenance).

    \b
    Examples:
      crawlsim run gaits/inching-2.yaml -o inching.h5 && crawlsim info inching.h5
      crawlsim info inching.h5 --json
    """
    from crawlsim.io.describe import describe  # start-up: h5py when the command runs

    with library_errors():
        d = describe(results_file)
    if as_json:
        click.echo(
            to_json(
                {k: v for k, v in d.items() if k != "attributes"}
                | {"attributes": {k: str(v) for k, v in d["attributes"].items()}}
            )
        )
    else:
        click.echo("\n".join(summary_lines(d)))
