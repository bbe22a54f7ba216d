"""Results for notebooks and files: the short repr and the HTML table, the status and message of
a run that ran out of periods, the contraction rate with its evidence, the note on a catch-up
verdict that depends on the grid, the time index of xarray, and the typed readers that give back
the very result the API returned."""

import dataclasses
import html
import math
import re

import numpy as np
import pytest
from scipy import stats

import crawlsim
from crawlsim.analysis.convergence import RATE_WINDOW, RateFit, fit_contraction_rate
from crawlsim.analysis.report import REPR_LINES, grid_note
from crawlsim.analysis.run import ExactVerdict
from crawlsim.api import open_run, open_sweep
from crawlsim.errors import ResultsFileError
from crawlsim.status import Convergence, RunStatus

from .conftest import GAITS

P4 = GAITS / "peristalsis-4.yaml"
TRIANGLE = GAITS / "paper" / "triangle.yaml"
SMOOTH = GAITS / "smooth-friction-3.yaml"


@pytest.fixture(scope="module")
def p4():
    return crawlsim.simulate(P4, steps_per_period=200)


@pytest.fixture(scope="module")
def triangle():
    """The paper's triangle: asymptotic convergence at the rate 1/8 the paper predicts."""
    return crawlsim.simulate(TRIANGLE, steps_per_period=60, save_every=3)


# -- repr and HTML -------------------------------------------------------------------------------
def test_repr_is_the_summary_in_at_most_25_lines(p4):
    text = repr(p4)
    lines = text.splitlines()
    assert len(lines) <= REPR_LINES == 25
    assert lines[0] == "<SimulationResult> gait peristalsis-4: 2 periods of 200 steps"
    v0 = next(line for line in lines if line.strip().startswith("v0 "))
    shown = float(v0.split()[1])
    error = float(v0.split()[3])
    assert abs(shown - p4.v0) <= error  # the digits printed are those the estimate supports
    assert "array(" not in text and "[[" not in text  # no arrays
    assert "  status                   successful" in lines
    assert (
        f"  trajectory               {len(p4.trajectory.t)} saved points (t, w, x, stress, "
        f"shape), {len(p4.trajectory.events['t'])} events" in lines
    )


def test_repr_html_is_a_table_of_the_summary(p4):
    table = p4._repr_html_()
    assert table.startswith("<table><caption>") and table.endswith("</table>")
    rows = dict(re.findall(r"<tr><th[^>]*>(.*?)</th><td[^>]*>(.*?)</td></tr>", table))
    assert html.unescape(rows["status"]) == "successful"
    shown, _, error = html.unescape(rows["v0"]).split()[:3]
    assert abs(float(shown) - p4.v0) <= float(error)
    assert rows["convergence"] == "finite-time: periodic from period 1"
    summary = p4.summary()
    assert float(html.unescape(rows["cost of transport bound"]).split()[0]) == summary["cost_of_transport_bound"]


# -- status and message --------------------------------------------------------------------------
@pytest.mark.parametrize("limit", ["iterate", "newton"])
def test_a_run_out_of_periods_says_so_and_what_to_change(limit):
    gait = crawlsim.load_gait(TRIANGLE).replace("simulation.limit", limit)
    result = crawlsim.simulate(gait, steps_per_period=60, max_periods=2)
    assert result.convergence == Convergence.NOT_CONVERGED
    assert result.status == RunStatus.MAX_PERIODS_REACHED == "max-periods-reached"
    assert not result.converged
    message = result.message
    assert message.startswith("the maximum number of periods was reached")
    assert "max_periods = 2" in message and "raise `max_periods`" in message
    assert ("`--limit newton`" in message) == (limit == "iterate")
    step = float(re.search(r"final Poincare step (\S+),", message).group(1))
    assert step == pytest.approx(result.history.poincare_step[-1], rel=1e-2)
    assert f"status                   max-periods-reached: {message}" in repr(result)
    assert result.summary()["status"] == "max-periods-reached"


def test_a_converged_run_has_no_message(p4, triangle):
    for result in (p4, triangle):
        assert result.status == RunStatus.SUCCESSFUL and result.message == ""


def test_a_catch_up_run_whose_error_cannot_be_measured_says_so(monkeypatch):
    """Catch-up's v0 is bounded only by its time-step error measured against the exact
    integrator: where that reference run fails, the run converges but its status says that v0
    has no error estimate, and the message why."""
    from crawlsim.analysis import run

    monkeypatch.setattr(run, "time_step_reference", lambda process, **options: None)
    result = crawlsim.simulate(P4, integrator="catch-up", steps_per_period=50)
    assert result.converged and result.v0 is not None and result.estimate.error_estimate is None
    assert result.status == RunStatus.NO_ERROR_ESTIMATE == "no-error-estimate"
    assert result.message == result.estimate.reason
    assert "the exact integrator's reference run failed" in result.message
    assert result.summary()["status"] == "no-error-estimate"


