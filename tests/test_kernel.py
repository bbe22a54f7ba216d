"""The compiled kernel (`crawlsim.kernel`): the certified catch-up step of a crawler chain.

What must hold:

* it is the same scheme as `crawlsim.projection.kkt` (the telescoped runs that generic processes keep): a
  certified KKT point of a strictly convex problem is unique, so both paths take the same steps
  to roundoff, and v0 agrees to 1e-12 on every example crawler;
* one source: the compiled functions and the same functions run as Python
  (`crawlsim.kernel.jit`'s interpreted form) give the same bits on fixed inputs (the kernel is
  plain IEEE arithmetic in a fixed order; numba does not contract or reassociate without
  fastmath);
* a step whose numbers are wrong is never accepted: it raises `CertificateError`, naming the
  time and the rows;
* a cold cache is announced with one line on stderr, a warm one is not.
"""

from pathlib import Path

import numpy as np
import pytest

from crawlsim.errors import CertificateError
from crawlsim.gait.corpus import random_gait
from crawlsim.gait.document import load_gait
from crawlsim.integrate import catchup
from crawlsim.integrate.exact import EventStepper
from crawlsim.integrate.stepping import CatchUpStepper
from crawlsim.kernel import chain, eventloop, jit
from crawlsim.model.process import compile_gait

ROOT = Path(__file__).resolve().parents[1]
CRAWLERS = sorted(
    p for p in [*ROOT.glob("gaits/*.yaml"), *ROOT.glob("gaits/paper/*.yaml")] if "sweeping-process" not in p.read_text()
)
#: Few periods of short chains: the same steps run as Python in the subprocess.
BITWISE = ("inching-2", "peristalsis-4", "smooth-friction-3", "anchoring-2")
#: Corpus gaits (`crawlsim.gait.corpus`) whose offsets need sampled zeros and jump projections:
#: a linear part and three harmonics (seed 18), a linear part and one harmonic (5), three
#: harmonics (4), each with steps signals.
BITWISE_SEEDS = (18, 5, 4)


@pytest.mark.parametrize("path", CRAWLERS, ids=lambda p: p.stem)
def test_kernel_steps_are_the_kkt_steps(path):
    """Three periods from the file's initial state with the kernel and with the telescoped
    runs of `crawlsim.projection.kkt`: states, slips and v0 of each period agree to roundoff (1e-12
    relative to the sizes involved), and the periods visit the same active sets."""
    process = compile_gait(load_gait(path))
    fast, slow = CatchUpStepper(process), CatchUpStepper(process, kernel=False)
    assert fast._kernel is not None
    for _ in range(3):
        a, b = fast.step_period(), slow.step_period()
        scale = max(1.0, float(np.max(np.abs(b.w))))
        assert np.max(np.abs(a.w - b.w)) <= 1e-12 * scale
        assert np.max(np.abs(a.x - b.x)) <= 1e-12 * max(1.0, float(np.max(np.abs(b.x))))
        v_a = float(np.mean(a.x[-1] - a.x[0])) / process.period
        v_b = float(np.mean(b.x[-1] - b.x[0])) / process.period
        assert abs(v_a - v_b) <= 1e-12
        assert [A.index.tolist() for A in a.visited] == [A.index.tolist() for A in b.visited]


@pytest.mark.parametrize("path", CRAWLERS, ids=lambda p: p.stem)
def test_compiled_event_loop_changes_nothing(path, monkeypatch):
    """The exact integrator's compiled event loop (`crawlsim.kernel.eventloop`) against its
    Python loop with the velocity problems solved by `crawlsim.projection.kkt` (the kernel switched
    off): the same certified KKT points, so the same decisions, events and states to roundoff,
    v0 of each period to 1e-12 and the same energy ledger (1e-12 relative)."""
    process = compile_gait(load_gait(path))
    fast = EventStepper(process)
    closed_form = fast._loop is not None
    fast_records = [fast.step_period() for _ in range(2)]
    assert (fast._loop is not None) == closed_form  # no period was handed over
    monkeypatch.setattr(catchup, "velocity", lambda *args: None)
    slow = EventStepper(process)
    slow._loop = None
    for a in fast_records:
        b = slow.step_period()
        assert np.max(np.abs(a.w - b.w)) <= 1e-12 * max(1.0, float(np.max(np.abs(b.w))))
        v_a = float(np.mean(a.x[-1] - a.x[0])) / process.period
        v_b = float(np.mean(b.x[-1] - b.x[0])) / process.period
        assert abs(v_a - v_b) <= 1e-12
        assert np.max(np.abs(a.events.t - b.events.t)) <= 1e-12
        assert [(t.cause, t.piece, t.active.index.tolist(), t.hit.tolist()) for t in a.transitions] == [
            (t.cause, t.piece, t.active.index.tolist(), t.hit.tolist()) for t in b.transitions
        ]
        assert [A.index.tolist() for A in a.visited] == [A.index.tolist() for A in b.visited]
        for name in ("work", "dissipation", "jump_loss"):
            x, y = getattr(a.energy, name), getattr(b.energy, name)
            assert abs(x - y) <= 1e-12 * max(1.0, abs(y)), name


