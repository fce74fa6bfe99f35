"""The post stage's CSV writer (a leaf module: every table of the run folder goes through it)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from fiberpipe.artifacts import write_text_atomic


def write_csv(path: Path, columns: dict[str, np.ndarray]) -> Path:
    """Write equal-length columns to CSV atomically (header = column names with units)."""
    names = list(columns)
    rows = zip(*[np.asarray(columns[n]).tolist() for n in names])
    import io

    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(names)
    for r in rows:
        w.writerow([f"{v:.9g}" if isinstance(v, float) else v for v in r])
    write_text_atomic(path, buf.getvalue())
    return path