# -- the contraction rate and its evidence -------------------------------------------------------
def test_the_rate_of_the_triangle_is_one_eighth_with_a_tiny_error(triangle):
    """Theorem: the triangle contracts by exactly 1/8 a period; the fit's residuals are
    roundoff, and its standard error says so."""
    assert triangle.convergence == Convergence.ASYMPTOTIC
    assert triangle.rate.rate == pytest.approx(0.125, rel=1e-7)
    assert triangle.rate.periods == RATE_WINDOW
    assert 0 < triangle.rate.error < 1e-6
    assert abs(triangle.rate.rate - 0.125) <= 10 * triangle.rate.error + 1e-9
    line = next(x for x in repr(triangle).splitlines() if "convergence" in x)
    assert f"fitted on {RATE_WINDOW} periods" in line and "contraction rate 0.125 per period" in line


def test_the_rate_error_is_the_standard_error_of_the_fitted_slope():
    """r = exp(slope) of log(step) on q; its error is r times the slope's standard error, as
    scipy's linear regression computes it, plus the roundoff of the logarithms (eps / s each,
    weighted by the slope's coefficients)."""
    rng = np.random.default_rng(7)
    q = np.arange(12)
    steps = 0.3 * 0.6**q * np.exp(0.05 * rng.standard_normal(q.size))
    fit = fit_contraction_rate(steps)
    chosen = q[-RATE_WINDOW:]
    reference = stats.linregress(chosen, np.log(steps[chosen]))
    assert fit.periods == RATE_WINDOW
    assert fit.rate == pytest.approx(math.exp(reference.slope), rel=1e-12)
    x = chosen - chosen.mean()
    roundoff = np.sum(np.abs(x) / np.sum(x * x) * np.finfo(float).eps / steps[chosen])
    assert fit.error == pytest.approx(fit.rate * (reference.stderr + roundoff), rel=1e-9)
    assert abs(fit.rate - 0.6) < 4 * fit.error  # the truth lies within the error bars
    two = fit_contraction_rate(np.array([1e-2, 1e-3]))
    assert two.rate == pytest.approx(0.1) and two.error is None and two.periods == 2


# -- a catch-up verdict that depends on the grid --------------------------------------------------
def test_catch_up_is_measured_against_the_exact_verdict():
    result = crawlsim.simulate(P4, integrator="catch-up", steps_per_period=100)
    assert result.exact.convergence == Convergence.FINITE_TIME  # the exact run's own verdict
    assert result.convergence == Convergence.FINITE_TIME and result.exact.note is None
    disagree = dataclasses.replace(
        result.run, convergence=Convergence.ASYMPTOTIC, rate=RateFit(0.0013, 1e-4, 8), periodic_from=None
    )
    note = grid_note(disagree)
    assert note == (
        "catch-up's verdict depends on the time grid (100 steps per period); the exact integrator finds finite-time"
    )
    shown = dataclasses.replace(disagree, exact=dataclasses.replace(disagree.exact, note=note))
    assert f"  grid                     {note}" in repr(shown)


def test_grid_note_compares_the_rates_of_two_asymptotic_verdicts(triangle):
    catch_up = dataclasses.replace(
        triangle.run, integrator="catch-up", exact=ExactVerdict(Convergence.ASYMPTOTIC, 0.125)
    )
    assert grid_note(catch_up) is None  # the same rate (the Jacobian's, 0.125)
    slower = dataclasses.replace(
        catch_up, solver=dataclasses.replace(catch_up.solver, jacobian_rate=None), rate=RateFit(0.097, 1e-3, 8)
    )
    assert grid_note(slower).endswith("the exact integrator finds asymptotic, rate 0.12")
    exact = dataclasses.replace(slower, integrator="exact")
    assert grid_note(exact) is None  # the exact integrator's verdict is the process's


# -- xarray and the typed readers -----------------------------------------------------------------
def test_to_xarray_indexes_time(p4):
    pytest.importorskip("xarray")
    tree = p4.to_xarray()
    assert tree.attrs["Conventions"] == "CF-1.10"
    trajectory = tree["trajectory"].to_dataset()
    t = p4.trajectory.t
    k = 137
    picked = trajectory.sel(time=t[k])
    np.testing.assert_array_equal(picked.x.values, p4.trajectory.x[k])
    np.testing.assert_array_equal(picked.t.values, t[k])
    limit = tree["limit"].to_dataset()
    np.testing.assert_array_equal(limit.sel(limit_time=p4.limit.t[50]).w.values, p4.limit.w[50])


