"""crawlsim: exact simulation of soft crawlers with dry friction.

The path from a gait file to an answer, one module per stage:

    gait.py        YAML gait file -> validated `Gait`
    model.py       `Gait` -> tabulated shape-space sweeping process (MODEL.md §2)
    projection.py  exact, certified projections (the only user of Clarabel)
    stepping.py    catch-up stepping, period by period
    analysis.py    convergence, v0, limit period
    h5io.py        HDF5 results files
    cli.py         the `crawlsim` command
"""

__version__ = "0.1.0"

from .api import run
from .errors import CertificateError, CrawlsimError, GaitError

__all__ = ["run", "CertificateError", "CrawlsimError", "GaitError", "__version__"]
