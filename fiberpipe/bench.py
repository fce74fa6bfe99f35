"""``fiberpipe bench``: the performance benchmarks in one run, written to ``docs/benchmarks.md``
(between the page's ``fiberpipe bench`` markers; the text around them is kept) with the machine,
the command and the date.

Parts (each can be skipped with ``--skip``):

* ``solver``  — element-steps per second, 40/160/640 fibers of 50 elements, contact off and on
  (:mod:`fiberpipe.benchmarks.bench_solver`);
* ``contact`` — ns per candidate pair of the contact pass, loose and squeezed bundles, per law
  (:mod:`fiberpipe.benchmarks.bench_contact`);
* ``pyelastica`` — the same 40-rod bundle with contact in PyElastica and in fiberpipe, same steps,
  as a ratio (:mod:`fiberpipe.benchmarks.bench_pyelastica`; needs the ``bench`` extra);
* ``paper40`` — time-to-solution of ``configs/paper-40.yaml`` at the study's settings (and the fast
  settings of ``FAST_OVERRIDES``): wall time, U reached, final load;
* ``imaging`` — the imaging stages' wall time and peak memory on a 200×400×1000 volume
  (:mod:`fiberpipe.benchmarks.bench_imaging`, part b; ``--quick``: a quarter of the length);
* ``reference`` — paper-40 against a checkout of the reference commit (``--reference``, or the
  environment variable ``FIBERPIPE_BENCH_REFERENCE``), alternating spans in one run
  (:mod:`fiberpipe.benchmarks.bench_ab`): the first 12 ms, and the whole loading with
  ``solver.stable_step: modes`` (time to solution);
* ``profile`` — where a paper-40 step spends its time, early (12 ms) and compacted (U ≈ 1 mm)
  (:mod:`fiberpipe.benchmarks.bench_profile`);
* ``threads`` — ``solver.threads: 2`` against one thread at 160 and 640 fibers, alternating in one
  process (:mod:`fiberpipe.benchmarks.bench_threads`).

Everything it runs is in the package: outside a source checkout the paper-40 scene is the copy in
``fiberpipe/benchmarks/data/`` and the page defaults to ``./benchmarks.md``. Measure on an idle
machine: the load average is recorded with every part.
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
PARTS = ("solver", "contact", "pyelastica", "paper40", "bundle400", "imaging", "reference", "profile", "threads")
# the time step of the paper-40 row "stable step per active mode" (docs/benchmarks.md), with the
# margin documented there: 0.85 of the beams' modal limit keeps the compacted bundle below its
# contact-inclusive limit (0.95 of it, the study settings' margin, does not)
MODES_OVERRIDES = {"solver.stable_step": "modes", "solver.dt_safety": 0.85}
# paper-40's first 12 ms in steps of the study settings (dt = 8.646e-8 s) and U ≈ 1 mm
PROFILE_STEPS = (138728, 708000)
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


def _reference_part(reference: Path | None, quick: bool, echo) -> list[str]:
    """Paper-40 against the reference checkout, alternating spans of simulated time in one run."""
    ba = _load("bench_ab")
    if reference is None:
        return ["## Against the reference commit", "",
                "not run: no reference checkout (`fiberpipe bench --reference PATH`, a checkout of the reference "
                "commit with its own `.venv`)", ""]
    reference = Path(reference).resolve()
    cfg = default_paper40_config().resolve()
    ref_cfg = reference / "configs" / "paper-40.yaml"
    for need in (reference / ".venv" / "bin" / "python", ref_cfg):
        if not need.exists():
            raise FileNotFoundError(f"--reference {reference}: no {need.relative_to(reference)} (a checkout of the "
                                    "reference commit after `make setup` there)")
    modes = [f"{k}={v}" for k, v in MODES_OVERRIDES.items()]
    cases = [("12 ms", 12e-3, 4 if quick else 10, [], 1)]
    if not quick:
        # the last case on two threads against the reference's one: compare its wall times
        cases += [("U = 1.15 mm", None, 10, [], 1), ("U = 1.15 mm", None, 10, modes, 1),
                  ("U = 1.15 mm", None, 10, modes + ["solver.threads=2"], 2)]
    rows = []
    for name, until, spans, new, threads in cases:
        echo(f"bench: against {reference}: paper-40 to {name} {' '.join(new)} ...")
        rows.append(ba.measure(reference, cfg, ref_cfg, until, spans, new, new_threads=threads))
    cmd = f"python -m fiberpipe.benchmarks.bench_ab --reference {reference}"
    return (["## Against the reference commit", "",
             f"`{cmd} --until 12ms --spans 10` and `{cmd} --spans 10 [--new solver.stable_step=modes "
             "--new solver.dt_safety=0.85 [--new solver.threads=2 --threads 2]]`: "
             f"the reference checkout `{reference}` and this code advance paper-40 alternately by equal spans "
             "of simulated time; CPU seconds of each worker (both see the same load), and their wall times "
             "(the ratio to compare for two threads, on an idle machine).", ""]
            + ba.HEADER + [l for r in rows for l in ba.lines(r, str(reference))] + [""])


def _profile_part(quick: bool, echo) -> list[str]:
    ps, bp = _load("paper40_states"), _load("bench_profile")
    steps = PROFILE_STEPS[:1] if quick else PROFILE_STEPS
    with tempfile.TemporaryDirectory() as td:
        base = Path(td) / "p40.npz"
        echo(f"bench: paper-40 states at steps {steps} ...")
        ps.main([str(base), *map(str, steps)])
        lines = bp.main([str(base.with_name(f"p40_{k}.npz")) for k in steps] + (["--steps", "1000"] if quick else []))
    return ["## Profile of a paper-40 step", "",
            "`python -m fiberpipe.benchmarks.paper40_states OUT.npz 138728 708000` then "
            "`python -m fiberpipe.benchmarks.bench_profile OUT_138728.npz OUT_708000.npz` (CPU time, best of 3 "
            "rotations of 3000 steps).", ""] + lines + [""]


def _bundle_part(quick: bool, echo) -> list[str]:
    """The 400-fiber specimen's cost per element-step against paper-40 (``make bench-400``): the
    specimen of ``configs/specimens/bundle-400.yaml`` is built once into ``runs/specimens/bundle-400``
    of the working folder (≈ 10 min) and reused."""
    import subprocess
    import sys

    head = ["## 400 fibers against paper-40", ""]
    specimen_cfg = default_paper40_config().parent / "specimens" / "bundle-400.yaml"
    if quick or not specimen_cfg.exists():
        why = "--quick" if quick else f"no {specimen_cfg} (a source checkout has it)"
        return head + [f"not run: {why} (`make bench-400`)", ""]
    run = Path("runs") / "specimens" / "bundle-400"
    if not (run / "config.yaml").exists():
        echo(f"bench: building the 400-fiber specimen into {run} (≈ 10 min) ...")
        subprocess.run([sys.executable, "-m", "fiberpipe.cli", "specimen", str(specimen_cfg), "--out", str(run)], check=True)
    echo("bench: 400 fibers against paper-40 ...")
    bb = _load("bench_bundle_cost")
    r = bb.measure(run / "config.yaml")
    return head + [f"`fiberpipe specimen {specimen_cfg.name} --out {run}` then `python -m fiberpipe.benchmarks.bench_bundle_cost "
                   f"{run}/config.yaml` (both scenes from rest, alternating, CPU time; {load()}).", ""] + bb.table(r) + [""]


def _threads_part(quick: bool, echo) -> list[str]:
    import subprocess
    import sys
    echo("bench: threads ...")
    args = [sys.executable, "-m", "fiberpipe.benchmarks.bench_threads"] + (["--fibers", "160", "--rounds", "4"] if quick else [])
    env = dict(os.environ, NUMBA_NUM_THREADS="2")
    body = []
    # without contact: the share of the step that runs in parallel (the contact pass is serial)
    for extra in ([[]] if quick else [[], ["--no-contact"]]):
        out = subprocess.run(args + extra, capture_output=True, text=True, env=env)
        rows = [l for l in out.stdout.splitlines() if l.startswith("|")]
        if not rows:
            body.append(f"failed{' ' + extra[0] if extra else ''}: {out.stderr.strip()[-300:]}")
        else:
            body += rows[2:] if any(b.startswith("|") for b in body) else rows  # one header
    return ["## Threads", "", f"`NUMBA_NUM_THREADS=2 {' '.join(args[1:])} [--no-contact]` (wall time, alternating rounds in one "
            "process; the ratio holds only on an idle machine).", ""] + body + [""]


def run_bench(out: Path | None = None, *, quick: bool = False, skip=(), steps: int | None = None,
              echo=print, reference: Path | None = None) -> str:
    out = Path(out) if out else default_page()
    started = _dt.datetime.now(_dt.timezone.utc)
    cmd = "fiberpipe bench" + (" --quick" if quick else "") + "".join(f" --skip {s}" for s in skip)
    sec: list[str] = []
    loads: dict = {}

    if "solver" not in skip:
        echo("bench: solver throughput ...")
        bs = _load("bench_solver")
        n = steps or (200 if quick else 1000)
        rows = [bs.measure(f, n, 3, c) for c in (False, True) for f in (40, 160, 640)]
        loads["solver"] = load()
        sec += ["## Solver throughput", "",
                f"`python -m fiberpipe.benchmarks.bench_solver` (one thread, best of 3 calls of {n} steps; {loads['solver']}). "
                "Scene in the script's docstring: wavy fibers on a grid of pitch 2.2 r, clamps, damping, "
                "gravity; contact = hertz_oriented with friction.", ""] + bs.table(rows) + [""]
    if "contact" not in skip:
        echo("bench: contact pass ...")
        bc = _load("bench_contact")
        rows = bc.main(["--repeats", "20" if quick else "100"])
        loads["contact"] = load()
        sec += ["## Contact pass", "",
                f"`python -m fiberpipe.benchmarks.bench_contact` (40 fibers × 50 elements, hex bundle, 2 Gauss points; {loads['contact']}).", "",
                *bc.table_lines(rows)]
        sec.append("")
    if "pyelastica" not in skip:
        echo("bench: PyElastica ...")
        bp = _load("bench_pyelastica")
        try:
            r = bp.measure(steps=20 if quick else 100, repeats=1 if quick else 3)
        except ImportError as exc:
            sec += ["## PyElastica", "", f"not run: {exc} (install the bench extra: `pip install -e '.[bench]'`)", ""]
        else:
            loads["pyelastica"] = load()
            fp, pe = r["fiberpipe"], r["pyelastica"]
            sec += ["## Against PyElastica (same 40-rod bundle, contact on, same steps)", "",
                    f"`python -m fiberpipe.benchmarks.bench_pyelastica` ({loads['pyelastica']}).", "",
                    "| code | elements | steps | dt (s) | wall (s) | k element-steps/s |", "|---|---|---|---|---|---|"]
            for d in (fp, pe):
                sec.append(f"| {d['code']} | {d['elements']} | {d['steps']} | {d['dt']:.3g} | {d['seconds']:.3f} | "
                           f"{d['elem_steps_per_s'] / 1e3:.0f} |")
            sec += ["", f"fiberpipe / PyElastica per element-step: **{r['ratio']:.0f}×** (target ≥ 100×).", ""]
    if "paper40" not in skip:
        fast_name = ", ".join(f"{k} = {v}" for k, v in FAST_OVERRIDES.items())
        diverged: list[str] = []
        if quick:  # the fast settings only (~10 s); the study settings take ~2 min
            echo(f"bench: paper-40 fast settings {FAST_OVERRIDES} (--quick: not the study settings) ...")
            rows = [(fast_name, paper40_run({**FAST_OVERRIDES, "solver.output_frames": 2}), None)]
        else:
            echo("bench: paper-40 time-to-solution (study settings) ...")
            ref = paper40_run({"solver.output_frames": 2})
            rows = [("study settings", ref, None)]
            echo(f"bench: paper-40 {MODES_OVERRIDES} ...")
            modes = paper40_run({**MODES_OVERRIDES, "solver.output_frames": 2})
            rows.append(("solver.stable_step = modes", modes,
                         curve_error_binned(load_curve(ref), load_curve(modes), FAST_WINDOW_M)))
            echo(f"bench: paper-40 fast settings {FAST_OVERRIDES} ...")
            try:
                fast = paper40_run({**FAST_OVERRIDES, "solver.output_frames": 2})
            except Exception as exc:  # a diverging fast setting must not lose the study-settings figure
                echo(f"bench: fast settings failed: {exc}")
                diverged.append(f"{fast_name}: {type(exc).__name__}: {str(exc)[:300]}")
            else:
                rows.append((fast_name, fast, curve_error_binned(load_curve(ref), load_curve(fast), FAST_WINDOW_M)))
        loads["paper40"] = load()
        sec += ["## Time to solution: configs/paper-40.yaml", "",
                f"Mesh + simulate in one process, one thread ({loads['paper40']}). Load = load cell (upper plate).", "",
                "| settings | steps | element-steps | dt (s) | wall (s) | without first-chunk compile/load (s) | M element-steps/s | U reached (mm) | final load (N) | max load (N) | curve vs study settings (0.23 mm window means) |",
                "|---|---|---|---|---|---|---|---|---|---|---|"]
        for name, r, err in rows:
            sec.append(f"| {name} | {r['steps']} | {r['elem_steps']:.3g} | {r['dt_s']:.3g} | {r['wall_s']:.1f} | {r['wall_steady_s']:.1f} | "
                       f"{r['Mes_per_s']:.2f} | {r['U_mm']:.4f} | {r['F_cell_final_N']:.4g} | {r['F_cell_max_N']:.4g} | "
                       f"{'—' if err is None else f'{100 * err:.2f} %'} |")
        sec += [""] + [f"Not completed: {d}" for d in diverged] + ([""] if diverged else [])
    if "bundle400" not in skip:
        sec += _bundle_part(quick, echo)
    if "imaging" not in skip:
        echo("bench: imaging stages ...")
        bi = _load("bench_imaging")
        shape = (250, 200, 400) if quick else (1000, 200, 400)
        with tempfile.TemporaryDirectory() as td:
            head, tab, acc = bi.perf_part(shape, 12.0, [], Path(td))
        loads["imaging"] = load()
        sec += [f"## Imaging stages, {shape[0]}×{shape[1]}×{shape[2]} voxels", "",
                f"`python -m fiberpipe.benchmarks.bench_imaging` part (b) ({loads['imaging']}). {head}", "", tab, "", acc, ""]
    if "reference" not in skip:
        reference = reference or os.environ.get("FIBERPIPE_BENCH_REFERENCE") or None
        sec += _reference_part(Path(reference) if reference else None, quick, echo)
        loads["reference"] = load()
    if "profile" not in skip:
        sec += _profile_part(quick, echo)
    if "threads" not in skip:
        sec += _threads_part(quick, echo)
    text = "\n".join([
        BEGIN, "", "## Latest `fiberpipe bench` run", "",
        f"- date: {started.strftime('%Y-%m-%d %H:%M UTC')}",
        f"- machine: {machine()}",
        f"- command: `{cmd}`",
        "", *[l.replace("## ", "### ", 1) if l.startswith("## ") else l for l in sec], END]) + "\n"
    out.parent.mkdir(parents=True, exist_ok=True)
    old = out.read_text() if out.exists() else "# fiberpipe benchmarks\n\n"
    if BEGIN in old and END in old:
        new = old[: old.index(BEGIN)] + text + old[old.index(END) + len(END) + 1:]
    else:
        new = old.rstrip("\n") + "\n\n" + text
    out.write_text(new)
    return text
