"""The per-period spill of `crawlsim.analysis.convergence.History`: the periods come back as they
were added, whether they stayed in memory or went to the temporary file, and memory is bounded."""

from types import SimpleNamespace

import numpy as np

from crawlsim.analysis import convergence


def _periods(count: int) -> list[SimpleNamespace]:
    rng = np.random.default_rng(3)
    return [
        SimpleNamespace(w=rng.standard_normal((21, 4)), multipliers=rng.standard_normal((20, 8))) for _ in range(count)
    ]


def _replay(records, monkeypatch, limit: int) -> tuple[list, object]:
    monkeypatch.setattr(convergence, "SPILL_BYTES", limit)
    spill = convergence._PeriodSpill()
    for rec in records:
        spill.add(rec)
    return [(w.copy(), lam.copy()) for w, lam in spill.periods()], spill


def test_periods_come_back_unchanged_in_memory_on_file_and_across_the_switch(monkeypatch):
    records = _periods(6)
    size = records[0].w.nbytes + records[0].multipliers.nbytes
    for limit in (1 << 25, 0, 3 * size):  # all in memory, all on file, switch after 3 periods
        back, spill = _replay(records, monkeypatch, limit)
        assert len(back) == len(records)
        for (w, lam), rec in zip(back, records):
            assert w.shape == rec.w.shape and lam.shape == rec.multipliers.shape
            assert np.array_equal(w, rec.w) and np.array_equal(lam, rec.multipliers)
        on_file = spill._file is not None
        assert on_file == (limit < len(records) * size)
        assert not (on_file and spill._memory)  # past the limit nothing stays in memory
        spill.close()


def test_a_period_edited_after_it_was_added_is_kept_as_added(monkeypatch):
    """The kernel may reuse its arrays: the spill keeps a copy, as the file did."""
    records = _periods(2)
    kept = records[0].w.copy()
    monkeypatch.setattr(convergence, "SPILL_BYTES", 1 << 25)
    spill = convergence._PeriodSpill()
    spill.add(records[0])
    records[0].w[:] = 0.0
    spill.add(records[1])
    first = next(iter(spill.periods()))
    assert np.array_equal(first[0], kept)


def test_a_run_without_series_is_the_same_run_without_its_per_period_series():
    """``simulate(..., series=False)`` (a sweep point) changes no number of the run: the same
    periods are stepped; only the per-period distances to the limit (empty) and dissipations
    (NaN) are left out."""
    from pathlib import Path

    from crawlsim.analysis.run import simulate
    from crawlsim.gait.document import load_gait
    from crawlsim.model.process import compile_gait

    gait = load_gait(Path(__file__).resolve().parents[1] / "gaits" / "peristalsis-4.yaml")
    runs = {
        keep: simulate(compile_gait(gait), integrator="exact", history=False, series=keep) for keep in (True, False)
    }
    kept, left = runs[True], runs[False]
    assert len(kept.history.w12_distance) == len(kept.history.period) >= 1
    for key in convergence.DISTANCES:
        assert getattr(left.history, key).size == 0
    for name in ("v0", "v0_error_estimate", "periods", "limit_periods", "steps", "displacement_per_period"):
        assert left.summary()[name] == kept.summary()[name], name
    assert left.energy.dissipation == kept.energy.dissipation
    assert left.energy.cost_of_transport == kept.energy.cost_of_transport
    assert np.array_equal(left.history.poincare_step, kept.history.poincare_step)
    assert np.array_equal(left.history.displacement, kept.history.displacement)
    assert np.all(np.isnan(left.history.dissipation)) and np.all(np.isfinite(kept.history.dissipation))
    assert kept.history.dissipation[-1] == left.energy.dissipation  # the limit's, still made
