"""``crawlsim optimize``: the fastest or cheapest gait in a box of gait parameters."""

from __future__ import annotations

import math
from pathlib import Path

import click

import crawlsim
from crawlsim.cli import (
    BadInput,
    Terminated,
    _output_path,
    feedback_options,
    interrupt_exit,
    library_errors,
    main,
    simulation_options,
    to_json,
)
from crawlsim.cli.guards import force_option
from crawlsim.cli.progress import Progress
from crawlsim.integrate.resources import check_signal_work, gait_signal_work
from crawlsim.io.outputs import GAIT, check_target


@main.command()
@click.argument("gait_file", type=click.Path(exists=True, dir_okay=False))
@click.option(
    "--free",
    "free_specs",
    multiple=True,
    metavar="PATH=LO:HI",
    help="A free parameter: a dotted path of the gait document (as in --sweep, "
    "wildcards included: links.*.phase) and its bounds, both included. Repeat "
    "for more.",
)
@click.option("--maximize", metavar="QUANTITY", help="Maximise v0 (the default), displacement-per-period, ...")
@click.option("--minimize", metavar="QUANTITY", help="Minimise cost-of-transport, dissipation-per-period, v0, ...")
@click.option(
    "--subject-to",
    "constraints",
    multiple=True,
    metavar="'QUANTITY>=NUMBER'",
    help="A constraint, QUANTITY>=NUMBER or QUANTITY<=NUMBER (v0, cost_of_transport, "
    "dissipation_per_period, displacement_per_period). Repeat for more.",
)
@click.option(
    "--pareto",
    is_flag=True,
    help="The front of v0 (maximised) against cost_of_transport (minimised): its two "
    "ends and --front-points epsilon-constraint points between them.",
)
@click.option(
    "--front-points",
    type=click.IntRange(min=0),
    default=5,
    show_default=True,
    help="Points of the Pareto front between its two ends (--pareto).",
)
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False),
    help="HDF5 file of every evaluated point, the history of the best value, the "
    "runs and the settings (default: <gait stem>-optimize.h5). OUT.journal keeps "
    "finished points while it runs: rerun the same command to resume.",
)
@click.option(
    "--write-best",
    type=click.Path(dir_okay=False),
    metavar="BEST.yaml",
    help="Write the best gait as a gait file (crawlsim run reproduces its v0).",
)
@click.option(
    "--seed",
    type=click.IntRange(min=0),
    default=0,
    show_default=True,
    help="Seed of the search: the same seed gives the same result.",
)
@click.option(
    "--max-evaluations",
    type=click.IntRange(min=1),
    help="Budget of simulated points [default: 150 (n + 1) for n free parameters; "
    "with --pareto, that times (front points + 2) / 2].",
)
@click.option(
    "-j",
    "--jobs",
    type=click.IntRange(min=1),
    default=1,
    show_default=True,
    help="Local worker processes (each generation is one batch).",
)
@click.option(
    "--scheduler",
    metavar="ADDRESS",
    help="Run on an existing Dask cluster (tcp://host:8786); needs pip install 'crawlsim[dask]'.",
)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
@click.option(
    "--method",
    "search",
    type=click.Choice(["evolution", "gradient"]),
    help="evolution: differential evolution, then a pattern search; gradient: a "
    "coarse sample, then quasi-Newton runs (L-BFGS-B, SLSQP with --subject-to) "
    "on the exact sensitivities from its best points (exact integrator). "
    "[default: gradient to maximise v0 without constraints, else evolution]",
)
@simulation_options
@force_option
@feedback_options
def optimize(
    gait_file,
    free_specs,
    maximize,
    minimize,
    constraints,
    pareto,
    front_points,
    output,
    write_best,
    seed,
    max_evaluations,
    jobs,
    scheduler,
    as_json,
    search,
    settings,
    force,
    feedback,
):
    """Find the gait parameters in a box that maximise v0 (or minimise the cost of transport,
    ...), under constraints, or the Pareto front of v0 against the cost of transport.

    --method evolution: a seeded differential evolution (SciPy) evaluates each generation as one
    batch through the sweep engine (-j, --scheduler), then a batched pattern search polishes the
    best point. --method gradient: a coarse sample of the box (one batch), then quasi-Newton
    runs from its best points on the exact sensitivities of v0 and of the constraints
    (docs/sensitivity.md); v0 has kinks where the contact sequence changes, and the restarts
    keep one kink from ending the search. Points whose gait is invalid or whose run fails are
    recorded and never chosen. The exact integrator is the default, so the objective is exact
    to roundoff and the result reproducible.

    Exit codes: 0 done; 2 bad input, or no evaluated point satisfies the constraints (no file
    written); 130 interrupted (finished points kept in OUT.journal; rerun to resume).

    \b
    Examples:
      crawlsim optimize gaits/peristalsis-4.yaml --free links.1.phase=0:1 \\
          --free links.2.phase=0:1 --max-evaluations 60 --steps-per-period 20 \\
          --write-best best.yaml && crawlsim run best.yaml --steps-per-period 20
      crawlsim optimize gaits/peristalsis-4.yaml --free 'links.*.amplitude=0.1:0.4' \\
          --free links.1.phase=0:1 --minimize cost-of-transport --subject-to 'v0>=0.3' \\
          --max-evaluations 60 --steps-per-period 20 -o cheap.h5 && crawlsim plot cheap.h5
      crawlsim optimize gaits/peristalsis-3.yaml --free links.1.phase=0:1 --pareto \\
          --front-points 2 --max-evaluations 80 --steps-per-period 20 -o front.h5 --json
    """
    from crawlsim.design import problem as design  # start-up: the library when the command runs

    _check_options(free_specs, output)
    with library_errors():
        out = _targets(design, gait_file, output, write_best, scheduler, seed, force)
        if maximize and minimize:
            raise BadInput(
                f"--maximize {maximize} and --minimize {minimize}: give one objective "
                "(or --pareto for v0 against cost_of_transport)"
            )
        objective = None
        if maximize or minimize:
            option, sense = ("--minimize", design.Sense.MINIMIZE) if minimize else ("--maximize", design.Sense.MAXIMIZE)
            objective = design.Objective(design.quantity(minimize or maximize, option), sense)
        free = [design.parse_free(spec) for spec in free_specs]
        cons = [design.parse_constraint(text) for text in constraints]
        # the gait file's integrator (else exact), written into its document: the best gait records it
        integrator = crawlsim.api.load_gait(gait_file).simulation.integrator
        gait = crawlsim.api.load_gait(gait_file, **{"integrator": integrator, **settings.given()})
        check_signal_work(gait_signal_work(gait), gait.source)  # before any evaluation
        problem = design.make_problem(gait, free, objective=objective, constraints=cons, pareto=pareto)
        method = design.Method(
            seed=seed,
            max_evaluations=max_evaluations,
            front_points=front_points,
            search=design.default_search(problem, search),
        )
        result = _search(problem, method, out, jobs, scheduler, feedback)
        result.check_feasible()
        if write_best is not None:
            result.write_best(write_best)
    summary = result.summary()
    if as_json:
        summary.update(output=str(out), best_gait=write_best)
        click.echo(to_json(summary))
    else:
        click.echo(_text(result, summary, out, write_best))