def test_example_crawlers_take_the_compiled_event_loop():
    """Every example crawler runs compiled, whatever its offsets' basis (linear, one harmonic,
    or several: smooth-friction-3, whose zeros are sampled)."""
    names = {p.stem for p in CRAWLERS if EventStepper(compile_gait(load_gait(p)))._loop is not None}
    assert names == {p.stem for p in CRAWLERS} and "smooth-friction-3" in names


def test_corrupted_piece_fails_the_sample_certificate():
    """The grid samples of a piece of peristalsis-4 pass their certificate as computed, and fail
    it (a constraint violated, complementarity lost) when the piece's state is shifted by 1e-9
    relative: `sample_piece` is what stands between a wrong piece and the results. (Making
    it return True lets the corrupted piece through.)"""
    process = compile_gait(load_gait(ROOT / "gaits" / "peristalsis-4.yaml"))
    stepper = EventStepper(process)
    stepper.step_period()
    record = stepper.step_period()
    loop = stepper._loop
    assert loop is not None
    tr = record.transitions[1]
    i = int(np.argmin(np.abs((record.events.t - record.start) / process.period - tr.u)))
    w0, lam_cum = record.events.w[i], np.zeros(process.polyhedron.m)
    signs = catchup.signs_of(tr.active, process.blocks)
    N, nb = process.blocks, stepper.basis.size
    coef = loop.coef[tr.piece]
    D, l, dx0, Ydx = np.empty(N), np.empty(N - 1), np.empty(N), np.empty((nb, N))
    base, Wc = np.empty(N - 1), np.empty((nb, N - 1))
    inverse, gram = eventloop.piece(loop.k, signs, w0, coef, D, l, dx0, Ydx, base, Wc, np.empty(N))
    assert inverse > 0
    PHI = stepper.basis.values(np.linspace(tr.u, record.transitions[2].u, 6))
    G = len(PHI)

    def certify(base):
        W, LAMC, report = np.zeros((G, N - 1)), np.zeros((G, 2 * N)), np.zeros(8)
        ok = eventloop.sample_piece(
            loop.k,
            float(np.max(loop.k)),
            loop.c_scale,
            coef,
            signs,
            PHI,
            1,
            G,
            W,
            LAMC,
            lam_cum,
            dx0,
            Ydx,
            base,
            Wc,
            inverse,
            gram,
            0.0,
            0.0,
            report,
            np.empty((0, 0)),
            np.empty(0),
            np.empty((0, 0)),
        )
        return ok, report

    ok, _ = certify(base)
    assert ok
    shift = 1e-9 * float(np.max(np.abs(base))) * np.where(np.arange(N - 1) % 2, 1.0, -1.0)
    ok, report = certify(base + shift)
    assert not ok
    assert max(report[eventloop.R_PRIMAL], report[eventloop.R_COMP]) > report[eventloop.R_TOLP]


def _periods(paths) -> dict:
    """Two periods of each gait, catch-up and exact, as their bits."""
    out = {}
    for path in paths:
        if path.startswith("seed "):  # a corpus gait of 2-5 blocks at 100 steps per period
            gait = random_gait(int(path[5:]), blocks=(2, 5), stiffness_ratio=1e6, friction_ratio=1e3)
            process = compile_gait(gait, 100)
        else:
            process = compile_gait(load_gait(path))
        for stepper in (CatchUpStepper(process), EventStepper(process)):
            records = [stepper.step_period() for _ in range(2)]
            out[f"{path} {type(stepper).__name__}"] = [
                [r.w.tobytes().hex(), r.multipliers.tobytes().hex()]
                + ([] if r.events is None else [r.events.t.tobytes().hex(), repr(r.energy)])
                for r in records
            ]
    return out


def test_compiled_and_python_kernels_agree_bit_for_bit():
    """Two periods of catch-up and of the exact integrator (its compiled event loop, with
    closed-form and sampled zeros, `crawlsim.kernel.sampling`): states, slips, event times and
    energy ledgers, bit for bit."""
    paths = [str(ROOT / "gaits" / f"{name}.yaml") for name in BITWISE]
    paths += [f"seed {seed}" for seed in BITWISE_SEEDS]
    with jit.forced("compiled"):
        compiled = _periods(paths)
    with jit.forced("python"):
        python = _periods(paths)
    assert compiled.keys() == python.keys() and len(compiled) == 2 * len(paths)
    for key in compiled:
        assert compiled[key] == python[key], key


def _corrupted(scale: float) -> CatchUpStepper:
    """peristalsis-4 after one period, about to step its second on the set of that period's
    first step (learnt from a twin stepper), whose factor the kernel keeps, scaled by
    ``scale`` behind its back: a value the compiled code receives."""
    process = compile_gait(load_gait(ROOT / "gaits" / "peristalsis-4.yaml"))
    twin, stepper = CatchUpStepper(process), CatchUpStepper(process)
    twin.step_period()
    stepper.step_period()
    rows = np.flatnonzero(twin.step_period().multipliers[0] > 0)
    assert rows.size
    stepper.active = process.polyhedron.factor(rows)
    kernel = stepper._kernel
    assert kernel is not None
    kernel.load(stepper.active)
    kernel.factored[:] = kernel.signs
    kernel.norms[:] = chain.factor(kernel.k, kernel.signs, kernel.D, kernel.l)
    kernel.D *= scale
    return stepper


