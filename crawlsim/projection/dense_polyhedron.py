"""A generic polyhedral sweeping process (docs/model.md §5): dense B and M, Cholesky of
G_A = B_A M^{-1} B_A^T, and LICQ decided by the conditioning of G_A (`GENERIC_RCOND`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from crawlsim.projection.certificate import GENERIC_RCOND, Dependent, Floats
from crawlsim.projection.polyhedron import ActiveSet, Polyhedron


class _DenseSet(ActiveSet):
    def __init__(self, poly: DensePolyhedron, index: np.ndarray):
        self.index = index
        if len(index) > poly.n:
            raise Dependent(index)
        G = poly.normals[index] @ poly.minv_bt[:, index]
        s = np.linalg.svd(G, compute_uv=False)
        if not s[-1] > GENERIC_RCOND * s[0]:
            raise Dependent(index)
        self._chol = np.linalg.cholesky(G)
        self.inverse_norm = float(math.sqrt(len(index)) / s[-1])
        self.gram_norm = float(np.max(np.sum(np.abs(G), axis=1)))

    def solve(self, R: np.ndarray) -> np.ndarray:
        from scipy.linalg import cho_solve

        R = np.asarray(R, dtype=float)
        flat = R.reshape(-1, self.size).T
        out: np.ndarray = cho_solve((self._chol, True), flat).T.reshape(R.shape)
        return out


class DensePolyhedron(Polyhedron):
    """A generic polyhedral sweeping process: dense normals B (m, n) and metric M (n, n)."""

    def __init__(self, normals: npt.ArrayLike, metric: npt.ArrayLike, c_scale: float):
        super().__init__()
        self.normals: Floats = np.ascontiguousarray(normals, dtype=float)
        self.metric: Floats = np.ascontiguousarray(metric, dtype=float)
        self.m, self.n = self.normals.shape
        self.metric_inv: Floats = np.linalg.inv(self.metric)  # n x n, once: a constant of the problem
        self.minv_bt = self.metric_inv @ self.normals.T
        self.row_norm = float(np.max(np.sum(np.abs(self.normals), axis=1), initial=1.0))
        self.response_norm = float(np.max(np.sum(np.abs(self.minv_bt), axis=1), initial=1.0))
        self.c_scale = c_scale if c_scale > 0 else 1.0

    def apply(self, W: np.ndarray) -> np.ndarray:
        return np.asarray(W, dtype=float) @ self.normals.T

    def respond(self, LAM: np.ndarray) -> np.ndarray:
        return np.asarray(LAM, dtype=float) @ self.minv_bt.T

    def licq(self, index: npt.ArrayLike) -> bool:
        index = np.asarray(index, dtype=int)
        if len(index) == 0:
            return True
        if len(index) > self.n:
            return False
        G = self.normals[index] @ self.minv_bt[:, index]
        s = np.linalg.svd(G, compute_uv=False)
        return bool(s[-1] > GENERIC_RCOND * s[0])

    def _factor(self, index: np.ndarray) -> ActiveSet:
        return _DenseSet(self, index)

    def _numbers(self, size: int) -> int:
        return size * size + 8

    def metric_times(self, w: np.ndarray) -> np.ndarray:
        return np.asarray(w, dtype=float) @ self.metric.T

    def metric_solve(self, v: np.ndarray) -> np.ndarray:
        return np.asarray(v, dtype=float) @ self.metric_inv.T

    def metric_root(self, v: np.ndarray) -> np.ndarray:
        return np.asarray(v, dtype=float) @ self._root  # rows v -> (L^T v)^T = v^T L

    def metric_root_transpose(self, v: np.ndarray) -> np.ndarray:
        return np.asarray(v, dtype=float) @ self._root.T

    @property
    def _root(self) -> Floats:
        """L with M = L L^T (Cholesky)."""
        cached = getattr(self, "_root_cache", None)
        if cached is None:
            cached = np.linalg.cholesky(self.metric)
            self._root_cache = cached
        return cached

    def dense_normals(self) -> np.ndarray:
        return self.normals

    def dense_metric(self) -> np.ndarray:
        return self.metric

    def clarabel_matrices(self) -> tuple[Any, Any]:
        import scipy.sparse as sp

        return sp.csc_matrix(np.triu(self.metric)), sp.csc_matrix(self.normals)
