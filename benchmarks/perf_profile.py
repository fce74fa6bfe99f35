"""Where the step loop's time goes, per thread and per compiled function: Linux ``perf`` sampling
of the jitted kernels, named.

    python benchmarks/perf_profile.py [--state STATE.npz] [--config CONFIG] [--threads 2]

The scene is a run config's (``--config``; paper-40 at the study's settings without it), from a
state saved by ``benchmarks/paper40_states.py`` (``--state``) or from rest. A child process compiles the step loop (into an empty numba cache, so that every
kernel has the LLVM module its name is read from), writes ``/tmp/perf-PID.map`` (the address and
name of each compiled function, which ``perf report`` reads for code without a symbol table), then
runs ``--steps`` timed steps under ``perf record -e cycles:u`` (perf falls back to a clock where the
machine gives no cycle counter; the table names the event). Only the samples of the timed steps are
counted. The code sampled is the code compiled in the child: a run that loads the kernels from
numba's cache runs copies that can round differently in the last bit (docs/reliability.md), with the
same work. Each thread's samples are grouped by function; ``libgomp`` is the OpenMP runtime,
where a thread with no task waits (a second thread's share there is the serial part of the step).

Strategy: numba's functions are linked into the step loop as separate functions unless LLVM inlines
them, so the names are those of the kernels that stay calls (the beam pass, the node update, the
contact pass's pair range and merge, the laws' look-ups, the friction kernels); code inlined into
them counts as theirs. Needs ``perf`` and ``kernel.perf_event_paranoid`` ≤ 2 (user-space
sampling of one's own process).
"""

from __future__ import annotations

import argparse
import collections
import gc
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import weakref
from pathlib import Path


_PROXIES = (weakref.ProxyType, weakref.CallableProxyType)


def write_perf_map() -> int:
    """``/tmp/perf-PID.map`` for every function numba compiled in this process (not those loaded from
    its cache, which keep no LLVM module to name them); returns how many."""
    from numba.core.codegen import CPUCodeLibrary

    addrs = {}
    for lib in gc.get_objects():
        if type(lib) in _PROXIES or not isinstance(lib, CPUCodeLibrary):  # a weak proxy's referent may be gone
            continue
        mod = getattr(lib, "_final_module", None)
        if mod is None:
            continue
        for fn in mod.functions:
            if fn.is_declaration:
                continue
            try:
                p = lib._codegen._engine.get_function_address(fn.name)
            except Exception:  # a function of a library not finalised
                continue
            if p:
                addrs[p] = fn.name
    items = sorted(addrs.items())
    with open(f"/tmp/perf-{os.getpid()}.map", "w") as fh:
        for k, (a, name) in enumerate(items):
            size = min(items[k + 1][0] - a if k + 1 < len(items) else 1 << 16, 1 << 22)
            fh.write(f"{a:x} {size:x} {name}\n")
    return len(items)


def _child(a) -> None:
    from fiberpipe.benchmarks.scenes import scene_and_state
    from fiberpipe.solver.integrator import Integrator

    if a.bench_fibers:  # the thread bench's bundle (fiberpipe.benchmarks.bench_threads)
        from fiberpipe.benchmarks.bench_threads import _bench_scene

        model, effects, dt, state = _bench_scene(a.bench_fibers, True, a.pitch)
    else:
        model, effects, dt, state = scene_and_state(a.state, a.config)
    integrator = Integrator(model, effects, dt, history_rows=10, history_every=10**9, threads=a.threads)
    print(f"PID {os.getpid()}", flush=True)  # the map's name, for the parent to remove it
    if integrator.advance(state, a.warmup)[0] != 0:
        raise SystemExit("the warm-up steps stopped (the state diverges at these settings)")
    write_perf_map()
    t0 = time.clock_gettime(time.CLOCK_MONOTONIC)
    w0 = time.perf_counter()
    status = integrator.advance(state, a.steps)[0]
    wall = time.perf_counter() - w0
    t1 = time.clock_gettime(time.CLOCK_MONOTONIC)
    if status != 0:
        raise SystemExit("the timed steps stopped (the state diverges at these settings)")
    print(f"WINDOW {t0:.6f} {t1:.6f} {wall / a.steps * 1e6:.2f} {model.n_elements}", flush=True)


def _short_name(sym: str) -> str:
    """``module.function`` of a numba symbol (Itanium-mangled ``_ZN…``), else the symbol."""
    s = sym[3:] if sym.startswith("_ZN") else ""
    names = []
    while s and s[0].isdigit():
        n = re.match(r"\d+", s).group()
        s = s[len(n):]
        names.append(s[:int(n)])
        s = s[int(n):]
    return ".".join(names[-2:]) if names else sym[:60]


def aggregate(report_text: str) -> dict:
    """Samples per thread and per function from ``perf report --sort pid,dso,sym -n --stdio``."""
    per = collections.defaultdict(collections.Counter)
    for line in report_text.splitlines():
        m = re.match(r"\s*[\d.]+%\s+(\d+)\s+(\d+):\S+\s+(.*?)\s+\[.\]\s+(.*)", line)
        if not m:
            continue
        n, tid, dso, sym = int(m[1]), m[2], m[3], m[4].strip()
        if "JIT" in dso or dso.startswith("perf-"):
            key = _short_name(sym)
        elif "gomp" in dso:
            key = "libgomp (OpenMP runtime: waiting, task start)"
        elif "libm" in dso:
            key = "libm (" + sym.split("@")[0] + ")"
        else:
            key = f"{os.path.basename(dso)}"
        per[tid][key] += n
    return per


