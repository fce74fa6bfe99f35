"""Helpers the readers share: length units of metadata, numeric attributes, optional imports."""

from __future__ import annotations

import importlib
import json

import numpy as np

from ...errors import InputError
from .._util import voxel_size_zyx

#: Metres per unit, for the length units found in image metadata (ImageJ, OME, HDF5, NeXus, NIfTI).
UNIT_M = {
    "m": 1.0, "meter": 1.0, "metre": 1.0, "meters": 1.0, "metres": 1.0,
    "cm": 1e-2, "centimeter": 1e-2, "centimetre": 1e-2,
    "mm": 1e-3, "millimeter": 1e-3, "millimetre": 1e-3, "millimeters": 1e-3,
    "um": 1e-6, "µm": 1e-6, "μm": 1e-6, "micron": 1e-6, "microns": 1e-6, "micrometer": 1e-6,
    "micrometre": 1e-6, "micrometers": 1e-6, "\\u00b5m": 1e-6,
    "nm": 1e-9, "nanometer": 1e-9, "nanometre": 1e-9,
}


def unit_to_m(unit) -> float | None:
    """Metres per ``unit`` (a name or abbreviation), None if unknown or missing."""
    if unit is None:
        return None
    if isinstance(unit, bytes):
        unit = unit.decode()
    return UNIT_M.get(str(unit).strip().lower())


def attr_numbers(v) -> np.ndarray:
    """An attribute holding numbers: an array, a scalar, or JSON text (fiberpipe artifacts store
    lists as JSON, e.g. ``voxel_size_m = "[1e-05, 1e-05, 1e-05]"``)."""
    if isinstance(v, bytes):
        v = v.decode()
    if isinstance(v, str):
        try:
            v = json.loads(v)
        except ValueError:
            raise ValueError(f"not a number or a list of numbers: {v!r}") from None
    return np.asarray(v, dtype=np.float64)


def attrs_voxel_size(attrs) -> np.ndarray | None:
    """(dz, dy, dx) in m from attributes ``voxel_size_m``, ``voxel_size`` (+ ``units``/``unit``,
    default m) or Fiji/ilastik ``element_size_um`` (z y x), or None."""
    if "voxel_size_m" in attrs:
        return voxel_size_zyx(attr_numbers(attrs["voxel_size_m"]))
    if "voxel_size" in attrs:
        f = unit_to_m(attrs.get("units", attrs.get("unit", "m"))) or 1.0
        return voxel_size_zyx(attr_numbers(attrs["voxel_size"]) * f)
    if "element_size_um" in attrs:
        return voxel_size_zyx(attr_numbers(attrs["element_size_um"]) * 1e-6)
    return None


def need(module: str, fmt: str, where: str):
    """Import an optional library, or an InputError saying which extra installs it."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise InputError(f"reading {fmt} needs the Python package {module!r}: pip install 'fiberpipe[formats]'",
                         where=where) from None


def first_bad_chunk(shape, chunks, read_block) -> tuple[tuple[int, ...], Exception] | None:
    """Read a chunked array block by block; the grid index of the first block that fails, and why."""
    grid = [range(0, s, c) for s, c in zip(shape, chunks)]
    import itertools

    for start in itertools.product(*grid):
        sl = tuple(slice(a, min(a + c, s)) for a, c, s in zip(start, chunks, shape))
        try:
            read_block(sl)
        except Exception as exc:  # noqa: BLE001 — codec and I/O libraries raise many types
            return tuple(a // c for a, c in zip(start, chunks)), exc
    return None


def why(exc: Exception) -> str:
    """``Type: message`` of an exception on one line (library messages may span several)."""
    return f"{type(exc).__name__}: {' '.join(str(exc).split())}"


def read_whole(arr, label: str, where: str):
    """All of a chunked array (h5py dataset, Zarr array); a read that fails names the first
    unreadable chunk by its grid index, in one line (``label``: "dataset 'x'", "Zarr array '/'")."""
    try:
        return arr[...]
    except Exception as exc:  # noqa: BLE001 — h5py and the Zarr codecs raise many types for damaged data
        chunks = getattr(arr, "chunks", None)
        if chunks is not None:
            bad = first_bad_chunk(arr.shape, chunks, lambda sl: arr[sl])
            if bad is not None:
                idx, err = bad
                raise InputError(f"unreadable chunk {idx} of {label} ({why(err)})", where=where) from None
        raise InputError(f"cannot read {label} ({why(exc)})", where=where) from None
