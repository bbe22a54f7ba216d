"""The exact projection: KKT certificates on random polytopes, and refusals.

For the convex QP min 1/2 |z - z_trial|_M^2 s.t. B z <= c, the KKT conditions
M (z - z_trial) + B^T lambda = 0, B z <= c, lambda >= 0, lambda_i (B z - c)_i = 0 are necessary
and sufficient, so checking them independently of the projector proves the answer optimal.
"""

from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from crawlsim.errors import CertificateError, DegenerateModelError
from crawlsim.projection.adapter import ExactProjector


@st.composite
def polytopes(draw):
    n = draw(st.integers(1, 4))
    m = draw(st.integers(n + 1, 3 * n + 3))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    B = rng.normal(size=(m, n))
    center = rng.normal(size=n)
    c = B @ center + rng.uniform(0.05, 2.0, size=m)  # nonempty: contains `center`
    A = rng.normal(size=(n, n))
    M = A @ A.T + 0.5 * np.eye(n)
    z_trial = center + rng.normal(scale=draw(st.sampled_from([0.1, 1.0, 10.0])), size=n)
    return B, c, M, z_trial


@settings(max_examples=150, deadline=None)
@given(polytopes())
def test_projection_satisfies_kkt(problem):
    B, c, M, z_trial = problem
    proj = ExactProjector.dense(B, M, float(np.max(np.abs(c)))).project(z_trial, c)
    z, lam = proj.point, proj.multipliers
    scale = max(1.0, float(np.max(np.abs(c))), float(np.max(np.abs(z_trial))))
    slack = B @ z - c
    assert np.max(slack) <= 1e-12 * scale  # primal feasibility
    assert np.min(lam) >= -1e-12 * scale  # dual sign
    assert np.max(np.abs(lam * slack)) <= 1e-11 * scale**2  # complementarity
    stationarity = M @ (z - z_trial) + B.T @ lam
    assert np.max(np.abs(stationarity)) <= 1e-11 * scale * max(1.0, np.max(np.abs(M)))
    # inactive constraints carry exactly zero multiplier
    inactive = np.setdiff1d(np.arange(len(c)), proj.active.index)
    assert np.all(lam[inactive] == 0.0)


@settings(max_examples=60, deadline=None)
@given(polytopes())
def test_projection_is_idempotent_and_the_fast_formula_agrees(problem):
    B, c, M, z_trial = problem
    projector = ExactProjector.dense(B, M, float(np.max(np.abs(c))))
    first = projector.project(z_trial, c)
    again = projector.project(first.point, c)
    assert np.allclose(again.point, first.point, atol=1e-12, rtol=0)
    assert np.max(np.abs(again.multipliers)) <= 1e-10
    z, lam, _, _ = projector.polyhedron.solve_on(first.active, z_trial, c)
    assert np.array_equal(z, first.point) and np.array_equal(lam, first.multipliers)


def test_dependent_active_normals_fail_with_a_message():
    """Three constraints through one vertex of the plane: the multipliers are not unique."""
    B = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    c = np.zeros(3)
    projector = ExactProjector.dense(B, np.eye(2), 1.0)
    with pytest.raises(DegenerateModelError, match=r"\{0, 1, 2\} are linearly dependent at t = 0.25"):
        projector.project(np.array([1.0, 1.0]), c, time=0.25)


def test_empty_set_is_an_error_not_a_step():
    B = np.array([[1.0], [-1.0]])
    c = np.array([-1.0, -1.0])  # z <= -1 and z >= 1
    with pytest.raises(CertificateError, match="Clarabel could not solve"):
        ExactProjector.dense(B, np.eye(1), 1.0).project(np.array([0.0]), c)


def test_persistent_and_fresh_solvers_agree():
    rng = np.random.default_rng(3)
    B = rng.normal(size=(6, 3))
    c = B @ np.zeros(3) + 1.0
    a = ExactProjector.dense(B, np.eye(3), 1.0)
    b = ExactProjector.dense(B, np.eye(3), 1.0, persistent=False)
    for _ in range(20):
        z = rng.normal(scale=3, size=3)
        pa, pb = a.project(z, c), b.project(z, c)
        assert np.array_equal(pa.point, pb.point)


class _Stale:
    """A persistent Clarabel solver whose updates leave it stalled: every solve refused
    (status DualInfeasible), as rough seed 7388's was on a Newton candidate of its limit search
    (tests/test_breakpoints.py), where a solver set up on the same data solved it."""

    def __init__(self, solver):
        self.solver = solver

    def update(self, **data):
        self.solver.update(**data)

    def solve(self):
        import clarabel

        solution = self.solver.solve()
        return SimpleNamespace(status=clarabel.SolverStatus.DualInfeasible, z=solution.z, s=solution.s)


def test_a_refused_solve_of_an_updated_solver_is_solved_again_from_a_fresh_set_up():
    """An updated solver keeps the scaling it equilibrated for its first data; a refusal of
    its solve is no verdict on a projection (its set is not empty, and M > 0 bounds the
    objective): the projection is solved again by a solver set up on its data, and is the one
    a fresh solver gives. A set that is empty is still refused after the second solve."""
    B = np.random.default_rng(3).normal(size=(3, 3))
    B = np.vstack([B, -B])  # |B_i w| <= c_i: bounded
    c = np.ones(6)
    projector = ExactProjector.dense(B, np.eye(3), 1.0)
    fresh = ExactProjector.dense(B, np.eye(3), 1.0, persistent=False)
    z = 5.0 * B[0]  # outside: Clarabel proposes
    assert projector.project(z, c).used_clarabel
    stale = projector._solver = _Stale(projector._solver)
    z = -5.0 * B[1]
    proj = projector.project(z, c)
    assert proj.used_clarabel and projector._solver is not stale
    assert np.array_equal(proj.point, fresh.project(z, c).point)
    projector._solver = _Stale(projector._solver)
    with pytest.raises(CertificateError, match="Clarabel could not solve"):
        projector.project(z, -c)  # B_0 w <= -1 and B_0 w >= 1
