"""Reading and writing CT volumes: :func:`load_volume` dispatches to the format readers of
:mod:`fiberpipe.imaging.readers` (TIFF file or folder of slices, .npy, HDF5/NeXus, MetaImage,
NIfTI, Zarr, headerless raw) and checks what they return."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ._util import voxel_size_zyx

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
        ``.npy`` file, an HDF5 or NeXus file (``.h5``/``.hdf5``/``.nxs``), a MetaImage header
        (``.mhd``/``.mha``), a NIfTI image (``.nii``/``.nii.gz``), a Zarr store (``.zarr`` folder)
        or a headerless raw file (any other suffix; needs ``shape`` and ``dtype``); see
        :mod:`fiberpipe.imaging.readers`.
    voxel_size_m : float or (dz, dy, dx), optional
        Voxel size, m; overrides the file's metadata (ImageJ ``unit``/``spacing`` + X/YResolution,
        OME PhysicalSize*, HDF5/Zarr ``voxel_size_m`` / ``element_size_um`` attributes, NeXus axes,
        MetaImage ``ElementSpacing`` (mm), NIfTI ``pixdim`` and units, OME-Zarr scale). TIFF
        resolutions in inches (the 72 dpi default of image writers) do not count as a voxel size.
    dataset : str, optional
        HDF5 dataset or Zarr array name (default: the NeXus default signal, the OME-Zarr full
        resolution, or the only dataset with 3 or more dimensions).
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
    from .readers import reader_for

    p = Path(path)
    where = str(p)
    if not p.exists():
        raise InputError("file not found", where=where)
    vol, vs, source = reader_for(p).read(p, dataset=dataset, shape=shape, dtype=dtype)
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
