"""The exceptions and warnings of crawlsim: one taxonomy, one home.

Two families, which the command line maps to exit codes:

* `InputError` (exit code 2): something the user gave cannot be used. The message names the
  source (a file, an option), the key path inside it and what was expected. Under it:
  `GaitError` (a gait or process file or document), `SweepSpecError` (``--sweep``, ``--shard``,
  ``--free`` and similar specifications), `ResultsFileError` (a results file that cannot be
  read), `OutputError` (an output target that must not be replaced or cannot be written),
  `ResourceError` (a request that would not fit in the memory allowed) and `DegenerateModelError`
  (the model itself does not determine the motion at some time).
* Everything else that derives from `CrawlsimError` (exit code 1) is an internal failure:
  `CertificateError` (an exact step could not be certified) and `EventError` (the exact
  integrator cannot go on). On a valid gait either is a bug in crawlsim, never a verdict on the
  user's input.
"""

from __future__ import annotations


class CrawlsimError(Exception):
    """Base class of every crawlsim exception."""


class InputError(CrawlsimError, ValueError):
    """Bad input, reported as ``source: keypath: message`` (exit code 2, no traceback)."""

    def __init__(self, source: str, keypath: str, message: str):
        self.source, self.keypath, self.message = str(source), str(keypath), str(message)
        parts = [p for p in (self.source, self.keypath) if p]
        super().__init__(": ".join([*parts, self.message]))


class GaitError(InputError):
    """A gait file (or document) is invalid."""


class SweepSpecError(InputError):
    """A sweep, shard or optimisation specification on the command line is invalid."""


class ResultsFileError(InputError):
    """A results file is missing, unreadable, of another kind, or lacks what a command needs."""

    def __init__(self, message: str, source: str = "", keypath: str = ""):
        super().__init__(source, keypath, message)


class OutputError(InputError):
    """An output target is refused: it is not a results file of the same kind (``--force``
    replaces it), it is a special file, or its folder is missing or not writable."""


class ResourceError(InputError):
    """A request would need more memory (or time) than allowed; nothing was allocated."""


class DegenerateModelError(InputError):
    """The model does not determine the motion at some time (for crawlers: the uniqueness
    condition fails at an instant the run must step on). The message names the time, the
    blocks and the reason."""


class CertificateError(CrawlsimError, ArithmeticError):
    """An exact step could not be certified (KKT conditions fail beyond roundoff)."""


class EventError(CrawlsimError):
    """The event-driven integrator cannot go on: too many events, or Zeno-like accumulation."""


class GaitWarning(UserWarning):
    """A gait that runs but shows something unphysical: an actuator length that goes negative
    (`crawlsim.gait.crawler_spec.negative_length`)."""


class LicqWarning(UserWarning):
    """The active normals of a generic process are dependent at some time (not an error there:
    the projected point is unique, only the reactions are not)."""
