"""Skeleton of a mask larger than memory: thinning slab by slab, tile by tile, with a halo.

Topology-preserving thinning is local: a voxel's fate depends on voxels within about the object's
half-thickness of it, so a slab thinned with a halo of a few fiber radii on each side (in tiles
across the slice, each with the same halo) has, in its interior, the skeleton of the whole volume
up to the order in which equivalent voxels are peeled (one-voxel shifts; measured in
``tests/imaging/test_skeleton_chunked.py``). The radius on the skeleton is the EDT of the same
padded tile, exact while it is smaller than the halo (checked). Slabs run one after another, or on
a Dask cluster when given a scheduler; a slab comes back as its skeleton voxels and radii and is
written as it arrives, so memory holds a padded tile and one slab of output."""

from __future__ import annotations

import numpy as np
from scipy import ndimage as ndi

from ..errors import InputError


def _skeleton_slab(src, a: int, b: int, halo: int, sampling, tile: int):
    """Skeleton and radius of slices a..b, in tiles of ``tile`` x ``tile`` pixels, each read with
    ``halo`` voxels around it on every side (so memory follows the tile, not the slice area).
    Returns the skeleton voxels as (n, 3) int32 indices relative to slice a, their radii, and the
    largest radius."""
    from skimage.morphology import skeletonize as _sk

    arr = src.open() if hasattr(src, "open") else src
    n, H, W = (int(x) for x in arr.shape)
    lo, hi = max(0, a - halo), min(n, b + halo)
    idx, rad, rmax = [], [], 0.0
    for y0 in range(0, H, tile):
        for x0 in range(0, W, tile):
            y1, x1 = min(H, y0 + tile), min(W, x0 + tile)
            ylo, yhi, xlo, xhi = max(0, y0 - halo), min(H, y1 + halo), max(0, x0 - halo), min(W, x1 + halo)
            m = np.asarray(arr[lo:hi, ylo:yhi, xlo:xhi]).astype(bool, copy=False)
            if not m.any():
                continue
            sk = _sk(m).astype(bool, copy=False)
            inner = (slice(a - lo, b - lo), slice(y0 - ylo, y1 - ylo), slice(x0 - xlo, x1 - xlo))
            pts = np.argwhere(sk[inner])
            if not len(pts):
                continue
            # the EDT only around the skeleton's own slices and tile (+ halo): exact below the halo
            d = ndi.distance_transform_edt(m, sampling=sampling)
            r = d[inner][sk[inner]].astype(np.float32)
            del d
            idx.append((pts + np.array([0, y0, x0])).astype(np.int32))
            rad.append(r)
            rmax = max(rmax, float(r.max()))
    if idx:
        return a, b, np.concatenate(idx), np.concatenate(rad), rmax
    return a, b, np.zeros((0, 3), np.int32), np.zeros(0, np.float32), 0.0


def skeletonize_chunked(src, out_skeleton, out_radius, *, slab: int = 64, halo: int = 32, tile: int = 512,
                        voxel_size_m=None, scheduler=None) -> dict:
    """Skeleton (and radius on it) of a mask on disk, slab by slab along axis 0.

    Parameters
    ----------
    src : SliceSource or array-like
        The mask; anything read by 3D boxes ``[a:b, y0:y1, x0:x1]`` (h5py dataset, zarr array, numpy
        array, :class:`fiberpipe.imaging.trace_chunked.SliceSource` of HDF5 or Zarr).
    out_skeleton, out_radius : array-likes of the mask's shape (bool, float32)
        Written slab by slab (h5py datasets, zarr arrays or numpy arrays).
    slab, halo : int
        Slices per slab and voxels read on each side of a slab's tile (a few fiber radii).
    tile : int
        Tile size in y and x, pixels: a slab is thinned tile by tile, each with the halo.
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
    from ._dask import _client

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
        a, b, pts, rad, rm = res
        shp = (b - a,) + tuple(arr.shape[1:])
        sk = np.zeros(shp, dtype=bool)
        sk[pts[:, 0], pts[:, 1], pts[:, 2]] = True
        out_skeleton[a:b] = sk
        del sk
        rr = np.zeros(shp, dtype=np.float32)
        rr[pts[:, 0], pts[:, 1], pts[:, 2]] = rad
        out_radius[a:b] = rr
        count += len(pts)
        rmax = max(rmax, rm)

    if client is None:
        for a, b in jobs:
            _store(_skeleton_slab(src, a, b, int(halo), sampling, int(tile)))
    else:
        from dask.distributed import as_completed

        futures = [client.submit(_skeleton_slab, src, a, b, int(halo), sampling, int(tile), pure=False) for a, b in jobs]
        for fut in as_completed(futures):
            _store(fut.result())
            fut.release()
    hmin = int(halo) * (min(sampling) if sampling is not None else 1.0)
    if rmax >= hmin:
        raise InputError(f"skeletonize: a radius of {rmax:.1f} voxels reaches the halo of {halo} slices; raise the halo")
    return {"slabs": len(jobs), "skeleton_voxels": count, "max_radius_vox": rmax}
