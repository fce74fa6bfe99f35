"""CPU cost per step of contact variants on saved paper-40 states, alternating in one process.

    NUMBA_NUM_THREADS=1 python benchmarks/bench_contact_variants.py STATE.npz [STATE.npz ...]

The states come from ``benchmarks/paper40_states.py`` (``make profile-paper40`` saves the
early and the compacted phase). Each variant is one Integrator on the same mesh; they advance the same
state by the same number of steps, in alternating order, each timed by the process's CPU clock, so
the ratios hold on a busy machine. The friction histories start afresh from each state.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

VARIANTS = {
    "blend 1 mm": {"scene.contact": {"law": "hertz_oriented", "blend_length": "1 mm"}},
    "blend 0.05 mm (default)": {"scene.contact": {"law": "hertz_oriented"}},
}


def measure(states: list[Path], steps: int = 1500, rounds: int = 6) -> list[dict]:
    from fiberpipe.solver.integrator import Integrator

    from fiberpipe.benchmarks.scenes import load_state, scene

    integs = {}
    for name, ov in VARIANTS.items():
        model, effects, settings, dt = scene(ov)
        integs[name] = Integrator(model, effects, dt, history_rows=10, history_every=10**9)
    out = []
    for path in states:
        sts = {n: load_state(path) for n in integs}
        for n, it in integs.items():
            it.advance(sts[n], 300)  # compile and warm
        cpu = dict.fromkeys(integs, 0.0)
        for r in range(rounds):
            for n in (list(integs) if r % 2 == 0 else list(integs)[::-1]):
                t0 = time.process_time()
                integs[n].advance(sts[n], steps)
                cpu[n] += time.process_time() - t0
        base = cpu[next(iter(integs))]
        out.append({"state": Path(path).name, "us_per_step": {n: c / (steps * rounds) * 1e6 for n, c in cpu.items()},
                    "ratio": {n: c / base for n, c in cpu.items()}})
    return out


def main(argv=None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    if not argv:
        raise SystemExit("usage: python benchmarks/bench_contact_variants.py STATE.npz [STATE.npz ...]")
    print("| state | " + " | ".join(VARIANTS) + " |")
    print("|---" * (len(VARIANTS) + 1) + "|")
    for row in measure([Path(a) for a in argv]):
        print(f"| {row['state']} | " + " | ".join(f"{row['us_per_step'][n]:.0f} µs ({row['ratio'][n]:.2f})"
                                                 for n in VARIANTS) + " |", flush=True)


if __name__ == "__main__":
    main()
