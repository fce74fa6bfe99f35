"""Contact-pass cost: ns per candidate segment pair, per law, loose and squeezed bundles.

40 fibers × 50 elements (0.3 mm, r = 0.25 mm) in a hexagonal bundle, slightly wavy (so crossing
angles are small but not zero), centre spacing ``2r + gap``. Times the contact pass
(:func:`fiberpipe.solver.contact_potential.contact_forces_pot`, normal forces only, every candidate
pair evaluated) and the friction pass on the Verlet list the hook would use (skin 0.2 r).

    NUMBA_NUM_THREADS=1 .venv/bin/python -m fiberpipe.benchmarks.bench_contact [--repeats 200]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from fiberpipe.solver.contact_pairs import gauss_points
from fiberpipe.solver.contact_potential import contact_forces_pot
from fiberpipe.solver.contact_state import new_records
from fiberpipe.solver.friction import friction_forces
from fiberpipe.solver.laws import make_law
from fiberpipe.solver.neighbours import build_pairs

R = 0.25e-3


def hex_bundle(n_fibers=40, n_el=50, L=15e-3, gap=0.0, wave=0.02e-3, seed=0):
    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(n_fibers)))
    s = np.linspace(0, L, n_el + 1)
    pitch = 2 * R + gap
    xs = []
    for k in range(n_fibers):
        i, j = divmod(k, side)
        cx = pitch * (i + 0.5 * (j % 2))
        cy = pitch * j * np.sqrt(3) / 2
        a, ph = wave * rng.random(), 2 * np.pi * rng.random()
        xs.append(np.column_stack([cx + a * np.sin(2 * np.pi * s / L + ph), cy + a * np.cos(2 * np.pi * s / L + ph), s]))
    x = np.vstack(xs)
    seg = []
    fib = []
    arc = []
    for k in range(n_fibers):
        for e in range(n_el):
            seg.append((k * (n_el + 1) + e, k * (n_el + 1) + e + 1))
            fib.append(k)
            arc.append((e * L / n_el, (e + 1) * L / n_el))
    return (x, np.array(seg, np.int64), np.full(len(seg), R), np.array(fib, np.int64), np.array(arc))


def measure(gap, law_name, n_gauss=2, repeats=200, friction=True):
    x, seg, rad, fib, arc = hex_bundle(gap=gap)
    cap = 64 * len(seg)
    pairs = np.zeros((cap, 2), np.int64)
    keys = np.zeros(cap, np.int64)
    n = build_pairs(x, seg, rad, fib, arc, 0.2 * R, 2 * R, pairs, keys)
    extra = {"linear": {"stiffness": 1e9}, "scaled_stiffness": {"preset": "table3_identified"}}.get(law_name, {})
    law = make_law(law_name, E_pa=15e9, nu=0.3, **extra)
    gxi, gw = gauss_points(n_gauss)
    f = np.zeros_like(x)
    rec = new_records(n)
    fn, cn, cs, ct = rec.fn, rec.normal, rec.s, rec.t
    args = (x, seg, rad, arc, pairs, n, law.law_id, law.params(), gxi, gw, 0.0, f, rec, np.zeros(0), 0.0)
    e, na = contact_forces_pot(*args)
    best = np.inf
    for _ in range(5):
        t = time.perf_counter()
        for _ in range(repeats):
            contact_forces_pot(*args)
        best = min(best, (time.perf_counter() - t) / repeats)
    v = np.zeros_like(x)
    hist = np.zeros((n, 3))
    friction_forces(v, seg, pairs, n, fn, cn, cs, ct, 0.2, 1e3, 1e-8, hist, f)
    bf = np.inf
    for _ in range(5):
        t = time.perf_counter()
        for _ in range(repeats):
            friction_forces(v, seg, pairs, n, fn, cn, cs, ct, 0.2, 1e3, 1e-8, hist, f)
        bf = min(bf, (time.perf_counter() - t) / repeats)
    return {"gap_nm": gap * 1e9, "law": law_name, "gauss": n_gauss, "pairs": n, "active": int(na),
            "us_contact": best * 1e6, "ns_per_pair": best * 1e9 / n, "ns_per_active": best * 1e9 / max(na, 1),
            "ns_per_element": best * 1e9 / len(seg), "us_friction": bf * 1e6}


def table_lines(rows) -> list[str]:
    """The contact-pass table (one row per gap and law), also used by ``fiberpipe bench``."""
    lines = ["| gap | law | candidate pairs | in contact | µs per pass | ns per pair | ns per pair in contact | ns per element | friction µs |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        pa = f"{r['ns_per_active']:.0f}" if r["active"] else "—"
        lines.append(f"| {r['gap_nm']:.0f} nm | {r['law']} | {r['pairs']} | {r['active']} | {r['us_contact']:.0f} | "
                     f"{r['ns_per_pair']:.1f} | {pa} | {r['ns_per_element']:.0f} | {r['us_friction']:.0f} |")
    return lines


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=200)
    ap.add_argument("--out", default=None, help="write a markdown page (e.g. docs/bench/contact.md)")
    a = ap.parse_args(argv)
    rows = []
    for gap in (0.05e-3, -50e-9):
        for law in ("hertz_oriented", "linear", "scaled_stiffness"):
            r = measure(gap, law, repeats=a.repeats)
            rows.append(r)
            print(" ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in r.items()), flush=True)
    if a.out:
        import datetime as _dt
        import os
        import platform
        lines = ["# Contact pass cost", "",
                 f"- date: {_dt.datetime.now(_dt.timezone.utc).strftime('%Y-%m-%d %H:%M UTC')}",
                 f"- machine: {os.cpu_count()} CPUs, {platform.processor() or platform.machine()}, load average "
                 f"{os.getloadavg()[0]:.2f} at the end",
                 f"- command: `NUMBA_NUM_THREADS=1 .venv/bin/python -m fiberpipe.benchmarks.bench_contact --repeats {a.repeats} --out {a.out}`",
                 "- scene: see the script's docstring (hex bundle, 40 × 50 elements, 2 Gauss points, skin 0.2 r)", "",
                 ] + table_lines(rows)
        from pathlib import Path
        Path(a.out).write_text("\n".join(lines) + "\n")
    return rows


if __name__ == "__main__":
    main()
