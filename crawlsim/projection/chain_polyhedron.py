"""A crawler's polyhedron: B = [D^T; -D^T], M = K^{-1}, every operation O(N).

Row j < N is block j at its forward friction limit, row N + j the same block at its backward
limit; a block is never at both (mu^+ + mu^- > 0). Writing the slips dx = lambda^+ - lambda^-,
the KKT system on an active set A becomes

    L_JJ dx_J = f_J - f*_J,   L = D^T K D (the chain's stiffness Laplacian, tridiagonal),

with J the saturated blocks, f = D^T w their elastic forces and f* their friction limits
(+mu^+ or -mu^-). L_JJ is a principal submatrix of a tridiagonal M-matrix: it is tridiagonal
in block order, positive definite unless J is every block (L 1 = 0), and its inverse is
entrywise non-negative, so ||L_JJ^{-1}||_inf = max(L_JJ^{-1} 1) and each slip's roundoff has
a componentwise bound (`ChainPolyhedron.row_tolerance`). LICQ holds exactly when J is not every
block, which is also when the multipliers (the slips) are unique (docs/model.md §3; paper
Lemma lem:licqstar).
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
import numpy.typing as npt

from crawlsim.kernel.policy import RTOL
from crawlsim.projection.certificate import SMALL_CHAIN, Dependent, Floats, Step, Tolerance
from crawlsim.projection.polyhedron import ActiveSet, Polyhedron
from crawlsim.projection.tridiagonal import _lapack, ldl_solve, ldl_tridiagonal


class _ChainSet(ActiveSet):
    """G_A = S L_JJ S in block order (module docstring): L_JJ is tridiagonal, its free-block
    gaps splitting it into independent segments, factored once by LDL^T."""

    def __init__(self, poly: ChainPolyhedron, index: np.ndarray):
        N = poly.blocks
        self.index = index
        blocks = index % N
        order = np.argsort(blocks)
        self._order = order  # rows of A in block order
        self._signs = np.where(index < N, 1.0, -1.0)[order]
        J = blocks[order]
        d = poly.laplacian_diagonal[J]
        e = np.where(np.diff(J) == 1, -poly.stiffness[J[:-1]], 0.0)
        self._lapack = len(J) > SMALL_CHAIN
        if self._lapack:
            dpttrf, _ = _lapack()
            D, l, info = dpttrf(d, e)
            if info != 0:  # not positive definite: only when J is every block, refused earlier
                raise Dependent(index)
            self._D, self._l = D, l
        else:
            self._D, self._l = ldl_tridiagonal(d, e)
        # L_JJ is an M-matrix: its inverse is non-negative, so ||L_JJ^{-1}||_inf = max(L_JJ^{-1} 1)
        self.inverse_norm = float(np.max(self._solve_block(np.ones((1, len(J))))))
        self.gram_norm = float(np.max(2.0 * d))

    def _solve_block(self, rhs: np.ndarray) -> np.ndarray:
        """L_JJ^{-1} rhs for rhs (k, a) in block order (rows are right-hand sides)."""
        if not self._lapack:
            return ldl_solve(self._D, self._l, rhs)
        _, dpttrs = _lapack()
        x, info = dpttrs(self._D, self._l, rhs.T)
        return np.asarray(x).T

    def solve(self, R: np.ndarray) -> np.ndarray:
        R = np.asarray(R, dtype=float)
        flat = R.reshape(-1, self.size)
        y = self._solve_block(flat[:, self._order] * self._signs) * self._signs
        out = np.empty_like(flat)
        out[:, self._order] = y
        return out.reshape(R.shape)


class ChainPolyhedron(Polyhedron):
    """A crawler of N blocks with link stiffnesses k (module docstring): B = [D^T; -D^T],
    M = K^{-1}. Nothing of size N^2 is ever formed."""

    def __init__(self, stiffness: npt.ArrayLike, c_scale: float):
        super().__init__()
        k: Floats = np.asarray(stiffness, dtype=float)
        self.stiffness = k
        self.blocks = len(k) + 1
        self.n = len(k)
        self.m = 2 * self.blocks
        diag = np.zeros(self.blocks)
        diag[:-1] += k
        diag[1:] += k
        self.laplacian_diagonal = diag  # L_jj = k_{j-1} + k_j
        self.row_norm = 2.0
        self.response_norm = 2.0 * float(np.max(k))
        self.c_scale = c_scale if c_scale > 0 else 1.0

    def forces(self, W: np.ndarray) -> np.ndarray:
        """f = D^T w (..., N): f_j = w_{j-1} - w_j with w_{-1} = w_{N-1} = 0."""
        W = np.asarray(W, dtype=float)
        f = np.empty(W.shape[:-1] + (self.blocks,))
        f[..., 0] = -W[..., 0]
        f[..., 1:-1] = W[..., :-1] - W[..., 1:]
        f[..., -1] = W[..., -1]
        return f

    def apply(self, W: np.ndarray) -> np.ndarray:
        W = np.asarray(W, dtype=float)
        N = self.blocks
        out = np.empty(W.shape[:-1] + (2 * N,))
        f = out[..., :N]
        f[..., 0] = W[..., 0]
        f[..., 1 : N - 1] = W[..., 1:]
        f[..., 1 : N - 1] -= W[..., :-1]
        f[..., N - 1] = -W[..., -1]
        out[..., N:] = f  # rows N.. are -f; rows ..N are f = D^T w
        np.negative(f, out=f)
        return out

    def respond(self, LAM: np.ndarray) -> np.ndarray:
        LAM = np.asarray(LAM, dtype=float)
        N = self.blocks
        dx: Floats = LAM[..., :N] - LAM[..., N:]
        return (dx[..., 1:] - dx[..., :-1]) * self.stiffness

    def licq(self, index: npt.ArrayLike) -> bool:
        blocks = np.asarray(index, dtype=int) % self.blocks
        return len(np.unique(blocks)) == len(blocks) and len(blocks) < self.blocks

    def _factor(self, index: np.ndarray) -> ActiveSet:
        return _ChainSet(self, index)

    def dependency(self, index: np.ndarray) -> np.ndarray | None:
        """Every block saturated: B^T lambda = D (lambda^+ - lambda^-) vanishes for slips
        dx = 1, that is lambda = S 1 (the signs of the rows)."""
        index = np.asarray(index, dtype=int)
        if self.licq(index):
            return None
        blocks = index % self.blocks
        if len(np.unique(blocks)) < len(blocks):  # a block at both limits: opposite normals
            z = np.zeros(len(index))
            dup = blocks == blocks[-1]
            z[dup] = 1.0
            return z
        return np.where(index < self.blocks, 1.0, -1.0)

    def tight_stop(self, tight: np.ndarray, any_inactive: np.ndarray) -> np.ndarray:
        """LICQ of a chain's tight rows fails only with every block tight (module docstring)."""
        N = self.blocks
        stop: np.ndarray = np.asarray(any_inactive) & (tight[:, :N] | tight[:, N:]).all(axis=1)
        return stop

    def degenerate_slips(self, step: Step, tight: np.ndarray, tol: Tolerance) -> bool:
        """Every block tight: the slips are unique only up to a rigid translation s 1, with s
        in the interval keeping every tight multiplier non-negative (lambda + s S 1 >= 0);
        they are determined exactly when that interval is a point (to roundoff)."""
        blocks = tight % self.blocks
        if len(np.unique(blocks)) < self.blocks:
            return False
        signs = np.where(tight < self.blocks, 1.0, -1.0)
        lam = step.multipliers[tight]
        upper = np.min(lam[signs < 0], initial=np.inf)  # s <= lam_j for s_j = -1
        lower = -np.min(lam[signs > 0], initial=np.inf)  # s >= -lam_j for s_j = +1
        return bool(upper - lower > float(np.max(tol.dual)))

    def row_tolerance(
        self, active: ActiveSet, w_trial: np.ndarray, c: np.ndarray, lam: np.ndarray, tol: Tolerance
    ) -> Tolerance:
        """Each active row's own dual tolerance, the componentwise bound of
        `crawlsim.kernel.chain.row_duals` (same formula, numpy): with L_JJ^{-1} >= 0,

            |dx - dx*|_i <= 2 RTOL (L_JJ^{-1} s)_i,
            s = |f| + |f*| + c_scale max(k_{i-1}, k_i) / max k + |w_{i-1}| + |w_i| + |L_JJ| |dx|,

        capped by the scalar bound; inactive rows keep the scalar one."""
        if not active.size:
            return tol
        N = self.blocks
        idx = active.index
        blocks = idx % N
        sign = np.where(idx < N, 1.0, -1.0)
        absdx = np.zeros(N + 2)
        absdx[blocks + 1] = np.abs(lam[idx])
        kpad = np.concatenate([[0.0], self.stiffness, [0.0]])
        wpad = np.abs(np.concatenate([[0.0], np.asarray(w_trial, dtype=float), [0.0]]))
        left, right = kpad[blocks], kpad[blocks + 1]
        floor = self.c_scale * np.maximum(left, right) / float(np.max(self.stiffness))
        s = (
            2.0 * (wpad[blocks] + wpad[blocks + 1])
            + np.abs(c[idx])
            + floor
            + (left + right) * absdx[blocks + 1]
            + left * absdx[blocks]
            + right * absdx[blocks + 2]
        )
        y = sign * active.solve(sign * s)
        told = np.full(self.m, float(tol.dual))
        told[idx] = np.minimum(2.0 * RTOL * y, float(tol.dual))
        return Tolerance(tol.primal, told)

    def metric_times(self, w: np.ndarray) -> np.ndarray:
        return np.asarray(w, dtype=float) / self.stiffness

    def metric_solve(self, v: np.ndarray) -> np.ndarray:
        return np.asarray(v, dtype=float) * self.stiffness

    def metric_root(self, v: np.ndarray) -> np.ndarray:
        return np.asarray(v, dtype=float) / np.sqrt(self.stiffness)

    def metric_root_transpose(self, v: np.ndarray) -> np.ndarray:
        return np.asarray(v, dtype=float) / np.sqrt(self.stiffness)

    def dense_normals(self) -> np.ndarray:
        return _dense_normals(self.blocks).copy()

    def dense_metric(self) -> np.ndarray:
        return np.diag(1.0 / self.stiffness)

    def sparse_normals(self) -> Any:
        import scipy.sparse as sp

        N, n = self.blocks, self.n
        i = np.arange(n)
        # D^T: row j has +1 at column j-1 and -1 at column j
        rows = np.concatenate([i + 1, i])
        cols = np.concatenate([i, i])
        vals = np.concatenate([np.ones(n), -np.ones(n)])
        Dt = sp.csr_matrix((vals, (rows, cols)), shape=(N, n))
        return sp.vstack([Dt, -Dt]).tocsc()

    def clarabel_matrices(self) -> tuple[Any, Any]:
        import scipy.sparse as sp

        return sp.diags(1.0 / self.stiffness, format="csc"), self.sparse_normals()


@functools.lru_cache(maxsize=8)
def _dense_normals(N: int) -> np.ndarray:
    """B = [D^T; -D^T] of a chain of N blocks, dense (2N, N - 1); kept for the sizes last seen,
    callers get a copy."""
    D = np.diff(np.eye(N), axis=0)
    return np.vstack([D.T, -D.T])
