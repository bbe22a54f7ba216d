"""A run to its periodic regime and what it measures (docs/model.md §4-6).

run          `simulate`: run a process to its periodic regime; convergence, v0, the limit period
energy       the energy ledger of a period
sensitivity  exact derivatives of v0 and the period's quantities
stall        the stall force and the steepest climbable slope
digits       printing a value with the digits its error estimate supports
"""
