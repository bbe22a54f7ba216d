"""The exceptions of crawlsim, one per way a run can fail.

The command line maps them to exit codes: `GaitError` (bad input) to 2, everything else to 1.
"""


class CrawlsimError(Exception):
    """Base class."""


class GaitError(CrawlsimError, ValueError):
    """A gait file (or document) is invalid. CLI maps it to exit code 2."""

    def __init__(self, source: str, keypath: str, message: str):
        self.source, self.keypath, self.message = source, keypath, message
        super().__init__(f"{source}: {keypath}: {message}" if keypath else f"{source}: {message}")


class CertificateError(CrawlsimError, ArithmeticError):
    """An exact projection could not be certified (KKT conditions fail beyond roundoff)."""


class ResultsFileError(CrawlsimError, ValueError):
    """A results file is missing, unreadable or lacks a group a command needs (exit code 2)."""
