"""A catch-up sweep with ``--sensitivity`` walks the limit period each point's own run settled on
(`crawlsim.analysis.run.Settled`): no point is stepped twice. Counted: the
catch-up periods stepped in the whole sweep are the periods its rows report, and each cell is
the closed form of the two-block crawler (tests/test_sensitivity_sweep.py), the value
`crawlsim.sensitivity` gives for that point's gait after searching its limit itself.
"""

from __future__ import annotations

import pytest

from crawlsim.analysis.sensitivity import sensitivity
from crawlsim.integrate.stepping import CatchUpStepper
from crawlsim.study import sweep as sweeps

from .test_sensitivity_sweep import _expected, _gait


def test_batched_catch_up_points_are_stepped_once(monkeypatch):
    gait = _gait(integrator="catch-up")
    stepped: list[int] = []
    step_period = CatchUpStepper.step_period

    def counted(self, *args, **kwargs):
        stepped.append(1)
        return step_period(self, *args, **kwargs)

    monkeypatch.setattr(CatchUpStepper, "step_period", counted)
    table = sweeps.sweep(gait, ["stiffness=[6,12]"], sensitivity=["stiffness", "period"])
    rows = table.rows
    assert [r.integrator for r in rows] == ["catch-up", "catch-up"]
    assert all(r.limit == "iterate" for r in rows)  # finite-time: no Newton step
    assert len(stepped) == sum(r.periods for r in rows) > 0
    monkeypatch.undo()
    for row, k in zip(rows, (6.0, 12.0)):
        alone = sensitivity(gait.replace("stiffness", k), ["stiffness"])["stiffness"]
        assert row.derivatives["stiffness"] == pytest.approx(alone.v0.value, abs=1e-12)
        assert row.derivatives["stiffness"] == pytest.approx(_expected(k)["dv0/dstiffness"], abs=1e-10)
        assert row.derivatives["period"] == pytest.approx(-row.v0 / 2.0, abs=1e-12)
