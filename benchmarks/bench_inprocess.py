"""This code's step loop against a reference checkout's, in one process, from one saved state.

    python benchmarks/bench_inprocess.py --reference CHECKOUT [--state STATE.npz]
        [--config CONFIG.yaml] [--threads N] [--steps 200] [--rounds 20] [--clock wall|cpu]

Both sides advance their own copy of the state (paper-40's scene from this checkout's config, or
``--config``'s; from rest without ``--state``) by ``--steps`` steps per round, the sides
alternating and the order flipping every round; each block is timed by the wall clock. The
figures: each side's best and median block (µs per step), the median of the rounds' ratios (this
code / reference), the ratio of the best blocks, and each side's Σ|x| at the end (equal to the last
digit when a change leaves the results as they are). ``--reference .`` runs this code against a copy of itself: its ratios are the method's own
bias (about 1.01–1.03 for paper-40 on two threads).

Why one process: on a shared virtual machine the same code and state ran up to 1.8× slower in one
process than in another started minutes later (docs/benchmarks.md), so the worker-per-side
comparison of ``benchmarks/bench_ab.py`` cannot tell a few percent apart; blocks
alternated within one process see the same machine. The reference needs this code's interface for
states and scenes (``benchmarks.scenes.scene``, ``load_state``, ``solver.Integrator``); for
older commits use ``bench_ab``.
"""

from __future__ import annotations

# Strategy: the reference's package is mirrored into a folder of the temporary directory under
# another name (``fpref``), its absolute imports of ``fiberpipe`` rewritten; a file is rewritten
# only when its text changed, so numba's cache beside the mirror (keyed on each file's time stamp)
# stays valid from one run to the next and only the first run compiles the reference's kernels.

import argparse
import hashlib
import importlib
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

MIRROR_NAME = "fpref"
_IMPORT = re.compile(r"\b(from|import) fiberpipe\b")


def mirror_package(checkout: Path, root: Path | None = None, name: str = MIRROR_NAME) -> Path:
    """The folder holding ``name``, a copy of ``checkout/fiberpipe`` whose ``from fiberpipe`` and
    ``import fiberpipe`` read ``name``; files whose text is unchanged keep their time stamp."""
    src = Path(checkout).resolve() / "fiberpipe"
    if not (src / "__init__.py").is_file():
        raise SystemExit(f"error: {checkout}: no fiberpipe package in it (give the checkout's root folder)")
    if root is None:
        key = hashlib.sha1(str(src).encode()).hexdigest()[:12]
        root = Path(tempfile.gettempdir()) / f"fiberpipe-inprocess-{key}"
    dst = root / name
    wanted = set()
    for path in src.rglob("*"):
        if "__pycache__" in path.parts or path.is_dir():
            continue
        out = dst / path.relative_to(src)
        wanted.add(out)
        data = path.read_bytes()
        if path.suffix == ".py":
            data = _IMPORT.sub(lambda m: f"{m.group(1)} {name}", data.decode()).encode()
        if out.is_file() and out.read_bytes() == data:
            continue
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_bytes(data)
    for path in list(dst.rglob("*")):  # files the reference no longer has
        if path.is_file() and "__pycache__" not in path.parts and path not in wanted:
            path.unlink()
    return root


def _scene_module(package: str):
    """The side's scene and state loaders: ``benchmarks.scenes`` of the package, or
    ``benchmarks.paper40_states`` of versions that shipped it in the package."""
    for name in ("benchmarks.scenes", "benchmarks.paper40_states"):
        try:
            return importlib.import_module(f"{package}.{name}")
        except ImportError:
            continue
    raise ImportError(f"no {package}.benchmarks.scenes")


def _side(package: str, config: Path, state: Path | None, threads: int, warmup: int):
    """``(integrator, state)`` of one side, advanced by ``warmup`` steps (its kernels compiled or
    loaded)."""
    # each side's own scene and state loaders, the ones every version since the named interfaces
    # has (not scene_and_state, which older references lack)
    try:
        scenes = _scene_module(package)
        solver = importlib.import_module(f"{package}.solver")
        model, effects, _, dt = scenes.scene(config=config)
        state_now = scenes.load_state(state) if state is not None else solver.State.at_rest(model)
        integrator = solver.Integrator(model, effects, dt, history_rows=10, history_every=10**9, threads=threads)
    except (ImportError, AttributeError, TypeError) as e:
        raise SystemExit(f"error: {package}: no benchmarks.scenes.scene/load_state or Integrator as this code's "
                         f"({e}); compare older commits with bench_ab") from None
    if state_now.x.shape[0] != model.n_nodes:
        raise SystemExit(f"error: {state}: a state of {state_now.x.shape[0]} nodes, the scene has {model.n_nodes} "
                         f"(give the state's --config)")
    _advance(integrator, state_now, warmup, package)
    return integrator, state_now


def _advance(integrator, state, steps: int, package: str) -> None:
    status, done, bad = integrator.advance(state, steps)
    if status != 0 or done != steps:
        raise SystemExit(f"error: {package}: the run stopped after {done} of {steps} steps (status {status}, "
                         f"node {bad}): its blocks would not be comparable")


def load_sides(root: Path, *, state: Path | None = None, config: Path | None = None, threads: int = 1,
               warmup: int = 50) -> dict:
    """``{"reference": (integrator, state), "this code": (integrator, state)}``, the reference from its
    mirror in ``root`` (:func:`mirror_package`), each advanced by ``warmup`` steps; both sides read the
    same config (None: this code's paper-40)."""
    if config is None:
        from fiberpipe.bench import default_paper40_config

        config = Path(default_paper40_config())
    if str(root) not in sys.path:
        sys.path.insert(0, str(root))
    return {"reference": _side(MIRROR_NAME, config, state, threads, warmup),
            "this code": _side("fiberpipe", config, state, threads, warmup)}


