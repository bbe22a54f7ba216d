"""`crawlsim validate`: every error of every file, each with file and key path; exit 0 or 2."""

import pytest
from click.testing import CliRunner

from crawlsim.cli import main
from crawlsim.gait.document import validation_errors

from .conftest import GAITS

GOOD = """\
blocks: 3
period: 1.0
stiffness: 10.0
links: [{kind: cosine, mean: 1.0, amplitude: 0.3}, 1.0]
friction: {forward: 1.0, backward: 2.5}
"""

#: Five independent structural errors: each must be listed.
BROKEN = """\
blocks: 3
period: -1
stiffness: [1, .inf]
links: [{kind: cosine, mean: 1.0, amplitud: 0.3}, {kind: steps, times: [0, 0.5], values: [1]}]
friction: {forward: 1.0, backwrad: 2.5}
simulation: {steps_per_period: 0}
"""

#: Structure valid; three semantic errors that do not depend on each other.
SEMANTIC = """\
blocks: 3
period: 1.0
stiffness: [1, 2, 3]
links: [{kind: cosine, mean: 1.0, amplitude: 0.3}, 1.0]
friction:
  - {forward: -1.0, backward: 2.5}
  - {forward: 1.0, backward: {kind: cosine, mean: 0.5, amplitude: 1.0}}
  - {forward: 1.0, backward: 2.5}
"""


def write(folder, name, text):
    path = folder / name
    path.write_text(text)
    return str(path)


def test_every_structural_error_is_listed(tmp_path):
    path = write(tmp_path, "broken.yaml", BROKEN)
    found = {(e.keypath, e.message.split(",")[0]) for e in validation_errors(path)}
    keys = {k for k, _ in found}
    assert {
        "period",
        "stiffness[1]",
        "links[0].amplitud",
        "links[0].amplitude",
        "links[1].values",
        "friction.backwrad",
        "friction.backward",
        "simulation.steps_per_period",
    } <= keys, found
    result = CliRunner().invoke(main, ["validate", path])
    assert result.exit_code == 2
    lines = [line for line in result.output.splitlines() if line.startswith(path)]
    assert len(lines) == len(validation_errors(path)) >= 8
    assert all(line.startswith(f"{path}: ") for line in lines)
    assert "1 of 1 gait files invalid" in result.output


def test_semantic_errors_that_can_run_are_all_listed(tmp_path):
    path = write(tmp_path, "semantic.yaml", SEMANTIC)
    errors = validation_errors(path)
    assert [e.keypath for e in errors] == ["stiffness", "friction[0].forward", "friction[1].backward"]
    assert "expected 2 stiffness values (one per link), got 3" in errors[0].message
    assert "its minimum is -1" in errors[1].message and "its minimum is -0.5" in errors[2].message


def test_valid_files_and_mixed_lists(tmp_path):
    good = write(tmp_path, "good.yaml", GOOD)
    bad = write(tmp_path, "bad.yaml", GOOD.replace("backward: 2.5", "backward: 2.0"))
    result = CliRunner().invoke(main, ["validate", good])
    assert result.exit_code == 0 and result.output == f"{good}: valid\n"
    result = CliRunner().invoke(main, ["validate", good, bad, str(tmp_path / "missing.yaml"), "/dev/zero"])
    assert result.exit_code == 2
    assert f"{good}: valid" in result.output
    assert f"{bad}: friction: uniqueness condition violated: for J = {{1, 2}}" in result.output
    assert "missing.yaml: no such gait file" in result.output
    assert "/dev/zero: is a device, not a gait file" in result.output
    assert "3 of 4 gait files invalid" in result.output


@pytest.mark.parametrize("path", sorted(GAITS.rglob("*.yaml")), ids=lambda p: p.name)
def test_every_example_gait_is_valid(path):
    assert validation_errors(path) == []


def test_yaml_errors_are_one_error(tmp_path):
    path = write(tmp_path, "syntax.yaml", "blocks: [3\n")
    errors = validation_errors(path)
    assert len(errors) == 1 and "YAML syntax error at line" in errors[0].message


NEGATIVE = """\
blocks: 3
period: 2.0
stiffness: 10.0
links:
  - {kind: cosine, mean: 1.0, amplitude: 0.3}
  - {kind: cosine, mean: MEAN, amplitude: 1.3, phase: 0.25}
friction: {forward: 1.0, backward: 1.5}
simulation: {steps_per_period: 100}
"""


def test_a_negative_actuator_length_is_run_with_a_warning_naming_link_and_time(tmp_path):
    """links[1] = 1 + 1.3 cos 2 pi (u - 1/4) reaches 1 - 1.3 = -0.3 at u = 3/4, t = 1.5 (T = 2):
    validate and every command that reads the file warn, naming the link and the time, and run
    (issue 35: it ran silently while blocks 2 and 3 passed through each other). The warning's
    claim holds: adding a constant c to L translates K(t) = C(t) - K L(t) by -K c and leaves the
    slips alone, so v0 with mean 1.5 (L > 0) is v0 with mean 1.0."""
    import warnings

    import crawlsim

    path = tmp_path / "neg.yaml"
    path.write_text(NEGATIVE.replace("MEAN", "1.0"))
    warning = (
        f"Warning: {path}: links[1]: the actuator length goes negative (-0.3 at t = 0.75 T = 1.5), so blocks 2 and 3 "
        "can pass through each other"
    )
    runner = CliRunner()
    for args in (["validate", str(path)], ["velocity", str(path)]):
        r = runner.invoke(main, args)
        assert r.exit_code == 0 and r.stderr.startswith(warning) and len(r.stderr.splitlines()) == 1, r.stderr
    with pytest.warns(crawlsim.GaitWarning, match="goes negative"):
        negative = crawlsim.simulate(crawlsim.load_gait(path), keep_trajectory=False)
    path.write_text(NEGATIVE.replace("MEAN", "1.5"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        positive = crawlsim.simulate(crawlsim.load_gait(path), keep_trajectory=False)
    assert negative.v0 == pytest.approx(
        positive.v0, abs=negative.estimate.error_estimate + positive.estimate.error_estimate
    )
    assert positive.v0 > 0.01
