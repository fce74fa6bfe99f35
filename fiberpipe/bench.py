"""``fiberpipe bench``: the performance benchmarks in one run, written to ``docs/benchmarks.md``
(between the page's ``fiberpipe bench`` markers; the text around them is kept) with the machine,
the command and the date.

Parts (each can be skipped with ``--skip``):

* ``solver``  — element-steps per second, 40/160/640/1000 fibers of 50 elements, contact off and on
  (:mod:`fiberpipe.benchmarks.bench_solver`);
* ``contact`` — ns per candidate pair of the contact pass, loose and squeezed bundles, per law
  (:mod:`fiberpipe.benchmarks.bench_contact`);
* ``pyelastica`` — the same 40-rod bundle with contact in PyElastica and in fiberpipe, same steps,
  as a ratio (:mod:`fiberpipe.benchmarks.bench_pyelastica`; needs the ``bench`` extra);
* ``paper40`` — time-to-solution of ``configs/paper-40.yaml`` at the study's settings (and the fast
  settings of ``FAST_OVERRIDES``): wall time, U reached, final load;
* ``imaging`` — the imaging stages' wall time and peak memory on a 200×400×1000 volume
  (:mod:`fiberpipe.benchmarks.bench_imaging`, part b; ``--quick``: a quarter of the length);
* ``threads`` — ``solver.threads: 2`` against one thread at 160, 640 and 1000 fibers, alternating in one
  process (:mod:`fiberpipe.benchmarks.bench_threads`).

Everything it runs is in the package: outside a source checkout the paper-40 scene is the copy in
``fiberpipe/benchmarks/data/`` and the page defaults to ``./benchmarks.md``. Measure on an idle
machine: the load average is recorded with every part. The developer's measurements (A/B against a
reference checkout, profiles, the largest stable step, one-off studies) are scripts of the source
checkout's ``benchmarks/`` folder, run by the Makefile's targets (docs/benchmarks.md).
"""

from __future__ import annotations

import datetime as _dt
import os
import platform
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CHECKOUT = (ROOT / "pyproject.toml").exists() and (ROOT / "configs" / "paper-40.yaml").exists()
PACKAGED_PAPER40 = Path(__file__).resolve().parent / "benchmarks" / "data" / "paper-40.yaml"
BEGIN = "<!-- fiberpipe bench: begin (generated, replaced by every run) -->"
END = "<!-- fiberpipe bench: end -->"
PARTS = ("solver", "contact", "pyelastica", "paper40", "imaging", "threads")
# the time step of the paper-40 row "stable step per active mode" (docs/benchmarks.md), with the
# margin documented there: 0.85 of the beams' modal limit keeps the compacted bundle below its
# contact-inclusive limit (0.95 of it, the study settings' margin, does not)
MODES_OVERRIDES = {"solver.stable_step": "modes", "solver.dt_safety": 0.85}
# the fastest setting of docs/benchmarks.md, "Fast settings", within 2 %: mass scaling 100 with
# α/100 and the modal step; its load-cell curve is 1.44 % from the study settings' (0.23 mm window
# means; one run stands for its ensemble with the default contact)
FAST_OVERRIDES = {"solver.mass_scaling": 100, "scene.damping.alpha": "1e3 1/s", **MODES_OVERRIDES}
FAST_WINDOW_M = 0.23e-3  # window of the curve comparison


def _load(name: str):
    import importlib
    return importlib.import_module(f"fiberpipe.benchmarks.{name}")


def default_paper40_config() -> Path:
    """``configs/paper-40.yaml`` of a source checkout, else the copy shipped with the package."""
    return ROOT / "configs" / "paper-40.yaml" if CHECKOUT else PACKAGED_PAPER40


def default_page() -> Path:
    """``docs/benchmarks.md`` of a source checkout, else ``benchmarks.md`` in the working folder."""
    return ROOT / "docs" / "benchmarks.md" if CHECKOUT else Path("benchmarks.md")


