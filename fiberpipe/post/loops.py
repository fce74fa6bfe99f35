"""Loading cycles of a ``scene.loading.path``: the closed loops, their dissipated energy, and the
residual strain after each unloading.

A cycle is two consecutive moves of opposite direction whose second returns to the first one's start
travel (an unloading then a reloading past the unloading's start, or a loading then an unloading back
to its start); a move belongs to one cycle at most, the earliest. The loop runs from the history row
before the first move to the row where the second move crosses back to the start travel, its end
interpolated linearly in U.

Its plate work ``W`` is the change of the prescribed-motion work (``energy/external``, ALLWK, booked
at every step as the plates' reaction times their travel increment) over the loop: the plates' work on
the bundle when no load, gravity or drive acts (these add their own work to ALLWK). ``loop_area`` is
``Σ_plates ∮ F dU`` (F the reaction, positive when pressed; U the travel towards the bundle) by the
trapezoid rule on the recorded rows only: the area of the plotted loop, which misses the force's
fluctuations between rows (12 % less than W on a three-fiber cycle with friction recorded every 56
steps). Over a closed loop W equals the energy dissipated (friction + damping) plus the change of the
stored energy (strain + kinetic + contact stored, state functions), which the energy columns give
independently: ``balance_error`` = (W − dissipated − Δstored)/W.

The residual strain after an unloading is U/H₀ at the first history row of the unloading move whose
load-cell force falls to ``unloaded_fraction`` of the run's peak load or below (the plate has left the
bundle), H₀ the plates' initial gap; none when the load stays above it to the move's end.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

#: the load-cell force (× the run's peak load) below which an unloading plate has left the bundle
UNLOADED_FRACTION = 1e-2

#: the energy columns whose change over a loop is the stored energy's (state functions)
STORED_COLUMNS = ("strain", "kinetic_leapfrog", "contact_stored")
#: the energy columns whose change over a loop is the dissipated energy
DISSIPATED_COLUMNS = ("friction", "damping")


@dataclass
class Cycle:
    """One closed loading cycle (SI)."""

    cycle: int
    first_segment: int
    start_U_m: float
    turn_U_m: float
    t_start_s: float
    t_end_s: float
    plate_work_J: float          # Δ energy/external over the loop (nan without energies)
    loop_area_J: float           # Σ ∮ F dU over the recorded rows
    dissipated_J: float          # Δ(friction + damping) over the loop (nan without energies)
    stored_change_J: float       # Δ(strain + kinetic_leapfrog + contact_stored) (nan without energies)
    balance_error: float         # (W − dissipated − Δstored) / W


@dataclass
class Unloading:
    """The residual strain after one unloading move."""

    segment: int
    from_U_m: float
    to_U_m: float
    residual_U_m: float | None   # the travel at which the load fell to the unloaded threshold
    residual_strain: float | None  # residual_U_m / H₀
    load_at_end_N: float


def segment_runs(segment: np.ndarray) -> list[tuple[int, int, int]]:
    """``(segment, first row, last row + 1)`` of each run of equal segment indices, in order."""
    seg = np.asarray(segment).astype(np.int64)
    if seg.size == 0:
        return []
    cut = np.flatnonzero(np.diff(seg)) + 1
    starts = np.concatenate([[0], cut])
    ends = np.concatenate([cut, [seg.size]])
    return [(int(seg[a]), int(a), int(b)) for a, b in zip(starts, ends)]


def _plate_work(U: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Cumulative Σ_c ∫ F_c dU_c (J) over the rows, trapezoid rule; U, F (T, C)."""
    dW = 0.5 * (F[1:] + F[:-1]) * np.diff(U, axis=0)
    return np.concatenate([[0.0], np.cumsum(dW.sum(axis=1))])


def _at(x: np.ndarray, i: int, frac: float) -> float:
    """x interpolated between rows i − 1 and i (frac = 1: row i)."""
    return float(x[i - 1] + frac * (x[i] - x[i - 1])) if i > 0 else float(x[i])


