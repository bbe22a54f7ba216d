"""The statuses crawlsim reports, as string enums: they compare equal to their values and are
written as those values to JSON, CSV and HDF5."""

from __future__ import annotations

from enum import StrEnum


class Convergence(StrEnum):
    """How a run reached its periodic regime (docs/model.md §4)."""

    FINITE_TIME = "finite-time"  # exactly periodic from some period on
    ASYMPTOTIC = "asymptotic"  # geometric convergence only, with a contraction rate
    NOT_CONVERGED = "not-converged"  # max_periods ran out first


class PointStatus(StrEnum):
    """The outcome of one point of a sweep (or of an optimisation)."""

    OK = "ok"
    NOT_CONVERGED = "not-converged"
    INVALID = "invalid"  # the point's gait is refused (the message says why)
    FAILED = "failed"  # the run stopped with an internal failure (the message says why)


class Integrator(StrEnum):
    """The integrators of `crawlsim.integrate.stepping.STEPPERS`."""

    CATCH_UP = "catch-up"
    EXACT = "exact"


class RunStatus(StrEnum):
    """The outcome of one run, in the manner of diffrax's ``RESULTS``: `RunResult.message`
    says what to change when it is not `SUCCESSFUL`."""

    SUCCESSFUL = "successful"  # the periodic limit was found, and v0 (if any) bounded
    MAX_PERIODS_REACHED = "max-periods-reached"  # max_periods ran out before the limit
    # the limit was found, but v0 has no error estimate: a catch-up run whose time-step error
    # could not be measured against the exact integrator (the message says why)
    NO_ERROR_ESTIMATE = "no-error-estimate"


class LimitMethod(StrEnum):
    """How a run's periodic limit was found (`crawlsim.integrate.limit`)."""

    NEWTON = "newton"  # the periodic-limit solver found and verified it
    ITERATE = "iterate"  # the true iterates reached it themselves


class RigidStatus(StrEnum):
    """How the rigid limit found its events (`crawlsim.analysis.rigid`)."""

    CLOSED_FORM = "closed-form"  # every crossing and weight event in closed form
    SAMPLED = "sampled"  # some found by certified sampling: the estimate holds its uncertainty
