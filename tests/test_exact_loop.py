"""The compiled event loop's shortcuts change nothing (`crawlsim.kernel.eventloop`).

What must hold:

* `next_event` seeks the crossing of only the rows whose bounds let them cross before the
  earliest event found so far, and seeks first the row its slope bound lets cross first; the
  event and the rows it hits are those of seeking every row's crossing over the whole piece;
* a period's record owns its arrays: later periods, which may reuse the arrays of records
  nobody holds any more, never write into a record that is still held.
"""

from pathlib import Path

import numpy as np
import pytest

from crawlsim.gait.document import load_gait
from crawlsim.integrate import catchup
from crawlsim.integrate.exact import EventStepper
from crawlsim.kernel import eventloop, sampling
from crawlsim.kernel.events import hit_together
from crawlsim.model.process import compile_gait

ROOT = Path(__file__).resolve().parents[1]


def _every_row(loop, stepper, signs, base, Wc, Ydx, coef, inverse, u0, u1):
    """(first, hit) with `crossing` sought for every row over the whole piece (horizon u1)."""
    N, nb = signs.size, coef.shape[0]
    linear, H = stepper.basis.linear, stepper.basis.harmonics
    Rdx = np.empty((nb, N))
    eventloop.derivative(Ydx, linear, H, Rdx)
    tol_gap = 0.5 * eventloop.RTOL * loop.c_scale
    tol_rate = eventloop.rate_tolerance(eventloop.offset_size(coef), signs, Rdx, inverse)
    Z, reach = np.empty((2 * N, nb)), np.empty(2 * N, dtype=np.int8)
    phi0 = np.empty(nb)
    eventloop.basis_values(u0, 0, linear, H, phi0)
    eventloop.row_functions(
        linear, H, coef, signs, base, Wc, Rdx, tol_gap, tol_rate, u0, u1, phi0, Z, reach, np.empty((2 * N, 3))
    )
    active = np.array([(r < N and signs[r % N] > 0) or (r >= N and signs[r % N] < 0) for r in range(2 * N)])
    times = np.array(
        [
            eventloop.crossing(Z[r], tol_rate if active[r] else tol_gap, u0, u1, linear, H, phi0, u1)
            for r in range(2 * N)
        ]
    )
    if np.isnan(times).any():  # no closed form: the certified sampling over the whole piece
        count = sampling.cells(u0, u1, stepper.cells_per_cycle, H)
        S = np.empty(count + 1)
        sampling.grid(u0, u1, count, S)
        for r in np.flatnonzero(np.isnan(times)):
            times[r] = sampling.crossing(
                Z[r],
                tol_rate if active[r] else tol_gap,
                u0,
                u1,
                linear,
                H,
                u1,
                S,
                np.empty((count + 1, nb)),
                np.zeros(1, dtype=np.int64),
            )
    first = float(np.min(times))
    if not first < u1:
        return np.inf, np.zeros(2 * N, dtype=bool)
    eventloop.basis_values(first, 0, linear, H, phi0)
    together = [
        times[r] <= first + eventloop.SIMULTANEOUS and hit_together(Z[r], loop.c_scale, phi0) for r in range(2 * N)
    ]
    return first, (~active) & ((times == first) | np.array(together))


@pytest.mark.parametrize("name", ["peristalsis-4", "earthworm-100", "inching-2", "smooth-friction-3"])
def test_next_event_is_that_of_every_row(name):
    """At every transition of a period, the next event and its hit rows from `next_event` are
    those of the crossings of all rows over the whole piece (the piece rebuilt from the
    recorded state and set); smooth-friction-3's offsets have several harmonics, so its zeros
    come from the certified sampling."""
    process = compile_gait(load_gait(ROOT / "gaits" / f"{name}.yaml"))
    stepper = EventStepper(process)
    stepper.step_period()
    record = stepper.step_period()
    loop = stepper._loop
    assert loop is not None
    N, nb = process.blocks, stepper.basis.size
    u_events = (record.events.t - record.start) / process.period
    checked = 0
    for tr in record.transitions:
        if tr.cause == "jump":
            continue
        i = int(np.argmin(np.abs(u_events - tr.u)))
        w0 = record.events.w[i]
        signs = catchup.signs_of(tr.active, N)
        coef = loop.coef[tr.piece]
        D, l, dx0, Ydx = np.empty(N), np.empty(N - 1), np.empty(N), np.empty((nb, N))
        base, Wc = np.empty(N - 1), np.empty((nb, N - 1))
        inverse, _ = eventloop.piece(loop.k, signs, w0, coef, D, l, dx0, Ydx, base, Wc, np.empty(N))
        u0, u1 = tr.u, float(stepper.pieces.edges[tr.piece + 1])
        hit = np.zeros(2 * N, dtype=bool)
        m = 2 * N
        u, handoff = eventloop.next_event(
            loop.c_scale,
            stepper.basis.linear,
            stepper.basis.harmonics,
            coef,
            eventloop.offset_size(coef),
            signs,
            base,
            Wc,
            Ydx,
            inverse,
            u0,
            u1,
            hit,
            np.empty((nb, N)),
            np.empty((m, nb)),
            np.empty(m),
            np.empty(m, dtype=np.int8),
            np.empty((m, 3)),
            np.empty(nb),
            stepper.cells_per_cycle,
        )
        assert not handoff
        first, every_hit = _every_row(loop, stepper, signs, base, Wc, Ydx, coef, inverse, u0, u1)
        assert u == first
        if u < u1:
            assert np.array_equal(hit, every_hit)
            checked += 1
    assert checked >= 2


def test_held_records_keep_their_arrays():
    """Records held by the caller keep their values while later periods run (a period reuses
    only the arrays of records nobody holds)."""
    process = compile_gait(load_gait(ROOT / "gaits" / "peristalsis-4.yaml"))
    stepper = EventStepper(process)
    assert stepper._loop is not None
    held = [stepper.step_period() for _ in range(3)]
    copies = [(r.w.copy(), r.multipliers.copy(), r.x.copy()) for r in held]
    for _ in range(4):
        stepper.step_period()  # dropped at once: its arrays may serve the next period
    for record, (w, mu, x) in zip(held, copies):
        assert np.array_equal(record.w, w)
        assert np.array_equal(record.multipliers, mu)
        assert np.array_equal(record.x, x)
    # the periods differ (the first from the initial state), so a shared array would show
    assert not np.array_equal(held[0].x, held[1].x)
