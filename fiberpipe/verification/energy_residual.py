"""The energy residual of the solver runs a verification case makes.

Every case runs the solver through :func:`simulate` here, which notes each run's largest
|``history/energy/residual``| (the state-function balance: the leapfrog kinetic term, the strain
energy, the stored contact energy and the dissipations against the loads' work; docs/verification.md)
in every recorder :func:`recording` has open. ``python -m fiberpipe.verification`` opens one per
case and prints the figures after the table.
"""

from __future__ import annotations

from contextlib import contextmanager

import numpy as np

from ..solver import simulate as _solver_simulate

#: the largest |residual| the tolerance of docs/verification.md allows a run
RESIDUAL_TOLERANCE = 1e-3

_open: list[list[float]] = []


def recorded_simulate(*args, **kwargs):
    """:func:`fiberpipe.solver.integrator.simulate`; its run's largest |energy residual| goes to every open recorder."""
    res = _solver_simulate(*args, **kwargs)
    r = np.asarray(res.history.get("energy/residual", ()), dtype=float)
    if r.size:
        for runs in _open:
            runs.append(float(np.max(np.abs(r))))
    return res


@contextmanager
def recording():
    """A list that collects the largest |energy residual| of each run made while it is open."""
    runs: list[float] = []
    _open.append(runs)
    try:
        yield runs
    finally:
        _open.remove(runs)


def format_residuals(residuals: dict[str, list[float]]) -> str:
    """The residual table: per case, each run's largest |energy residual|, flagged above the tolerance."""
    lines = ["| case | runs | largest \\|energy residual\\| of each run | within 1e-3 |", "|---|---|---|---|"]
    for name, runs in residuals.items():
        if not runs:
            continue
        over = sum(r > RESIDUAL_TOLERANCE for r in runs)
        lines.append(f"| {name} | {len(runs)} | {', '.join(f'{r:.2g}' for r in runs)} | "
                     f"{'yes' if not over else f'{len(runs) - over} of {len(runs)}'} |")
    return "\n".join(lines)
