"""The model: a gait compiled to its shape-space polyhedral sweeping process (docs/model.md §1-2, §6).

    process      `Gait` -> `SweepingProcess`
    crawler      the `Crawler` of a process: stress, shape, block forces, stress bounds, dissipation
    offsets      the offsets c(t) in closed form
    uniqueness   the uniqueness condition, decided exactly, every violating subset listed
    loads        external loads and slopes
"""
