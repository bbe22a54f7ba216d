"""The certified KKT kernel (crawlsim.projection.kkt): structure, factorisations, certificates, runs.

A projection w* = argmin 1/2 |w - w_trial|_M^2 s.t. B w <= c is characterised by its KKT
conditions, M (w* - w_trial) + B^T lambda = 0, B w* <= c, lambda >= 0, lambda_i (B w* - c)_i = 0;
the tests check them independently of the kernel, on crawler chains (N up to 40, stiffness
ratios up to 1e6, friction ratios 1e-3 to 1e3) and on generic polytopes.
"""

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from crawlsim.projection import certificate, tridiagonal
from crawlsim.projection.adapter import ExactProjector
from crawlsim.projection.chain_polyhedron import ChainPolyhedron
from crawlsim.projection.dense_polyhedron import DensePolyhedron

EPS = np.finfo(float).eps


def chain_problem(seed, blocks, stiffness_ratio, friction_ratio, push):
    """A crawler's step: stiffnesses spread over ``stiffness_ratio``, friction limits mu+, mu-
    with mu-/mu+ up to ``friction_ratio`` either way, actuator lengths L, and a trial state
    pushed by ``push`` (in units of the friction force over the stiffness)."""
    rng = np.random.default_rng(seed)
    k = np.exp(rng.uniform(0, np.log(stiffness_ratio), blocks - 1))
    mu_plus = np.exp(rng.uniform(-1, 1, blocks))
    mu_minus = mu_plus * np.exp(rng.uniform(-np.log(friction_ratio), np.log(friction_ratio), blocks))
    L = 1.0 + 0.3 * rng.normal(size=blocks - 1)
    poly = ChainPolyhedron(k, 1.0)
    DtKL = poly.forces(k * L)
    c = np.concatenate([mu_plus - DtKL, mu_minus + DtKL])
    w_trial = -k * L + push * rng.normal(size=blocks - 1) * np.max(mu_plus)
    return poly, c, w_trial


def assert_kkt(poly, c, w_trial, step, rtol=1e-12):
    """The KKT conditions, checked with the dense B and M (not the kernel's operators)."""
    B, M = poly.dense_normals(), poly.dense_metric()
    w, lam = step.point, step.multipliers
    lam_scale = np.max(np.abs(lam), initial=0.0)
    size = max(1.0, np.max(np.abs(c)), 2 * np.max(np.abs(w_trial)), np.max(np.abs(B.T @ lam)))
    slack = B @ w - c
    assert np.max(slack) <= rtol * size
    assert np.min(lam) >= -rtol * size * max(1.0, step.active.inverse_norm) - rtol * lam_scale
    assert np.max(np.abs(slack[step.active.index]), initial=0.0) <= rtol * size
    stationarity = M @ (w - w_trial) + B.T @ lam
    assert np.max(np.abs(stationarity)) <= 1e3 * EPS * size * max(1.0, np.max(np.abs(M)))
    inactive = np.setdiff1d(np.arange(poly.m), step.active.index)
    assert np.all(lam[inactive] == 0.0)


@pytest.mark.parametrize("shape", [(8,), (3, 8), (7, 8), (5, 4, 6), (2, 1)])
def test_chain_operators_are_the_dense_matrices(shape):
    """B w and M^{-1} B^T lambda of a chain equal the dense D^T, K D products, for any
    leading shape (the telescoped runs and the basis coefficients use 2-D and 3-D arrays)."""
    rng = np.random.default_rng(sum(shape))
    k = rng.uniform(0.5, 5, shape[-1])
    poly = ChainPolyhedron(k, 1.0)
    W = rng.normal(size=shape)
    LAM = rng.normal(size=shape[:-1] + (poly.m,))
    B, Minv = poly.dense_normals(), np.linalg.inv(poly.dense_metric())
    np.testing.assert_allclose(poly.apply(W), W @ B.T, rtol=0, atol=1e-14)
    np.testing.assert_allclose(poly.respond(LAM), LAM @ (Minv @ B.T).T, rtol=0, atol=1e-13)


