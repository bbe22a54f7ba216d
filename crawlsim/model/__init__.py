"""The model: a gait compiled to its shape-space polyhedral sweeping process (docs/model.md §1-2, §6).

What decides whether a gait file is valid (its loads, the uniqueness condition) is read in
`crawlsim.gait`, the layer below: a `Gait` that exists is one the model can compile.

    process      `Gait` -> `SweepingProcess`
    crawler      the `Crawler` of a process: stress, shape, block forces, stress bounds, dissipation
    offsets      the offsets c(t) in closed form
"""
