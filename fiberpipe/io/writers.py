"""The registry of traced-fiber writers (``fiberpipe export FORMAT FIBERS.h5 --out FILE``): one
module per format, each a function ``write(path, fibers)`` of :class:`~fiberpipe.polylines.Polylines`."""

from __future__ import annotations

from pathlib import Path
from typing import Callable, NamedTuple


class FiberWriter(NamedTuple):
    write: Callable  # write(path, fibers) -> Path
    suffix: str      # the file name's suffix
    what: str        # the program that reads it


def _fiberscout(path, fibers):
    from .fiberscout import write_fiberscout_csv

    return write_fiberscout_csv(path, fibers)


def _avizo(path, fibers):
    from .avizo import write_avizo_spatialgraph

    return write_avizo_spatialgraph(path, fibers)


#: Format name -> writer.
FIBER_WRITERS: dict[str, FiberWriter] = {
    "fiberscout": FiberWriter(_fiberscout, ".csv", "open_iA FeatureScout (FCP fiber CSV)"),
    "avizo": FiberWriter(_avizo, ".am", "Avizo / Amira (SpatialGraph)"),
}


def export_fibers(fmt: str, fibers_path: str | Path, out: str | Path | None = None) -> Path:
    """Write the ``fibers`` artifact at ``fibers_path`` in format ``fmt`` to ``out`` (default: beside
    it, with the format's suffix). An unknown format is a one-line InputError naming the known ones."""
    from fiberpipe.artifacts import read_fibers
    from fiberpipe.errors import InputError

    if fmt not in FIBER_WRITERS:
        raise InputError(f"unknown export format {fmt!r} (known: {', '.join(sorted(FIBER_WRITERS))})")
    writer = FIBER_WRITERS[fmt]
    out = Path(fibers_path).with_suffix(writer.suffix) if out is None else Path(out)
    return writer.write(out, read_fibers(fibers_path))
