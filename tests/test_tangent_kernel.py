"""The compiled tangent walk (`crawlsim.kernel.tangent`) is one source: the compiled functions and
the same functions run as Python (``NUMBA_DISABLE_JIT=1``, in a subprocess) give the same bits on
the same inputs, for both integrators' walks, with parameters that move the offsets only (a
phase), the friction weights and the stiffness, across jumps of ``steps`` signals and hits.
The walks are loops of IEEE arithmetic in a fixed order (no BLAS, no fastmath), so nothing
may differ; the least-squares solve after them (`implicit`) agrees to roundoff.

Each subprocess runs the gaits to their limit first; with the JIT disabled the integrator's
kernels run as Python too, and reach the same limit periods bit for bit
(tests/test_kernel.py), so the walks start from the same records.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

#: (gait file, integrator, parameter paths): every branch of the walks (hits, releases,
#: jumps of steps signals, a moving stiffness and friction).
CASES = [
    ("peristalsis-4", "exact", ["links.*.phase", "stiffness", "friction.forward"]),
    ("peristalsis-4", "catch-up", ["links.1.phase", "links.0.amplitude", "stiffness", "friction.backward"]),
    ("anchoring-2", "exact", ["links.0.values.1", "stiffness", "friction.0.forward.values.0"]),
    ("smooth-friction-3", "exact", ["links.1.phase", "stiffness.1", "friction.0.forward.amplitude"]),
]

WALKS = r"""
import json, sys
import numpy as np
import crawlsim
from crawlsim import api
from crawlsim.analysis import sensitivity as S, sensitivity_terms as st
from crawlsim.analysis.sensitivity_walk import walk_catch_up, walk_exact
from crawlsim.kernel.implicit import implicit

cases, out = json.loads(sys.argv[1]), sys.argv[2]
result = {}
for name, integrator, paths in cases:
    gait = crawlsim.load_gait(f"gaits/{name}.yaml").replace(
        "simulation.integrator", integrator, "simulation.steps_per_period", 200)
    run = api.run(gait, history=False)
    lim = S._limit_of_run(gait, run.settled)
    co = st.coefficients_of(gait, lim.process)
    params = [st.parameter_of(gait, co, keys) for keys in S._expand(gait, paths)]
    dC, dMu, dk = S._stack(co, [p for p in params if p.dC is not None])
    walk = (walk_exact if integrator == "exact" else walk_catch_up)(lim, co, dC, dMu, dk)
    result[f"{name} {integrator}"] = {
        "W": walk.W.tolist(), "L": walk.L.tolist(), "D": walk.D.tolist(),
        "lam": walk.lam.tolist(), "dissipation": walk.dissipation,
        "w_end": walk.w_end.tolist(), "kinks": walk.kinks,
        "touches": [(m, t.tolist()) for m, t in walk.touches],
        "column_kinks": None if walk.column_kinks is None else walk.column_kinks.tolist(),
        "implicit": [np.asarray(x).tolist() for x in implicit(walk.W, walk.L, walk.D,
                                                              gait.blocks)]}
with open(out, "w") as f:
    json.dump(result, f)
"""


def _walks(out: Path, disable_jit: bool) -> dict:
    env = dict(os.environ)
    env.pop("NUMBA_DISABLE_JIT", None)
    if disable_jit:
        env["NUMBA_DISABLE_JIT"] = "1"
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    subprocess.run(
        [sys.executable, "-c", WALKS, json.dumps(CASES), str(out)],
        check=True,
        env=env,
        cwd=ROOT,
        capture_output=True,
        timeout=900,
    )
    return json.loads(out.read_text())


def test_compiled_and_python_walks_agree_bit_for_bit(tmp_path):
    compiled = _walks(tmp_path / "compiled.json", disable_jit=False)
    python = _walks(tmp_path / "python.json", disable_jit=True)
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
