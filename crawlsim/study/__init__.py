"""Studies of gaits: one run, sweeps, the paper's checks.

simulation   one gait to its periodic regime: run, simulate, SimulationResult, open_run
sweep        parameter sweeps of v0: the entry points (sweep, run_sweep), resumable
grid         the axes (PATH=SPEC), linked dimensions, the grid of edited gait documents
points       one point validated, compiled and run: a row of the table, extra columns
executors    where points run: here, local workers (only when they pay), a Dask cluster
journal      finished points kept across interruptions
table        the sweep table, its CSV and HDF5 files, the join of shards
paper        the paper's convergence results, reproduced
"""
