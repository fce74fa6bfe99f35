"""``python -m fiberpipe.verification [--quick] [CASE ...]``: print the verification table.

Exit status 1 when a checked row fails; informational rows (known not reproduced, see
:class:`~fiberpipe.verification.cases.Row`) are printed but do not count."""

from __future__ import annotations

import argparse
import sys
import time

from .cases import CASES
from .contact_cases import CONTACT_CASES
from .energy_residual import format_residuals, recording

ALL_CASES = {**CASES, **CONTACT_CASES}


def run_all(quick: bool = False, only=None, residuals: dict | None = None):
    """Every verification case of docs/verification.md (beams 1-4, contact and friction 5-8), in
    order; ``residuals`` (if given) gets each case's list of its runs' largest |energy residual|."""
    rows = []
    for name, fn in ALL_CASES.items():
        if only and name not in only:
            continue
        with recording() as runs:
            r = fn(quick=quick)
        rows.extend(r if isinstance(r, list) else [r])
        if residuals is not None:
            residuals[name] = runs
    return rows


def format_table(rows) -> str:
    lines = ["| case | reference | measured | error | tolerance | result | note |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        unit = f" {r.unit}" if r.unit else ""
        tol = f"{'> ' if r.must_exceed else ''}{100 * r.tolerance:.3g} %"
        lines.append(f"| {r.case} | {r.reference:.6g}{unit} | {r.measured:.6g}{unit} | {100 * r.error:.3g} % | "
                     f"{tol} | {r.status} | {r.note} |")
    return "\n".join(lines)


def summary(rows) -> str:
    checked = [r for r in rows if not r.informational]
    info = [r for r in rows if r.informational]
    text = f"{sum(r.passed for r in checked)}/{len(checked)} passed"
    if info:
        text += (f"; informational (not counted): {len(info)} row{'s' if len(info) != 1 else ''}, "
                 f"{sum(not r.passed for r in info)} not reproduced")
    return text


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m fiberpipe.verification")
    ap.add_argument("--quick", action="store_true", help="shorter variants of each case")
    ap.add_argument("cases", nargs="*", choices=[[]] + list(ALL_CASES), help="subset of cases")
    a = ap.parse_args(argv)
    t = time.perf_counter()
    residuals: dict = {}
    rows = run_all(quick=a.quick, only=a.cases or None, residuals=residuals)
    print(format_table(rows))
    if any(residuals.values()):
        print("\nEnergy residual of each run (state functions; docs/verification.md):\n")
        print(format_residuals(residuals))
    print(f"\n{summary(rows)} in {time.perf_counter() - t:.1f} s")
    return 0 if all(r.passed for r in rows if not r.informational) else 1


if __name__ == "__main__":
    sys.exit(main())
