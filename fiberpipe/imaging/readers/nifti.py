"""NIfTI-1/2 (``.nii``, ``.nii.gz``), read with nibabel. The array's i j k axes are x y z, so the
volume is their transpose (z y x); the voxel size is ``pixdim`` in the header's spatial unit
(none when the unit is unknown)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import InputError
from . import register
from ._common import need, unit_to_m, why


def read(path: Path, **_):
    where = str(path)
    nib = need("nibabel", "NIfTI", where)
    try:
        img = nib.load(str(path))
    except Exception as exc:  # noqa: BLE001 — nibabel raises many types for damaged headers
        raise InputError(f"cannot read NIfTI header ({why(exc)})", where=where) from None
    hdr = img.header
    shape = tuple(int(s) for s in img.shape)
    try:
        data = np.asanyarray(img.dataobj)
    except Exception as exc:  # noqa: BLE001 — truncated data: nibabel/gzip raise OSError, EOFError, ValueError
        nbytes = int(np.prod(shape)) * np.dtype(hdr.get_data_dtype()).itemsize
        raise InputError(f"NIfTI header dim {list(shape)} of {hdr.get_data_dtype()} needs {nbytes} bytes of data, "
                         f"which the file does not hold ({why(exc)})", where=where) from None
    while data.ndim > 3 and data.shape[-1] == 1:
        data = data[..., 0]
    if data.ndim != 3:
        raise InputError(f"NIfTI image of shape {shape}; need one 3D grey volume", where=where)
    vol = np.ascontiguousarray(data.transpose(2, 1, 0))
    unit = hdr.get_xyzt_units()[0]
    f = unit_to_m({"micron": "um"}.get(unit, unit))
    zooms = [float(z) for z in hdr.get_zooms()[:3]]
    vs = np.array(zooms[::-1]) * f if f and all(z > 0 for z in zooms) else None
    return vol, vs, f"nifti:{path}"


register("nifti", (".nii", ".nii.gz"), read)
