"""Figures of an optimisation file (`crawlsim.io.optfile.read_optimization`), in the shared style.

* objective: how the search converged, the best value of the objective against the number of
  simulated points (a step line), over every evaluated value (faint dots), with the global search
  and the polish told apart; for a Pareto front, the hypervolume of the front found so far, with
  the start of each run marked;
* pareto-front: the cost of transport against v0 of every evaluated point that runs (faint), the
  non-dominated front (a step line: between two front points nothing better exists among the
  evaluated points) and the chosen gaits (the optima of the runs) numbered.
"""

from __future__ import annotations

import json
import textwrap

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from crawlsim.errors import ResultsFileError
from crawlsim.plotting.style import FAINT, REFERENCE, Units, colours, figure_style, label, new_figure, title, units_of

#: Labels of the optimisable quantities: (name, symbol, dimension of `style.DIMENSIONS`).
QUANTITY_LABELS = {
    "v0": ("average velocity", "v_0", "velocity"),
    "cost_of_transport": ("cost of transport", "c", "force"),
    "dissipation_per_period": ("dissipation per period", "D", None),
    "displacement_per_period": ("displacement per period", "d", "length"),
}

#: Characters a line of a title holds within the axes of a figure of `style.WIDTH`.
TITLE_WIDTH = 60


def quantity_label(name: str, units: Units) -> str:
    """The axis label of an optimisable quantity. v0 without a time unit is drawn as it is (the
    period may be a free parameter, so v0 T would not be one quantity)."""
    words, symbol, dimension = QUANTITY_LABELS[name]
    if name == "v0" and units.time is None:
        return label(words, symbol)
    if dimension is None:  # an energy: force times length
        unit = " ".join(u for u in (units.force, units.length) if u)
        return f"{words} ${symbol}$" + (f" ({unit})" if units.force and units.length else "")
    return label(words, symbol, dimension, units)


def _need(data: dict, group: str, *names: str) -> None:
    for name in names:
        if name not in (data.get(group) or {}):
            raise ResultsFileError(f"the optimisation figures need /{group}/{name}, which is missing")


def objective_figure(data: dict) -> Figure:
    """The convergence of the search (see the module docstring)."""
    _need(data, "history", "evaluations", "best", "run", "stage")
    attrs = data["attrs"]
    units = units_of(data)
    hist, evals = data["history"], data["evaluations"]
    pareto = bool(attrs.get("pareto", 0))
    n = np.asarray(hist["evaluations"], dtype=float)
    stage = np.asarray(hist["stage"])
    name = str(attrs.get("name", "gait"))
    with figure_style():
        fig, axs = new_figure(height=3.6)
        ax = axs[0, 0]
        blue, vermillion = colours(2)
        if pareto:
            _need(data, "history", "hypervolume")
            hv = np.asarray(hist["hypervolume"], dtype=float)
            ax.step(n, hv, where="post", color=blue, label="hypervolume of the front so far")
            runs = np.asarray(hist["run"])
            starts = [0, *np.flatnonzero(np.diff(runs)) + 1]
            labels = _run_labels(data["runs"])
            for k, s in enumerate(starts):
                first = n[s] - _batch_size(hist, s)
                ax.axvline(first, color=FAINT, linewidth=0.8, linestyle="--")
                ax.text(
                    first,
                    1.0,
                    f" {k + 1}",
                    transform=ax.get_xaxis_transform(),
                    va="top",
                    ha="left",
                    color=REFERENCE,
                    fontsize=8,
                )
            ax.set_ylabel("hypervolume (v0 × cost of transport)")
            what = "Pareto front of v0 against cost of transport: convergence"
            ax.text(
                0.0,
                -0.2,
                "runs: " + "; ".join(labels),
                transform=ax.transAxes,
                fontsize=7.5,
                color=REFERENCE,
                va="top",
                wrap=True,
            )
        else:
            quantity = str(attrs.get("objective_quantity", "v0"))
            values = np.asarray(evals[quantity], dtype=float)
            ok = np.asarray(evals["feasible"], dtype=bool) & np.isfinite(values)
            index = np.arange(1, len(values) + 1)
            ax.plot(
                index[ok],
                values[ok],
                linestyle="none",
                marker=".",
                markersize=3,
                color=FAINT,
                label="evaluated point (feasible)",
            )
            best = np.asarray(hist["best"], dtype=float)
            ax.step(n, best, where="post", color=blue, linewidth=1.8, label="best so far")
            polish = stage == 2
            if np.any(polish):
                first = n[np.argmax(polish)] - _batch_size(hist, int(np.argmax(polish)))
                ax.axvspan(first, n[-1], color="#E6E6E6", zorder=-1, linewidth=0, label="pattern search (polish)")
            final = best[np.isfinite(best)]
            if final.size:
                ax.axhline(final[-1], color=REFERENCE, linestyle=":", linewidth=1.0, label=f"best {final[-1]:.6g}")
                _zoom(ax, values[ok], final[-1], str(attrs.get("objective_sense")))
            ax.set_ylabel(quantity_label(quantity, units))
            what = f"{attrs.get('objective', '')}: convergence"
        ax.set_xlabel("points simulated")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_xlim(0, max(float(n[-1]) if n.size else 1.0, 1.0))
        ax.set_title(title(name, what))
        ax.legend(loc="lower right" if not pareto else "lower right")
    return fig


