"""Every certificate check can fail: corrupted numbers must raise `CertificateError`.

A test that passes whether or not a check runs proves nothing about the check. Each test here
corrupts one kind of number the integrators produce, far above roundoff (a relative 1e-3 in
the solves, 1e-8 to 1e-6 of the scale of c in a state), and asserts that the run stops with
a `CertificateError` instead of going on:

* the kernel's solves (`ActiveSet.solve` of every factored set, through the public
  `Polyhedron.factor`): a wrong step, in both integrators, on a smooth gait and on one whose
  friction jumps;
* an exact piece (the closed form of w(u) on an interval with a fixed active set), pushed out
  of K(t) along the normal of one of its active rows: caught by the sampled trajectory's
  certificate, and, with that certificate switched off, by the Clarabel check of
  ``check_every_step``;
* the exact integrator's state after a jump of c, pushed out of K(t+) the same way;
* the iterative refinement of the kernel: an ill-conditioned generic process whose first solve
  misses its complementarity tolerance, so that only the refined step is certified.

The piece and the jump are reached through the stepper's ``_piece`` and its projector on the
Python loop (``kernel=False``; there is no other way to corrupt one piece alone); the rest goes
through public interfaces. The compiled loop's own corruptions are in tests/test_kernel.py.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from crawlsim.errors import CertificateError
from crawlsim.gait.document import load_gait
from crawlsim.integrate.stepping import make_stepper
from crawlsim.kernel.policy import REFINE_FRACTION
from crawlsim.model.process import compile_gait
from crawlsim.projection.adapter import ExactProjector
from crawlsim.projection.dense_polyhedron import DensePolyhedron
from crawlsim.projection.polyhedron import ActiveSet

GAITS = Path(__file__).resolve().parents[1] / "gaits"
INTEGRATORS = ("exact", "catch-up")
#: peristalsis-4: smooth offsets; anchoring-2: friction switched by steps (jumps of c)
CORRUPTIBLE = ("peristalsis-4", "anchoring-2")


def process_of(name: str, steps: int = 100):
    return compile_gait(load_gait(GAITS / f"{name}.yaml"), steps)


class _Scaled(ActiveSet):
    """A factored set whose solves are off by a relative ``error``."""

    def __init__(self, inner: ActiveSet, error: float):
        self.inner, self.error = inner, error
        self.index, self.inverse_norm, self.gram_norm = (inner.index, inner.inverse_norm, inner.gram_norm)

    def solve(self, R):
        return self.inner.solve(R) * (1.0 + self.error)


def corrupt_solves(process, error: float = 1e-3) -> None:
    """Every active set the process's polyhedron factors from now on solves wrongly. One step
    of iterative refinement leaves a residual of error^2 = 1e-6 of the step's slips, above the
    tolerance (1e-14 of the step's numbers) even for a catch-up step's small slips."""
    poly = process.polyhedron
    factor = poly.factor
    poly.factor = lambda index: _Scaled(factor(index), error)


def outward(poly, active: ActiveSet, size: float) -> np.ndarray:
    """A change of w that raises the slack of the first active row by ``size`` (out of K):
    M^{-1} b_i, scaled."""
    e = np.zeros(poly.m)
    e[active.index[0]] = 1.0
    d = poly.respond(e)
    return d * (size / float(poly.apply(d)[active.index[0]]))


def corrupt_pieces(stepper, relative: float = 1e-8) -> None:
    """Every exact piece with an active row starts ``relative`` x the scale of c outside K."""
    poly = stepper.poly
    size = relative * poly.c_scale
    make = stepper._piece

    def piece(active, w0, piece_index, u0):
        p = make(active, w0, piece_index, u0)
        if active.size:
            p.base[...] = p.base + outward(poly, active, size)
        return p

    stepper._piece = piece


def periods(stepper, count: int = 3) -> None:
    for _ in range(count):
        stepper.step_period()


@pytest.mark.parametrize("name", CORRUPTIBLE)
@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_a_wrong_step_raises_in_both_integrators(integrator, name):
    """Wrong solves of every active set raise. Both integrators run here on the Python path of
    `crawlsim.projection.kkt` (``kernel=False``), the one the polyhedron's factors reach; the compiled
    kernel's own corrupted factor and piece are in tests/test_kernel.py."""
    options = {"kernel": False}
    process = process_of(name)
    # the uncorrupted run is certified
    periods(make_stepper(process_of(name), integrator, **options))
    corrupt_solves(process)
    # the message names the time and the rows (the set that failed, in the crawler's words)
    with pytest.raises(CertificateError, match=r"certificate.* at t = \d.*J = \{\d"):
        periods(make_stepper(process, integrator, **options))


@pytest.mark.parametrize("name", CORRUPTIBLE)
def test_a_corrupted_exact_piece_raises(name):
    stepper = make_stepper(process_of(name), "exact", kernel=False)
    periods(stepper)  # certified
    corrupt_pieces(stepper)
    with pytest.raises(
        CertificateError,
        match=r"exact trajectory failed its certificate at "
        r"t = \d.*; rows J = \{\d.*; active set J = \{\d",
    ):
        periods(stepper)


def test_a_piece_off_by_a_few_tolerances_is_refined():
    """Every exact piece pushed out of K(t) by 5e-14 of the scale of c, a few times the
    tolerance (the size of the closed form's roundoff on chains stiff to the accepted limits):
    each sample that fails is refined, projected onto K(t_j) and certified, and the run goes on
    from there (it used to stop with a CertificateError); v0 moves by roundoff. Pushed 1e-8 out,
    far beyond the refinement's reach, it still stops (`test_a_corrupted_exact_piece_raises`)."""
    from crawlsim.kernel.policy import REFINE_LIMIT

    clean = make_stepper(process_of("peristalsis-4"), "exact", kernel=False)
    stepper = make_stepper(process_of("peristalsis-4"), "exact", kernel=False)
    refined = []
    refine = stepper._refine
    stepper._refine = lambda *args: refined.append(args[1]) or refine(*args)
    corrupt_pieces(stepper, relative=5e-14)
    for _ in range(3):
        a, b = clean.step_period(), stepper.step_period()
        assert abs(np.mean(a.x[-1] - a.x[0]) - np.mean(b.x[-1] - b.x[0])) < 1e-12
    assert refined and 5e-14 * REFINE_LIMIT < 1e-8  # refined here, not there
    assert set(refined) <= set(stepper._grid) and set(refined) - set(stepper.pieces.edges)  # at samples


def test_clarabel_check_of_every_step_catches_a_corrupted_piece_alone():
    """``check_every_step``: Clarabel must find a state outside K(t_j) by itself, with the
    kernel's certificate of the sampled trajectory switched off."""
    stepper = make_stepper(process_of("peristalsis-4"), "exact", check_every_step=True, kernel=False)
    periods(stepper, 1)
    corrupt_pieces(stepper, relative=1e-6)
    stepper._certify_piece = lambda *args: 0.0
    with pytest.raises(CertificateError, match="Clarabel moves the exact state"):
        periods(stepper)


def test_a_corrupted_jump_raises():
    """anchoring-2: the friction of both blocks jumps at t = T/2 and T; the state after the
    jump is the projector's, pushed out of K(t+) here."""
    stepper = make_stepper(process_of("anchoring-2"), "exact", kernel=False)
    periods(stepper)
    poly, project = stepper.poly, stepper.projector.project
    jumps = []

    def corrupted(w_trial, c, **options):
        proj = project(w_trial, c, **options)
        if np.all(np.isfinite(c)) and options.get("fixed") is None and proj.active.size:
            jumps.append(options.get("time"))  # a jump of c (velocity problems have inf rows)
            point = proj.point + outward(poly, proj.active, 1e-8 * poly.c_scale)
            return type(proj)(point, proj.multipliers, proj.active, proj.used_clarabel)
        return proj

    stepper.projector.project = corrupted
    with pytest.raises(
        CertificateError,
        match=r"projection at the jump of c at t = \d.*; rows "
        r"J = \{\d.*; active set J = \{\d",
    ):
        periods(stepper)
    assert jumps


def ill_conditioned(seed: int):
    """A generic process (n = 5, m = 8) whose first solve must miss its tolerance, on any BLAS:
    metric M with eigenvalues from 1e-5 to 1 and an antisymmetric part of 1e-13 (symmetric only
    to roundoff, as a metric computed from data is), and c built so that the projection of w
    onto K is known: w* = w - M^{-1} B_A^T lambda with A = {0, 1, 2, 3}, lambda_A > 0,
    c_A = B_A w* and the other rows 0.1 to 1 slack (the KKT conditions, so w* is the
    projection).

    Why the first solve misses: M^{-1} then has an antisymmetric part of about
    1e-13 |M^{-1}|^2 (the derivative of the inverse, -M^{-1} S M^{-1}), up to 1e-3 of |M^{-1}|,
    and so does G_A = B_A M^{-1} B_A^T, while its Cholesky factor reads one triangle: the first
    solve solves the symmetric part, and leaves a residual of that antisymmetric part times
    lambda, set by the construction rather than by roundoff (measured: 37 to 9100 tolerances
    over seeds 0-19). The residual is computed from B and M^{-1} themselves, so one refinement
    on it removes that part."""
    rng = np.random.default_rng(seed)
    n, m = 5, 8
    U, _ = np.linalg.qr(rng.normal(size=(n, n)))
    M = U @ np.diag(10 ** rng.uniform(-5, 0, n)) @ U.T
    S = rng.normal(size=(n, n))
    M = (M + M.T) / 2 + 1e-13 * (S - S.T)
    B = rng.normal(size=(m, n))
    poly = DensePolyhedron(B, M, 1.0)
    w = rng.normal(size=n) * 10
    lam = np.zeros(m)
    lam[:4] = rng.uniform(0.5, 1.5, 4)
    target = w - poly.respond(lam)
    c = poly.apply(target)
    c[4:] += rng.uniform(0.1, 1.0, 4)
    return poly, np.arange(4), w, c, target, lam


def first_solve_residual(poly, index, w, c) -> float:
    """The complementarity residual of the first solve on A, in units of its tolerance."""
    A = poly.factor(index)
    lam = np.zeros(poly.m)
    lam[index] = A.solve(poly.apply(w)[index] - c[index])
    slack = poly.apply(w - poly.respond(lam)) - c
    tol = poly.tolerance(A, np.max(np.abs(c)), np.max(np.abs(w)), np.max(np.abs(lam)))
    return float(np.max(np.abs(slack[index])) / tol.primal)


def test_refinement_is_needed_and_makes_the_step_certified():
    """Iterative refinement on B_A w - c_A (kkt.py) is what certifies these steps: the first
    solve alone fails its complementarity tolerance (`ill_conditioned`: by at least 10 times
    it on every seed), the refined step passes, as a single projection and in a telescoped
    run of steps."""
    assert REFINE_FRACTION < 1.0
    for seed in range(10):
        poly, index, w, c, target, lam = ill_conditioned(seed)
        assert first_solve_residual(poly, index, w, c) > 10.0
        proj = ExactProjector(poly).project(w, c, warm=index)
        np.testing.assert_array_equal(proj.active.index, index)
        scale = np.max(np.abs(target))
        np.testing.assert_allclose(proj.point, target, atol=1e-8 * scale)
        np.testing.assert_allclose(proj.multipliers, lam, rtol=1e-6, atol=1e-8)
        # the same step as a run of two (telescoped: one solve for both), certified
        run = poly.run(poly.factor(index), w, np.vstack([c, c]))
        assert run.accepted == 2 and run.failed is None


def projected_step(name: str = "peristalsis-4"):
    """A step that slips: the initial state of ``name`` projected onto K(t) at the first grid
    time where it is outside, certified by the projector (point, active set)."""
    process = process_of(name)
    poly = process.polyhedron
    w = process.initial
    j = int(np.flatnonzero((poly.apply(w)[None, :] - process.offsets).max(axis=1) > 1e-3)[0])
    c = process.offsets[j]
    proj = ExactProjector(poly).project(w, c)
    assert proj.active.size
    return process, w, c, proj


def test_a_telescoped_run_accepts_no_wrong_step():
    """`Polyhedron.run` (catch-up's runs of steps on one active set): the same step solved right
    is accepted, solved wrongly it is not (the full step then decides)."""
    process, w, c, proj = projected_step()
    poly = process.polyhedron
    C = np.vstack([c, c])
    good = poly.run(proj.active, w, C)
    assert good.accepted == 2
    np.testing.assert_allclose(good.w[0], proj.point, atol=1e-12 * poly.c_scale)
    bad = poly.run(_Scaled(proj.active, 1e-3), w, C)
    assert bad.accepted == 0 and bad.failed is not None and not bad.failed.ok


@pytest.mark.parametrize("error", [1e-10, -1e-10])
def test_refinement_certifies_slightly_wrong_chain_solves(error):
    """The chain's own LDL^T is backward stable: its first solve stays far inside the
    tolerance (measured: at most 0.013 of it over 300 random chains of up to 3000 blocks and
    stiffness ratios up to 1e14), so the refinement is needed only where a solve is a little
    off, as a less accurate factorisation would make it. A relative 1e-10 leaves a residual
    of about 1e-10 of the step's forces, above the tolerance (1e-14 of them); one refinement
    leaves 1e-20: certified, in a single step and in a telescoped run."""
    process, w, c, proj = projected_step()
    poly = process.polyhedron
    scaled = _Scaled(proj.active, error)
    point, _, slack, tol = poly.solve_on(scaled, w, c)
    assert poly.certify(slack, proj.multipliers, scaled, tol).ok
    np.testing.assert_allclose(point, proj.point, atol=1e-12 * poly.c_scale)
    run = poly.run(scaled, w, np.vstack([c, c]))
    assert run.accepted == 2
    # and the first solve alone is not certified: the refinement is what passes it
    lam = np.zeros(poly.m)
    lam[proj.active.index] = scaled.solve(poly.apply(w)[proj.active.index] - c[proj.active.index])
    first = poly.apply(w - poly.respond(lam)) - c
    assert np.max(np.abs(first[proj.active.index])) > tol.primal


def test_a_run_stops_where_a_dependent_set_of_rows_becomes_tight():
    """`Polyhedron.run` of a generic process: the square corner {z1 <= c0, z2 <= c1} (active)
    with the redundant face z1 + z2 <= c2 through it at the third step only (c2 = c0 + c1).
    There the tight normals are dependent (LICQ fails): the run must stop so that the full step
    decides (a `LicqWarning` for a generic process, the uniqueness check for a crawler), not
    run through it; the steps before it are accepted."""
    poly = DensePolyhedron(np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]), np.eye(2), 1.0)
    A = poly.factor([0, 1])
    C = np.array([[0.5, 0.5, 1.5], [0.4, 0.4, 1.2], [0.3, 0.3, 0.6], [0.2, 0.2, 0.9]])
    run = poly.run(A, np.array([1.0, 1.0]), C)
    assert run.accepted == 2 and run.degenerate and run.failed is None
    np.testing.assert_allclose(run.w[:2], [[0.5, 0.5], [0.4, 0.4]], atol=1e-15)
    # with the redundant face slack at every step, the whole run is accepted
    C[2, 2] = 0.7
    assert poly.run(A, np.array([1.0, 1.0]), C).accepted == 4
