"""The model: a gait compiled to its shape-space polyhedral sweeping process (docs/model.md §1-2, §6).

    process      `Gait` -> `SweepingProcess`
    offsets      the offsets c(t) in closed form
    uniqueness   the uniqueness condition, decided exactly
    loads        external loads and slopes
"""