@pytest.mark.parametrize("blocks", [3, 6, 7, 40, 200])
def test_chain_factor_solves_and_bounds_the_inverse(blocks):
    """An active set's solve equals the dense solve with G_A = B_A M^{-1} B_A^T (numpy LDL^T
    for small sets, LAPACK dpttrf/dpttrs for large ones), and its inverse norm is exactly
    ||G_A^{-1}||_inf (L_JJ is an M-matrix, so the norm is max(L_JJ^{-1} 1))."""
    rng = np.random.default_rng(blocks)
    k = np.exp(rng.uniform(0, np.log(1e4), blocks - 1))
    poly = ChainPolyhedron(k, 1.0)
    J = rng.choice(blocks, size=blocks - 1, replace=False)
    index = np.where(rng.uniform(size=J.size) < 0.5, J, J + blocks)
    A = poly.factor(index)
    B = poly.dense_normals()[A.index]
    G = B @ np.linalg.inv(poly.dense_metric()) @ B.T
    R = rng.normal(size=(5, A.size))
    x, ref = A.solve(R), np.linalg.solve(G, R.T).T
    # forward error of a backward-stable solve: a few eps times the condition number
    cond = A.inverse_norm * A.gram_norm
    assert np.max(np.abs(x - ref)) <= 100 * EPS * cond * np.max(np.abs(ref))
    assert A.inverse_norm == pytest.approx(np.max(np.sum(np.abs(np.linalg.inv(G)), axis=1)), rel=1e-9)


def test_chain_licq_is_not_every_block_and_not_both_limits():
    poly = ChainPolyhedron(np.ones(3), 1.0)  # 4 blocks, rows 0..3 forward, 4..7 backward
    assert poly.licq([0, 1, 6])
    assert not poly.licq([0, 1, 2, 7])  # every block at a limit: L 1 = 0
    assert not poly.licq([1, 5])  # block 1 at both limits: opposite normals
    with pytest.raises(certificate.Dependent):
        poly.factor([0, 1, 2, 7])


@settings(max_examples=120, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    blocks=st.integers(2, 40),
    stiffness_ratio=st.sampled_from([1.0, 1e2, 1e4, 1e6]),
    friction_ratio=st.sampled_from([1.0, 10.0, 1e3]),
    push=st.sampled_from([0.1, 1.0, 10.0]),
)
@example(seed=0, blocks=40, stiffness_ratio=1e6, friction_ratio=1e3, push=10.0)
@example(seed=3, blocks=2, stiffness_ratio=1.0, friction_ratio=1.0, push=0.1)
@example(seed=354367586, blocks=17, stiffness_ratio=1.0, friction_ratio=1.0, push=0.1)
@example(seed=1987, blocks=2, stiffness_ratio=1.0, friction_ratio=1000.0, push=0.1)
@example(seed=0, blocks=6, stiffness_ratio=1e4, friction_ratio=1.0, push=1.0)
def test_chain_projection_satisfies_kkt_and_agrees_with_clarabel(seed, blocks, stiffness_ratio, friction_ratio, push):
    """A crawler's certified step meets the KKT conditions to roundoff, and no point of
    Clarabel's beats it. With f(w) = |w - w_trial|_M^2 / 2 (strongly convex) and the certified
    (w*, lambda*), every w satisfies

        |w - w*|_M^2 / 2 <= f(w) - f(w*) + lambda*^T max(B w - c, 0),

    so the interior-point point w_ip obeys it (a wrong w* would let a better w_ip break it),
    and its right side is within a hundred times Clarabel's gap and feasibility tolerances
    (1e-10, relative to its objective f(w) - |w_trial|_M^2 / 2). The distance itself is only
    their square root: where a limit is weakly active the interior point sits 2e-6 away (seed
    354367586), which a bound on |w_ip - w*| of 1e-6 had wrongly called a disagreement."""
    poly, c, w_trial = chain_problem(seed, blocks, stiffness_ratio, friction_ratio, push)
    projector = ExactProjector(poly)
    proj = projector.project(w_trial, c)
    step = certificate.Step(proj.point, proj.multipliers, proj.active, None)  # type: ignore[arg-type]
    assert_kkt(poly, c, w_trial, step)
    lam_ip, _ = projector._clarabel(w_trial, c)
    import clarabel

    if projector.clarabel_status not in (clarabel.SolverStatus.Solved, clarabel.SolverStatus.AlmostSolved):
        # Clarabel stopped early (MaxIterations on seed 1987: two blocks, an interior trial
        # point, limits from 0.39 to 223): no reference point, but its iterate is still a
        # proposal, and the kernel certifies the same projection from it
        again = projector.project(w_trial, c, verify=True)
        assert again.used_clarabel
        assert_kkt(poly, c, w_trial, certificate.Step(again.point, again.multipliers, again.active, None))  # type: ignore[arg-type]
        np.testing.assert_allclose(
            again.point, proj.point, rtol=0, atol=1e-13 * max(1.0, float(np.max(np.abs(w_trial))))
        )
        return
    w_ip = w_trial - poly.respond(lam_ip)
    B, M = poly.dense_normals(), poly.dense_metric()

    def f(w):
        return 0.5 * (w - w_trial) @ M @ (w - w_trial)

    f_star = f(proj.point)
    excess = f(w_ip) - f_star + proj.multipliers @ np.maximum(B @ w_ip - c, 0.0)
    d = w_ip - proj.point
    roundoff = 1e-13 * max(1.0, f_star)
    assert 0.5 * d @ M @ d <= excess + roundoff
    # Clarabel's objective is f(w) - |w_trial|_M^2 / 2: its tolerances are relative to that
    objective = max(1.0, f_star, 0.5 * w_trial @ M @ w_trial)
    assert excess <= 100 * 1e-10 * objective


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), blocks=st.integers(2, 12))
def test_chain_and_dense_kernels_agree(seed, blocks):
    """The same projection through the chain structure and through the dense code."""
    poly, c, w_trial = chain_problem(seed, blocks, 1e3, 1e2, 1.0)
    dense = DensePolyhedron(poly.dense_normals(), poly.dense_metric(), 1.0)
    a = ExactProjector(poly).project(w_trial, c)
    b = ExactProjector(dense).project(w_trial, c)
    np.testing.assert_allclose(a.point, b.point, rtol=0, atol=1e-11 * max(1, np.max(np.abs(c))))
    np.testing.assert_allclose(a.multipliers, b.multipliers, rtol=1e-8, atol=1e-11)


