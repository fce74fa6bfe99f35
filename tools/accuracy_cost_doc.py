"""Regenerate the generated section of docs/accuracy-cost.md from the studies' tables.

    .venv/bin/python tools/accuracy_cost_doc.py [--runs runs/studies] [--out docs/accuracy-cost.md]

`make studies` runs every configs/studies/*.yaml into runs/studies/<name>/ and then this script,
which copies each runs/studies/<name>/study.md between the page's `studies` markers.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from generated import replace_section  # noqa: E402

ORDER = ["rearrangement-velocity-alpha", "mesh-convergence", "dt-safety", "rotational-inertia",
         "paper40-fast-settings"]
BEGIN, END = "<!-- studies: begin", "<!-- studies: end"


def section(runs: Path) -> str:
    names = [n for n in ORDER if (runs / n / "study.md").exists()]
    names += sorted(p.parent.name for p in runs.glob("*/study.md") if p.parent.name not in names)
    parts = []
    for n in names:
        text = (runs / n / "study.md").read_text().strip().replace("# Study ", "## Study ", 1)
        parts += [text, "", f"Config: `configs/studies/{n}.yaml`; Pareto plot: `runs/studies/{n}/pareto.png`.", ""]
    return "\n".join(parts) if parts else "No study results found: run `make studies`."


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", default=str(ROOT / "runs" / "studies"))
    ap.add_argument("--out", default=str(ROOT / "docs" / "accuracy-cost.md"))
    a = ap.parse_args(argv)
    replace_section(Path(a.out), BEGIN, END, section(Path(a.runs)))
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
