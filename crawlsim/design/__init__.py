"""Gait design: searches that run a gait many times to choose its numbers.

optimize     the driver of `crawlsim optimize`: one objective, or the Pareto front
problem      free parameters, objective, constraints, the feasibility rules; the search's settings
search       the shared evaluator (batches through the sweep engine); evolution + pattern search
descent      the gradient search: sample (or evolution), then quasi-Newton on exact gradients
optresult    the answer: evaluations, history, runs, front, hypervolume
stall        the stall force and the steepest slope, searched by runs at probed loads
"""
