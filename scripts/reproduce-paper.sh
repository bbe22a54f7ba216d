#!/usr/bin/env bash
# Reproduce the paper's Section 5 (finite-time and asymptotic-only convergence) and Theorem
# th:speed with the example files in gaits/paper/, and print a table: the paper's claim, what
# crawlsim measured, pass or fail (Markdown). Exit status 1 if any check fails.
#   scripts/reproduce-paper.sh            # the files' own grids (a few seconds)
#   scripts/reproduce-paper.sh --quick    # coarser grids, as in tests/test_paper.py
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
exec python -m crawlsim.study.paper "$@"
