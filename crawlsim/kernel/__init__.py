"""crawlsim's compiled kernel: the certified catch-up step of a crawler chain (`chain`), and the
thin driver that allocates its arrays, calls it, and turns what it reports into crawlsim's
errors (`catchup`).

Nothing here is imported until a crawler is stepped: `crawlsim validate` and the CLI's start-up
do not load numba. With ``NUMBA_DISABLE_JIT=1`` the compiled functions run as Python.
"""
