"""The printed v0 keeps its promise: |printed v0 - exact v0| <= printed error estimate.

`crawlsim run` prints v0 with only the digits its error estimate supports (`crawlsim.analysis.digits`).
The exact v0 it is checked against comes from an independent computation: the exact
integrator on another time grid (997 points per period, which the exact integrator only samples
for output) by plain period iteration (no periodic-limit solver), or a closed form. This holds
with the default command (the exact integrator) and with ``--integrator catch-up``, whose
time-step error is measured against the exact integrator and printed.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner

from crawlsim.analysis.digits import how_found, supported, with_error
from crawlsim.analysis.run import simulate
from crawlsim.cli import main
from crawlsim.errors import GaitError
from crawlsim.gait.corpus import random_document
from crawlsim.gait.document import gait_from_document, load_gait, with_simulation
from crawlsim.model.process import compile_gait

GAITS = Path(__file__).resolve().parent.parent / "gaits"
EXAMPLES = sorted(
    p
    for p in [*GAITS.glob("*.yaml"), *GAITS.glob("paper/*.yaml")]
    if yaml.safe_load(p.read_text()).get("kind", "crawler") == "crawler"
    and yaml.safe_load(p.read_text())["blocks"] <= 20
)
LINE = re.compile(r"^  v0 +(-?[0-9.]+) ± ([0-9.e-]+) ", re.M)


def exact_v0(gait) -> tuple[float, float]:
    """v0 by the exact integrator on a 997-point grid, by plain iteration to roundoff, and its
    own error bound (the tail of an asymptotic iteration: not negligible beside a Newton limit
    verified to roundoff)."""
    run = simulate(
        compile_gait(with_simulation(gait, steps_per_period=997)),
        integrator="exact",
        limit="iterate",
        max_periods=3000,
        tolerance=0.0,
        history=False,
    )
    assert run.converged and run.v0 is not None and run.estimate.error_estimate is not None
    return run.v0, run.estimate.error_estimate


def printed(path: Path, tmp_path: Path, *extra: str) -> tuple[float, float, str]:
    r = CliRunner().invoke(main, ["run", str(path), "-o", str(tmp_path / "r.h5"), "--force", *extra])
    assert r.exit_code == 0, r.output
    m = LINE.search(r.output)
    assert m, r.output
    return float(m.group(1)), float(m.group(2)), m.group(1)


def check(path: Path, tmp_path: Path, reference: tuple[float, float], *extra: str) -> None:
    v0, err, text = printed(path, tmp_path, *extra)
    exact, exact_err = reference
    assert abs(v0 - exact) <= err + exact_err, (path.name, extra, text, err, reference)
    if err == 0:  # no block slips: v0 is exactly 0
        assert v0 == exact == 0
        return
    # only supported digits: the last printed digit is at the error's leading digit
    decimals = len(text.split(".")[1]) if "." in text else 0
    assert 10.0**-decimals <= err < 10.0 ** (1 - decimals) * 1.0000001


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.stem)
def test_example_gaits(path, tmp_path):
    reference = exact_v0(load_gait(path))
    check(path, tmp_path, reference)
    check(path, tmp_path, reference, "--integrator", "catch-up")


def test_anchoring_closed_form(tmp_path):
    """anchoring-2 moves 0.3 per period of length 1 (docs/model.md §1): exactly 0.3 printed."""
    v0, err, _ = printed(GAITS / "anchoring-2.yaml", tmp_path)
    assert abs(v0 - 0.3) <= err < 1e-12


def test_catch_up_without_its_exact_reference_claims_no_bound(tmp_path, monkeypatch):
    """When the exact reference run fails, catch-up's time-step error (first order in the step)
    is unknown, so v0 has no error estimate: --json gives v0_error_estimate null and
    v0_error_reason says why, and the text prints v0 without ± and with the same reason. The
    period iteration's part, which bounds only the iteration, is still reported as such."""
    import json

    from crawlsim.errors import EventError
    from crawlsim.integrate.exact import EventStepper

    def fail(self):
        raise EventError("forced failure of the exact reference run")

    monkeypatch.setattr(EventStepper, "step_period", fail)
    gait = GAITS / "inching-2.yaml"
    runner = CliRunner()
    r = runner.invoke(main, ["run", str(gait), "--integrator", "catch-up", "--json", "-o", str(tmp_path / "j.h5")])
    assert r.exit_code == 0, r.output
    summary = json.loads(r.stdout)
    assert summary["integrator"] == "catch-up" and summary["v0"] is not None
    assert summary["v0_error_estimate"] is None and summary["v0_error_time_step"] is None
    assert "could not be measured" in summary["v0_error_reason"]
    assert summary["v0_error_period_iteration"] > 0
    text = runner.invoke(main, ["run", str(gait), "--integrator", "catch-up", "-o", str(tmp_path / "t.h5")])
    assert text.exit_code == 0, text.output
    (line,) = [ln for ln in text.output.splitlines() if ln.startswith("  v0 ")]
    assert "±" not in line and summary["v0_error_reason"] in line
    monkeypatch.undo()
    ok = json.loads(
        runner.invoke(
            main, ["run", str(gait), "--integrator", "catch-up", "--json", "-o", str(tmp_path / "ok.h5")]
        ).stdout
    )
    assert ok["v0_error_reason"] is None and ok["v0_error_time_step"] is not None
    assert ok["v0_error_estimate"] >= ok["v0_error_time_step"]


