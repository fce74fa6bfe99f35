"""When the imaging stages run chunk by chunk (``chunks``, docs/imaging.md "Volumes larger than
memory"), and the pieces they share: the chunked mask and skeleton artifacts, a strided sample of
a volume on disk."""

from __future__ import annotations

import logging

import numpy as np

from fiberpipe.config import Config
from fiberpipe.errors import InputError

log = logging.getLogger("fiberpipe")

#: Bytes per voxel the in-memory stages hold (the input, float32 smoothing, int32 labels, the
#: mask, the EDT's slab): ``chunks.mode: auto`` compares voxels x this with ``chunks.memory_budget``.
IN_MEMORY_BYTES_PER_VOXEL = 16

#: HDF5 chunk of the chunked artifacts (slices, rows, columns), capped by the volume's shape.
H5_CHUNK = (16, 256, 256)


def chunked(cfg: Config, shape) -> bool:
    """Whether a stage on a volume of ``shape`` runs chunk by chunk: ``chunks.mode`` on, or auto
    and the in-memory working set above ``chunks.memory_budget``."""
    mode = cfg.chunks.mode
    if mode != "auto":
        return mode == "on"
    need = float(np.prod([int(n) for n in shape], dtype=float)) * IN_MEMORY_BYTES_PER_VOXEL
    if need > cfg.chunks.memory_budget:
        log.info("chunks: the volume %s needs about %.3g GB in memory, above chunks.memory_budget = %.3g GB: "
                 "chunk by chunk", tuple(shape), need / 1e9, cfg.chunks.memory_budget / 1e9)
        return True
    return False


def volume_source(cfg: Config, volume_path):
    """The input volume as a slab-by-slab source when the segment stage runs chunked, else None.

    ``chunks.mode: on`` on a format that is read whole is an InputError naming the key; ``auto``
    reads such a file whole (its size is not known without reading it)."""
    from fiberpipe.imaging.volume_source import chunkable, open_volume_source

    if cfg.chunks.mode == "off":
        return None
    if not chunkable(volume_path):
        if cfg.chunks.mode == "on":
            open_volume_source(volume_path)  # raises the one-line error naming the format
        return None
    inp = cfg.input
    src, vs, desc = open_volume_source(volume_path, dataset=inp.dataset, shape=tuple(inp.shape) if inp.shape else None,
                                       dtype=inp.dtype)
    if not chunked(cfg, src.shape):
        src.close()
        return None
    return src, vs, desc


def h5_chunks(shape) -> tuple[int, int, int]:
    return tuple(int(min(c, n)) for c, n in zip(H5_CHUNK, shape))


def create_volume_dataset(f, name: str, shape, dtype, units: str):
    """A chunked, compressed dataset of a volume artifact (gzip level 1: a mask compresses well and
    the stages read it back slab by slab)."""
    ds = f.create_dataset(name, shape=tuple(shape), dtype=dtype, chunks=h5_chunks(shape), compression="gzip",
                          compression_opts=1, shuffle=True)
    ds.attrs["units"] = units
    return ds


class StridedSample:
    """A 3D array on disk as seen by the orientation measures: ``shape``, ``size``, ``ndim`` and
    strided boxes ``[::a, ::b, ::c]`` read one sampled slice at a time (no whole-volume read)."""

    def __init__(self, arr):
        self.arr = arr
        self.shape = tuple(int(n) for n in arr.shape)
        self.size = int(np.prod(self.shape))
        self.ndim = 3
        self.dtype = np.dtype(bool)

    def __getitem__(self, key):
        if not (isinstance(key, tuple) and len(key) == 3 and all(isinstance(k, slice) for k in key)):
            raise TypeError("StridedSample reads strided boxes [a:b:s, ...] only")
        ks = range(*key[0].indices(self.shape[0]))
        rows = [np.asarray(self.arr[k])[key[1], key[2]] for k in ks]
        return np.stack(rows).astype(bool, copy=False)


def check_not_empty(n_voxels: int, where: str) -> None:
    if n_voxels == 0:
        raise InputError("segmentation found no fiber voxels; check segment.threshold", where=where)