def _assert_same_result(mine, read):
    assert type(read) is type(mine)
    assert read.summary() == mine.summary()
    assert read.status == mine.status and read.convergence == mine.convergence
    for f in dataclasses.fields(mine.history):
        np.testing.assert_array_equal(getattr(read.history, f.name), getattr(mine.history, f.name), err_msg=f.name)
    for f in dataclasses.fields(mine.limit):
        a, b = getattr(mine.limit, f.name), getattr(read.limit, f.name)
        assert (a is None) == (b is None), f.name
        if a is not None:
            np.testing.assert_array_equal(b, a, err_msg=f.name)
    for name in ("t", "w", "x", "stress", "shape", "reaction"):
        a, b = getattr(mine.trajectory, name), getattr(read.trajectory, name)
        assert (a is None) == (b is None), name
        if a is not None:
            np.testing.assert_array_equal(b, a, err_msg=name)
    assert (mine.trajectory.events is None) == (read.trajectory.events is None)
    for name, values in (mine.trajectory.events or {}).items():
        np.testing.assert_array_equal(read.trajectory.events[name], values)
    for name in ("residuals", "kinds"):
        a, b = getattr(mine.solver, name), getattr(read.solver, name)
        assert (a is None) == (b is None), name
        if a is not None:
            np.testing.assert_array_equal(b, a)
    assert read.provenance == mine.provenance
    assert read.units == mine.units


@pytest.mark.parametrize("which", ["p4", "triangle", "catch-up"])
def test_open_run_gives_back_the_result_simulate_returned(which, p4, triangle, tmp_path):
    mine = {"p4": p4, "triangle": triangle}.get(which) or crawlsim.simulate(
        SMOOTH, integrator="catch-up", steps_per_period=50
    )
    path = mine.save(tmp_path / "run.h5")
    read = open_run(path)
    _assert_same_result(mine, read)
    assert read.output == path and repr(read).splitlines()[-1] == f"  {'written':<24} {path}"
    again = read.save(tmp_path / "copy.h5")  # a file read back saves the same bytes
    assert again.read_bytes() == path.read_bytes()


def test_run_files_of_the_cli_read_as_the_api_result(tmp_path):
    out = tmp_path / "inching.h5"
    result = crawlsim.run(GAITS / "inching-2.yaml", output=out)
    read = open_run(out)
    assert read.summary() == {**result.summary(), "wall_time": read.summary()["wall_time"]}
    assert read.v0 == result.v0 and read.status == RunStatus.SUCCESSFUL


def test_open_sweep_gives_back_the_dataset_sweep_returned(tmp_path):
    xr = pytest.importorskip("xarray")

    out = tmp_path / "sweep.h5"
    grid = crawlsim.sweep(P4, {"links.*.amplitude": [0.2, 0.3]}, steps_per_period=100, output=out)
    read = open_sweep(out)
    xr.testing.assert_identical(read.drop_attrs(), grid.drop_attrs())
    skip = {"created"}
    assert {k: v for k, v in read.attrs.items() if k not in skip} == {
        k: v for k, v in grid.attrs.items() if k not in skip
    }
    np.testing.assert_array_equal(read.v0.values, grid.v0.values)
    with pytest.raises(ResultsFileError, match="not a crawlsim sweep file"):
        open_sweep(crawlsim.simulate(P4, steps_per_period=50).save(tmp_path / "run.h5"))


def test_info_prints_the_rate_with_its_evidence(triangle, tmp_path):
    from click.testing import CliRunner

    from crawlsim.cli import main

    path = triangle.save(tmp_path / "triangle.h5")
    r = CliRunner().invoke(main, ["info", str(path)])
    assert r.exit_code == 0, r.output
    line = next(x for x in r.output.splitlines() if x.startswith("  convergence"))
    error = f"{triangle.rate.error:.1g}"
    assert line == (
        "  convergence              asymptotic, contraction rate 0.125 per period "
        f"(± {error}, fitted on {RATE_WINDOW} periods)"
    )


def test_the_exact_verdict_is_claimed_only_where_the_reference_run_shows_it(p4, triangle):
    """The reference run stops at the verified limit: its own verdict counts where its iterates
    reached the limit themselves; after the solver, a Jacobian rate r > 0 means asymptotic at r;
    otherwise nothing is claimed."""
    from crawlsim.analysis.run import exact_verdict
    from crawlsim.status import LimitMethod

    assert p4.solver.method == LimitMethod.ITERATE
    assert exact_verdict(p4.run) == ExactVerdict(Convergence.FINITE_TIME, None)
    assert triangle.solver.method == LimitMethod.NEWTON
    verdict = exact_verdict(triangle.run)
    assert verdict.convergence == Convergence.ASYMPTOTIC and verdict.rate == pytest.approx(0.125, rel=1e-9)
    for rate in (None, 0.0):
        unformed = dataclasses.replace(triangle.run, solver=dataclasses.replace(triangle.solver, jacobian_rate=rate))
        assert exact_verdict(unformed) is None
