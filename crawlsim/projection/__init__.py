"""Exact, certified projections onto polyhedra, in Python: every projection of every integrator is
solved on an active set and certified here, or in the compiled kernel (`crawlsim.kernel`) with
the same tolerance policy.

    kkt          the overview: a projection, its KKT conditions, the names below re-exported
    certificate  the certificate of a step, the records of a certified step or run
    tridiagonal  LDL^T of the chain's tridiagonal blocks
    polyhedron   `Polyhedron`: active sets, the certified step on one, their primal-dual updates
    chain_polyhedron  the crawler's K(t) = {w : D^T w within the friction limits}
    dense_polyhedron  a generic process's K(t) = {w : B w <= c}, dense B
    adapter      the one Clarabel adapter: which active set, when the updates do not settle
"""