def _check_options(free_specs, output) -> None:
    if not free_specs:
        raise BadInput("give at least one free parameter: --free PATH=LO:HI, for example --free links.1.phase=0:1")
    if output == "-":
        raise BadInput(
            "--output -: the results of an optimisation are an HDF5 file, which "
            "cannot be streamed to stdout; give a file name (-o opt.h5), and --json "
            "prints the answer on stdout"
        )


def _targets(design, gait_file, output, write_best, scheduler, seed, force) -> Path:
    """The results file, checked with the --write-best file, the --scheduler address and the
    seed (``design``: `crawlsim.design.problem`) before any work."""
    if scheduler is not None:
        from crawlsim.study.executors import check_scheduler  # start-up: the sweep engine for a cluster

        check_scheduler(scheduler)
    design.Method(seed=seed)  # refuses a seed the results file cannot hold, before any work
    out = _output_path(output, Path(gait_file).stem + "-optimize", force, inputs=[gait_file])
    if out.suffix.lower() not in (".h5", ".hdf5"):
        raise BadInput(f"--output {out}: an optimisation is written to HDF5: give a name ending in .h5")
    if write_best is not None:
        # never the gait file optimised (nor the results file): refused like every output
        check_target(write_best, GAIT, inputs=[gait_file, out], force=force, option="--write-best")
    return out


