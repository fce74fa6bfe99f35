"""TIFF: a 3D (multi-page, ImageJ hyperstack or OME) TIFF, or a folder of 2D TIFF slices."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ...errors import InputError
from . import register
from ._common import unit_to_m

SUFFIXES = (".tif", ".tiff")


def _natural_key(p: Path):
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", p.name)]


def _resolution_size(page, tag: str) -> float | None:
    """Pixel size in the file's unit from an X/YResolution tag (pixels per unit), or None."""
    t = page.tags.get(tag)
    if t is None:
        return None
    num, den = t.value if isinstance(t.value, tuple) else (t.value, 1)
    if not num or not den:
        return None
    return float(den) / float(num)


def tiff_voxel_size(tif) -> np.ndarray | None:
    """(dz, dy, dx) in m from ImageJ or OME metadata, or None if the file carries none."""
    page = tif.pages[0]
    # OME-XML: PhysicalSizeX/Y/Z with units (default micrometre)
    if tif.is_ome and tif.ome_metadata:
        xml = tif.ome_metadata
        vals = {}
        for ax in "XYZ":
            m = re.search(rf'PhysicalSize{ax}="([0-9.eE+-]+)"', xml)
            u = re.search(rf'PhysicalSize{ax}Unit="([^"]+)"', xml)
            if m:
                f = unit_to_m(u.group(1) if u else "um")
                if f:
                    vals[ax] = float(m.group(1)) * f
        if "X" in vals:
            dx = vals["X"]
            dy = vals.get("Y", dx)
            dz = vals.get("Z", dx)
            return np.array([dz, dy, dx])
    # ImageJ: unit and spacing (z) in the description, X/YResolution in pixels per unit
    ij = tif.imagej_metadata
    if ij is not None:
        f = unit_to_m(ij.get("unit"))
        sx = _resolution_size(page, "XResolution")
        if f and sx:
            sy = _resolution_size(page, "YResolution") or sx
            dz = float(ij.get("spacing", sx))
            return np.array([dz * f, sy * f, sx * f])
        return None
    # plain TIFF: only a centimetre resolution unit is taken as real; inch (the 72/96 dpi default of
    # every image writer) or none is "no voxel size"
    ru = page.tags.get("ResolutionUnit")
    if ru is not None and int(ru.value) == 3:
        sx = _resolution_size(page, "XResolution")
        if sx:
            sy = _resolution_size(page, "YResolution") or sx
            return np.array([sx, sy, sx]) * 1e-2
    return None


def _check_tiff_complete(tif, path: Path) -> None:
    """Raise InputError if the TIFF's image data extend past the end of the file (truncated)."""
    # tifffile reads a truncated stack without error (it returns the pages it finds), so the data
    # offsets are checked against the file size, and ImageJ's declared image count against the
    # pages present.
    size = path.stat().st_size
    series = tif.series[0] if tif.series else None
    if series is not None and getattr(series, "dataoffset", None) is not None:
        if series.dataoffset + series.nbytes > size:
            raise InputError("TIFF image data run past the end of the file; truncated", where=str(path))
    for page in tif.pages:
        offs = getattr(page, "dataoffsets", ())
        counts = getattr(page, "databytecounts", ())
        if any(o + c > size for o, c in zip(offs, counts)):
            raise InputError("TIFF image data run past the end of the file; truncated", where=str(path))
    ij = tif.imagej_metadata
    if ij and "images" in ij and series is not None:
        n_img = int(np.prod(series.shape[:-2])) if len(series.shape) > 2 else 1
        if int(ij["images"]) > n_img:
            raise InputError(f"ImageJ TIFF declares {ij['images']} images, holds {n_img}; truncated",
                             where=str(path))


def read_tiff_file(path: Path):
    """(image array, voxel size or None) of one TIFF file."""
    import tifffile

    try:
        with tifffile.TiffFile(path) as tif:
            _check_tiff_complete(tif, path)
            vs = tiff_voxel_size(tif)
            vol = tif.asarray()
    except InputError:
        raise
    except Exception as exc:  # tifffile raises many types for damaged files
        raise InputError(f"cannot read TIFF ({type(exc).__name__}: {exc}); not a TIFF or truncated",
                         where=str(path)) from None
    return vol, vs


def read(path: Path, **_):
    vol, vs = read_tiff_file(path)
    return vol, vs, f"tiff:{path}"


def read_folder(path: Path, **_):
    files = sorted((p for p in path.iterdir() if p.suffix.lower() in SUFFIXES and p.is_file()),
                   key=_natural_key)
    if not files:
        raise InputError("folder holds no .tif/.tiff slices", where=str(path))
    first, vs = read_tiff_file(files[0])
    first = np.squeeze(first)
    if first.ndim != 2:
        raise InputError(f"slice {files[0].name} is not a 2D image (shape {first.shape})", where=str(path))
    # preallocate once and fill slice by slice (no list of slices + stack copy)
    vol = np.empty((len(files),) + first.shape, dtype=first.dtype)
    vol[0] = first
    for k, f in enumerate(files[1:], start=1):
        im, _ = read_tiff_file(f)
        im = np.squeeze(im)
        if im.shape != first.shape:
            raise InputError(f"slice {f.name} has shape {im.shape}, expected {first.shape}", where=str(path))
        vol[k] = im
    return vol, vs, f"tiff-folder:{path}"


register("tiff", SUFFIXES, read)
register("tiff-folder", (), read_folder, claims_folder=lambda p: True)
