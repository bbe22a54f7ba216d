"""The HDF5 files of crawlsim, one import away: run results files, sweep files and optimisation
files, written and read.

The files are netCDF-4 files (HDF5 with the netCDF conventions), written with h5py: every axis of
every dataset is attached to a named dimension scale, and every dataset carries ``units`` (UDUNITS
syntax, "1" when dimensionless) and ``long_name``; enumerations carry the CF ``flag_values`` and
``flag_meanings``; the root carries ``Conventions``. So ``xarray.open_datatree(path,
engine="h5netcdf")`` opens every group with named dimensions, and ``h5dump -H`` reads as
documentation. docs/hdf5.md documents the layout; each module's tables are its single
source in the code:

    layout      the conventions shared by every file: dimension scales, CF attributes, atomic
                writes, reading attributes and columns
    runfile     run files (`RUN_VARIABLES`): `ResultsWriter` streams a run, `RowsRecorder` keeps
                it in memory
    runread     reading run files: `read_results`, `read_provenance`, `read_attrs`
    sweepfile   sweep files (`SWEEP_VARIABLES`): `write_sweep`, `read_sweep`, `axis_name`
    optfile     optimisation files (`OPTIMIZATION_VARIABLES`): `write_optimization`,
                `read_optimization`
    describe    a summary of any of them without reading the trajectories (`crawlsim info`)

Readers accept format_version 1 (the layout before dimension scales, units and provenance) and 2;
the dicts they return have the same keys for both, format 2 adding new keys only. The typed
readers, which return the types of the Python API, are `crawlsim.api.open_run` and
`crawlsim.api.open_sweep`. Writes are atomic (`crawlsim.io.atomic`): a failed run leaves no file
behind.
"""

from __future__ import annotations

from crawlsim.io.atomic import GuardedFile
from crawlsim.io.describe import describe
from crawlsim.io.layout import (
    CONVENTIONS,
    CONVERGENCE_FLAGS,
    FORMAT_VERSION,
    LIMIT_FLAGS,
    NOT_A_VARIABLE,
    READABLE_VERSIONS,
    SLIP_FLAGS,
    SOLVER_PERIOD_FLAGS,
    STATUS_FLAGS,
    Var,
)
from crawlsim.io.optfile import (
    OBJECTIVE_QUANTITIES,
    OPTIMIZATION_VARIABLES,
    STAGE_FLAGS,
    read_optimization,
    write_optimization,
)
from crawlsim.io.runfile import (
    ROOT_COORDINATES,
    RUN_VARIABLES,
    SOLVER_VARIABLES,
    TIME_DIMENSIONS,
    ResultsWriter,
    RowsRecorder,
    period_rows,
)
from crawlsim.io.runread import read_attrs, read_provenance, read_results
from crawlsim.io.sweepfile import SWEEP_VARIABLES, axis_name, read_sweep, write_sweep

__all__ = [
    "CONVENTIONS",
    "CONVERGENCE_FLAGS",
    "FORMAT_VERSION",
    "GuardedFile",
    "LIMIT_FLAGS",
    "NOT_A_VARIABLE",
    "OBJECTIVE_QUANTITIES",
    "OPTIMIZATION_VARIABLES",
    "READABLE_VERSIONS",
    "ROOT_COORDINATES",
    "RUN_VARIABLES",
    "SLIP_FLAGS",
    "SOLVER_PERIOD_FLAGS",
    "SOLVER_VARIABLES",
    "STAGE_FLAGS",
    "STATUS_FLAGS",
    "SWEEP_VARIABLES",
    "TIME_DIMENSIONS",
    "ResultsWriter",
    "RowsRecorder",
    "Var",
    "axis_name",
    "describe",
    "period_rows",
    "read_attrs",
    "read_optimization",
    "read_provenance",
    "read_results",
    "read_sweep",
    "write_optimization",
    "write_sweep",
]