def _search(problem, method, out, jobs, scheduler, feedback):
    """Run the search with progress on stderr (the best value so far as the bar's note)."""
    from crawlsim.design import optimize as opt  # start-up: the search's library, when it runs
    from crawlsim.design.search import OptimizationInterrupted  # (its interrupt, raised there)

    budget = method.budget(problem)
    bar = Progress("optimize", "point", budget, mode=feedback.mode)
    runs = 2 + method.front_points if problem.pareto else 1

    def report(batch):
        run = f"run {batch.run + 1}/{runs}: " if problem.pareto else ""
        if batch.feasible:
            what = ("v0" if batch.run == 0 else "cost_of_transport") if problem.pareto else problem.objective.quantity
            bar.set_note(f"{run}best {what} {batch.best:.10g}")
        else:
            bar.set_note(f"{run}no feasible point yet")
        if feedback.verbose:
            bar.message(
                f"batch {batch.batch} (run {batch.run}, {batch.stage}): "
                f"{batch.evaluations} points, best "
                + (f"{batch.best!r}" if batch.feasible else "none feasible")
                + ("" if math.isnan(batch.step) else f", step {batch.step:.3g}")
            )

    try:
        result = opt.optimize(
            problem, method, output=out, jobs=jobs, scheduler=scheduler, progress=bar.update, report=report
        )
    except OptimizationInterrupted as exc:
        bar.close()
        where = "not kept" if exc.journal is None else "nothing to keep"
        if exc.journal is not None and exc.done:  # the journal exists once a point is in it
            where = f"kept in {exc.journal}; run the same command again to resume"
        click.echo(f"Interrupted: {exc.done} points finished, {where}.", err=True)
        cause: BaseException | None = exc
        while cause is not None and not isinstance(cause, Terminated):
            cause = cause.__context__  # SIGTERM is two exceptions down (the sweep's, then ours)
        raise interrupt_exit(cause or exc) from None
    except BaseException:
        bar.close()
        raise
    bar.close(complete=True)
    if feedback.verbose:
        for e in result.evaluations:
            if e.row.status in ("invalid", "failed"):
                click.echo(f"evaluation {e.index} {e.row.status}: {e.row.message}", err=True)
    return result


def _text(result, summary, out, write_best) -> str:
    from crawlsim.analysis.digits import with_error

    problem = result.problem
    best = result.best_point
    what = "Pareto front of v0 against cost_of_transport" if problem.pareto else result.runs[0].text
    lines = [
        f"{problem.base.name}: {what}",
        f"  method                   {result.method.name}, seed {result.method.seed}",
    ]
    for path, value in result.best_values.items():
        lines.append(f"  {path:<24} {value!r}")
    for name in ("v0", "cost_of_transport", "dissipation_per_period"):
        # as `crawlsim run` prints them: v0 to the digits its estimate supports, with it
        value, error = getattr(best.row, name), best.row.v0_error_estimate if name == "v0" else None
        lines.append(f"  {name:<24} {'n/a' if value is None else with_error(value, error)}")
    lines.append(f"  {'feasible':<24} {'yes' if result.feasible else 'no'}")
    lines.append(_evaluations_line(result))
    if problem.pareto:
        lines += _front_lines(problem, summary)
    lines += _budget_lines(result)
    lines.append(f"  {'wall time':<24} {result.wall_time:.3g} s")
    lines.append(f"  {'results':<24} {out}")
    if write_best is not None:
        lines.append(f"  {'best gait':<24} {write_best}")
    return "\n".join(lines)


def _evaluations_line(result) -> str:
    """How many points were simulated, by stage (the gradient search's sample and its
    evaluations with a gradient), and how many did not run."""
    counts, stages = result.counts(), result.stage_counts()
    bad = ", ".join(f"{counts[k]} {k}" for k in ("invalid", "failed", "not-converged") if counts[k])
    kinds = ("global", "with gradient") if result.method.gradient else ("global", "polish")
    return (
        f"  {'evaluations':<24} {len(result.evaluations)} of {result.budget} allowed: "
        f"{stages['global']} {kinds[0]}, {stages['polish']} {kinds[1]}" + (f"; {bad}" if bad else "")
    )


def _front_lines(problem, summary) -> list[str]:
    chosen = [p for p in summary["front"] if p["chosen"]]
    lines = [f"  {'front':<24} {len(summary['front'])} points, {len(chosen)} of them optima of the runs:"]
    for point in chosen:
        values = ", ".join(f"{p}={point[p]:.6g}" for p in problem.paths)
        lines.append(f"    v0 {point['v0']:.6g}  cost_of_transport {point['cost_of_transport']:.6g}  ({values})")
    return lines


def _budget_lines(result) -> list[str]:
    """The runs stopped by their budget: not converged, their optima may improve with a
    larger one."""
    spent = [(k, r) for k, r in enumerate(result.runs, 1) if r.out_of_budget]
    if not spent:
        return []
    lines = [
        f"  {'out of budget':<24} {len(spent)} of {len(result.runs)} run"
        f"{'s' if len(result.runs) > 1 else ''} (--max-evaluations):"
    ]
    lines += [f"    run {k}, {run.text}: {run.stop}" for k, run in spent]
    return lines
