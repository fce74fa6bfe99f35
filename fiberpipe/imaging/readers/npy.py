"""NumPy ``.npy`` arrays (no voxel size: it comes from the config)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import InputError
from . import register


def read(path: Path, **_):
    try:
        vol = np.load(path, allow_pickle=False)
    except Exception:  # numpy's reasons (e.g. "allow_pickle=False") do not help a user
        raise InputError("is not a readable .npy volume (damaged, truncated, another format, or an array "
                         "of Python objects); save the volume with numpy.save", where=str(path)) from None
    return vol, None, f"npy:{path}"


register("npy", (".npy",), read)
