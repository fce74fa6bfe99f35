"""Reading and writing CT volumes (3D TIFF, folder of 2D TIFF slices, .npy, HDF5, raw)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..errors import InputError
from ._util import voxel_size_zyx

#: Metres per unit, for the length units found in ImageJ/OME metadata and HDF5 attributes.
_UNIT_M = {
    "m": 1.0, "meter": 1.0, "metre": 1.0,
    "cm": 1e-2, "centimeter": 1e-2, "centimetre": 1e-2,
    "mm": 1e-3, "millimeter": 1e-3, "millimetre": 1e-3,
    "um": 1e-6, "µm": 1e-6, "μm": 1e-6, "micron": 1e-6, "microns": 1e-6, "micrometer": 1e-6,
    "micrometre": 1e-6, "\\u00b5m": 1e-6,
    "nm": 1e-9, "nanometer": 1e-9, "nanometre": 1e-9,
}
_TIFF_SUFFIXES = (".tif", ".tiff")
_H5_SUFFIXES = (".h5", ".hdf5", ".hdf", ".he5")


def _unit_to_m(unit) -> float | None:
    if unit is None:
        return None
    u = str(unit).strip().lower()
    return _UNIT_M.get(u)


def _natural_key(p: Path):
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", p.name)]


# ----------------------------------------------------------------------------------------------
# TIFF metadata
# ----------------------------------------------------------------------------------------------
def _resolution_size(page, tag: str) -> float | None:
    """Pixel size in the file's unit from an X/YResolution tag (pixels per unit), or None."""
    t = page.tags.get(tag)
    if t is None:
        return None
    num, den = t.value if isinstance(t.value, tuple) else (t.value, 1)
    if not num or not den:
        return None
    return float(den) / float(num)


def _tiff_voxel_size(tif) -> np.ndarray | None:
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
                f = _unit_to_m(u.group(1) if u else "um")
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
        f = _unit_to_m(ij.get("unit"))
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


def _read_tiff(path: Path):
    import tifffile

    try:
        with tifffile.TiffFile(path) as tif:
            _check_tiff_complete(tif, path)
            vs = _tiff_voxel_size(tif)
            vol = tif.asarray()
    except InputError:
        raise
    except Exception as exc:  # tifffile raises many types for damaged files
        raise InputError(f"cannot read TIFF ({type(exc).__name__}: {exc}); not a TIFF or truncated",
                         where=str(path)) from None
    return vol, vs


def _read_tiff_folder(path: Path):
    import tifffile

    files = sorted((p for p in path.iterdir() if p.suffix.lower() in _TIFF_SUFFIXES and p.is_file()),
                   key=_natural_key)
    if not files:
        raise InputError("folder holds no .tif/.tiff slices", where=str(path))
    first, vs = _read_tiff(files[0])
    first = np.squeeze(first)
    if first.ndim != 2:
        raise InputError(f"slice {files[0].name} is not a 2D image (shape {first.shape})", where=str(path))
    # preallocate once and fill slice by slice (no list of slices + stack copy)
    vol = np.empty((len(files),) + first.shape, dtype=first.dtype)
    vol[0] = first
    for k, f in enumerate(files[1:], start=1):
        im, _ = _read_tiff(f)
        im = np.squeeze(im)
        if im.shape != first.shape:
            raise InputError(f"slice {f.name} has shape {im.shape}, expected {first.shape}", where=str(path))
        vol[k] = im
    return vol, vs


def _find_3d_datasets(h5):
    import h5py

    found = []

    def visit(name, obj):
        if isinstance(obj, h5py.Dataset) and obj.ndim >= 3:
            found.append(name)

    h5.visititems(visit)
    return found


def _attr_numbers(v) -> np.ndarray:
    """An attribute holding numbers: an array, a scalar, or JSON text (fiberpipe artifacts store
    lists as JSON, e.g. ``voxel_size_m = "[1e-05, 1e-05, 1e-05]"``)."""
    if isinstance(v, bytes):
        v = v.decode()
    if isinstance(v, str):
        import json

        try:
            v = json.loads(v)
        except ValueError:
            raise ValueError(f"not a number or a list of numbers: {v!r}") from None
    return np.asarray(v, dtype=np.float64)


def _h5_voxel_size(ds) -> np.ndarray | None:
    for obj in (ds, ds.file):
        a = obj.attrs
        if "voxel_size_m" in a:
            return voxel_size_zyx(_attr_numbers(a["voxel_size_m"]))
        if "voxel_size" in a:
            f = _unit_to_m(a.get("units", a.get("unit", "m"))) or 1.0
            return voxel_size_zyx(np.asarray(a["voxel_size"], dtype=np.float64) * f)
        if "element_size_um" in a:  # Fiji/ilastik HDF5 convention, z y x
            return voxel_size_zyx(np.asarray(a["element_size_um"], dtype=np.float64) * 1e-6)
    return None


