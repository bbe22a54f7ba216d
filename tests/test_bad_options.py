"""Bad options are refused before any computation (issue 19, items 8 and 11): exit code 2, one
line naming the option and what was expected, no traceback, nothing written (no results file,
no journal), and the simulation never started.

Each refusal was, before its fix, a traceback after or during the work: an int64 overflow in the
HDF5 writer (--save-every), a 10^19-point linspace (--sweep NUM), Dask's parser
(--scheduler), h5py refusing a 2**70 seed after the whole search (leaving its journal), the
results file's folder found missing only when it was renamed into place (nosuchdir/../x.h5),
and the input gait replaced by ``optimize --write-best``; and, issue 31, a whole run for
``--sensitivity blocks`` (no derivative) and a search over ``--free period=1:1e300`` (most of
its box invalid).
"""

from __future__ import annotations

import pytest
from click.testing import CliRunner

import crawlsim.api
import crawlsim.design.optimize
from crawlsim.cli import main
from crawlsim.design.problem import Method
from crawlsim.errors import SweepSpecError
from crawlsim.study import executors

GAIT = """\
blocks: 2
period: 1.0
stiffness: 10.0
links:
  - {kind: cosine, mean: 1.0, amplitude: 0.3}
friction: {forward: 1.0, backward: 2.0}
simulation: {steps_per_period: 20, max_periods: 5}
"""


@pytest.fixture
def folder(tmp_path, monkeypatch):
    """A folder holding g.yaml, where nothing may be computed: the simulation, the sweep and the
    search fail the test if they start."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "g.yaml").write_text(GAIT)

    def computed(*args, **kwargs):
        raise AssertionError("computation started before the bad option was refused")

    monkeypatch.setattr(crawlsim.api, "run", computed)
    monkeypatch.setattr(crawlsim.study.sweep, "run_sweep", computed)
    monkeypatch.setattr(crawlsim.design.optimize, "optimize", computed)
    return tmp_path


def refused(folder, *args: str, phrase: str) -> str:
    result = CliRunner().invoke(main, list(args))
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output and not isinstance(result.exception, AssertionError)
    message = result.output.strip()
    assert len(message.splitlines()) == 1, message
    assert message.startswith("Error: ") and phrase in message, message
    assert sorted(p.name for p in folder.iterdir()) == ["g.yaml"], "a file was written"
    assert (folder / "g.yaml").read_text() == GAIT
    return message


OPT = ("optimize", "g.yaml", "--free", "links.0.phase=0:1", "--max-evaluations", "4")


@pytest.mark.parametrize(
    "args, phrase",
    [
        (("run", "g.yaml", "--save-every", "99999999999999999999999"), "--save-every"),
        (("velocity", "g.yaml", "--sweep", "period=1:2:9999999999999999999"), "at most 1,000,000"),
        (
            ("velocity", "g.yaml", "--sweep", "period=1:2:2000", "--sweep", "stiffness=1:2:2000"),
            "the grid has 4,000,000 points",
        ),
        # (without the dask extra, "Dask is not installed": see the test below for the address)
        (("velocity", "g.yaml", "--sweep", "period=1,2", "--scheduler", "notaurl"), "--scheduler notaurl: "),
        ((*OPT, "--scheduler", "notaurl"), "--scheduler notaurl: "),
        ((*OPT, "--seed", str(2**70)), "--seed"),
        (("run", "g.yaml", "-o", "nosuchdir/../x.h5"), "nosuchdir does not exist"),
        (("velocity", "g.yaml", "--sweep", "period=1,2", "-o", "nosuchdir/../x.csv"), "nosuchdir does not exist"),
        ((*OPT, "-o", "nosuchdir/../x.h5"), "nosuchdir does not exist"),
        ((*OPT, "--write-best", "nosuchdir/../best.yaml"), "nosuchdir does not exist"),
        ((*OPT, "--write-best", "g.yaml"), "is the input file g.yaml"),
        ((*OPT, "--write-best", "./g.yaml"), "is the input file g.yaml"),
        ((*OPT, "-o", "o.h5", "--write-best", "o.h5"), "is the input file o.h5"),
        (("velocity", "g.yaml", "--sweep", "period=1,2", "-o", "t.csv", "--dpi", "100"), "add --plot"),
        (("velocity", "g.yaml", "--sensitivity", "blocks"), "blocks: not a continuous parameter"),
        (
            ("velocity", "g.yaml", "--sweep", "period=1,2", "--sensitivity", "blocks", "-o", "s.csv"),
            "blocks: not a continuous parameter",
        ),
        (("optimize", "g.yaml", "--free", "period=1:1e300"), "HI = 1e+300 is refused: expected a positive number"),
        (("optimize", "g.yaml", "--free", "stiffness=-5:2"), "LO = -5.0 is refused"),
    ],
    ids=[
        "save-every",
        "sweep-num",
        "grid-size",
        "scheduler",
        "optimize-scheduler",
        "seed-2**70",
        "run-dotdot",
        "velocity-dotdot",
        "optimize-dotdot",
        "write-best-dotdot",
        "write-best-input",
        "write-best-input-path",
        "write-best-output",
        "figure-option-without-plot",
        "sensitivity-blocks",
        "sweep-sensitivity-blocks",
        "free-beyond-the-schema",
        "free-below-the-schema",
    ],
)
def test_refused_before_any_computation(folder, args, phrase):
    refused(folder, *args, phrase=phrase)


def test_the_largest_seed_is_accepted():
    """2**63 - 1 is the largest seed the results file holds; it is a valid search."""
    Method(seed=2**63 - 1)
    with pytest.raises(SweepSpecError):
        Method(seed=2**63)


@pytest.mark.parametrize(
    "address, valid",
    [
        ("notaurl", False),
        ("tcp://", False),
        ("tcp://host:x", False),
        ("foo://host:1", False),
        ("tcp://host:0", False),
        ("tcp://127.0.0.1:8786", True),
        ("127.0.0.1:8786", True),
        ("tls://scheduler.example:8786", True),
    ],
)
def test_scheduler_addresses(address, valid):
    """With Dask installed, an address is SCHEME://HOST:PORT (or HOST:PORT) with a known scheme
    and a port from 1 to 65535; anything else is refused before a connection is tried."""
    pytest.importorskip("distributed")
    if valid:
        executors.check_scheduler(address)
        return
    with pytest.raises(SweepSpecError, match="expected the address of a Dask"):
        executors.check_scheduler(address)
