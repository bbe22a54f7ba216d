#!/usr/bin/env python3
"""Switch off each certificate check, one at a time, and see a test go red.

A certificate test proves something only if it fails when the check it guards is gone. Each
mutant below edits one check out of a copy of the source (a `return True`, a skipped
refinement, a tolerance put back to the scalar bound), runs the tests that guard it on that
copy, and must see at least one of them fail. The copy shares one numba cache, so only the
mutants of the compiled kernel recompile it.

    python scripts/certificate-mutants.py            # every mutant
    python scripts/certificate-mutants.py --only chain.settle

Prints one line per mutant (the first failing test, or NOT CAUGHT) and exits 1 when any mutant
survives.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CERT = "tests/test_certificates.py"
KERNEL = "tests/test_kernel.py"
KKT = "tests/test_kkt.py"
EXACT = "tests/test_exact.py"

#: (name, file, the check's source, its replacement, tests that must catch it)
MUTANTS = [
    (
        "exact._certify_piece",
        "crawlsim/integrate/exact.py",
        "        bad = (primal > tol.primal) | (dual > dual_tol) | (comp > tol.primal)\n",
        "        bad = np.zeros(len(primal), dtype=bool)\n",
        [CERT],
    ),
    (
        "exact._certify_jump",
        "crawlsim/integrate/exact.py",
        "        cert = poly.certify(slack, proj.multipliers, proj.active, tol)\n        if not cert.ok:",
        "        cert = poly.certify(slack, proj.multipliers, proj.active, tol)\n        if False:",
        [CERT],
    ),
    (
        "exact._verify",
        "crawlsim/integrate/exact.py",
        "            if moved > 100 * tol.primal:",
        "            if False:",
        [CERT],
    ),
    (
        "Certificate.ok",
        "crawlsim/projection/certificate.py",
        "        return (self.primal <= t.primal and self.dual <= self._dual_tol\n"
        "                and self.complementarity <= t.primal)",
        "        return True",
        [CERT],
    ),
    (
        "Polyhedron.solve_on refinement",
        "crawlsim/projection/polyhedron.py",
        "        if np.abs(slack[idx]).max() > REFINE_FRACTION * tol.primal:",
        "        if False:",
        [CERT],
    ),
    (
        "Polyhedron.run certificate",
        "crawlsim/projection/polyhedron.py",
        "        ok = (primal <= tol.primal) & (dual <= tol.dual) & (comp <= tol.primal)",
        "        ok = np.ones(len(primal), dtype=bool)",
        [CERT],
    ),
    (
        "Polyhedron.run refinement",
        "crawlsim/projection/polyhedron.py",
        "        if np.any(comp > REFINE_FRACTION * tol.primal):",
        "        if False:",
        [CERT],
    ),
    (
        "ChainPolyhedron.row_tolerance",
        "crawlsim/projection/chain_polyhedron.py",
        "        if not active.size:\n            return tol\n        N = self.blocks",
        "        if True:\n            return tol\n        N = self.blocks",
        [KKT],
    ),
    (
        "chain.settle certificate",
        "crawlsim/kernel/chain.py",
        "        if primal <= tol_p and dual <= dual_tol and comp <= tol_p:",
        "        if True:",
        [KERNEL],
    ),
    (
        "chain.settle_from sign check",
        "crawlsim/kernel/chain.py",
        "        if duals or negative > 0.0 or not (primal <= tol_p and comp <= tol_p and 0.0 <= tol_d):",
        "        if duals:",
        [KERNEL],
    ),
    (
        "chain.on_set refinement",
        "crawlsim/kernel/chain.py",
        "    if active and comp > REFINE_FRACTION * tol_p:",
        "    if False:",
        [KERNEL],
    ),
    (
        "chain.row_duals",
        "crawlsim/kernel/chain.py",
        "        bound = 2.0 * RTOL * s[i]\n",
        "        bound = np.inf\n",
        [KKT],
    ),
    (
        "sampling.crossing curvature bound",
        "crawlsim/kernel/sampling.py",
        "    bound = h * h / 8.0 * curvature(z, linear, H)\n",
        "    bound = 0.0\n",
        [EXACT + "::test_tangential_contact_of_a_fourier_offset_between_samples"],
    ),
    (
        "eventloop.sample_piece certificate",
        "crawlsim/kernel/eventloop.py",
        "        if primal > tol_p or dual > tol_d or comp > tol_p:",
        "        if False:",
        [KERNEL + "::test_compiled_loop_samples_taken_at_wrong_times_raise"],
    ),
]


def run(name, path, old, new, tests, workdir: Path, env) -> str:
    source = (ROOT / path).read_text()
    if source.count(old) != 1:
        return f"the check is not in {path} as written here: update this script"
    target = workdir / path
    target.write_text(source.replace(old, new))
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", *tests],
            cwd=workdir,
            env=env,
            capture_output=True,
            text=True,
            timeout=3600,
        )
    finally:
        shutil.copy2(ROOT / path, target)
    if proc.returncode == 0:
        return "NOT CAUGHT"
    failed = [line for line in proc.stdout.splitlines() if line.startswith(("FAILED", "ERROR"))]
    if failed:
        return "caught by " + failed[0].split()[1]
    return f"caught: pytest exit {proc.returncode}: " + " | ".join(proc.stdout.splitlines()[-3:])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", help="run the mutants whose name contains this")
    args = parser.parse_args()
    survivors = 0
    with tempfile.TemporaryDirectory() as folder:
        workdir = Path(folder)
        for part in ("crawlsim", "tests", "gaits"):
            shutil.copytree(ROOT / part, workdir / part, ignore=shutil.ignore_patterns("__pycache__"))
        for name in ("pyproject.toml", "README.md"):
            shutil.copy2(ROOT / name, workdir / name)
        env = dict(os.environ, PYTHONPATH=str(workdir), NUMBA_CACHE_DIR=str(workdir / ".numba-cache"))
        env.pop("NUMBA_DISABLE_JIT", None)
        for name, path, old, new, tests in MUTANTS:
            if args.only and args.only not in name:
                continue
            outcome = run(name, path, old, new, tests, workdir, env)
            survivors += not outcome.startswith("caught")
            print(f"{name:36s} {outcome}", flush=True)
    return 1 if survivors else 0


if __name__ == "__main__":
    sys.exit(main())
