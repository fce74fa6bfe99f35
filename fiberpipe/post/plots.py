"""PNG plots of a simulation (matplotlib, Agg backend: no screen needed)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from fiberpipe.post.energies import ABAQUS_NAMES  # noqa: E402


def _save(fig, path: Path) -> Path:
    """Save a figure atomically (temporary file, then rename) and close it."""
    from fiberpipe.artifacts import atomic_path

    fig.tight_layout()
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)
    return path


def plot_force_displacement(path: Path, curves: dict[str, tuple[np.ndarray, np.ndarray]], *, title: str = "",
                            phases: dict | None = None) -> Path:
    """One or several F(U) curves; ``curves`` maps a label to (U in m, F in N). ``phases``
    (:func:`fiberpipe.post.phases.compaction_phases` of the first curve) shades the transition and
    the steep rise. Curves whose peaks span more than two decades share a symmetric-log load axis
    (linear below 1 % of the smallest peak), so that a 1 N run stays readable beside a 1 kN one."""
    fig, ax = plt.subplots(figsize=(6, 4))
    for label, (U, F) in curves.items():
        ax.plot(np.asarray(U) * 1e3, F, label=label)
    u1 = (phases or {}).get("rearrangement_end_U_m")
    if u1 is not None:
        u_end = max(float(np.max(np.asarray(U))) for U, _ in curves.values()) * 1e3
        u2 = phases.get("steep_start_U_m")
        ax.axvspan(u1 * 1e3, (u2 * 1e3 if u2 is not None else u_end), color="C1", alpha=0.12, lw=0,
                   label="transition")
        if u2 is not None:
            ax.axvspan(u2 * 1e3, u_end, color="C3", alpha=0.12, lw=0, label="steep rise")
        ax.legend(fontsize=8)
    ax.set_xlabel("plate displacement U [mm]")
    ax.set_ylabel("compaction load F [N]")
    peaks = [float(np.max(np.abs(F))) for _, F in curves.values() if np.size(F)]
    peaks = [p for p in peaks if p > 0]
    if len(peaks) > 1 and max(peaks) > 100 * min(peaks):
        ax.set_yscale("symlog", linthresh=0.01 * min(peaks))
        ax.set_ylabel("compaction load F [N] (symmetric log)")
    ax.grid(alpha=0.3)
    if len(curves) > 1:
        ax.legend(fontsize=8 if len(curves) > 4 else None, loc="upper left")
    if title:
        ax.set_title(title)
    return _save(fig, path)


def plot_energies(path: Path, x: np.ndarray, energy: dict[str, np.ndarray], *, xlabel: str, quasi_static_fail=None) -> Path:
    fig, ax = plt.subplots(figsize=(6, 4))
    for name, series in energy.items():
        if name == "residual":
            continue
        label = f"{name} ({ABAQUS_NAMES[name]})" if name in ABAQUS_NAMES else name
        ax.plot(x, np.abs(series), label=label)
    if quasi_static_fail is not None and np.any(quasi_static_fail):
        ax.fill_between(x, 0, 1, where=quasi_static_fail, transform=ax.get_xaxis_transform(), color="red", alpha=0.08, label="K_e > 1e-2 S_e")
    ax.set_yscale("symlog", linthresh=1e-9)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("energy [J]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    return _save(fig, path)


def plot_series(path: Path, x: np.ndarray, ys: dict[str, np.ndarray], *, xlabel: str, ylabel: str, logy: bool = False) -> Path:
    fig, ax = plt.subplots(figsize=(6, 4))
    for label, y in ys.items():
        ax.plot(x, y, label=label)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if logy:
        ax.set_yscale("log")
    ax.grid(alpha=0.3)
    if len(ys) > 1:
        ax.legend(fontsize=8)
    return _save(fig, path)


def plot_loops(path: Path, U_m: np.ndarray, F_N: np.ndarray, segment: np.ndarray) -> Path:
    """Load against plate displacement on a loading path, one colour per path segment."""
    fig, ax = plt.subplots(figsize=(6, 4))
    U, F, seg = np.asarray(U_m) * 1e3, np.asarray(F_N), np.asarray(segment).astype(int)
    for k in np.unique(seg):
        sel = np.flatnonzero(seg == k)
        sel = np.concatenate([[sel[0] - 1], sel]) if sel[0] > 0 else sel  # join the segments
        # later segments drawn thinner and every other one dashed: a move that retraces an earlier
        # one leaves it visible beneath
        ax.plot(U[sel], F[sel], color=f"C{k % 10}", ls="--" if k % 2 else "-", lw=max(3.0 - 0.8 * k, 0.8),
                label=f"segment {k}")
    ax.set_xlabel("plate displacement U [mm]")
    ax.set_ylabel("compaction load F [N]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, path)
