"""Symmetric tridiagonal LDL^T, vectorised over leading axes (chains, single and batched).

A crawler's KKT systems are principal submatrices of its tridiagonal stiffness Laplacian
(`crawlsim.projection.chain_polyhedron`): LDL^T without pivoting is backward stable for them (an
M-matrix), in numpy for short active sets and with LAPACK's ``dpttrf``/``dpttrs`` for long ones.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def ldl_tridiagonal(d: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """LDL^T of symmetric tridiagonal matrices: diagonal ``d`` (..., N), off-diagonal ``e``
    (..., N-1). Returns (D, l): the pivots and the subdiagonal of the unit factor."""
    D = np.array(d, dtype=float, copy=True)
    e = np.asarray(e, dtype=float)
    l = np.empty_like(e)
    for i in range(1, D.shape[-1]):
        l[..., i - 1] = e[..., i - 1] / D[..., i - 1]
        D[..., i] -= l[..., i - 1] * e[..., i - 1]
    return D, l


def ldl_solve(D: np.ndarray, l: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solve with an LDL^T factor for right-hand sides ``b`` (..., K, N) (K vectors per
    system; D and l broadcast as (..., 1, N))."""
    y = np.array(b, dtype=float, copy=True)
    N = y.shape[-1]
    lb = l[..., None, :]
    for i in range(1, N):
        y[..., i] -= lb[..., i - 1] * y[..., i - 1]
    y /= D[..., None, :]
    for i in range(N - 2, -1, -1):
        y[..., i] -= lb[..., i] * y[..., i + 1]
    return y


def _lapack() -> tuple[Any, Any]:
    """(dpttrf, dpttrs): LAPACK's tridiagonal LDL^T factor and solve (untyped wrappers)."""
    # Imported only for long chains: scipy.linalg costs start-up time the short runs don't need.
    from scipy.linalg.lapack import dpttrf, dpttrs

    return dpttrf, dpttrs
