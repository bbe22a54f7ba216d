"""The certified KKT kernel: every projection step of every integrator is solved and certified here.

A step projects a trial point onto K = {w : B w <= c} in the metric M (docs/model.md §3):

    w* = argmin { 1/2 |w - w_trial|_M^2 : B w <= c }.

Its KKT conditions are necessary and sufficient (a strictly convex QP):

    M (w* - w_trial) + B^T lambda = 0,   B w* <= c,   lambda >= 0,   lambda_i (B w* - c)_i = 0.

On an active set A (rows with equality) they reduce to one linear system in lambda_A,

    G_A lambda_A = B_A w_trial - c_A,   G_A = B_A M^{-1} B_A^T,   w* = w_trial - M^{-1} B_A^T lambda_A,

which this module solves by a factorisation of G_A (LDL^T or Cholesky, never an explicit
inverse) and then *certifies*: primal feasibility, the sign of the multipliers and
complementarity, each to roundoff under one tolerance policy (`Polyhedron.tolerance`). A step
whose complementarity residual is above a quarter of its tolerance gets one step of iterative
refinement on that residual. Clarabel (`crawlsim.projection.adapter`) only proposes active sets; the
numbers of a step always come from here.

Two structures share the interface `Polyhedron` (`crawlsim.projection.polyhedron`):

* `ChainPolyhedron` (`crawlsim.projection.chain_polyhedron`), the crawler (docs/model.md §2):
  B = [D^T; -D^T] with D the (N-1) x N forward difference, M = K^{-1}; on A the system is the
  tridiagonal L_JJ dx_J = f_J - f*_J of the saturated blocks, O(N), and each multiplier gets
  its own componentwise dual tolerance;
* `DensePolyhedron` (`crawlsim.projection.dense_polyhedron`), a generic polyhedral process
  (docs/model.md §5): dense B and M, Cholesky of G_A, and LICQ decided by the conditioning of
  G_A.

The telescoped run of steps on a fixed active set (`Polyhedron.run`, the path of generic
processes) uses that after a step on A, B_A w = c_A, so the next k steps are

    w_{j+i} = w_j - M^{-1} B_A^T Lambda_i,   G_A Lambda_i = B_A w_j - c_A(t_{j+i}),

Lambda_i the cumulative multipliers: one factorisation and one multi-right-hand-side solve for a
whole run of steps, certified step by step in one vectorised pass. Crawlers step in the
compiled kernel (`crawlsim.kernel.chain`), single runs and sweeps' batches alike.

This module is the kernel's one name space: the tolerance policy and certificate records
(`crawlsim.projection.certificate`), the tridiagonal factorisation (`crawlsim.projection.tridiagonal`)
and the polyhedra above, re-exported.
"""

from crawlsim.kernel.policy import REFINE_FRACTION, RTOL, UPDATE_ITERATIONS
from crawlsim.projection.certificate import (
    CACHE_NUMBERS,
    GENERIC_RCOND,
    SMALL_CHAIN,
    Certificate,
    Dependent,
    Run,
    Step,
    Tolerance,
)
from crawlsim.projection.chain_polyhedron import ChainPolyhedron
from crawlsim.projection.dense_polyhedron import DensePolyhedron
from crawlsim.projection.polyhedron import ActiveSet, Polyhedron
from crawlsim.projection.tridiagonal import ldl_solve, ldl_tridiagonal

__all__ = [
    "CACHE_NUMBERS",
    "GENERIC_RCOND",
    "REFINE_FRACTION",
    "RTOL",
    "SMALL_CHAIN",
    "UPDATE_ITERATIONS",
    "ActiveSet",
    "Certificate",
    "ChainPolyhedron",
    "DensePolyhedron",
    "Dependent",
    "Polyhedron",
    "Run",
    "Step",
    "Tolerance",
    "ldl_solve",
    "ldl_tridiagonal",
]
