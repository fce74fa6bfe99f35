"""Skeleton of a mask larger than memory: thinning slab by slab with a halo.

Topology-preserving thinning is local: a voxel's fate depends on voxels within about the object's
half-thickness of it, so a slab thinned with a halo of a few fiber radii on each side has, in its
interior, the skeleton of the whole volume up to the order in which equivalent voxels are peeled
(one-voxel shifts at most; measured in ``tests/imaging/test_skeleton_chunked.py``). The radius on
the skeleton is the EDT of the same padded slab, exact while it is smaller than the halo (checked).
Slabs run one after another, or on a Dask cluster when given a scheduler; each result slab is
written as it arrives, so memory holds a few padded slabs only.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage as ndi

from ..errors import InputError


def _skeleton_slab(src, a: int, b: int, halo: int, sampling):
    """Skeleton and radius of slices a..b, from slices a - halo .. b + halo."""
    from skimage.morphology import skeletonize as _sk

    arr = src.open() if hasattr(src, "open") else src
    n = arr.shape[0]
    lo, hi = max(0, a - halo), min(n, b + halo)
    m = np.asarray(arr[lo:hi]).astype(bool, copy=False)
    if not m.any():
        return a, b, np.zeros((b - a,) + m.shape[1:], bool), np.zeros((b - a,) + m.shape[1:], np.float32), 0.0
    sk = _sk(m).astype(bool, copy=False)
    d = ndi.distance_transform_edt(m, sampling=sampling)
    inner = slice(a - lo, b - lo)
    sk_in = sk[inner]
    rad = np.where(sk_in, d[inner], 0.0).astype(np.float32)
    return a, b, sk_in, rad, float(rad.max()) if rad.size else 0.0


def skeletonize_chunked(src, out_skeleton, out_radius, *, slab: int = 64, halo: int = 32, voxel_size_m=None,
                        scheduler=None) -> dict:
    """Skeleton (and radius on it) of a mask on disk, slab by slab along axis 0.

    Parameters
    ----------
    src : SliceSource or array-like
        The mask; anything whose ``[a:b]`` reads slices a..b (h5py dataset, zarr array,
        :class:`fiberpipe.imaging.trace_chunked.SliceSource`).
    out_skeleton, out_radius : array-likes of the mask's shape (bool, float32)
        Written slab by slab (h5py datasets, zarr arrays or numpy arrays).
    slab, halo : int
        Slices per slab and slices read on each side of it (a few fiber radii).
    voxel_size_m : float or (dz, dy, dx), optional
        Only the ratios matter (the radius is in units of the smallest voxel size).
    scheduler : str or dask.distributed.Client, optional
        Slabs are thinned on the cluster's workers (``src`` then a SliceSource).

    Returns
    -------
    dict: ``slabs``, ``skeleton_voxels``, ``max_radius_vox``.

    Raises
    ------
    InputError
        When a radius reaches the halo (the EDT there would not be exact): raise ``halo``.
    """
    from .trace_chunked import _client

    arr = src.open() if hasattr(src, "open") else src
    n = int(arr.shape[0])
    if int(slab) < 1 or int(halo) < 1:
        raise InputError(f"skeletonize: slab and halo must be at least 1 slice, got {slab!r}, {halo!r}")
    sampling = None
    if voxel_size_m is not None:
        v = np.broadcast_to(np.asarray(voxel_size_m, dtype=np.float64), (3,))
        sampling = tuple(v / v.min())
    jobs = [(a, min(n, a + int(slab))) for a in range(0, n, int(slab))]
    client = _client(scheduler)
    count, rmax = 0, 0.0

    def _store(res):
        nonlocal count, rmax
        a, b, sk, rad, rm = res
        out_skeleton[a:b] = sk
        out_radius[a:b] = rad
        count += int(sk.sum())
        rmax = max(rmax, rm)

    if client is None:
        for a, b in jobs:
            _store(_skeleton_slab(src, a, b, int(halo), sampling))
    else:
        from dask.distributed import as_completed

        futures = [client.submit(_skeleton_slab, src, a, b, int(halo), sampling, pure=False) for a, b in jobs]
        for fut in as_completed(futures):
            _store(fut.result())
            fut.release()
    hmin = int(halo) * (min(sampling) if sampling is not None else 1.0)
    if rmax >= hmin:
        raise InputError(f"skeletonize: a radius of {rmax:.1f} voxels reaches the halo of {halo} slices; raise the halo")
    return {"slabs": len(jobs), "skeleton_voxels": count, "max_radius_vox": rmax}