def table(per: dict, us_per_step: float, main_tid: str, min_share: float = 0.005) -> list[str]:
    """Markdown tables of :func:`aggregate`'s samples: the main thread (``main_tid``, the process's id,
    which runs the step's serial parts) first, then the others with at least 5 % of its samples."""
    threads = sorted(per, key=lambda t: (t != main_tid, -sum(per[t].values())))
    lines = [f"{us_per_step:.1f} µs per step (wall)", ""]
    top = max(sum(c.values()) for c in per.values())
    for tid in threads:
        tot = sum(per[tid].values())
        if tot < 0.05 * top:
            continue  # the BLAS pool and other idle threads
        lines += [f"{'main thread' if tid == main_tid else 'thread ' + tid}: {tot} samples", "",
                  "| function | share of the thread's samples |", "|---|---|"]
        for name, n in per[tid].most_common():
            if n / tot >= min_share:
                lines.append(f"| {name} | {100 * n / tot:.1f} % |")
        lines.append("")
    return lines


def main(argv=None) -> list[str]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--state", help="a state saved by benchmarks/paper40_states.py (default: from rest)")
    ap.add_argument("--config", help="the run config of the scene (default: paper-40's)")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--warmup", type=int, default=300)
    ap.add_argument("--frequency", type=int, default=1999, help="samples per second and thread")
    ap.add_argument("--bench-fibers", type=int, default=0,
                    help="the thread bench's bundle of this many fibers instead of a config's scene")
    ap.add_argument("--pitch", type=float, default=1.98, help="its grid pitch in radii (with --bench-fibers)")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:
        _child(a)
        return []
    if shutil.which("perf") is None:
        raise SystemExit("perf_profile needs Linux perf (the linux-tools package) on the PATH")
    report, us, n_el, event, pid = _record(a)
    per = aggregate(report)
    if not per:
        raise SystemExit("perf recorded no samples of the timed steps (kernel.perf_event_paranoid ≤ 2 is needed)")
    where = " ".join(f"--{name} {value}" for name, value in (("config", a.config), ("state", a.state)) if value)
    lines = [f"`python benchmarks/perf_profile.py {where} --threads {a.threads} --steps {a.steps}`: "
             f"{n_el} elements, {a.threads} thread(s), perf event {event}, "
             f"load average {os.getloadavg()[0]:.2f}", ""]
    lines += table(per, us, main_tid=pid)
    print("\n".join(lines))
    return lines


def _record(a) -> tuple[str, float, int, str, str]:
    """Run the child under ``perf record`` and ``perf report`` its timed steps: ``(the report's text,
    µs per step, elements, the event perf sampled, the child's process id)``."""
    with tempfile.TemporaryDirectory(prefix="fiberpipe-perf-") as tmp:
        data = Path(tmp) / "perf.data"
        # numba's threads are fixed when it starts: at least the run's (make exports 1)
        threads = max(a.threads, int(os.environ.get("NUMBA_NUM_THREADS") or 0))
        env = dict(os.environ, NUMBA_CACHE_DIR=str(Path(tmp) / "numba-cache"), NUMBA_NUM_THREADS=str(threads))
        cmd = ["perf", "record", "-k", "CLOCK_MONOTONIC", "-e", "cycles:u", "-F", str(a.frequency), "-o",
               str(data), "--", sys.executable, str(Path(__file__).resolve()), "--child",
               "--threads", str(a.threads), "--steps", str(a.steps), "--warmup", str(a.warmup)]
        for flag, value in (("--state", a.state), ("--config", a.config),
                            ("--bench-fibers", a.bench_fibers and str(a.bench_fibers)), ("--pitch", str(a.pitch))):
            if value:
                cmd += [flag, value]
        run = subprocess.run(cmd, env=env, capture_output=True, text=True)
        out = {ln.split()[0]: ln.split()[1:] for ln in run.stdout.splitlines() if ln.split()[:1] in (["PID"], ["WINDOW"])}
        perf_map = Path(f"/tmp/perf-{out['PID'][0]}.map") if "PID" in out else None
        try:
            if run.returncode != 0 or "WINDOW" not in out:
                raise SystemExit(f"perf record failed ({run.returncode}): {run.stderr.strip()[-400:]}")
            t0, t1, us, n_el = out["WINDOW"]
            rep = subprocess.run(["perf", "report", "-i", str(data), "--time", f"{t0},{t1}", "--sort",
                                  "pid,dso,sym", "--no-children", "--stdio", "-n"], capture_output=True, text=True)
        finally:
            if perf_map is not None:
                perf_map.unlink(missing_ok=True)
    if rep.returncode != 0:
        raise SystemExit(f"perf report failed ({rep.returncode}): {rep.stderr.strip()[-400:]}")
    ev = re.search(r"of event '([^']+)'", rep.stdout)
    return rep.stdout, float(us), int(n_el), ev.group(1) if ev else "?", out["PID"][0]


if __name__ == "__main__":
    main()
