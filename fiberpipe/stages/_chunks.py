"""When the imaging stages run chunk by chunk (``chunks``, docs/imaging.md "Volumes larger than
memory"), and what they share: the source of the input volume, the chunked datasets of the mask
and skeleton artifacts."""

from __future__ import annotations

import logging

import numpy as np

from fiberpipe.config import Config

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
    reads such a file whole (its size is not known without reading it), and leaves a file it
    cannot open slab by slab (damaged, empty) to the whole-volume reader, whose errors say why."""
    from fiberpipe.errors import InputError
    from fiberpipe.imaging.volume_source import chunkable, open_volume_source

    if cfg.chunks.mode == "off":
        return None
    if not chunkable(volume_path):
        if cfg.chunks.mode == "on":
            open_volume_source(volume_path)  # raises the one-line error naming the format
        return None
    inp = cfg.input
    try:
        src, vs, desc = open_volume_source(volume_path, dataset=inp.dataset,
                                           shape=tuple(inp.shape) if inp.shape else None, dtype=inp.dtype)
    except InputError:
        if cfg.chunks.mode == "on":
            raise
        return None
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
