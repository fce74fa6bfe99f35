"""The regions of a cross ply in a volume larger than memory: the local fiber axis slab by slab.

:func:`fiberpipe.imaging.orientation.axis_regions` labels each fiber voxel with the volume axis its
fibers run along. Here it runs on slabs of the mask (read with a halo so the structure tensor's
window sees across the slab's faces, labels kept for the slab's own slices) and writes the labels
into a dataset on disk; :class:`RegionSource` then presents ``mask & label ∈ keep`` to the chunked
slices tracer (:func:`fiberpipe.imaging.trace_chunked.trace_chunked`), which traces each region
along its own axis as the in-memory tracer does (``trace.off_axis``).
"""

from __future__ import annotations

import numpy as np

from .orientation import axis_regions


class RegionMask:
    """``mask & (labels ∈ keep)`` of two arrays of one shape, read by the boxes the chunked tracer
    asks for (``[lo:hi]`` or ``[:, lo:hi]`` ...)."""

    def __init__(self, mask, labels, keep):
        self.mask, self.labels, self.keep = mask, labels, np.asarray(sorted(keep), dtype=np.uint8)
        self.shape = tuple(int(n) for n in mask.shape)
        self.chunks = getattr(mask, "chunks", None)
        self.dtype = np.dtype(bool)

    def __getitem__(self, key):
        m = np.asarray(self.mask[key]).astype(bool, copy=False)
        return m & np.isin(np.asarray(self.labels[key]), self.keep)


class RegionSource:
    """A picklable :class:`RegionMask` of two sources with ``open()`` (:class:`SliceSource`): Dask
    workers open the files themselves."""

    def __init__(self, mask_src, labels_src, keep):
        self.mask_src, self.labels_src, self.keep = mask_src, labels_src, tuple(int(k) for k in keep)

    def open(self) -> RegionMask:
        return RegionMask(self.mask_src.open(), self.labels_src.open(), self.keep)

    @property
    def shape(self):
        return tuple(self.mask_src.shape)

    def close(self) -> None:
        for s in (self.mask_src, self.labels_src):
            if hasattr(s, "close"):
                s.close()


def axis_labels_chunked(mask, labels_out, voxel_size_m, *, slab: int, halo: int, grey=None,
                        radius_vox: float | None = None, progress=None) -> np.ndarray:
    """Label every fiber voxel of ``mask`` (array-like on disk, read along axis 0) with its fibers'
    volume axis (:func:`~fiberpipe.imaging.orientation.axis_regions`: 0, 1, 2, or 255 off the mask)
    into ``labels_out`` (a writable uint8 dataset of the mask's shape), ``slab`` slices at a time
    with ``halo`` slices read on each side. Returns the share of the fiber voxels along each axis.

    Peak memory: one slab with its halos as a bool mask, its labels and, given ``grey``, its grey
    values (the labels of :func:`axis_regions` come from a strided sample of that slab).
    """
    n = int(mask.shape[0])
    counts = np.zeros(3)
    edges = list(range(0, n, int(slab))) + [n]
    for i, (b0, b1) in enumerate(zip(edges[:-1], edges[1:])):
        lo, hi = max(0, b0 - int(halo)), min(n, b1 + int(halo))
        m = np.asarray(mask[lo:hi]).astype(bool, copy=False)
        g = None if grey is None else np.asarray(grey[lo:hi])
        lab, _ = axis_regions(m, voxel_size_m, grey=g, radius_vox=radius_vox)
        own = lab[b0 - lo:b1 - lo]
        labels_out[b0:b1] = own
        counts += np.bincount(own[own < 3].ravel(), minlength=3)[:3]
        if progress is not None:
            progress(i + 1, len(edges) - 1)
    return counts / max(1.0, counts.sum())
