"""``crawlsim velocity --sensitivity PATH``: the lines and JSON of the derivatives of v0
(`crawlsim.sensitivity`), kept out of velocity.py so that the command only calls two functions."""

from __future__ import annotations

from typing import Any

import click


def compute(gait: Any, paths: tuple[str, ...], run: Any = None) -> Any:
    """The sensitivities of ``gait`` for ``paths`` at the limit period of ``run`` (the
    command's own run of the gait: the limit is not searched twice), with the gait's
    integrator: exact, or the catch-up scheme's discrete map (the lines say so)."""
    from crawlsim.analysis.sensitivity import sensitivity

    return sensitivity(gait, list(paths), run=run.settled)


def lines(result: Any, integrator: str) -> list[str]:
    """One line per parameter: dv0/dPATH with the digits its error estimate supports, or why
    it is not smooth with the one-sided values, or why it was not computed."""
    from crawlsim.analysis.digits import with_error

    out = []
    for p in result.parameters:
        name = f"dv0/d{p.path}"
        if p.method == "unsupported":
            out.append(f"{name}: not computed: {p.reason}")
        elif p.smooth:
            out.append(f"{name} = {with_error(p.v0.value, p.v0.error_estimate)}")
        else:
            sides = []
            for side, why in (("left", p.left_reason), ("right", p.right_reason)):
                d = getattr(p, side)
                sides.append(f"{side} {with_error(d.value, d.error_estimate)}" if d is not None else f"{side}: {why}")
            out.append(f"{name}: not smooth ({p.reason}); " + ", ".join(sides))
    if integrator != "exact":
        out.append(
            f"(derivatives of the {integrator} scheme's own discrete period map at its "
            f"v0 = {result.v0:.12g}, not of the exact v0: method {integrator})"
        )
    return out


def echo(result: Any, integrator: str) -> None:
    for line in lines(result, integrator):
        click.echo(line)