def _run_labels(runs: dict) -> list[str]:
    """``1 max v0``, ``2 min cost``, ``3 min cost, v0 >= 0.08``: the runs of a Pareto front."""
    out = []
    for k, (objective, eps) in enumerate(zip(runs["objective"], runs["epsilon"]), 1):
        sense, _, quantity = str(objective).partition(" ")
        text = f"{k} {sense[:3]} {'v0' if quantity == 'v0' else 'cost'}"
        if np.isfinite(eps):
            text += f" at v0 ≥ {eps:.3g}"
        out.append(text)
    return out


def _batch_size(hist: dict, i: int) -> float:
    n = np.asarray(hist["evaluations"], dtype=float)
    return float(n[i] - (n[i - 1] if i > 0 else 0.0))


def _zoom(ax, values: np.ndarray, best: float, sense: str) -> None:
    """Show the better half of the evaluated values: the early, poor points of a global search
    would otherwise flatten the approach to the optimum."""
    if values.size < 4:
        return
    if sense == "maximize":
        low = float(np.quantile(values, 0.25))
        span = best - low
        ax.set_ylim(low, best + 0.08 * span if span > 0 else best + 1e-12)
    else:
        high = float(np.quantile(values, 0.75))
        span = high - best
        ax.set_ylim(best - 0.08 * span if span > 0 else best - 1e-12, high)


def pareto_figure(data: dict) -> Figure:
    """The Pareto front of v0 against the cost of transport (see the module docstring)."""
    if "front" not in data:
        raise ResultsFileError("the pareto-front figure needs /front: the file was written without --pareto")
    _need(data, "front", "v0", "cost_of_transport", "chosen")
    _need(data, "evaluations", "v0", "cost_of_transport", "status")
    attrs = data["attrs"]
    units = units_of(data)
    evals, front = data["evaluations"], data["front"]
    v0 = np.asarray(evals["v0"], dtype=float)
    cot = np.asarray(evals["cost_of_transport"], dtype=float)
    ok = (np.asarray(evals["status"]) == "ok") & np.isfinite(v0) & np.isfinite(cot)
    fv, fc = np.asarray(front["v0"], dtype=float), np.asarray(front["cost_of_transport"], float)
    chosen = np.asarray(front["chosen"], dtype=bool)
    free = json.loads(attrs.get("free_json", "[]"))
    with figure_style():
        fig, axs = new_figure(height=4.0)
        ax = axs[0, 0]
        blue, vermillion = colours(2)
        ax.plot(v0[ok], cot[ok], linestyle="none", marker=".", markersize=3, color=FAINT, label="evaluated point")
        ax.step(fv, fc, where="post", color=blue, linewidth=1.2)
        ax.plot(
            fv, fc, linestyle="none", marker="o", markersize=4, color=blue, label=f"Pareto front ({len(fv)} points)"
        )
        ax.plot(
            fv[chosen],
            fc[chosen],
            linestyle="none",
            marker="D",
            markersize=7,
            markerfacecolor="none",
            markeredgecolor=vermillion,
            markeredgewidth=1.6,
            label="chosen gait (optimum of a run)",
        )
        for k, (x, y) in enumerate(zip(fv[chosen], fc[chosen]), 1):
            ax.annotate(str(k), (x, y), textcoords="offset points", xytext=(6, 5), color=vermillion, fontsize=8.5)
        if np.any(ok):
            # the cost of transport grows without bound as v0 goes to 0: show the front and the
            # better nine tenths of the points
            top = max(float(np.quantile(cot[ok], 0.9)), float(fc.max()) if fc.size else 0.0)
            low = float(cot[ok].min())
            pad = 0.05 * (top - low) if top > low else 0.5
            ax.set_ylim(low - pad, top + pad)
        ax.set_xlabel(quantity_label("v0", units))
        ax.set_ylabel(quantity_label("cost_of_transport", units))
        # The free parameters on lines of their own, wrapped, so that the title stays within
        # the axes however many there are.
        free_text = textwrap.fill(", ".join(f["path"] for f in free), width=TITLE_WIDTH, break_on_hyphens=False)
        ax.set_title(
            title(str(attrs.get("name", "gait")), "cost of transport against $v_0$")
            + (f"\nover {free_text}" if free_text else "")
        )
        ax.legend(loc="upper left")
    return fig


#: The figures of an optimisation file, by name (`crawlsim.plotting.OPTIMIZATION_FIGURES`).
OPTIMIZATION_FIGURE_FUNCTIONS = {"objective": objective_figure, "pareto-front": pareto_figure}