def test_corrupted_factor_raises_certificate_error():
    """With the pivots off by 1e-3 relative, the first step solves the wrong system; one step
    of iterative refinement leaves about (1e-3)^2 = 1e-6 of the residual, far above the 1e-14
    relative of the certificate, and the set is right (no multiplier of the wrong sign, no
    violated row), so no update applies: the step fails with its time and rows. (Switching
    off the certificate, or the refinement's trigger, lets the wrong step through.)"""
    stepper = _corrupted(1.0 + 1e-3)
    with pytest.raises(
        CertificateError,
        match=r"failed its certificate at t = 1\.001: .*"
        r"complementarity .*worst row 2 \(J = \{3\}",
    ):
        stepper.step_period()


def test_refinement_repairs_a_small_corruption():
    """The control: pivots off by 1e-9 leave (1e-9)^2 after one refinement, below roundoff, and
    the period is certified and equals the uncorrupted one to roundoff."""
    process = compile_gait(load_gait(ROOT / "gaits" / "peristalsis-4.yaml"))
    clean = CatchUpStepper(process)
    clean.step_period()
    expected = clean.step_period()
    got = _corrupted(1.0 + 1e-9).step_period()
    assert np.max(np.abs(got.w - expected.w)) <= 1e-12


def test_linear_crossing_closed_form():
    """f = a + s u: the zero is -a/s when it lies after u0; a row tight at u0 (roundoff puts
    its zero at or before u0) gets the time it exceeds its tolerance, (tol - a)/s; a falling
    or late one gets none."""
    from crawlsim.kernel.events import linear_crossings

    a = np.array([-1.0, 0.0, 1.0, -3.0])
    s = np.array([2.0, 2.0, -1.0, 2.0])
    tol = np.full(4, 1e-14)
    out = np.empty(4)
    linear_crossings(a, s, tol, 0.0, 1.0, out)
    assert out[0] == 0.5 and out[1] == 0.5e-14
    assert np.isinf(out[2]) and np.isinf(out[3])  # falling; crossing at 1.5, after u1


def test_harmonic_crossing_closed_form():
    """f = cos 2 pi u - 1/2 rises through 0 where cos theta = 1/2 on its way up, theta =
    2 pi - pi/3: u = 5/6 (from u0 = 0.3, when f < 0; and from u0 = 0.1, where f > 0 but
    falling). From u0 = 0.9, where f = 0.31 > 0 and rising, the row is crossing now: its event
    is at once (`crawlsim.kernel.events`: where f rises a tolerance above f(u0)), not at the
    next upward crossing a period later. With a phase, f = cos 2 pi (u - 1/4) - 1/2 =
    sin 2 pi u - 1/2 (alpha = 0, beta = 1) rises through 0 at u = 1/12."""
    from crawlsim.kernel.events import harmonic_crossings

    out = np.empty(1)
    for u0 in (0.3, 0.1):
        harmonic_crossings(np.array([-0.5]), np.array([1.0]), np.array([0.0]), np.array([1e-14]), u0, 1.0, out)
        assert out[0] == pytest.approx(5 / 6, abs=1e-14)
    harmonic_crossings(np.array([-0.5]), np.array([1.0]), np.array([0.0]), np.array([1e-14]), 0.9, 1.5, out)
    assert 0.9 < out[0] < 0.9 + 1e-13
    harmonic_crossings(np.array([-0.5]), np.array([0.0]), np.array([1.0]), np.array([1e-14]), 0.0, 1.0, out)
    assert out[0] == pytest.approx(1 / 12, abs=1e-14)


@pytest.mark.parametrize("name", ["peristalsis-4", "anchoring-2"])
def test_compiled_loop_samples_taken_at_wrong_times_are_never_kept(name):
    """The compiled event loop writes its grid samples from phi at the grid times, which it
    receives tabulated: tabulated 0.01 cycle late, every sample is the piece's closed form at
    the wrong time, off its interval where gaps have crossed zero. The sample certificate
    fails, and the period is handed to the Python loop (which refines a failure of roundoff's
    size, and stops on any other): the record is the true period's, not the wrong samples."""
    process = compile_gait(load_gait(ROOT / "gaits" / f"{name}.yaml"), 100)
    clean, stepper = EventStepper(process), EventStepper(process)
    clean.step_period(), stepper.step_period()
    loop = stepper._loop
    assert loop is not None
    loop.phi = np.ascontiguousarray(stepper.basis.values(stepper._grid + 0.01))
    record = stepper.step_period()
    assert loop.handoffs == 1
    np.testing.assert_allclose(record.w, clean.step_period().w, rtol=0, atol=1e-12 * process.scale)
