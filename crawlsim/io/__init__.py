"""Files: HDF5 (netCDF-4) results, provenance, atomic writes.

layout       the netCDF-4 conventions every file follows, and their helpers
runfile      a run's results file: its layout and its writer
runread      reading a run's results file
sweepfile    sweep files
optfile      optimisation files
describe     a summary of any file (crawlsim info)
provenance   what ran, on what, with what, and when
atomic       every file written beside its target, then renamed over it
outputs      what a command may replace, and what it must refuse
"""
