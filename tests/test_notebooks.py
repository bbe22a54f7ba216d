"""The example notebooks of docs/examples/ run, print the numbers of their closed forms, and the
outputs stored in them (which the documentation site renders) are what they print now.

Each notebook is executed afresh with nbclient in docs/examples/ (its gaits are ``../../gaits``),
on a kernel that imports this checkout. Its printed numbers are checked against what they must
be: v0 of peristalsis-4 to 8 digits (the exact integrator's v0, known to ~1e-13, printed to 12),
the force-velocity line of inching-2-towing against its closed form, the stall force to the
digits its bracket supports. Then every stored text output must match the fresh one with the
rules of tests/test_readme.py (numbers to the digits their estimate supports), and the stored
notebook must hold the same figures: the site shows the stored outputs, so they cannot drift
from what the code prints.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

from tests.test_readme import output_matches

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")
pytest.importorskip("ipykernel")
pytest.importorskip("xarray")
pytest.importorskip("h5netcdf")

#: each notebook runs in a fresh Jupyter kernel: .ci/run runs them in its slow step
pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "docs" / "examples"
NOTEBOOKS = sorted(EXAMPLES.glob("*.ipynb"))


def _texts(notebook) -> list[list[str]]:
    """The text each code cell printed (stdout, then its value's text unless it is a figure)."""
    out = []
    for cell in notebook.cells:
        if cell.cell_type != "code":
            continue
        # the kernel sends stdout in chunks wherever its buffer was flushed (a line can arrive
        # apart from its newline): the chunks are one text
        text = ""
        for output in cell.outputs:
            if output.output_type == "stream" and output.name == "stdout":
                text += output.text
            elif output.output_type == "execute_result" and "image/png" not in output.data:
                text += output.data.get("text/plain", "") + "\n"
            elif output.output_type == "error":
                raise AssertionError(f"{output.ename}: {output.evalue}")
        out.append([line.rstrip() for line in text.splitlines()])
    return out


def _figures(notebook) -> int:
    return sum(
        "image/png" in output.get("data", {})
        for cell in notebook.cells
        if cell.cell_type == "code"
        for output in cell.outputs
    )


_RUN: dict[str, object] = {}


def executed(path: Path):
    """The notebook at ``path``, executed afresh (once per test session)."""
    if path.name not in _RUN:
        notebook = nbformat.read(path, as_version=4)
        for cell in notebook.cells:
            if cell.cell_type == "code":
                cell.outputs = []
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
        client = nbclient.NotebookClient(
            notebook, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(EXAMPLES)}}
        )
        client.execute(env=env)
        _RUN[path.name] = notebook
    return _RUN[path.name]


def _value(lines: list[str], label: str) -> float:
    for line in lines:
        if line.startswith(label):
            return float(line[len(label) :].split()[0].rstrip(","))
    raise AssertionError(f"no line starting with {label!r} in {lines}")


def test_there_are_two_notebooks_or_more():
    assert {p.name for p in NOTEBOOKS} >= {"first-run.ipynb", "force-velocity.ipynb"}


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.name)
def test_stored_outputs_are_what_the_notebook_prints(path):
    """The rendered outputs (stored in the file) match a fresh run, and no stored output names
    a scratch folder or the shared folder the project was written from."""
    stored = nbformat.read(path, as_version=4)
    fresh = executed(path)
    for k, (want, got) in enumerate(zip(_texts(stored), _texts(fresh), strict=True)):
        assert output_matches(want, got), (
            f"{path.name}, code cell {k + 1}: stored\n" + "\n".join(want) + "\nbut it prints\n" + "\n".join(got)
        )
    assert _figures(stored) == _figures(fresh) >= 1
    text = path.read_text(encoding="utf-8")
    assert "/tmp" not in text and "../shared" not in text and "/work/" not in text


def test_first_run_numbers():
    """peristalsis-4: v0 = 0.3711554677 to 8 digits (README's first run), finite-time from
    period 1, the cost of transport, the trajectory's shape, four figures (result.plot), the xarray
    view."""
    fresh = executed(EXAMPLES / "first-run.ipynb")
    cells = _texts(fresh)
    printed = [line for cell in cells for line in cell]
    v0 = _value(printed, "v0                 ")
    assert abs(v0 - 0.37115546766) <= 5e-9
    assert "convergence        finite-time, periodic from period 1" in printed
    assert abs(_value(printed, "cost of transport  ") - 5.593899792) <= 5e-8
    assert "trajectory         2001 saved times, x of shape (2001, 4)" in printed
    summary = "\n".join(cells[1])
    assert re.search(r"v0 +0\.3711554676\d+ ± \de-1[34]", summary), summary
    assert _figures(fresh) == 4
    assert "backward_slip stick forward_slip" in printed


def test_force_velocity_numbers():
    """inching-2-towing: v0 = 0.4 + 0.1 F forward and -0.2 + 0.1 F past the stall (to 1e-12,
    printed to 6 decimals in the table), the point F = -1 invalid, the stall force -1 to 9
    digits, caused by a jump; one figure."""
    fresh = executed(EXAMPLES / "force-velocity.ipynb")
    printed = [line for cell in _texts(fresh) for line in cell]
    rows = [line.split() for line in printed if re.fullmatch(r"-?\d\.\d+ +(-?\d\.\d+|NaN)", line.strip())]
    assert len(rows) == 17
    for force, v0 in ((float(a), float(b)) for a, b in rows):
        if abs(force + 1) < 1e-9:
            assert v0 != v0  # NaN: the invalid point
        else:
            assert abs(v0 - (0.4 + 0.1 * force if force > -1 else -0.2 + 0.1 * force)) <= 1e-6
    assert any(line.startswith("invalid - ") and "uniqueness condition" in line for line in printed)
    for label in ("forward:  max |v0 - (0.4 + 0.1 F)| = ", "backward: max |v0 - (-0.2 + 0.1 F)| = "):
        assert _value(printed, label) <= 1e-12
    line = next(line for line in printed if line.startswith("stall force "))
    value, estimate = re.fullmatch(r"stall force (\S+) ± (\S+)", line).groups()
    assert abs(float(value) + 1.0) <= float(estimate) <= 1e-8
    assert "cause: jump" in printed
    assert _figures(fresh) == 1