def test_a_telescoped_run_is_the_steps_one_by_one():
    """On a fixed active set, k steps at once (one solve, cumulative multipliers) equal k
    single steps from each previous state, to roundoff."""
    poly, c, w_trial = chain_problem(5, 8, 10.0, 10.0, 3.0)
    proj = ExactProjector(poly).project(w_trial, c)
    A = proj.active
    # offsets moving slowly along the face: every step stays on A
    C = c + np.outer(np.linspace(0, 1e-3, 6)[1:], np.ones(poly.m)) * 0.0
    C[:, A.index] -= np.linspace(0, 1e-3, 6)[1:, None]
    run = poly.run(A, proj.point, C)
    assert run.accepted == len(C)
    w = proj.point
    for i in range(len(C)):
        w_i, lam_i, _, _ = poly.solve_on(A, w, C[i])
        np.testing.assert_allclose(run.w[i], w_i, rtol=0, atol=1e-13)
        np.testing.assert_allclose(run.multipliers[i], lam_i, rtol=0, atol=1e-13)
        w = w_i


def test_ldl_tridiagonal_solves_batches():
    rng = np.random.default_rng(0)
    d = rng.uniform(3, 5, (4, 7))
    e = rng.uniform(-1, 1, (4, 6))
    D, l = tridiagonal.ldl_tridiagonal(d, e)
    b = rng.normal(size=(4, 3, 7))
    x = tridiagonal.ldl_solve(D, l, b)
    for i in range(4):
        T = np.diag(d[i]) + np.diag(e[i], 1) + np.diag(e[i], -1)
        np.testing.assert_allclose(x[i], np.linalg.solve(T, b[i].T).T, rtol=1e-12)