def _closing_row(u: np.ndarray, a: int, b: int, u_start: float, upward: bool) -> tuple[int, float] | None:
    """First row in [a, b) where the travel u crosses back to ``u_start`` (upward: from below), with
    the interpolation fraction from the row before; None if it never does."""
    hit = np.flatnonzero(u[a:b] >= u_start) if upward else np.flatnonzero(u[a:b] <= u_start)
    if hit.size == 0:
        return None
    i = a + int(hit[0])
    if i == 0:
        return i, 1.0
    du = u[i] - u[i - 1]
    return i, float((u_start - u[i - 1]) / du) if du != 0 else 1.0


def loading_cycles(time_s, segment, plate_U_m, plate_F_N, energy: dict | None = None) -> list[Cycle]:
    """The closed cycles of a loading path (module docstring).

    time_s : (T,) s; segment : (T,) the history's path segment; plate_U_m, plate_F_N : (T, C) each
    plate's travel towards the bundle and reaction; energy : the history's energy columns (J).
    """
    t = np.asarray(time_s, float)
    U = np.asarray(plate_U_m, float).reshape(t.size, -1)
    F = np.asarray(plate_F_N, float).reshape(t.size, -1)
    moving = int(np.argmax(np.abs(U).max(axis=0))) if U.size else 0
    u = U[:, moving]
    W = _plate_work(U, F)
    runs = segment_runs(segment)
    out: list[Cycle] = []
    used = -1
    for k in range(len(runs) - 1):
        (s0, a0, b0), (s1, a1, b1) = runs[k], runs[k + 1]
        if k <= used or s1 != s0 + 1:
            continue
        u_start = float(u[a0 - 1]) if a0 > 0 else 0.0
        u_turn = float(u[b0 - 1])
        if u_turn == u_start:
            continue
        upward = u_turn < u_start  # an unloading first: the reloading closes the loop from below
        close = _closing_row(u, a1, b1, u_start, upward)
        if close is None:
            continue
        i, frac = close
        i0 = max(a0 - 1, 0)
        area = _at(W, i, frac) - float(W[i0])
        energy = energy or {}

        def delta(names):
            cols = [np.asarray(energy[n], float) for n in names if n in energy]
            return sum(_at(c, i, frac) - float(c[i0]) for c in cols) if cols else float("nan")
        work, diss, stored = delta(("external",)), delta(DISSIPATED_COLUMNS), delta(STORED_COLUMNS)
        err = (work - diss - stored) / work if work != 0 else float("nan")
        out.append(Cycle(len(out), s0, u_start, u_turn, float(t[i0]), _at(t, i, frac), work, area, diss, stored,
                         err))
        used = k + 1
    return out


def residual_strains(segment, U_m, F_N, gap_m: float, *, unloaded_fraction: float = UNLOADED_FRACTION
                     ) -> list[Unloading]:
    """The residual strain after each unloading move (module docstring). U_m, F_N: (T,) the moving
    plate's travel and the load-cell force; gap_m: the plates' initial gap H₀."""
    U, F = np.asarray(U_m, float), np.asarray(F_N, float)
    threshold = unloaded_fraction * max(float(np.max(F)) if F.size else 0.0, 0.0)
    out = []
    for s, a, b in segment_runs(segment):
        u_from = float(U[a - 1]) if a > 0 else 0.0
        if not U[b - 1] < u_from:
            continue
        hit = np.flatnonzero(F[a:b] <= threshold)
        res_u = float(U[a + int(hit[0])]) if hit.size else None
        strain = res_u / gap_m if res_u is not None and gap_m > 0 else None
        out.append(Unloading(s, u_from, float(U[b - 1]), res_u, strain, float(F[b - 1])))
    return out


def _columns(items) -> dict[str, np.ndarray]:
    """Dataclass rows as CSV columns (the field names carry the units); None as nan."""
    rows = [asdict(c) for c in items]
    names = list(rows[0]) if rows else []
    return {n: np.array([np.nan if r[n] is None else r[n] for r in rows], dtype=float) for n in names}