#: Kinds of fiberpipe artifacts that hold an image (read as a volume); the others (fibers, mesh,
#: simulation, ...) are refused as a volume input instead of reading one of their arrays.
_IMAGE_KINDS = ("volume", "mask")


def _read_h5(path: Path, dataset: str | None):
    import h5py

    try:
        h5 = h5py.File(path, "r")
    except OSError as exc:
        raise InputError(f"cannot open HDF5 file ({exc}); not HDF5 or truncated", where=str(path)) from None
    with h5:
        kind = h5.attrs.get("kind")
        kind = kind.decode() if isinstance(kind, bytes) else kind
        if dataset is None and isinstance(kind, str) and kind not in _IMAGE_KINDS:
            raise InputError(
                f"is a fiberpipe {kind} artifact, not a volume; input.volume takes a CT volume (TIFF, folder "
                f"of slices, .npy, HDF5 image, raw)" + (", and input.fibers a fibers artifact" if kind == "fibers" else ""),
                where=str(path))
        if dataset is None:
            names = _find_3d_datasets(h5)
            if len(names) != 1:
                what = "no 3D dataset" if not names else f"several 3D datasets {names}"
                raise InputError(f"{what}; give the dataset name", where=str(path))
            dataset = names[0]
        if dataset not in h5:
            raise InputError(f"no dataset {dataset!r}", where=str(path))
        ds = h5[dataset]
        try:
            vs = _h5_voxel_size(ds)
        except (ValueError, TypeError):  # an unreadable attribute is no voxel size (give voxel_size)
            vs = None
        try:
            vol = ds[()]
        except Exception as exc:
            raise InputError(f"cannot read dataset {dataset!r} ({exc})", where=str(path)) from None
    return vol, vs, dataset


def _read_raw(path: Path, shape, dtype):
    if shape is None or dtype is None:
        raise InputError("a raw volume needs shape (z, y, x) and dtype", where=str(path))
    shape = tuple(int(s) for s in shape)
    dtype = np.dtype(dtype)
    expected = int(np.prod(shape)) * dtype.itemsize
    size = path.stat().st_size
    if size != expected:
        raise InputError(f"raw file has {size} bytes, shape {shape} of {dtype} needs {expected}",
                         where=str(path))
    return np.fromfile(path, dtype=dtype).reshape(shape)


# ----------------------------------------------------------------------------------------------
# validation
# ----------------------------------------------------------------------------------------------
#: Fewest voxels along any axis of a volume the imaging stages accept. Tracing differentiates
#: the (smoothed) mask along every axis (``np.gradient``: at least 2 samples; ``trace.dominant_axis``)
#: and a fiber's cross-section is resolved only with a voxel each side of its centre: 3.
MIN_VOXELS_PER_AXIS = 3


def validate_volume(vol: np.ndarray, where: str) -> np.ndarray:
    """Check a volume is a non-empty, finite, non-constant 3D real array of at least
    :data:`MIN_VOXELS_PER_AXIS` voxels along each axis; returns it (squeezed).

    Raises
    ------
    InputError
        2D image, not 3D, empty, complex, any NaN (or all NaN), infinite values, thinner than
        3 voxels along an axis (e.g. a single slice), constant.
    """
    vol = np.asarray(vol)
    if vol.ndim > 3:
        vol = np.squeeze(vol)  # e.g. (Z, 1, Y, X) from a TIFF with a channel axis
    if vol.ndim == 2:
        raise InputError(f"a 2D image (shape {vol.shape}), need a 3D volume", where=where)
    if vol.ndim != 3:
        raise InputError(f"expected a 3D volume, got shape {vol.shape}", where=where)
    if vol.size == 0:
        raise InputError(f"the volume is empty (shape {vol.shape})", where=where)
    if vol.dtype.kind not in "biuf":
        raise InputError(f"unsupported voxel type {vol.dtype}", where=where)
    if vol.dtype.kind == "f":
        # slice by slice: no full-size boolean temporary
        n_nan = 0
        n_inf = 0
        for k in range(vol.shape[0]):
            s = vol[k]
            fin = np.isfinite(s)
            if not fin.all():
                nn = int(np.isnan(s).sum())
                n_nan += nn
                n_inf += int(s.size - fin.sum()) - nn
        if n_nan == vol.size:
            raise InputError("the volume is all NaN", where=where)
        if n_nan:
            raise InputError(f"the volume has {n_nan} NaN voxels", where=where)
        if n_inf:
            raise InputError(f"the volume has {n_inf} infinite voxels", where=where)
    if min(vol.shape) < MIN_VOXELS_PER_AXIS:
        axis = "zyx"[int(np.argmin(vol.shape))]
        raise InputError(
            f"the volume is too thin: {min(vol.shape)} voxel{'' if min(vol.shape) == 1 else 's'} along {axis} (shape {vol.shape}, z y x); fibers "
            f"are traced in 3D and need at least {MIN_VOXELS_PER_AXIS} voxels along each axis: give a 3D stack",
            where=where)
    lo, hi = vol.min(), vol.max()
    if lo == hi:
        raise InputError(f"the volume is constant (all voxels {_plain_number(lo)}): no fiber can be "
                         "told from the background", where=where)
    return vol


