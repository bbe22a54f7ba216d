"""Files: HDF5 (netCDF-4) results, provenance, atomic writes.

    hdf5         run, sweep and optimisation files: writing and reading
    provenance   what ran, on what, with what, and when
    atomic       every file written beside its target, then renamed over it
    outputs      what a command may replace, and what it must refuse
"""