def random_gaits(count: int = 20):
    """The first `count` random documents that are valid gaits (seeds 0, 1, ...), small N."""
    seed = 0
    while count:
        doc = random_document(seed, blocks=(2, 6), steps_per_period=200, max_periods=300)
        seed += 1
        try:
            gait = gait_from_document(doc, "random", default_name=doc["name"])
        except GaitError:
            continue
        count -= 1
        yield seed - 1, doc, gait


@pytest.mark.parametrize("seed, doc, gait", list(random_gaits()), ids=lambda v: str(v) if isinstance(v, int) else "")
def test_random_gaits(seed, doc, gait, tmp_path):
    path = tmp_path / f"random-{seed}.yaml"
    path.write_text(yaml.safe_dump(doc))
    reference = exact_v0(gait)
    check(path, tmp_path, reference)
    check(path, tmp_path, reference, "--integrator", "catch-up")


@pytest.mark.parametrize(
    "value, error, text, bound",
    [
        (0.370883735228, 2.7e-4, "0.3709", "0.0003"),
        (0.3, 7e-14, "0.30000000000000", "7e-14"),
        (0.371155467664744, 1e-13, "0.3711554676647", "2e-13"),
        (123.456, 3.2, "123", "4"),
        (-1e-5, 3e-4, "0.0000", "0.0004"),
        (2.5, 0.96, "2.5", "1"),
    ],
)
def test_supported_digits(value, error, text, bound):
    """Rounding at the error's leading digit moves the value by at most half a unit there; the
    printed bound adds that move and rounds up, so it still covers the true value."""
    assert supported(value, error) == (text, bound)
    assert abs(float(text) - value) + error <= float(bound)
    assert with_error(value, None) == f"{value:.12g}"
    assert with_error(0.0, 0.0) == "0 ± 0"


@pytest.mark.parametrize(
    "steps, periods, text",
    [
        (1, 1, "1 Newton step in 1 period"),
        (3, 5, "3 Newton steps in 5 periods"),
        (0, 2, "0 Newton steps in 2 periods"),
    ],
)
def test_how_found_counts(steps, periods, text):
    """The summary line names the counts in English: singular for one, plural otherwise."""
    line = how_found("newton", steps, periods, 0.125)
    assert line == f"Newton on the period map: {text}, verified by a plain period, Jacobian rate 0.125"
    assert how_found("iterate", None, None) == "plain iteration of the periods"
