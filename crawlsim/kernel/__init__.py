"""Exact, certified projections: where every step of every integrator is solved and certified.

    kkt          the KKT certificate and its tolerance policy; the certified projection step
    projection   the one Clarabel adapter: settings, solve, status rule
    chain        the compiled (numba) certified catch-up step of a crawler chain
    catchup      the driver that allocates the compiled step's arrays and turns its reports
                 into crawlsim's errors
    events       the compiled closed forms of the exact integrator's next event
    eventloop    the exact integrator's compiled event loop: one period of a crawler, certified

The compiled modules are not imported until a crawler is stepped: `crawlsim validate` and the
CLI's start-up do not load numba. With ``NUMBA_DISABLE_JIT=1`` they run as Python.
"""
