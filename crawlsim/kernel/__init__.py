"""The compiled kernel: the certified steps of a crawler's chain as functions of plain arrays and
scalars, one source that runs interpreted or compiled by numba (`jit`).

    jit          the two forms, and which one a piece of work runs
    policy       the one tolerance policy of every certificate
    chain        the certified catch-up step of a crawler chain
    piece        a piece of the exact flow: the basis phi(u), the piece's coefficients, an event's
                 velocity problems
    events       the exact integrator's next event on a piece: closed forms, the search
    sampling     the next event where no closed form exists: certified sampling
    eventloop    the exact integrator's event loop: one period of a crawler, certified
    jacobian     the products by the period map's Jacobian, for the limit's Newton step
    tangent      the tangent walk of an exact limit period, for exact sensitivities
    tangent_catchup  the same walk of a catch-up limit period
    implicit     the implicit function theorem at the walked limit: the derivatives

Importing these modules costs numpy alone: `crawlsim validate` and the CLI's start-up load none
of them, and small work runs them interpreted without loading numba.
"""
