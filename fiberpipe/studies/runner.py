"""Where the runs of a study, a fit or an ensemble go: this process, a local process pool, a local
Dask cluster or the Dask scheduler at an address (:func:`execute`), each run by the ordinary cached
pipeline (:func:`_run_point`)."""

from __future__ import annotations

import copy
import os
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import yaml

from fiberpipe.artifacts import write_text_atomic
from fiberpipe.config import validate_config
from fiberpipe.errors import ConfigError


_WARM: set = set()


def _warm_up(raw: dict, cfg, where: str) -> None:
    """Compile (or load from numba's cache) this scene's kernels once per process before a timed
    run, so that the first point's wall time does not include JIT compilation: the same config
    for a few dozen steps, into a throw-away folder."""
    key = tuple(sorted(cfg.scene.effects)) + (str(getattr(cfg.scene.contact, "law", "")),)
    if key in _WARM:
        return
    _WARM.add(key)
    import tempfile

    from fiberpipe.pipeline import run_pipeline

    w = copy.deepcopy(raw)
    w.setdefault("solver", {})
    w["solver"]["end_time"] = 2e-6
    w["solver"]["output_frames"] = 2
    w["solver"].pop("checkpoint_every", None)
    w.setdefault("post", {})
    w["post"]["plots"] = False
    try:
        wcfg = validate_config(w, where=where)
        with tempfile.TemporaryDirectory(prefix="fiberpipe-warm-") as d:
            run_pipeline(wcfg, Path(d) / "run")
    except Exception:  # a warm-up failure is not the point's failure: the real run reports it
        pass


def numba_threads(raws) -> str:
    """``NUMBA_NUM_THREADS`` for processes that run the configs ``raws``: the largest
    ``solver.threads`` they ask for (1 by default). numba reads it once, when it starts, and never
    runs more threads than it allows, so a worker started with 1 would run a ``solver.threads: 2``
    point on one thread."""
    def threads(raw):
        solver = raw.get("solver") if isinstance(raw, dict) else None
        value = solver.get("threads", 1) if isinstance(solver, dict) else 1
        return value if isinstance(value, int) and value > 0 else 1
    return str(max((threads(r) for r in raws), default=1))


def _run_point(raw: dict, run_dir: str, where: str) -> dict:
    """Run one point in this process (also used by worker processes)."""
    os.environ.setdefault("NUMBA_NUM_THREADS", numba_threads([raw]))
    from fiberpipe.pipeline import run_pipeline

    # the point's own config beside its results (its paths are absolute): what its summary, its run
    # log and the resume command of an interrupted simulation name
    point_config = Path(run_dir) / "config.yaml"
    point_config.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(point_config, yaml.safe_dump(raw, sort_keys=False, allow_unicode=True))
    cfg = validate_config(copy.deepcopy(raw), where=str(point_config))
    _warm_up(raw, cfg, where)
    t0 = time.perf_counter()
    report = run_pipeline(cfg, Path(run_dir))
    wall = time.perf_counter() - t0
    sim = report.stages.get("simulate", {})
    return {"wall_time_s": wall, "solver_wall_time_s": sim.get("solver_wall_time_s"), "steps": sim.get("steps"), "elements": sim.get("elements")}


def _execute(jobs, nworkers, scheduler, where, echo, fn=None) -> dict:
    """Run ``jobs`` ``(id, raw, run_dir)``: on the Dask scheduler at ``scheduler``; else, with more
    than one worker, on a local Dask cluster of ``nworkers`` processes (a local process pool without
    Dask); else one after the other in this process. Returns ``{id: fn result}``; ``fn(raw, run_dir,
    where)`` is :func:`_run_point` unless given (a module-level function, so workers can import it)."""
    _run_point = fn or globals()["_run_point"]
    # before this process or its workers start numba (the worker processes inherit it); a value the
    # user set stays
    os.environ.setdefault("NUMBA_NUM_THREADS", numba_threads([raw for _, raw, _ in jobs]))
    env = {"NUMBA_NUM_THREADS": os.environ["NUMBA_NUM_THREADS"]}
    if scheduler or nworkers > 1:
        try:
            from dask.distributed import Client, LocalCluster  # optional extra: fiberpipe[dask]
        except ImportError:
            if scheduler:
                raise ConfigError("--scheduler needs Dask: pip install 'fiberpipe[dask]'") from None
            echo(f"  on a local process pool ({nworkers} processes; Dask not installed)")
            with ProcessPoolExecutor(max_workers=nworkers) as pool:
                return _collect({jid: pool.submit(_run_point, raw, d, where) for jid, raw, d in jobs}, echo)
        if scheduler:
            echo(f"  on the Dask scheduler {scheduler}")
            with _connect(Client, scheduler) as client:
                return _collect({jid: client.submit(_run_point, raw, d, where, pure=False) for jid, raw, d in jobs}, echo)
        echo(f"  on a local Dask cluster ({nworkers} worker processes)")
        # the cluster in its own context: a Client given a cluster does not close it
        with LocalCluster(n_workers=nworkers, threads_per_worker=1, processes=True, env=env) as cluster, \
                Client(cluster) as client:
            return _collect({jid: client.submit(_run_point, raw, d, where, pure=False) for jid, raw, d in jobs}, echo)
    results = {}
    for jid, raw, d in jobs:
        results[jid] = _run_point(raw, d, where)
        echo(f"  {jid}: {results[jid]['wall_time_s']:.1f} s")
    return results


execute = _execute


CONNECT_TIMEOUT_S = 10.0  # how long a scheduler address is tried before it is refused


def _connect(client_type, address: str):
    """A Dask client of the scheduler at ``address``, or a one-line error naming it."""
    timeout_s = CONNECT_TIMEOUT_S
    try:
        return client_type(address, timeout=f"{timeout_s:g}s")
    except (OSError, TimeoutError, ValueError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ConfigError(f"--scheduler {address}: no Dask scheduler answers there within {timeout_s:g} s ({reason})") from None


def _collect(futures: dict, echo) -> dict:
    """Wait for ``{id: future}`` (concurrent.futures or Dask), in submission order."""
    results = {}
    for jid, fut in futures.items():
        results[jid] = fut.result()
        echo(f"  {jid}: {results[jid]['wall_time_s']:.1f} s")
    return results
