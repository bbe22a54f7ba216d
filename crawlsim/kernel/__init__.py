"""Exact, certified projections: where every step of every integrator is solved and certified.

    kkt          the overview: a projection, its KKT conditions, the names below re-exported
    certificate  the tolerance policy and the certificate of a step
    tridiagonal  LDL^T of the chain's tridiagonal blocks
    polyhedron   `Polyhedron`: active sets, the certified step on one, their primal-dual updates
    chain_polyhedron  the crawler's K(t) = {w : D^T w within the friction limits}
    dense_polyhedron  a generic process's K(t) = {w : B w <= c}, dense B
    projection   the one Clarabel adapter: settings, solve, status rule
    chain        the compiled (numba) certified catch-up step of a crawler chain
    catchup      the driver that allocates the compiled step's arrays and turns its reports
                 into crawlsim's errors
    events       the exact integrator's next event on a piece: closed forms, the search
    sampling     the next event where no closed form exists: certified sampling
    eventloop    the exact integrator's compiled event loop: one period of a crawler, certified
    piece        a piece of the exact flow: the basis phi(u), the piece's coefficients (compiled)
    tangent      the compiled tangent walk of an exact limit period, for exact sensitivities
    tangent_catchup  the same walk of a catch-up limit period
    implicit     the implicit function theorem at the walked limit: the derivatives
    jacobian     the compiled products by the period map's Jacobian, for the limit's Newton step

The compiled modules are not imported until a crawler is stepped: `crawlsim validate` and the
CLI's start-up do not load numba. With ``NUMBA_DISABLE_JIT=1`` they run as Python.
"""