def test_degenerate_slips_are_told_from_unique_ones():
    """Every block tight: the slips are unique only up to a rigid translation s 1 keeping
    every multiplier >= 0. Two blocks, block 1 at its forward limit with slip 1 and block 2
    at its backward limit with multiplier 0.5: s in [-1, 0.5] (not unique). With both
    multipliers 0 the interval is the point s = 0: unique."""
    poly = ChainPolyhedron(np.ones(1), 1.0)
    tol = certificate.Tolerance(1e-14, 1e-14)
    step = certificate.Step(np.zeros(1), np.array([1.0, 0.0, 0.0, 0.5]), poly.factor([0]), None)  # type: ignore[arg-type]
    assert poly.degenerate_slips(step, np.array([0, 3]), tol)
    step = certificate.Step(np.zeros(1), np.array([0.0, 0.0, 0.0, 0.0]), poly.factor([0]), None)  # type: ignore[arg-type]
    assert not poly.degenerate_slips(step, np.array([0, 3]), tol)


def exact_slips(poly, w_trial, c, index):
    """The slips of the equality system on ``index`` in rational arithmetic, from the same
    floating-point data: L_JJ dx_J = f_J - f*_J, f = D^T w_trial (module docstring of kkt)."""
    from fractions import Fraction

    N = poly.blocks
    blocks = [int(i) % N for i in index]
    order = np.argsort(blocks)
    J = [blocks[q] for q in order]
    rows = [int(index[q]) for q in order]
    k = [Fraction(float(v)) for v in poly.stiffness]
    w = [Fraction(0)] + [Fraction(float(v)) for v in w_trial] + [Fraction(0)]
    f = [w[i] - w[i + 1] for i in range(N)]
    rhs = [f[i] - (Fraction(float(c[r])) if r < N else -Fraction(float(c[r]))) for i, r in zip(J, rows)]
    diag = [(k[i - 1] if i > 0 else 0) + (k[i] if i < N - 1 else 0) for i in J]
    off = [-k[J[q]] if J[q + 1] == J[q] + 1 else Fraction(0) for q in range(len(J) - 1)]
    for q in range(1, len(J)):  # Thomas, exactly
        m = off[q - 1] / diag[q - 1]
        diag[q] -= m * off[q - 1]
        rhs[q] -= m * rhs[q - 1]
    dx = [Fraction(0)] * len(J)
    for q in range(len(J) - 1, -1, -1):
        dx[q] = (rhs[q] - (off[q] * dx[q + 1] if q < len(J) - 1 else 0)) / diag[q]
    lam = np.zeros(poly.m)
    for q, r in enumerate(rows):
        lam[r] = float(dx[q]) if r < N else -float(dx[q])
    return lam


@pytest.mark.parametrize("seed", range(4))
def test_row_dual_tolerances_bound_each_multiplier_and_follow_its_segment(seed):
    """Each active row's own dual tolerance (`ChainPolyhedron.row_tolerance`, compiled
    `chain.row_duals`) bounds the error of its multiplier against the rational solution of the
    same system, and on a chain whose stiffness spans 1e6 it is orders of magnitude below the
    scalar bound set by the stiffest link, where the kernel decides a soft segment's slip
    (tests/test_corpus.py: the seeds that exited 1 with the scalar bound). The compiled and
    numpy bounds are the same formula."""
    from crawlsim.kernel import chain

    poly, c, w_trial = chain_problem(seed, 30, 1e6, 1e3, 3.0)
    step = ExactProjector(poly).project(w_trial, c)
    A = step.active
    assert A.size >= 3
    _, lam, _, tol = poly.solve_on(A, w_trial, c)
    told = np.asarray(tol.dual)
    assert told.shape == (poly.m,)
    exact = exact_slips(poly, w_trial, c, A.index)
    idx = A.index
    assert np.all(np.abs(lam[idx] - exact[idx]) <= told[idx])
    scalar = float(np.max(told))  # inactive rows keep the scalar bound
    assert np.min(told[idx]) <= 1e-3 * scalar
    signs = np.zeros(poly.blocks, dtype=np.int8)
    signs[idx[idx < poly.blocks]] = 1
    signs[idx[idx >= poly.blocks] - poly.blocks] = -1
    w, lam_k, report, told_k = (np.empty(poly.n), np.empty(poly.m), np.zeros(6), np.empty(poly.m))
    status = chain.project_rows(
        poly.stiffness, poly.c_scale, w_trial, c, signs, np.zeros(poly.m, dtype=np.bool_), w, lam_k, report, told_k
    )
    assert status == chain.DONE
    np.testing.assert_allclose(told_k[idx], told[idx], rtol=1e-9)
