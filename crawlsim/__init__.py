"""crawlsim: exact simulation of soft crawlers with dry friction.

The path from a gait file to an answer, one module per stage:

    gait.py        YAML gait file -> validated `Gait`
    model.py       `Gait` -> tabulated shape-space sweeping process (docs/model.md §2)
    projection.py  exact, certified projections (the only user of Clarabel)
    stepping.py    catch-up stepping, period by period
    analysis.py    convergence, v0, limit period
    h5io.py        HDF5 results files
    cli/           the `crawlsim` command

``import crawlsim`` is light (no numpy): `run` and the modules above load when first used, so
that ``crawlsim --help`` and shell completion start fast.
"""

__version__ = "0.1.0"

from .errors import CertificateError, CrawlsimError, GaitError

__all__ = ["run", "CertificateError", "CrawlsimError", "GaitError", "__version__"]


def __getattr__(name):
    if name == "run":  # PEP 562: the numerical stack loads with the first run
        from .api import run

        globals()["run"] = run
        return run
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
