"""Volume readers, one module per format, each registering itself (the way meshio does).

A reader is a function ``read(path, *, dataset=None, shape=None, dtype=None) -> (volume,
voxel_size_m or None, source)`` registered with the file suffixes it takes (or, for a folder
format, a test of the folder). :func:`reader_for` picks one for a path; files of no known suffix
go to the headerless ``raw`` reader. Adding a format is one module here plus its entry in
:data:`_MODULES`.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional


@dataclass(frozen=True)
class Reader:
    """A registered volume format."""

    name: str
    suffixes: tuple[str, ...]
    read: Callable
    #: for a folder format: does this folder hold the format?
    claims_folder: Optional[Callable[[Path], bool]] = None
    #: the reader for files of no known suffix
    fallback: bool = False


READERS: dict[str, Reader] = {}


def register(name: str, suffixes=(), read: Callable | None = None, *, claims_folder=None, fallback: bool = False):
    """Register ``read`` as the reader of ``name`` (suffixes lower-case, with the dot)."""
    READERS[name] = Reader(name, tuple(s.lower() for s in suffixes), read, claims_folder, fallback)


def reader_for(path: Path) -> Reader:
    """The reader for ``path``: a folder format that claims the folder, else the longest matching
    suffix (``.nii.gz`` before ``.gz``), else the fallback (headerless raw)."""
    p = Path(path)
    if p.is_dir():
        for r in READERS.values():
            if r.claims_folder is not None and r.claims_folder(p):
                return r
    name = p.name.lower()
    best, best_len = None, 0
    for r in READERS.values():
        for s in r.suffixes:
            if name.endswith(s) and len(s) > best_len:
                best, best_len = r, len(s)
    if best is not None:
        return best
    return next(r for r in READERS.values() if r.fallback)


#: The format modules, in the order folder formats are asked (zarr before the TIFF folder).
_MODULES = ("zarr", "tiff", "npy", "hdf5", "metaimage", "nifti", "raw")

for _m in _MODULES:
    importlib.import_module(f"{__name__}.{_m}")
