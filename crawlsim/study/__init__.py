"""Studies of many gaits: sweeps, gait design, the paper's checks.

    sweep        parameter sweeps of v0, in batches, resumable
    optimize     the fastest or the cheapest gait in a box (derivative-free)
    gradient     gradient-based gait design with exact sensitivities
    paper        the paper's convergence results, reproduced
"""