def machine() -> str:
    cpu = platform.machine()
    try:
        cpu = next(l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo") if l.startswith("model name"))
    except Exception:
        pass
    import numba
    import numpy
    return (f"{cpu}, {os.cpu_count()} CPUs, Python {platform.python_version()}, numpy {numpy.__version__}, "
            f"numba {numba.__version__}, NUMBA_NUM_THREADS={os.environ.get('NUMBA_NUM_THREADS', 'default')}")


def load() -> str:
    a, b, c = os.getloadavg()
    return f"load average {a:.2f} / {b:.2f} / {c:.2f} (1/5/15 min)"


def config_mesh(cfg):
    """The mesh stage of ``cfg`` (its ``input.fibers``), run in a temporary folder and read back."""
    from fiberpipe.artifacts import read_mesh
    from fiberpipe.stages.mesh import run_mesh

    with tempfile.TemporaryDirectory() as td:
        mesh_path = Path(td) / "mesh.h5"
        run_mesh(cfg, Path(cfg.input.fibers), mesh_path)
        return read_mesh(mesh_path)


def paper40_run(overrides: dict | None = None, config: Path | None = None) -> dict:
    """Run ``configs/paper-40.yaml`` (mesh + simulate, in memory) and return the figures."""
    from fiberpipe.config import load_config
    from fiberpipe.solver.build import build_simulation
    from fiberpipe.solver import simulate

    config = config or default_paper40_config()
    cfg = load_config(config, overrides or {})
    model, effects, settings = build_simulation(config_mesh(cfg), cfg)
    first: list = []  # (wall, steps) at the end of the first jitted chunk (it includes compile / cache load)

    def progress(t_s, end_s, steps):
        if not first:
            first.append((time.perf_counter() - t0, steps))

    t0 = time.perf_counter()
    res = simulate(model, effects, settings, progress=progress)
    wall = time.perf_counter() - t0
    # the run's time without the first chunk's compile or cache load: the first chunk's steps at the
    # rate of the rest
    steady = wall
    if first and res.steps > first[0][1] > 0:
        w1, s1 = first[0]
        steady = (wall - w1) * res.steps / (res.steps - s1)
    h = res.history
    U = h["plate_displacement"][:, 0]
    F = h["plate_force"][:, 0]  # the moving (lower) plate's reaction: the load plus the drag of the fibers it sweeps
    F_cell = h["plate_force"][:, 1]  # the fixed upper plate: the study's load cell
    return {"overrides": dict(overrides or {}), "wall_s": wall, "wall_steady_s": steady,
            "first_chunk_s": first[0][0] if first else wall, "steps": int(res.steps), "elements": int(res.elements),
            "dt_s": float(res.dt_s), "elem_steps": float(res.steps) * res.elements,
            "Mes_per_s": res.steps * res.elements / wall / 1e6, "U_mm": float(U[-1] * 1e3),
            "F_final_N": float(F[-1]), "F_max_N": float(F.max()), "completed": bool(res.completed),
            "F_cell_final_N": float(F_cell[-1]), "F_cell_max_N": float(F_cell.max()),
            "U_curve": U.copy(), "F_curve": F.copy(), "F_cell_curve": F_cell.copy(), "t_curve": h["time"].copy()}


def load_curve(r: dict, key: str = "F_cell") -> dict | None:
    """The force curve ``key`` of a :func:`paper40_run` result as the ``U_curve``/``F_curve`` pair
    that :func:`curve_error` and :func:`curve_error_binned` read: ``"F_cell"`` the load cell (fixed
    upper plate, the study's measure), ``"F"`` the moving lower plate (the load plus the damping drag
    of the fibers it sweeps). None if ``r`` has no such curve (a failed run, or one saved without it)."""
    if f"{key}_curve" not in r or "U_curve" not in r:
        return None
    return {"U_curve": r["U_curve"], "F_curve": r[f"{key}_curve"]}


def curve_error(ref: dict, other: dict) -> float:
    """Largest |F − F_ref| over the loading, relative to the largest reference force, at equal U."""
    import numpy as np
    u_ref, f_ref = ref["U_curve"], ref["F_curve"]
    u, f = other["U_curve"], other["F_curve"]
    # loading branch only (U increasing), compared at the reference's U samples
    k = int(np.argmax(u_ref)) + 1
    kk = int(np.argmax(u)) + 1
    ui, order = np.unique(u[:kk], return_index=True)
    fi = np.interp(u_ref[:k], ui, f[:kk][order])
    return float(np.max(np.abs(fi - f_ref[:k])) / max(np.max(np.abs(f_ref[:k])), 1e-30))


def curve_error_binned(ref: dict, other: dict, window_m: float = 0.05e-3) -> float:
    """:func:`curve_error` on the mean load in U windows of ``window_m`` (0.05 mm): the largest
    |ΔF̄| over the windows, relative to the largest reference window mean.

    The pointwise error of two paper-40 runs is dominated by the timing of contact bursts (fibers
    snapping past each other), which any change of rounding moves: on the settled specimen the same
    settings with gravity perturbed by ±1e-8 differ by 25–29 % pointwise, by up to 8.9 % in 0.05 mm
    window means and 4.4 % in 0.23 mm ones (docs/benchmarks.md, "Fast settings").
    """
    import numpy as np
    u_ref = ref["U_curve"]
    edges = np.arange(0.0, float(np.max(u_ref)) + window_m, window_m)
    mr = window_means(u_ref, ref["F_curve"], edges)
    mo = window_means(other["U_curve"], other["F_curve"], edges)
    both = ~(np.isnan(mr) | np.isnan(mo))
    mr, mo = mr[both], mo[both]
    return float(np.max(np.abs(mo - mr)) / max(np.max(np.abs(mr)), 1e-30))


def window_means(U, F, edges):
    """Mean of F over the samples of the loading branch (up to the largest U) in each window
    ``[edges[w], edges[w + 1])`` of U; NaN where a window has none."""
    import numpy as np
    k = int(np.argmax(U)) + 1
    out = np.full(len(edges) - 1, np.nan)
    for w, (lo, hi) in enumerate(zip(edges[:-1], edges[1:])):
        sel = (U[:k] >= lo) & (U[:k] < hi)
        if sel.any():
            out[w] = F[:k][sel].mean()
    return out


def _threads_part(quick: bool, echo) -> list[str]:
    import subprocess
    import sys
    echo("bench: threads ...")
    args = [sys.executable, "-m", "fiberpipe.benchmarks.bench_threads"] + (["--fibers", "160", "--rounds", "4"] if quick else [])
    # the squeezed 1000-fiber bundle (contacts active): the scale row
    runs = [[]] if quick else [[], ["--no-contact"], ["--fibers", "1000", "--pitch", "1.98", "--steps", "100", "--rounds", "6"]]
    env = dict(os.environ, NUMBA_NUM_THREADS="2")
    body = []
    # without contact: the share of the step that runs in parallel (the contact pass is serial)
    for extra in runs:
        out = subprocess.run(args + extra, capture_output=True, text=True, env=env)
        rows = [l for l in out.stdout.splitlines() if l.startswith("|")]
        if not rows:
            body.append(f"failed{' ' + extra[0] if extra else ''}: {out.stderr.strip()[-300:]}")
        else:
            body += rows[2:] if any(b.startswith("|") for b in body) else rows  # one header
    return ["## Threads", "", f"`NUMBA_NUM_THREADS=2 python {' '.join(args[1:])} [--no-contact]` (wall time, alternating rounds in one "
            "process; the ratio holds only on an idle machine).", ""] + body + [""]


def _solver_part(quick: bool, steps: int | None, echo) -> list[str]:
    echo("bench: solver throughput ...")
    solver_bench = _load("bench_solver")
    n = steps or (200 if quick else 1000)
    rows = [solver_bench.measure(f, n, 3, c) for c in (False, True) for f in ((40, 160, 640) if quick else (40, 160, 640, 1000))]
    if not quick:  # the same bundles squeezed (pitch 1.98 r): the contact and friction passes on active pairs
        rows += [solver_bench.measure(f, n, 3, c, pitch_r=1.98) for c in (False, True) for f in (40, 1000)]
    return ["## Solver throughput", "",
            f"`python -m fiberpipe.benchmarks.bench_solver` (one thread, best of 3 calls of {n} steps; {load()}). "
            "Scene in the script's docstring: wavy fibers on a grid of pitch 2.2 r (and squeezed, 1.98 r), clamps, "
            "damping, gravity; contact = hertz_oriented with friction.", ""] + solver_bench.table(rows) + [""]


def _contact_part(quick: bool, echo) -> list[str]:
    echo("bench: contact pass ...")
    contact_bench = _load("bench_contact")
    rows = contact_bench.main(["--repeats", "20" if quick else "100"])
    return ["## Contact pass", "",
            f"`python -m fiberpipe.benchmarks.bench_contact` (40 fibers × 50 elements, hex bundle, 2 Gauss points; "
            f"{load()}).", "", *contact_bench.table_lines(rows), ""]


def _pyelastica_part(quick: bool, echo) -> list[str]:
    echo("bench: PyElastica ...")
    pyelastica_bench = _load("bench_pyelastica")
    try:
        result = pyelastica_bench.measure(steps=20 if quick else 100, repeats=1 if quick else 3)
    except ImportError as exc:
        return ["## PyElastica", "", f"not run: {exc} (install the bench extra: `pip install -e '.[bench]'`)", ""]
    lines = ["## Against PyElastica (same 40-rod bundle, contact on, same steps)", "",
             f"`python -m fiberpipe.benchmarks.bench_pyelastica` ({load()}).", "",
             "| code | elements | steps | dt (s) | wall (s) | k element-steps/s |", "|---|---|---|---|---|---|"]
    for d in (result["fiberpipe"], result["pyelastica"]):
        lines.append(f"| {d['code']} | {d['elements']} | {d['steps']} | {d['dt']:.3g} | {d['seconds']:.3f} | "
                     f"{d['elem_steps_per_s'] / 1e3:.0f} |")
    return lines + ["", f"fiberpipe / PyElastica per element-step: **{result['ratio']:.0f}×** (target ≥ 100×).", ""]


def _paper40_rows(quick: bool, echo) -> tuple[list, list[str]]:
    """``([(settings name, paper40_run result, curve error or None)], [runs that did not complete])``:
    the fast settings only with ``quick``, else the study settings, the modal step and the fast settings."""
    fast_name = ", ".join(f"{k} = {v}" for k, v in FAST_OVERRIDES.items())
    if quick:  # the fast settings only (~10 s); the study settings take ~2 min
        echo(f"bench: paper-40 fast settings {FAST_OVERRIDES} (--quick: not the study settings) ...")
        return [(fast_name, paper40_run({**FAST_OVERRIDES, "solver.output_frames": 2}), None)], []
    echo("bench: paper-40 time-to-solution (study settings) ...")
    study = paper40_run({"solver.output_frames": 2})
    rows = [("study settings", study, None)]
    echo(f"bench: paper-40 {MODES_OVERRIDES} ...")
    modes = paper40_run({**MODES_OVERRIDES, "solver.output_frames": 2})
    rows.append(("solver.stable_step = modes", modes,
                 curve_error_binned(load_curve(study), load_curve(modes), FAST_WINDOW_M)))
    echo(f"bench: paper-40 fast settings {FAST_OVERRIDES} ...")
    try:
        fast = paper40_run({**FAST_OVERRIDES, "solver.output_frames": 2})
    except Exception as exc:  # a diverging fast setting must not lose the study-settings figure
        echo(f"bench: fast settings failed: {exc}")
        return rows, [f"{fast_name}: {type(exc).__name__}: {str(exc)[:300]}"]
    rows.append((fast_name, fast, curve_error_binned(load_curve(study), load_curve(fast), FAST_WINDOW_M)))
    return rows, []


def _paper40_part(quick: bool, echo) -> list[str]:
    rows, diverged = _paper40_rows(quick, echo)
    lines = ["## Time to solution: configs/paper-40.yaml", "",
             f"Mesh + simulate in one process, one thread ({load()}). Load = load cell (upper plate).", "",
             "| settings | steps | element-steps | dt (s) | wall (s) | without first-chunk compile/load (s) | M element-steps/s | U reached (mm) | final load (N) | max load (N) | curve vs study settings (0.23 mm window means) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, r, err in rows:
        lines.append(f"| {name} | {r['steps']} | {r['elem_steps']:.3g} | {r['dt_s']:.3g} | {r['wall_s']:.1f} | "
                     f"{r['wall_steady_s']:.1f} | {r['Mes_per_s']:.2f} | {r['U_mm']:.4f} | {r['F_cell_final_N']:.4g} | "
                     f"{r['F_cell_max_N']:.4g} | {'—' if err is None else f'{100 * err:.2f} %'} |")
    return lines + [""] + [f"Not completed: {d}" for d in diverged] + ([""] if diverged else [])


def _imaging_part(quick: bool, echo) -> list[str]:
    echo("bench: imaging stages ...")
    imaging_bench = _load("bench_imaging")
    shape = (250, 200, 400) if quick else (1000, 200, 400)
    with tempfile.TemporaryDirectory() as td:
        head, stage_table, acc = imaging_bench.perf_part(shape, 12.0, [], Path(td))
    return [f"## Imaging stages, {shape[0]}×{shape[1]}×{shape[2]} voxels", "",
            f"`python -m fiberpipe.benchmarks.bench_imaging` part (b) ({load()}). {head}", "", stage_table, "", acc, ""]


def _write_between_markers(out: Path, text: str) -> None:
    """``text`` replaces the page's generated block (between :data:`BEGIN` and :data:`END`), or
    ends the page when it has none."""
    out.parent.mkdir(parents=True, exist_ok=True)
    old = out.read_text() if out.exists() else "# fiberpipe benchmarks\n\n"
    if BEGIN in old and END in old:
        new = old[: old.index(BEGIN)] + text + old[old.index(END) + len(END) + 1:]
    else:
        new = old.rstrip("\n") + "\n\n" + text
    out.write_text(new)


def run_bench(out: Path | None = None, *, quick: bool = False, skip=(), steps: int | None = None,
              echo=print) -> str:
    """The parts of :data:`PARTS` not in ``skip``, written between the markers of ``out`` (default
    :func:`default_page`) with the date, the machine and the command; returns the block."""
    out = Path(out) if out else default_page()
    started = _dt.datetime.now(_dt.timezone.utc)
    cmd = "fiberpipe bench" + (" --quick" if quick else "") + "".join(f" --skip {s}" for s in skip)
    parts = {"solver": lambda: _solver_part(quick, steps, echo), "contact": lambda: _contact_part(quick, echo),
             "pyelastica": lambda: _pyelastica_part(quick, echo), "paper40": lambda: _paper40_part(quick, echo),
             "imaging": lambda: _imaging_part(quick, echo), "threads": lambda: _threads_part(quick, echo)}
    sections = [line for name in PARTS if name not in skip for line in parts[name]()]
    text = "\n".join([
        BEGIN, "", "## Latest `fiberpipe bench` run", "",
        f"- date: {started.strftime('%Y-%m-%d %H:%M UTC')}",
        f"- machine: {machine()}",
        f"- command: `{cmd}`",
        "", *[l.replace("## ", "### ", 1) if l.startswith("## ") else l for l in sections], END]) + "\n"
    _write_between_markers(out, text)
    return text
