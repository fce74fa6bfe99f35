"""Headerless raw volumes: any file of no known suffix; ``shape`` (z, y, x) and ``dtype`` given."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import InputError
from . import register


def read(path: Path, *, shape=None, dtype=None, **_):
    if shape is None or dtype is None:
        raise InputError("a raw volume needs shape (z, y, x) and dtype", where=str(path))
    shape = tuple(int(s) for s in shape)
    dtype = np.dtype(dtype)
    expected = int(np.prod(shape)) * dtype.itemsize
    size = path.stat().st_size
    if size != expected:
        raise InputError(f"raw file has {size} bytes, shape {shape} of {dtype} needs {expected}",
                         where=str(path))
    vol = np.fromfile(path, dtype=dtype).reshape(shape)
    return vol, None, f"raw:{path}:{tuple(vol.shape)}:{vol.dtype}"


register("raw", (), read, fallback=True)
