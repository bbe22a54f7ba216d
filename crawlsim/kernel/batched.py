"""Batched telescoped runs for crawlers of one block count (`crawlsim.integrate.batch`).

The run of steps on a fixed active set of `crawlsim.kernel.polyhedron.Polyhedron.run`, for a
batch of gaits at once: after a step on A, B_A w = c_A, so the next k steps are

    w_{j+i} = w_j - M^{-1} B_A^T Lambda_i,   G_A Lambda_i = B_A w_j - c_A(t_{j+i}),

Lambda_i the cumulative multipliers, with one padded LDL^T per gait, certified step by step
under the tolerance policy of `crawlsim.kernel.certificate`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crawlsim.kernel.certificate import REFINE_FRACTION, RTOL, UPDATE_ITERATIONS
from crawlsim.kernel.tridiagonal import ldl_solve, ldl_tridiagonal


@dataclass(frozen=True, eq=False)
class ChainFactors:
    """Padded LDL^T factors of the active sets of a batch of crawlers (each row one gait):
    ``signs`` (b, N) +1 forward limit, -1 backward limit, 0 free."""

    signs: np.ndarray
    D: np.ndarray
    l: np.ndarray
    inverse_norm: np.ndarray  # (b,) ||G_A^{-1}||_inf
    gram_norm: np.ndarray  # (b,)


def chain_factors(stiffness: np.ndarray, signs: np.ndarray) -> ChainFactors:
    """Factor the padded systems L~ of gaits with stiffnesses (b, N-1) and active signs
    (b, N). No gait may have every block active (LICQ; the caller checks)."""
    k = np.asarray(stiffness, dtype=float)
    signs = np.asarray(signs, dtype=float)
    diag = np.zeros(signs.shape)
    diag[:, :-1] += k
    diag[:, 1:] += k
    active = signs != 0
    d = np.where(active, diag, 1.0)
    e = np.where(active[:, :-1] & active[:, 1:], -k, 0.0)
    D, l = ldl_tridiagonal(d, e)
    y = ldl_solve(D, l, active[:, None, :].astype(float))[:, 0, :]
    inverse_norm = np.max(np.where(active, y, 0.0), axis=1)
    gram_norm = np.max(np.where(active, 2.0 * diag, 0.0), axis=1)
    return ChainFactors(signs, D, l, inverse_norm, gram_norm)


@dataclass(frozen=True, eq=False)
class ChainRuns:
    """Telescoped runs of a batch of crawlers (`run_chains`): per gait b and step i."""

    w: np.ndarray  # (b, K, n)
    multipliers: np.ndarray  # (b, K, 2N), each step's
    slack: np.ndarray  # (b, K, 2N), B w - c
    primal_tolerance: np.ndarray  # (b, K)
    dual_tolerance: np.ndarray  # (b, K)
    ok: np.ndarray  # (b, K) the step's certificate holds
    stop: np.ndarray  # (b, K) every block tight to roundoff: LICQ fails, the full step decides


def chain_apply(W: np.ndarray) -> np.ndarray:
    """B w = [D^T w; -D^T w] for states (..., N-1) of crawlers."""
    padded = np.zeros(W.shape[:-1] + (W.shape[-1] + 2,))
    padded[..., 1:-1] = W
    f = padded[..., :-1] - padded[..., 1:]
    return np.concatenate([f, -f], axis=-1)


def chain_respond(stiffness: np.ndarray, LAM: np.ndarray) -> np.ndarray:
    """M^{-1} B^T lambda = K D (lambda^+ - lambda^-) for multipliers (b, ..., 2N) and
    stiffnesses (b, N-1)."""
    N = LAM.shape[-1] // 2
    dx = LAM[..., :N] - LAM[..., N:]
    k = stiffness.reshape(stiffness.shape[:1] + (1,) * (LAM.ndim - 2) + stiffness.shape[1:])
    return (dx[..., 1:] - dx[..., :-1]) * k


def run_chains(stiffness: np.ndarray, factors: ChainFactors, w: np.ndarray, C: np.ndarray,
               c_scale: np.ndarray) -> ChainRuns:
    """Telescoped runs of a batch: gait b steps from w[b] to the offsets C[b] (b, K, 2N) on its
    own fixed active set, certified with the tolerance policy of `Polyhedron.tolerance`
    (||B|| = 2, ||M^{-1} B^T|| = 2 max k for a chain)."""
    N = factors.signs.shape[1]
    s = factors.signs[:, None, :]
    active = s != 0
    F = chain_apply(w)[:, None, :N]
    target = np.where(s > 0, C[..., :N], -C[..., N:])  # the friction limit force f*
    rhs = np.where(active, F - target, 0.0)  # S r = f - f* on the saturated blocks
    dx = ldl_solve(factors.D, factors.l, rhs)  # cumulative slips (0 on free blocks)
    mask = np.concatenate([s > 0, s < 0], axis=-1)

    def state(dx):
        LAMC = np.concatenate([np.where(s > 0, dx, 0.0), np.where(s < 0, -dx, 0.0)], axis=-1)
        W = w[:, None, :] - chain_respond(stiffness, LAMC)
        return LAMC, W, chain_apply(W) - C

    LAMC, W, slack = state(dx)
    c_size = np.max(np.abs(C), axis=-1)
    lam_size = np.max(np.abs(LAMC), axis=-1)
    kmax = np.max(stiffness, axis=-1)[:, None]
    size = np.maximum(np.maximum(np.maximum(c_scale[:, None], c_size),
                                 2.0 * np.max(np.abs(W), axis=-1)), 4.0 * kmax * lam_size)
    tolp = RTOL * size
    told = 2.0 * RTOL * factors.inverse_norm[:, None] * (size + factors.gram_norm[:, None] * lam_size)
    comp = np.max(np.where(mask, np.abs(slack), 0.0), axis=-1)
    redo = comp > REFINE_FRACTION * tolp
    if redo.any():  # one step of iterative refinement on B_A w - c_A, where needed
        res = np.where(s > 0, slack[..., :N], np.where(s < 0, -slack[..., N:], 0.0))
        dx = dx + ldl_solve(factors.D, factors.l, res) * redo[..., None]
        LAMC, W, slack = state(dx)
        comp = np.max(np.where(mask, np.abs(slack), 0.0), axis=-1)
    LAM = np.diff(LAMC, axis=1, prepend=np.zeros_like(LAMC[:, :1]))
    primal = np.max(slack, axis=-1)
    dual = -np.min(np.where(mask, LAM, np.inf), axis=-1)
    dual = np.where(np.isfinite(dual), dual, 0.0)
    ok = (primal <= tolp) & (dual <= told) & (comp <= tolp)
    tight = (slack >= -tolp[..., None]) | mask
    stop = (tight[..., :N] | tight[..., N:]).all(axis=-1)
    return ChainRuns(W, LAM, slack, tolp, told, ok, stop)


def refine_chains(stiffness: np.ndarray, signs: np.ndarray, w: np.ndarray, c: np.ndarray,
                  c_scale: np.ndarray, iterations: int = UPDATE_ITERATIONS):
    """One step of each gait of a batch (w (b, n) to c (b, 2N)) by the primal-dual active-set
    updates of `Polyhedron.refine`, vectorised, from the active signs (b, N).

    Returns (w, multipliers, signs, certified): the rows of gaits that did not settle (or
    reached a set with every block saturated, or a tight set failing LICQ) are not certified and
    go to their own projector."""
    b, N = signs.shape
    w_out = np.array(w, dtype=float, copy=True)
    lam_out = np.zeros((b, 2 * N))
    signs = np.array(signs, dtype=float, copy=True)
    done = np.zeros(b, dtype=bool)
    todo = np.arange(b)
    for _ in range(iterations):
        full = (signs[todo] != 0).all(axis=1)
        todo = todo[~full]
        if not todo.size:
            break
        f = chain_factors(stiffness[todo], signs[todo])
        runs = run_chains(stiffness[todo], f, w[todo], c[todo][:, None, :], c_scale[todo])
        ok = runs.ok[:, 0] & ~runs.stop[:, 0]
        good = todo[ok]
        w_out[good], lam_out[good], done[good] = runs.w[ok, 0], runs.multipliers[ok, 0], True
        bad = ~runs.ok[:, 0]  # certified with every block tight: the projector decides LICQ
        if not bad.any():
            break
        lam, slack = runs.multipliers[bad, 0], runs.slack[bad, 0]
        tolp, told = runs.primal_tolerance[bad, 0][:, None], runs.dual_tolerance[bad, 0][:, None]
        new = signs[todo[bad]]
        drop = ((lam[:, :N] < -told) & (new > 0)) | ((lam[:, N:] < -told) & (new < 0))
        new[drop] = 0.0
        kept = new.copy()
        new[slack[:, :N] > tolp] = 1.0
        new[slack[:, N:] > tolp] = -1.0
        # adding every violated row may saturate every block (LICQ fails): add the worst only
        full = (new != 0).all(axis=1)
        if full.any():
            worst = np.argmax(slack[full], axis=1)
            rows_full = np.flatnonzero(full)
            new[full] = kept[full]
            new[rows_full, worst % N] = np.where(worst < N, 1.0, -1.0)
        unchanged = (new == signs[todo[bad]]).all(axis=1)
        signs[todo[bad]] = new
        todo = todo[bad][~unchanged]
    return w_out, lam_out, signs, done
