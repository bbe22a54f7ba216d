"""An event of the compiled exact loop touches only what can change (`crawlsim.kernel.eventloop`).

What must hold, each against the computation over the whole chain that it replaces:

* `piece.rebuild` of the ranges of blocks whose sign changed (`eventloop.rebuild_changed`) gives
  the numbers of the whole piece of the new set from the same state, bit for bit: the padded
  tridiagonal system decouples at a free block;
* `events.next_event_kept` gives the event time and hit rows of `events.next_event`, from its
  crossings kept per row as from crossings sought afresh, after u0 moves on;
* `eventloop.decide_local` decides every event of a period as `eventloop.decide` does;
* the energy terms summed by chunks, only the stale chunks again, are the sums over every link
  and slipping block;
* the loop on a 16-block wave (several runs per set, kept runs, velocity problems on a run of
  their own) gives the same bits compiled and interpreted (`crawlsim.kernel.jit`).
"""

import importlib.util
from pathlib import Path

import numpy as np

from crawlsim.gait.document import gait_from_document
from crawlsim.integrate import catchup
from crawlsim.integrate.exact import EventStepper
from crawlsim.kernel import chain, eventloop, jit
from crawlsim.kernel import events as kernel_events
from crawlsim.model.process import compile_gait

ROOT = Path(__file__).resolve().parents[1]


