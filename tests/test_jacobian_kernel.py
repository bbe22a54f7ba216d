"""The compiled products of the period map's Jacobian (`crawlsim.kernel.jacobian`, packed by
`crawlsim.integrate.limit.packed_jacobian`) are J v and J^T v of the factors visited in a period:
they agree with the numpy products factor by factor (`apply_jacobian`,
`apply_jacobian_transpose`) to 1e-12 relative on random vectors, for periods with projectors
only (catch-up) and with saltations (exact, hits that swap the active set), on uniform and
random stiffness; and the compiled functions and the same source run as Python
(`crawlsim.kernel.jit`'s two forms, on the same packed arrays) give the same bits: they
are loops of IEEE arithmetic in a fixed order.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from crawlsim.gait.corpus import random_gait
from crawlsim.gait.document import gait_from_document
from crawlsim.integrate.limit import (
    PackedJacobian,
    Saltation,
    apply_jacobian,
    apply_jacobian_transpose,
    factors,
    newton_step,
    packed_jacobian,
)
from crawlsim.integrate.stepping import make_stepper
from crawlsim.kernel import jit
from crawlsim.model.process import compile as compile_gait

ROOT = Path(__file__).resolve().parents[1]


def wave_document(N: int, steps: int, segments: bool) -> dict:
    """The retrograde cosine wave of scripts/bench-scale.py: phase i/(N-1) ("body") or
    (i/10) mod 1 ("segments", the 1000-block run's gait)."""
    return {
        "name": f"wave-{N}",
        "blocks": N,
        "period": 1.0,
        "stiffness": 10.0,
        "links": [
            {"kind": "cosine", "mean": 1.0, "amplitude": 0.3, "phase": (i / 10) % 1 if segments else i / (N - 1)}
            for i in range(N - 1)
        ],
        "friction": {"forward": 1.0, "backward": 2.13},
        "simulation": {"steps_per_period": steps},
    }


#: name -> (process, integrator, periods stepped before the period whose factors are taken)
CASES = {
    "wave-10 exact": (lambda: compile_gait(gait_from_document(wave_document(10, 100, False), "w")), "exact", 3),
    "wave-10 catch-up": (lambda: compile_gait(gait_from_document(wave_document(10, 100, False), "w")), "catch-up", 3),
    "segments-64 exact": (lambda: compile_gait(gait_from_document(wave_document(64, 100, True), "s")), "exact", 2),
    "random-236 exact": (lambda: compile_gait(random_gait(236, blocks=(2, 16)), 1000), "exact", 5),
    "random-237 exact": (lambda: compile_gait(random_gait(237, blocks=(2, 12)), 1000), "exact", 2),
}


@pytest.fixture(scope="module")
def periods():
    """The factors of one period of every case (after a few periods towards its limit)."""
    out = {}
    for name, (make, integrator, warm) in CASES.items():
        process = make()
        stepper = make_stepper(process, integrator)
        for _ in range(warm):
            record = stepper.step_period()
        out[name] = process, factors(process, record)
    return out


@pytest.mark.parametrize("name", list(CASES))
def test_compiled_products_are_the_numpy_products(periods, name):
    process, fs = periods[name]
    poly = process.polyhedron
    packed = packed_jacobian(poly, fs)
    assert isinstance(packed, PackedJacobian)
    salts = sum(isinstance(f, Saltation) for f in fs)
    # the exact periods carry saltations (their hits swap the set), catch-up none
    assert (salts > 0) == name.endswith("exact")
    assert len(fs) - salts > 0 and packed.blocks.size > 0
    V = np.random.default_rng(3).standard_normal((5, poly.n))
    for v in V:
        for compiled, numpy_ in (
            (packed.apply(v), apply_jacobian(poly, fs, v)),
            (packed.apply_transpose(v), apply_jacobian_transpose(poly, fs, v)),
        ):
            assert np.linalg.norm(compiled - numpy_) <= 1e-12 * np.linalg.norm(numpy_)
        # <J v, u> = <v, J^T u>: the two products are each other's transposes
        u = V[0]
        assert packed.apply(v) @ u == pytest.approx(v @ packed.apply_transpose(u), rel=1e-12)
    # neighbouring projectors of nested sets are merged: the product above is the same
    if name == "segments-64 exact":
        assert len(packed.kinds) < len(fs) / 2
    # J is not the identity (the test could not tell the products apart otherwise)
    assert np.linalg.norm(packed.apply(V[1]) - V[1]) > 1e-3 * np.linalg.norm(V[1])


def test_projectors_of_nested_sets_merge_into_the_larger():
    """P_A' P_A = P_A P_A' = P_A' where the blocks of A lie within those of A' (M-orthogonal
    projectors onto null B_A' within null B_A), also back over several; a saltation or a set
    that is neither stops the merge. The merged product is the unmerged one (numpy) to
    roundoff, on a chain of 8 blocks with unequal links."""
    from crawlsim.projection.chain_polyhedron import ChainPolyhedron

    poly = ChainPolyhedron([1.0, 3.0, 0.5, 2.0, 7.0, 1.5, 4.0], 1.0)
    N = poly.blocks
    S = Saltation(2, np.linspace(-1.0, 1.0, poly.n), 0.7)
    sets = [[1], [1, 2 + N], [5], [1, 2, 5, 6], [0], [3], [0, 3 + N], S, [0], [4]]
    fs = [poly.factor(np.array(r)) if isinstance(r, list) else r for r in sets]
    packed = packed_jacobian(poly, fs)
    assert packed is not None
    # [1] < [1, 2] kept as [1, 2]; [5] then [1, 2, 5, 6] swallows both; [0], [3] are kept
    # apart until [0, 3] swallows both; the saltation stops [0] from merging into [0, 3]
    bounds = [packed.blocks[a:b].tolist() for a, b in zip(packed.starts[:-1], packed.starts[1:])]
    assert packed.kinds.tolist() == [0, 0, 1, 0, 0]
    assert bounds == [[1, 2, 5, 6], [0, 3], [], [0], [4]]
    V = np.random.default_rng(2).standard_normal((4, poly.n))
    for v in V:
        np.testing.assert_allclose(packed.apply(v), apply_jacobian(poly, fs, v), rtol=0, atol=1e-13 * np.linalg.norm(v))
        np.testing.assert_allclose(
            packed.apply_transpose(v), apply_jacobian_transpose(poly, fs, v), rtol=0, atol=1e-13 * np.linalg.norm(v)
        )


def test_matrix_free_step_with_compiled_products_is_the_dense_step(periods, monkeypatch):
    """LSMR with the compiled products gives the dense minimal-norm Newton step (to LSMR's
    tolerance), and the Python products give the same step where no chain is packed."""
    import crawlsim.integrate.limit as limit_module

    process, fs = periods["segments-64 exact"]
    poly = process.polyhedron
    F = np.random.default_rng(5).standard_normal(poly.n) * 1e-3
    dense = newton_step(poly, fs, F)
    monkeypatch.setattr(limit_module, "DENSE_JACOBIAN", 0)
    compiled = newton_step(poly, fs, F)
    monkeypatch.setattr(limit_module, "packed_jacobian", lambda poly, visited: None)
    python = newton_step(poly, fs, F)
    scale = np.max(np.abs(dense))
    np.testing.assert_allclose(compiled, dense, rtol=0, atol=1e-8 * scale)
    np.testing.assert_allclose(compiled, python, rtol=0, atol=1e-10 * scale)


def _products(inputs: dict) -> dict:
    """pack, J v and J^T v of each packed Jacobian of ``inputs`` in the current form."""
    world = jit.kernel()
    out = {}
    for name in sorted({key.split(":")[0] for key in inputs}):
        a = {key.split(":")[1]: value for key, value in inputs.items() if key.startswith(name + ":")}
        D, l = np.empty(len(a["blocks"])), np.empty(len(a["blocks"]))
        world.jacobian.pack(a["k"], a["kinds"], a["starts"], a["blocks"], D, l)
        args = (a["k"], a["kinds"], a["starts"], a["blocks"], D, l, a["slot"], a["rows"], a["rates"], a["jumps"])
        out[name + ":D"], out[name + ":l"] = D, l
        for i, v in enumerate(a["V"]):
            x, y = v.copy(), v.copy()
            world.jacobian.apply(*args, x)
            world.jacobian.apply_transpose(*args, y)
            out[f"{name}:J{i}"], out[f"{name}:JT{i}"] = x, y
    return out


def test_compiled_and_python_products_agree_bit_for_bit(periods):
    inputs = {}
    for name in ("wave-10 exact", "random-236 exact", "segments-64 exact"):
        process, fs = periods[name]
        p = packed_jacobian(process.polyhedron, fs)
        assert p is not None
        for key, value in dict(
            k=p.stiffness,
            kinds=p.kinds,
            starts=p.starts,
            blocks=p.blocks,
            slot=p.slot,
            rows=p.rows,
            rates=p.rates,
            jumps=p.jumps,
            V=np.random.default_rng(11).standard_normal((3, process.polyhedron.n)),
        ).items():
            inputs[f"{name}:{key}"] = value
    with jit.forced("compiled"):
        compiled = _products(inputs)
    with jit.forced("python"):
        python = _products(inputs)
    assert compiled.keys() == python.keys() and len(compiled) == 3 * (2 + 2 * 3)
    for key in compiled:
        np.testing.assert_array_equal(compiled[key], python[key], err_msg=key)
    # the products moved the vectors (J is not the identity)
    assert not np.array_equal(compiled["wave-10 exact:J0"], inputs["wave-10 exact:V"][0])