def measure(root: Path, *, state: Path | None = None, config: Path | None = None, threads: int = 1,
            steps: int = 200, rounds: int = 20, warmup: int = 50, clock=time.perf_counter) -> dict:
    """Blocks of ``steps`` steps of both sides (:func:`load_sides`), alternated over ``rounds`` rounds
    in this process; µs per step of each block, per side, by ``clock`` (the wall clock, or
    ``time.process_time``: the CPU time of the process, which on a loaded machine leaves out the time
    it waits for a core)."""
    sides = load_sides(root, state=state, config=config, threads=threads, warmup=warmup)
    blocks = {name: [] for name in sides}
    for r in range(rounds):
        for name in (list(sides) if r % 2 == 0 else list(sides)[::-1]):
            integrator, state_now = sides[name]
            t0 = clock()
            _advance(integrator, state_now, steps, name)
            blocks[name].append(1e6 * (clock() - t0) / steps)
    ref, new = blocks["reference"], blocks["this code"]
    return {"blocks_us": blocks, "ratio_median": statistics.median(n / r for n, r in zip(new, ref)),
            "ratio_best": min(new) / min(ref), "abs_x_sum": {name: float(abs(st.x).sum()) for name, (_, st) in
                                                                sides.items()}}


def table(result: dict) -> list[str]:
    rows = ["| side | best (µs/step) | median (µs/step) | Σ|x| at the end (m) |", "|---|---|---|---|"]
    for name, us in result["blocks_us"].items():
        rows.append(f"| {name} | {min(us):.1f} | {statistics.median(us):.1f} | {result['abs_x_sum'][name]!r} |")
    rows.append(f"\nthis code / reference: median of the rounds' ratios {result['ratio_median']:.3f}, "
                f"best blocks {result['ratio_best']:.3f}")
    return rows


def _check_inputs(state: Path | None, config: Path | None) -> None:
    """A one-line error for a state that is not one ``fiberpipe.benchmarks.scenes.save_state`` wrote, or a config
    that does not load."""
    import numpy as np

    from fiberpipe.config import load_config
    from fiberpipe.errors import FiberpipeError

    if state is not None:
        try:
            with np.load(state) as d:
                missing = {"x", "q", "v", "w", "acc", "t", "step"} - set(d.files)
        except Exception as e:  # noqa: BLE001 (numpy raises OSError, ValueError, EOFError, BadZipFile...)
            raise SystemExit(f"error: {state}: not a saved state ({type(e).__name__}: {e})") from None
        if missing:
            raise SystemExit(f"error: {state}: not a saved state (no {', '.join(sorted(missing))})")
    if config is not None:
        try:
            load_config(config)
        except FiberpipeError as e:
            raise SystemExit(f"error: {config}: {e}") from None


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reference", type=Path, required=True, help="a checkout's root folder ('.': this one)")
    ap.add_argument("--state", type=Path, help="a saved state (benchmarks/paper40_states.py); default: from rest")
    ap.add_argument("--config", type=Path, help="the run config of the scene (default: paper-40's)")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--steps", type=int, default=200, help="steps per block")
    ap.add_argument("--rounds", type=int, default=20)
    ap.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                    help="time blocks by the wall clock or by the process's CPU time (a loaded machine)")
    ap.add_argument("--compile-only", type=Path, help=argparse.SUPPRESS)  # the mirror's folder
    args = ap.parse_args(argv)
    if args.threads < 1 or args.steps < 1 or args.rounds < 1:
        raise SystemExit("error: --threads, --steps and --rounds must be at least 1")
    # numba reads its thread count when it starts: before anything imports it
    if int(os.environ.get("NUMBA_NUM_THREADS", "0") or 0) < args.threads:
        os.environ["NUMBA_NUM_THREADS"] = str(args.threads)
    if args.compile_only:  # the parent checked the inputs and made the mirror
        load_sides(args.compile_only, state=args.state, config=args.config, threads=args.threads, warmup=1)
        return
    for path in (args.state, args.config):
        if path is not None and not path.is_file():
            raise SystemExit(f"error: {path}: no such file")
    _check_inputs(args.state, args.config)
    root = mirror_package(args.reference)  # a folder without the package: its one-line error here
    # both sides' kernels compiled and cached by a process of their own first: a kernel compiled in
    # the process that runs it calls its callees as compiled on their own, one loaded from the cache
    # runs its own copies of them, and the two ran 3–4 % apart on paper-40 (docs/reliability.md,
    # "Where bit for bit stops")
    opts = ["--reference", str(args.reference.resolve()), "--threads", str(args.threads), "--compile-only", str(root)]
    for flag, path in (("--state", args.state), ("--config", args.config)):
        if path is not None:
            opts += [flag, str(path.resolve())]
    package_root = str(Path(__file__).resolve().parents[1])  # this code, whatever the working folder
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, (package_root, os.environ.get("PYTHONPATH")))))
    child = subprocess.run([sys.executable, str(Path(__file__).resolve()), *opts], env=env)
    if child.returncode != 0:
        raise SystemExit(f"error: compiling the two sides failed (exit status {child.returncode})")
    result = measure(root, state=args.state, config=args.config, threads=args.threads, steps=args.steps,
                     rounds=args.rounds, clock=time.process_time if args.clock == "cpu" else time.perf_counter)
    print("\n".join(table(result)))


if __name__ == "__main__":
    main()