def _wave(N: int, steps: int = 1000):
    spec = importlib.util.spec_from_file_location("bench_scale", ROOT / "scripts" / "bench-scale.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return compile_gait(gait_from_document(module.wave_document(N, steps, wave="segments"), f"wave-{N}"))


def _full_piece(k, signs, w0, coef):
    """The piece of ``signs`` from w0 over the whole chain (`eventloop.piece`)."""
    N, nb = signs.shape[0], coef.shape[0]
    D, l, dx0, Ydx = np.empty(N), np.empty(N - 1), np.empty(N), np.empty((nb, N))
    base, Wc = np.empty(N - 1), np.empty((nb, N - 1))
    inverse, gram = eventloop.piece(k, signs, w0, coef, D, l, dx0, Ydx, base, Wc, np.empty(N))
    return D, l, dx0, Ydx, base, Wc, inverse, gram


def test_rebuilt_runs_are_the_whole_piece():
    """A 40-block chain with stiffness spread over three decades: the piece of a set rebuilt
    over every block, and then only over the ranges an exchange of signs on four blocks
    touches (a run split, two runs merged, a sign reversed, a new run), has the factor, slips,
    links and norms of `eventloop.piece` of the new set, bit for bit; the untouched runs keep
    their numbers."""
    rng = np.random.default_rng(7)
    N, nb = 40, 3
    k = 10.0 ** rng.uniform(0, 3, N - 1)
    coef = rng.normal(size=(nb, 2 * N))
    w0 = rng.normal(size=N - 1)
    old = np.zeros(N, dtype=np.int8)
    old[[2, 3, 4, 5, 9, 10, 12, 13, 20, 21, 22, 30]] = [1, 1, 1, 1, -1, -1, 1, 1, 1, -1, -1, 1]
    new = old.copy()
    new[4] = 0  # the run 2..5 splits
    new[11] = 1  # the runs 9..10 and 12..13 merge
    new[21] = 1  # a sign reversed inside a run
    new[35] = -1  # a run of its own
    D, l, inv = np.ones(N), np.zeros(N - 1), np.zeros(N)
    dx0, Ydx, Rdx = np.empty(N), np.empty((nb, N)), np.empty((nb, N))
    base, Wc = np.empty(N - 1), np.empty((nb, N - 1))
    lam_cum, lam_now = np.zeros(2 * N), rng.normal(size=2 * N)
    dirty = np.zeros(N, dtype=np.bool_)
    stale = np.zeros((N + eventloop.CHUNK - 1) // eventloop.CHUNK, dtype=np.bool_)
    args = (w0, coef, False, 1, D, l, inv, dx0, Ydx, Rdx, base, Wc, lam_cum, lam_now, dirty, stale)
    eventloop.rebuild_changed(k, old, old, *args, True)
    expected = _full_piece(k, old, w0, coef)
    for got, want in zip((D, l, dx0, Ydx, base, Wc), expected[:6]):
        assert np.array_equal(got, want)
    assert eventloop.set_norms(k, old, inv) == expected[6:]
    assert dirty.all() and np.array_equal(lam_cum, lam_now)

    kept_links = Wc[:, 25:29].copy()  # links of the run at 22..20 are rebuilt, 25..28 not
    dirty[:] = False
    lam_cum[:] = 0.0
    eventloop.rebuild_changed(k, old, new, *args, False)
    expected = _full_piece(k, new, w0, coef)
    for got, want in zip((D, l, dx0, Ydx, base, Wc), expected[:6]):
        assert np.array_equal(got, want)
    assert eventloop.set_norms(k, new, inv) == expected[6:]
    assert np.array_equal(Wc[:, 25:29], kept_links)
    # the ranges: 2..5, 9..13, 20..22, 35 and their neighbours, nothing else
    touched = np.zeros(N, dtype=bool)
    for lo, hi in ((2, 5), (9, 13), (20, 22), (35, 35)):
        touched[lo - 1 : hi + 2] = True
    assert np.array_equal(dirty, touched)
    committed = np.zeros(N, dtype=bool)
    for lo, hi in ((2, 5), (9, 13), (20, 22), (35, 35)):
        committed[lo : hi + 1] = True
    both = np.concatenate([committed, committed])
    assert np.array_equal(lam_cum[both], lam_now[both]) and not lam_cum[~both].any()


def _wave_period(N: int, periods: int):
    process = _wave(N)
    stepper = EventStepper(process)
    for _ in range(periods - 1):
        stepper.step_period()
    return process, stepper, stepper.step_period()


def _fresh(ctx, u0):
    """`next_event` from u0 on the piece ``ctx``: (event time, hit rows)."""
    loop, stepper, N, nb, coef, signs, base, Wc, Ydx, inverse, u1 = ctx[:11]
    m = 2 * N
    hit = np.zeros(m, dtype=bool)
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
    return u, hit


def _kept(ctx, u0):
    """`next_event_kept` from u0 on the piece ``ctx`` with its kept crossings."""
    loop, stepper, N, nb, coef, signs, base, Wc, _, inverse, u1, Rdx, dirty, hit, Z, times, tols = ctx
    return kernel_events.next_event_kept(
        loop.c_scale,
        stepper.basis.linear,
        stepper.basis.harmonics,
        coef,
        eventloop.offset_size(coef),
        signs,
        base,
        Wc,
        Rdx,
        inverse,
        u0,
        u1,
        dirty,
        hit,
        Z,
        times,
        tols,
        np.empty(nb),
    )


def test_kept_crossings_are_the_crossings_sought_afresh():
    """On the pieces of a period of the 64-block segments wave: `next_event_kept` with every
    row's crossing sought finds `next_event`'s event and hit rows; moved on to halfway to
    that event, with no row changed, it finds them again from its kept crossings, as
    `next_event` does from scratch."""
    process, stepper, record = _wave_period(64, 3)
    loop = stepper._loop
    assert loop is not None
    N, nb, m = process.blocks, stepper.basis.size, 2 * process.blocks
    linear, H = stepper.basis.linear, stepper.basis.harmonics
    assert kernel_events.closed_forms(linear, H)
    u_events = (record.events.t - record.start) / process.period
    checked = 0
    for tr in list(record.transitions)[1:40]:
        i = int(np.argmin(np.abs(u_events - tr.u)))
        signs = catchup.signs_of(tr.active, N)
        coef = loop.coef[tr.piece]
        _, _, _, Ydx, base, Wc, inverse, _ = _full_piece(loop.k, signs, record.events.w[i], coef)
        Rdx = np.empty((nb, N))
        eventloop.derivative(Ydx, linear, H, Rdx)
        hit = np.zeros(m, dtype=np.bool_)
        ctx = (
            loop,
            stepper,
            N,
            nb,
            coef,
            signs,
            base,
            Wc,
            Ydx,
            inverse,
            float(stepper.pieces.edges[tr.piece + 1]),
            Rdx,
            np.ones(N, dtype=np.bool_),
            hit,
            np.empty((m, nb)),
            np.empty(m),
            np.empty(m),
        )
        u, expected_hit = _fresh(ctx, tr.u)
        assert _kept(ctx, tr.u) == u and np.array_equal(hit, expected_hit)
        assert not ctx[12].any()  # nothing left dirty
        if not u < ctx[10]:
            continue
        later = tr.u + 0.5 * (u - tr.u)
        u_later, hit_later = _fresh(ctx, later)
        assert _kept(ctx, later) == u_later == u and np.array_equal(hit, hit_later)
        checked += 1
    assert checked >= 20


def test_local_decisions_are_those_of_the_whole_chain():
    """At every event of a period of the 256-block segments wave (period 3), from the piece of
    the set before it: `decide_local`, which solves velocity problems only on the runs that
    can change, returns `decide`'s set; most runs are left to their piece, and some events
    do solve a run."""
    process, stepper, record = _wave_period(256, 3)
    loop = stepper._loop
    assert loop is not None
    N, nb, m = process.blocks, stepper.basis.size, 2 * process.blocks
    linear, H = stepper.basis.linear, stepper.basis.harmonics
    kmax = float(np.max(loop.k))
    u_ev = (record.events.t - record.start) / process.period
    u_tr, _, signs_tr, _, hit_tr = record.transitions.arrays
    solved, events = 0, 0
    for e in range(1, len(u_tr)):
        if not u_tr[e] > u_tr[e - 1]:
            continue
        warm = signs_tr[e - 1].copy()
        coef = loop.coef[0]
        i_prev = int(np.argmin(np.abs(u_ev - u_tr[e - 1])))
        i_now = int(np.argmin(np.abs(u_ev - u_tr[e])))
        *_, Ydx, base, Wc, inverse, _ = _full_piece(loop.k, warm, record.events.w[i_prev], coef)
        Rdx = np.empty((nb, N))
        eventloop.derivative(Ydx, linear, H, Rdx)
        w, forced = record.events.w[i_now], hit_tr[e].copy()

        def scratch():
            return (
                np.empty(nb),
                np.empty(m),
                np.empty(m),
                np.zeros((3, m), dtype=np.bool_),
                np.empty((4, m)),
                np.zeros((5, N)),
                np.empty((2 + chain.UPDATE_ITERATIONS, N), dtype=np.int8),
                np.full(N, 2, dtype=np.int8),
                np.empty(N),
                np.empty(N - 1),
                np.zeros(2),
                np.zeros(8),
            )

        whole, local = np.empty(N, dtype=np.int8), np.empty(N, dtype=np.int8)
        ok = eventloop.decide(
            loop.k, kmax, loop.c_scale, linear, H, coef, float(u_tr[e]), w, forced, warm, whole, *scratch(), warm
        )
        parts = scratch()
        ok_local = eventloop.decide_local(
            loop.k,
            kmax,
            loop.c_scale,
            linear,
            H,
            coef,
            eventloop.offset_size(coef),
            float(u_tr[e]),
            w,
            forced,
            warm,
            local,
            *parts,
            Rdx,
            inverse,
            np.empty(N),
            warm,  # the set of the piece before: held (`crawlsim.kernel.piece.tight_rows`)
        )
        assert ok and ok_local
        assert np.array_equal(local, whole), e
        hot = int(np.count_nonzero(parts[3][1, :N]))
        assert hot < N // 4
        solved += hot > 0
        events += 1
    assert events >= 100 and solved >= events // 2


def test_energy_terms_by_chunks():
    """The pieces' energy products summed by chunks are the sums over all links and slipping
    blocks (to roundoff); after the links of one chunk change, summing that chunk alone again
    gives the bits of summing every chunk."""
    rng = np.random.default_rng(3)
    N, nb = 100, 3
    signs = rng.integers(-1, 2, N).astype(np.int8)
    base, Wc, dY = rng.normal(size=N - 1), rng.normal(size=(nb, N - 1)), rng.normal(size=(nb, N))
    KLc, dLc = rng.normal(size=(nb, N - 1)), rng.normal(size=(nb, N - 1))
    Mc, lc = rng.normal(size=(nb, 2 * N)), rng.normal(size=(nb, 2 * N))
    chunks = (N + eventloop.CHUNK - 1) // eventloop.CHUNK
    stale, partial = np.ones(chunks, dtype=np.bool_), np.zeros((chunks, 3, nb, nb))
    out = np.empty((3, nb, nb))
    eventloop.energy_terms(signs, base, Wc, dY, KLc, dLc, Mc, lc, True, out, stale, partial)
    assert not stale.any()
    stress = Wc + KLc
    stress[0] += base
    rows = np.where(signs > 0, np.arange(N), N + np.arange(N))
    act = signs != 0
    expected = np.stack(
        [
            stress @ dLc.T,
            -(Mc[:, rows[act]] * signs[act]) @ dY[:, act].T,
            -(lc[:, rows[act]] * signs[act]) @ dY[:, act].T,
        ]
    )
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    Wc[:, 40:50] += 1.0  # links of chunk 1 only
    stale[1] = True
    eventloop.energy_terms(signs, base, Wc, dY, KLc, dLc, Mc, lc, True, out, stale, partial)
    again = np.empty((3, nb, nb))
    eventloop.energy_terms(
        signs,
        base,
        Wc,
        dY,
        KLc,
        dLc,
        Mc,
        lc,
        True,
        again,
        np.ones(chunks, dtype=np.bool_),
        np.zeros((chunks, 3, nb, nb)),
    )
    assert np.array_equal(out, again)


def test_local_events_compiled_and_python_agree_bit_for_bit():
    """Three periods of the 16-block segments wave (200 steps per period): states, slips,
    event times and energy, the same bits in the kernel's two forms."""
    outputs = []
    for form in ("compiled", "python"):
        with jit.forced(form):
            stepper = EventStepper(_wave(16, 200))
            out = []
            for _ in range(3):
                r = stepper.step_period()
                e = r.energy
                out.append(
                    [
                        r.w.tobytes(),
                        r.multipliers.tobytes(),
                        r.events.t.tobytes(),
                        (e.work, e.dissipation, e.energy_end),
                    ]
                )
            outputs.append(out)
    assert outputs[0] == outputs[1]
