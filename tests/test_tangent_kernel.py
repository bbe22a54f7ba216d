"""The compiled tangent walk (`crawlsim.kernel.tangent`) is one source: the compiled functions and
the same functions interpreted (`crawlsim.kernel.jit`) give the same bits on
the same inputs, for both integrators' walks, with parameters that move the offsets only (a
phase), the friction weights and the stiffness, across jumps of ``steps`` signals and hits.
The walks are loops of IEEE arithmetic in a fixed order (no BLAS, no fastmath), so nothing
may differ; the least-squares solve after them (`implicit`) agrees to roundoff.

Each form runs the gaits to their limit first; interpreted, the integrator's kernels reach the
same limit periods bit for bit (tests/test_kernel.py), so the walks start from the same records.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

import crawlsim
from crawlsim import api
from crawlsim.analysis import sensitivity as S
from crawlsim.analysis import sensitivity_terms as st
from crawlsim.analysis.sensitivity_walk import walk_catch_up, walk_exact
from crawlsim.kernel import jit

ROOT = Path(__file__).resolve().parents[1]

#: (gait file, integrator, parameter paths): every branch of the walks (hits, releases,
#: jumps of steps signals, a moving stiffness and friction).
CASES = [
    ("peristalsis-4", "exact", ["links.*.phase", "stiffness", "friction.forward"]),
    ("peristalsis-4", "catch-up", ["links.1.phase", "links.0.amplitude", "stiffness", "friction.backward"]),
    ("anchoring-2", "exact", ["links.0.values.1", "stiffness", "friction.0.forward.values.0"]),
    ("smooth-friction-3", "exact", ["links.1.phase", "stiffness.1", "friction.0.forward.amplitude"]),
]


def _walks() -> dict:
    """Each case run to its limit and walked, in the current form."""
    result = {}
    for name, integrator, paths in CASES:
        gait = crawlsim.load_gait(ROOT / "gaits" / f"{name}.yaml").replace(
            "simulation.integrator", integrator, "simulation.steps_per_period", 200
        )
        run = api.run(gait, history=False)
        lim = S._limit_of_run(gait, run.settled)
        co = st.coefficients_of(gait, lim.process)
        params = [st.parameter_of(gait, co, keys) for keys in S._expand(gait, paths)]
        dC, dMu, dk = S._stack(co, [p for p in params if p.dC is not None])
        walk = (walk_exact if integrator == "exact" else walk_catch_up)(lim, co, dC, dMu, dk)
        result[f"{name} {integrator}"] = {
            "W": walk.W.tolist(),
            "L": walk.L.tolist(),
            "D": walk.D.tolist(),
            "lam": walk.lam.tolist(),
            "dissipation": walk.dissipation,
            "w_end": walk.w_end.tolist(),
            "kinks": walk.kinks,
            "touches": [(m, t.tolist()) for m, t in walk.touches],
            "column_kinks": None if walk.column_kinks is None else walk.column_kinks.tolist(),
            "implicit": [
                np.asarray(x).tolist() for x in jit.kernel().implicit.implicit(walk.W, walk.L, walk.D, gait.blocks)
            ],
        }
    return result


def test_compiled_and_python_walks_agree_bit_for_bit():
    with jit.forced("compiled"):
        compiled = _walks()
    with jit.forced("python"):
        python = _walks()
    assert compiled.keys() == python.keys() and len(compiled) == len(CASES)
    for key in compiled:
        a, b = compiled[key], python[key]
        # the walks carry tangents: not all zero, and as many columns as n + p
        assert np.any(np.asarray(a["W"]) != 0.0) and np.any(np.asarray(a["D"]) != 0.0), key
        # the least-squares solve takes its SVD from LAPACK, which numba and numpy call through
        # different bindings: the same to roundoff (relative 1e-12), not bit for bit
        for x, y in zip(a.pop("implicit"), b.pop("implicit")):
            np.testing.assert_allclose(x, y, rtol=1e-12, atol=1e-14, err_msg=key)
        assert a == b, key