def plate_gap_m(cfg, mesh) -> float:
    """The plates' initial gap H₀ (m): their configured positions, else touching the bundle (as the
    solver places them)."""
    p = cfg.scene.plates
    ax = {"x": 0, "y": 1, "z": 2}[p.axis]
    r = np.repeat(np.asarray(mesh.radius_m, float), np.diff(np.asarray(mesh.node_offsets)))
    c = np.asarray(mesh.nodes_m, float)[:, ax]
    lo = float(p.lower_position) if p.lower_position is not None else float(np.min(c - r))
    hi = float(p.upper_position) if p.upper_position is not None else float(np.max(c + r))
    return hi - lo


def write_loops(out_dir, cfg, sim, U_m, F_N) -> tuple[list[str], dict]:
    """``loading_cycles.csv``, ``unloadings.csv`` and ``loops.png`` of a run on a loading path;
    returns the files written and the summary entries."""
    from fiberpipe.post import plots
    from fiberpipe.post.tables import write_csv

    h = sim.history
    seg = np.asarray(h["segment"])
    cycles = loading_cycles(h["time"], seg, h["plate_displacement"], h["plate_force"], sim.energy)
    gap = plate_gap_m(cfg, sim.mesh)
    unloads = residual_strains(seg, U_m, F_N, gap)
    write_csv(out_dir / "loading_cycles.csv", _columns(cycles))
    write_csv(out_dir / "unloadings.csv", _columns(unloads))
    plots.plot_loops(out_dir / "loops.png", U_m, F_N, seg)
    summary = {"plate_gap_m": gap, "loading_cycles": [asdict(c) for c in cycles],
               "unloadings": [asdict(u) for u in unloads]}
    return ["loading_cycles.csv", "unloadings.csv", "loops.png"], summary


def report_lines(summary: dict, fmt) -> list[str]:
    """The report's loading-cycle tables (``fmt(value, unit)`` formats a number)."""
    cycles, unloads = summary.get("loading_cycles"), summary.get("unloadings")
    if cycles is None and unloads is None:
        return []
    lines = ["", "## Loading cycles", "",
             "Over each closed loop: plate work W = Δ ALLWK (the energy the cycle dissipates, once the state "
             "returns); loop area = ∮F dU over the recorded rows; dissipated = Δ(friction + damping); Δ stored = "
             "Δ(strain + kinetic + contact stored) (docs/outputs.md).", ""]
    if cycles:
        lines += ["| cycle | U start → turn | plate work W | loop area | dissipated | Δ stored | "
                  "(W − dissipated − Δstored)/W |", "| --- | --- | --- | --- | --- | --- | --- |"]
        lines += [f"| {c['cycle']} | {fmt(c['start_U_m'] * 1e3, 'mm')} → {fmt(c['turn_U_m'] * 1e3, 'mm')} | "
                  f"{fmt(c['plate_work_J'], 'J')} | {fmt(c['loop_area_J'], 'J')} | {fmt(c['dissipated_J'], 'J')} | "
                  f"{fmt(c['stored_change_J'], 'J')} | {fmt(c['balance_error'])} |" for c in cycles]
    else:
        lines.append("No closed cycle: no move returns to the start of the move before it.")
    if unloads:
        lines += ["", "| unloading (segment) | U from → to | residual U | residual strain | load at its end |",
                  "| --- | --- | --- | --- | --- |"]
        lines += [f"| {u['segment']} | {fmt(u['from_U_m'] * 1e3, 'mm')} → {fmt(u['to_U_m'] * 1e3, 'mm')} | "
                  f"{fmt(None if u['residual_U_m'] is None else u['residual_U_m'] * 1e3, 'mm')} | "
                  f"{fmt(u['residual_strain'])} | {fmt(u['load_at_end_N'], 'N')} |" for u in unloads]
    return lines
