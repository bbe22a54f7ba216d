"""The one tolerance policy of every certificate, for every step of every integrator: the
Python polyhedra (`crawlsim.projection.polyhedron`) and the compiled steps (`crawlsim.kernel.chain`,
`crawlsim.kernel.eventloop`, `crawlsim.kernel.piece`) call the same functions.

A step is held to `RTOL` of the size of the numbers it sums ([How a step is made exact]
(docs/exact-step.md)): B w - c adds |c|, ||B|| |w| and, through w = w_trial - M^{-1} B^T lambda,
||B|| ||M^{-1} B^T|| |lambda|, so

    size  = max(c_scale, |c|, ||B|| |w|, ||B|| ||M^{-1} B^T|| |lambda|),
    tol_p = RTOL size,   tol_d = 2 RTOL ||G_A^{-1}|| (size + ||G_A|| |lambda|):

the multipliers are G_A^{-1} times such a residual, plus the solve's own roundoff. A
complementarity residual above `REFINE_FRACTION` of tol_p gets one step of iterative
refinement; an uncertified step gets at most `UPDATE_ITERATIONS` primal-dual updates of its set.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from crawlsim.kernel.jit import jit

#: Relative tolerance of every certificate: about 45 ulps of the size of the step's numbers.
RTOL = 1e-14
#: A complementarity residual above this fraction of its tolerance triggers refinement.
REFINE_FRACTION = 0.25
#: Primal-dual active-set updates tried before a step is handed to Clarabel.
UPDATE_ITERATIONS = 12
#: An exact grid sample whose certificate fails by at most this many times its tolerance is
#: refined (`crawlsim.integrate.exact.EventStepper._refine`: the closed form's roundoff, on
#: chains stiff to the accepted limits); beyond, it is an internal error.
REFINE_LIMIT = 100.0


@jit
def tolerances(c_scale: Any, c_size: Any, w_part: Any, lam_part: Any, inverse: Any, gram: Any, lam_size: Any) -> Any:
    """(tol_p, tol_d) of a step (or, interpreted, of arrays of steps): ``w_part`` = ||B|| |w|,
    ``lam_part`` = ||B|| ||M^{-1} B^T|| |lambda|, ``inverse`` = ||G_A^{-1}||, ``gram`` = ||G_A||."""
    size = np.maximum(np.maximum(c_scale, c_size), np.maximum(w_part, lam_part))
    return RTOL * size, 2.0 * RTOL * inverse * (size + gram * lam_size)
