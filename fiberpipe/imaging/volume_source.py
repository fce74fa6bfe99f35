"""The input volume as a handle read slab by slab (volumes larger than memory).

:func:`open_volume_source` finds, without reading the voxels, where a volume file keeps them: an
HDF5/NeXus dataset, a Zarr array, the data file of an uncompressed MetaImage, the array of a
``.npy`` file, a headerless raw file; and returns a picklable
:class:`~fiberpipe.imaging.trace_chunked.SliceSource` on it (each process, a Dask worker too,
opens the file itself), its voxel size from the header, and a description for provenance. The
dataset choice and the voxel size follow the whole-volume readers of
:mod:`fiberpipe.imaging.readers`, so both paths read the same array.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from .io import MIN_VOXELS_PER_AXIS
from .trace_chunked import SliceSource

#: The formats whose voxels are read slab by slab; the others (TIFF, NIfTI, compressed MetaImage)
#: are read whole.
CHUNKED_FORMATS = "HDF5/NeXus, Zarr, MetaImage (uncompressed), .npy or raw"


def chunkable(path) -> bool:
    """Whether :func:`open_volume_source` can read ``path`` slab by slab (by format, not content)."""
    from .readers import reader_for

    p = Path(path)
    name = reader_for(p).name
    if name == "metaimage":
        from .readers.metaimage import layout

        try:
            return not layout(p)["compressed"]
        except InputError:
            return True  # the error is reported when the volume is opened
    return name in ("hdf5", "zarr", "npy", "raw")


def _npy(p: Path, where: str):
    try:
        with open(p, "rb") as f:
            fmt = np.lib.format
            version = fmt.read_magic(f)
            read_header = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
            shape, fortran, dtype = read_header(f)
            offset = f.tell()
    except Exception:  # numpy's reasons do not help a user
        raise InputError("is not a readable .npy volume (damaged, truncated or another format)", where=where) from None
    if fortran or dtype.hasobject:
        raise InputError("a .npy volume in Fortran order or of Python objects cannot be read slab by slab; save "
                         "it with numpy.save from a C-ordered array", where=where)
    need = offset + int(np.prod(shape)) * dtype.itemsize
    if p.stat().st_size < need:
        raise InputError(f"the .npy file is truncated ({p.stat().st_size} bytes, its header needs {need})", where=where)
    return SliceSource(p, shape=shape, dtype=dtype, offset=offset), None, f"npy:{p}"


def open_volume_source(path, *, dataset: str | None = None, shape=None, dtype=None):
    """A slab-by-slab handle on the volume ``path`` (the arguments of :func:`fiberpipe.imaging.io.load_volume`).

    Returns
    -------
    source : SliceSource
    voxel_size_m : (3,) ndarray or None
        From the header, when it has one.
    description : str

    Raises
    ------
    InputError
        A format that is read whole (TIFF, NIfTI, compressed MetaImage), a missing file, a header
        that disagrees with the data size, not a 3D grey volume, thinner than 3 voxels.
    """
    from .readers import reader_for

    p = Path(path)
    where = str(p)
    if not p.exists():
        raise InputError("file not found", where=where)
    fmt = reader_for(p).name
    if fmt == "hdf5":
        from .readers.hdf5 import locate

        name, vs, _, _ = locate(p, dataset=dataset)
        src, desc = SliceSource(p, name), f"hdf5:{p}:{name}"
    elif fmt == "zarr":
        from .readers.zarr import locate

        name, vs, _, _ = locate(p, dataset=dataset)
        src, desc = SliceSource(p, name), f"zarr:{p}" + (f":{name}" if name else "")
    elif fmt == "metaimage":
        from .readers.metaimage import layout

        lay = layout(p)
        if lay["compressed"]:
            raise InputError(f"a compressed MetaImage is read whole; the chunked stages read {CHUNKED_FORMATS}: "
                             "write it uncompressed", where=where)
        src = SliceSource(lay["data"], shape=lay["shape"], dtype=lay["dtype"], offset=lay["start"])
        vs, desc = lay["voxel_size_m"], f"metaimage:{p}"
    elif fmt == "npy":
        src, vs, desc = _npy(p, where)
    elif fmt == "raw":
        if shape is None or dtype is None:
            raise InputError("a raw volume needs shape (z, y, x) and dtype", where=where)
        shp, dt = tuple(int(s) for s in shape), np.dtype(dtype)
        need = int(np.prod(shp)) * dt.itemsize
        if p.stat().st_size != need:
            raise InputError(f"raw file has {p.stat().st_size} bytes, shape {shp} of {dt} needs {need}", where=where)
        src, vs, desc = SliceSource(p, shape=shp, dtype=dt), None, f"raw:{p}:{shp}:{dt}"
    else:
        raise InputError(f"a {fmt} volume is read whole; the chunked stages read {CHUNKED_FORMATS}: convert it "
                         "(or set chunks.mode: off)", where=where)
    arr = src.open()
    shp = tuple(int(n) for n in arr.shape)
    if len(shp) != 3:
        raise InputError(f"expected a 3D volume, got shape {shp}", where=where)
    if int(np.prod(shp)) == 0:
        raise InputError(f"the volume is empty (shape {shp})", where=where)
    if np.dtype(arr.dtype).kind not in "biuf":
        raise InputError(f"unsupported voxel type {arr.dtype}", where=where)
    if min(shp) < MIN_VOXELS_PER_AXIS:
        raise InputError(f"the volume is too thin: {min(shp)} voxels along {'zyx'[int(np.argmin(shp))]} (shape "
                         f"{shp}, z y x); fibers are traced in 3D and need at least {MIN_VOXELS_PER_AXIS} voxels "
                         "along each axis", where=where)
    return src, vs, desc
