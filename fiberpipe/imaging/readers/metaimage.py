"""MetaImage (ITK): a ``.mhd`` text header beside its raw data file, or a ``.mha`` with the data
after the header. Read with NumPy (memory-mapped when uncompressed); the voxel size is
``ElementSpacing`` (x y z) in millimetres, ITK's convention."""

from __future__ import annotations

import zlib
from pathlib import Path

import numpy as np

from ...errors import InputError
from . import register
from ._common import why

#: MetaImage element types (MET_*) -> NumPy types (ITK's sizes on 64-bit Linux)
_TYPES = {
    "MET_UCHAR": "u1", "MET_CHAR": "i1", "MET_USHORT": "u2", "MET_SHORT": "i2",
    "MET_UINT": "u4", "MET_INT": "i4", "MET_ULONG": "u8", "MET_LONG": "i8",
    "MET_ULONG_LONG": "u8", "MET_LONG_LONG": "i8", "MET_FLOAT": "f4", "MET_DOUBLE": "f8",
}


def read_header(path: Path) -> tuple[dict, int]:
    """The header's ``key = value`` pairs (up to ``ElementDataFile``, which ends it) and the byte
    offset just after it (where a ``.mha``'s data begin)."""
    header, offset = {}, 0
    with open(path, "rb") as f:
        for raw in f:
            offset += len(raw)
            line = raw.decode("latin-1").strip()
            if not line:
                continue
            if "=" not in line:
                raise InputError(f"not a MetaImage header (line {line[:40]!r} has no '=')", where=str(path))
            k, v = (t.strip() for t in line.split("=", 1))
            header[k] = v
            if k == "ElementDataFile":
                break
            if len(header) > 200:
                break
    if "ElementDataFile" not in header or "DimSize" not in header or "ElementType" not in header:
        raise InputError("not a MetaImage header (needs DimSize, ElementType and ElementDataFile)", where=str(path))
    return header, offset


def _true(v) -> bool:
    return str(v).strip().lower() in ("true", "1", "yes")


def layout(path: Path) -> dict:
    """Where and how the voxels are stored, from the header, checked against the data file's
    size: ``data`` (file), ``start`` (byte offset), ``shape`` (z y x), ``dtype``, ``compressed``,
    ``voxel_size_m`` (z y x, or None). The chunked stages read an uncompressed file slab by slab."""
    where = str(path)
    h, offset = read_header(path)
    try:
        dims = [int(x) for x in h["DimSize"].split()]
        ndims = int(h.get("NDims", len(dims)))
    except ValueError:
        raise InputError(f"MetaImage DimSize {h['DimSize']!r} is not a list of integers", where=where) from None
    channels = int(h.get("ElementNumberOfChannels", "1"))
    if ndims != 3 or len(dims) != 3 or channels != 1:
        raise InputError(f"MetaImage of {ndims} dimensions {dims} and {channels} channels; need one 3D grey volume",
                         where=where)
    et = h["ElementType"].upper()
    if et not in _TYPES:
        raise InputError(f"MetaImage ElementType {et} is not supported ({', '.join(_TYPES)})", where=where)
    msb = _true(h.get("BinaryDataByteOrderMSB", h.get("ElementByteOrderMSB", "False")))
    dtype = np.dtype(_TYPES[et]).newbyteorder(">" if msb else "<")
    shape = tuple(dims[::-1])  # DimSize is x y z; the array is z y x
    need = int(np.prod(shape)) * dtype.itemsize
    src = h["ElementDataFile"]
    if src.upper() == "LOCAL":
        data, start = path, offset
    elif src.upper() == "LIST" or "%" in src:
        raise InputError(f"MetaImage ElementDataFile {src!r} (one file per slice) is not supported; "
                         "convert to a single data file", where=where)
    else:
        data, start = path.parent / src, 0
        if not data.exists():
            raise InputError(f"MetaImage data file {src} (ElementDataFile) does not exist", where=where)
    size = data.stat().st_size - start
    compressed = _true(h.get("CompressedData", "False"))
    if not compressed:
        hs = int(h.get("HeaderSize", "0"))
        if hs == -1:  # the data are the last bytes of the file
            start, size = start + size - need, need
        elif hs > 0:
            start, size = start + hs, size - hs
        if size != need:
            raise InputError(f"MetaImage header DimSize {' '.join(map(str, dims))} of {et} needs {need} bytes, "
                             f"{data.name} holds {size}", where=where)
    vs = None
    spacing = h.get("ElementSpacing", h.get("ElementSize"))
    if spacing:
        try:
            sx, sy, sz = (float(x) for x in spacing.split())
            vs = np.array([sz, sy, sx]) * 1e-3
        except ValueError:
            vs = None
    return {"data": data, "start": start, "shape": shape, "dtype": dtype, "compressed": compressed,
            "voxel_size_m": vs, "dims": dims, "element_type": et, "bytes": need}


def read(path: Path, **_):
    where = str(path)
    lay = layout(path)
    data, start, shape, dtype, need = lay["data"], lay["start"], lay["shape"], lay["dtype"], lay["bytes"]
    if lay["compressed"]:
        with open(data, "rb") as f:
            f.seek(start)
            blob = f.read()
        try:
            buf = zlib.decompress(blob)
        except zlib.error as exc:
            raise InputError(f"MetaImage compressed data {data.name} are unreadable ({why(exc)}); truncated or damaged",
                             where=where) from None
        if len(buf) != need:
            raise InputError(f"MetaImage header DimSize {' '.join(map(str, lay['dims']))} of {lay['element_type']} "
                             f"needs {need} bytes, the compressed data hold {len(buf)}", where=where)
        vol = np.frombuffer(buf, dtype=dtype).reshape(shape)
    else:
        vol = np.memmap(data, dtype=dtype, mode="r", offset=start, shape=shape)
    if not dtype.isnative:
        vol = vol.astype(dtype.newbyteorder("="))
    return vol, lay["voxel_size_m"], f"metaimage:{path}"


register("metaimage", (".mhd", ".mha"), read)
