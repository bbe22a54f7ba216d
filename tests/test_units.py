"""Unit strings of a gait file's ``units:`` block are checked against `UNIT_NAMES`, with a
did-you-mean; results files' units are read leniently by the one `Units` class."""

from pathlib import Path

import pytest
from click.testing import CliRunner

from crawlsim.cli import main
from crawlsim.gait.units import UNIT_NAMES, Units, unit_problem

GAIT = """\
blocks: 2
period: 1.0
stiffness: 10.0
links: [{kind: cosine, mean: 1.0, amplitude: 0.3}]
friction: {forward: 1.0, backward: 2.0}
simulation: {steps_per_period: 20, max_periods: 5}
units: {length: mm, time: s, force: Newtons}
"""


@pytest.mark.parametrize("command", ["validate", "run"])
def test_a_spelled_out_unit_is_refused_with_its_symbol_suggested(tmp_path: Path, command):
    """Exit 2, the file, the key path, what was expected and the symbol; no traceback, no file."""
    path = tmp_path / "newtons.yaml"
    path.write_text(GAIT)
    args = [command, str(path)] + (["-o", str(tmp_path / "out.h5")] if command == "run" else [])
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 2
    assert (
        f"{path}: units.force: expected a unit of force, one of "
        f"{', '.join(UNIT_NAMES['force'])}; got 'Newtons'" in result.output
    )
    assert "did you mean 'N'?" in result.output
    assert "Traceback" not in result.output
    assert not (tmp_path / "out.h5").exists()


@pytest.mark.parametrize(
    "base, name, expected",
    [
        ("force", "newton", "did you mean 'N'?"),
        ("length", "millimetres", "did you mean 'mm'?"),
        ("length", "MM", "did you mean 'mm'?"),
        ("time", "N", "got 'N', a unit of force"),
        ("force", "zorg", "got 'zorg'"),
    ],
)
def test_unit_problems_name_what_was_expected(base, name, expected):
    problem = unit_problem(base, name)
    assert problem is not None and expected in problem
    assert problem.startswith(f"expected a unit of {base}, one of ")


def test_every_listed_unit_is_accepted():
    assert all(unit_problem(base, name) is None for base, names in UNIT_NAMES.items() for name in names)


def test_units_are_parsed_leniently_from_files():
    assert Units.parse('{"length": "mm", "force": "N"}') == Units(length="mm", force="N")
    assert Units.parse(b'{"time": "s"}') == Units(time="s")
    assert Units.parse("not json") == Units()
    assert Units.parse({"length": " ", "time": 3}) == Units()
    assert Units.parse(None).of("velocity") == "1"
    assert Units.parse({"length": "mm", "time": "s"}).of("velocity") == "mm/s"
