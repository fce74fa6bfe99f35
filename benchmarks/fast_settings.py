"""Fast settings of paper-40 against the study-settings curve (issue 7: < 30 s within 2 %).

Runs ``configs/paper-40.yaml`` at the study's settings, the same settings with gravity perturbed by
1e-8 (the chaotic floor: any change of rounding moves the bundle's contact bursts), and cheaper
candidates (mass scaling k with α/k, which keeps the damping force α m v; loading velocity × k with
α/k, the same drag at k × the speed). Compares each lower-plate force curve with the reference by
``fiberpipe.bench.curve_error`` (largest pointwise |ΔF|, relative to the largest F) and by
``fiberpipe.bench.curve_error_binned`` (the same on the mean load in U windows of 0.05 mm).

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/fast_settings.py [--out FILE.md]
"""

from __future__ import annotations

import sys
import time

from fiberpipe.bench import curve_error, curve_error_binned, paper40_run

CANDIDATES = [
    ("study settings, gravity × (1 + 1e-8) (chaotic floor)", {"scene.gravity.acceleration": [0, "-9.8100001 m/s^2", 0]}),
    ("mass scaling 25, α = 4e3 1/s", {"solver.mass_scaling": 25, "scene.damping.alpha": "4e3 1/s"}),
    ("mass scaling 36, α = 2.78e3 1/s", {"solver.mass_scaling": 36, "scene.damping.alpha": "2.7778e3 1/s"}),
    ("mass scaling 100, α = 1e3 1/s", {"solver.mass_scaling": 100, "scene.damping.alpha": "1e3 1/s"}),
    ("velocity × 5 (5e3 mm/min), α = 2e4 1/s", {"scene.loading.velocity": "5000 mm/min", "scene.damping.alpha": "2e4 1/s"}),
    ("mass scaling 16, α = 6.25e3 1/s", {"solver.mass_scaling": 16, "scene.damping.alpha": "6.25e3 1/s"}),
    ("0.6 mm elements", {"mesh.element_length": "0.6 mm"}),
    ("0.6 mm elements, velocity × 1.25, α = 8e4 1/s", {"mesh.element_length": "0.6 mm", "scene.loading.velocity": "1250 mm/min",
                                                    "scene.damping.alpha": "8e4 1/s"}),
]
if "--only-new" in sys.argv:  # the candidates added last (the first ones: docs/benchmarks.md)
    CANDIDATES = CANDIDATES[-3:]


def main(argv=None) -> str:
    argv = list(sys.argv[1:] if argv is None else argv)
    out = argv[argv.index("--out") + 1] if "--out" in argv else None
    base = {"solver.output_frames": 2}
    ref = paper40_run(dict(base))
    rows = [("study settings (reference)", ref, None, None)]
    for name, ov in CANDIDATES:
        try:
            r = paper40_run({**base, **ov})
        except Exception as exc:  # a diverging candidate is a result too
            rows.append((name, {"wall_s": float("nan"), "steps": 0, "U_mm": float("nan")}, f"failed: {exc}"[:80], None))
            continue
        rows.append((name, r, curve_error(ref, r), curve_error_binned(ref, r)))
    lines = [f"Measured {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, one thread.", "",
             "| settings | steps | wall (s) | U reached (mm) | pointwise curve error | binned curve error (0.05 mm) |",
             "|---|---|---|---|---|---|"]
    for name, r, e1, e2 in rows:
        f1 = "—" if e1 is None else (e1 if isinstance(e1, str) else f"{100 * e1:.1f} %")
        f2 = "—" if e2 is None else f"{100 * e2:.2f} %"
        lines.append(f"| {name} | {r['steps']} | {r['wall_s']:.1f} | {r['U_mm']:.4f} | {f1} | {f2} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if out:
        with open(out, "w") as fh:
            fh.write(text)
    return text


if __name__ == "__main__":
    main()