def _plain_number(v) -> str:
    """A voxel value as a plain number (``0``, ``7.5``), never ``np.uint8(0)``."""
    v = np.asarray(v).item()
    return f"{v:g}" if isinstance(v, float) else str(v)


def load_volume(path, *, voxel_size_m=None, dataset: str | None = None, shape=None, dtype=None):
    """Load a CT volume and its voxel size.

    Parameters
    ----------
    path : str or Path
        A 3D (multi-page) TIFF, a folder of 2D TIFF slices (natural sort order = z order), a
        ``.npy`` file, an HDF5 file (``.h5``/``.hdf5``) or a headerless raw file (any other suffix;
        needs ``shape`` and ``dtype``).
    voxel_size_m : float or (dz, dy, dx), optional
        Voxel size, m; overrides the file's metadata (ImageJ ``unit``/``spacing`` + X/YResolution,
        OME PhysicalSize*, HDF5 ``voxel_size_m`` / ``element_size_um`` attributes). TIFF resolutions
        in inches (the 72 dpi default of image writers) do not count as a voxel size.
    dataset : str, optional
        HDF5 dataset name (default: the file's only dataset with 3 or more dimensions).
    shape : (3,) ints, optional
        Raw files: volume shape (z, y, x).
    dtype : numpy dtype, optional
        Raw files: voxel type, e.g. ``"uint8"`` or ``"<u2"``.

    Returns
    -------
    volume : (Z, Y, X) ndarray
        As stored (8/16-bit integers or float), not converted.
    voxel_size_m : (3,) float64 ndarray
        (dz, dy, dx), m.
    source : str
        A description of what was read (format, path, dataset), for provenance.

    Raises
    ------
    InputError
        Missing file, unreadable or truncated file, 2D image, empty, NaN or constant volume, no
        voxel size in the file or the arguments.
    """
    p = Path(path)
    where = str(p)
    if not p.exists():
        raise InputError("file not found", where=where)
    suffix = p.suffix.lower()
    if p.is_dir():
        vol, vs = _read_tiff_folder(p)
        source = f"tiff-folder:{p}"
    elif suffix in _TIFF_SUFFIXES:
        vol, vs = _read_tiff(p)
        source = f"tiff:{p}"
    elif suffix == ".npy":
        try:
            vol = np.load(p, allow_pickle=False)
        except Exception:  # numpy's reasons (e.g. "allow_pickle=False") do not help a user
            raise InputError("is not a readable .npy volume (damaged, truncated, another format, or an array "
                             "of Python objects); save the volume with numpy.save", where=where) from None
        vs = None
        source = f"npy:{p}"
    elif suffix in _H5_SUFFIXES:
        vol, vs, ds = _read_h5(p, dataset)
        source = f"hdf5:{p}:{ds}"
    else:
        vol = _read_raw(p, shape, dtype)
        vs = None
        source = f"raw:{p}:{tuple(vol.shape)}:{vol.dtype}"
    vol = validate_volume(vol, where)
    if voxel_size_m is not None:
        try:
            vs = voxel_size_zyx(voxel_size_m)
        except ValueError as exc:
            raise InputError(str(exc), where=where) from None
    if vs is None:
        raise InputError("no voxel size in the file's metadata; give voxel_size", where=where)
    try:
        vs = voxel_size_zyx(vs)
    except ValueError:
        raise InputError(f"invalid voxel size in metadata: {vs}", where=where) from None
    return vol, vs, source


def save_volume_tif(path, volume: np.ndarray, voxel_size_m) -> None:
    """Write a volume as an ImageJ-compatible multi-page TIFF with its voxel size.

    Parameters
    ----------
    path : str or Path
    volume : (Z, Y, X) ndarray
        uint8, uint16 or float32 (ImageJ's types); bool is written as uint8 0/255, other types
        are converted to float32.
    voxel_size_m : float or (dz, dy, dx)
        Voxel size, m; stored in micrometres (``unit=micron``, ``spacing`` = dz, X/YResolution =
        pixels per micron), which FIJI and :func:`load_volume` read back.
    """
    import tifffile

    v = voxel_size_zyx(voxel_size_m) * 1e6  # um
    vol = np.asarray(volume)
    if vol.ndim != 3:
        raise InputError(f"save_volume_tif: expected a 3D volume, got shape {vol.shape}", where=str(path))
    if vol.dtype == bool:
        vol = vol.astype(np.uint8) * 255
    elif vol.dtype not in (np.uint8, np.uint16, np.float32):
        vol = vol.astype(np.float32)
    from fiberpipe.artifacts import atomic_path

    with atomic_path(path, suffix=".tif") as tmp:  # a crash never leaves a half-written volume
        tifffile.imwrite(tmp, vol, imagej=True, resolution=(1.0 / v[2], 1.0 / v[1]),
                         metadata={"spacing": float(v[0]), "unit": "micron", "axes": "ZYX"})
