"""Stepping a sweeping process period by period (docs/model.md §3, docs/integrators.md).

stepping     catch-up stepping of a tabulated process
exact        exact, event-driven integration
compiled     the exact integrator's periods handed to the compiled event loop
limit        the periodic limit by semismooth Newton on the period map
ledger       the exact integrator's energy ledger, integrated on its pieces
resources    the memory a run needs, checked before it is allocated
"""
