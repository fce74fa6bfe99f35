"""Tracing volumes larger than memory: the slices tracer in blocks of slices read from disk.

The slices tracer reads one slice at a time, so a mask on disk (HDF5, Zarr, raw) sliced along the
fibers' axis never needs to be in memory. The slices are cut into blocks; each block is tracked on
its own (one after another, or in parallel on a Dask cluster when given a scheduler), the pieces
of all blocks are stored compactly (int32 slice, float32 centre and radius) and joined across the
block boundaries by the tracer's own gap merging, which chains a track ending in the last slice of
a block to the one starting in the first slice of the next. Peak memory: one block's tracks as
Python objects plus all tracks in compact form plus a slice's detection arrays, independent of the
number of slices beyond the compact tracks (16 bytes per fiber and slice).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..polylines import Polylines
from ._util import voxel_size_zyx
from ._dask import _client
from .trace import (_GreySlices, _join, drop_oblique_into_meta, estimate_radius_vox, finish_tracks, grey_levels,
                    grey_radius_of_slices, grey_sigma_along, slice_options, track_gain, track_slices)


class SliceSource:
    """A picklable handle on a 3D array on disk, read slice by slice along axis 0.

    ``SliceSource(path.h5, "mask")`` (HDF5 dataset), ``SliceSource(path.zarr)`` or
    ``SliceSource(path.zarr, "name")`` (Zarr array or an array of a group), ``SliceSource(path.raw,
    shape=(z, y, x), dtype="uint16")`` (headerless raw, C order; ``offset``: bytes before the
    voxels, as in a MetaImage or ``.npy`` file). The file is opened on first use in each process
    (Dask workers get the path, not an open handle).
    """

    def __init__(self, path, dataset: str | None = None, *, shape=None, dtype=None, offset: int = 0):
        self.path, self.dataset = str(path), dataset
        self.shape_raw, self.dtype = (tuple(int(s) for s in shape) if shape is not None else None), dtype
        self.offset = int(offset)
        self._arr = None

    def __getstate__(self):
        d = dict(self.__dict__)
        d["_arr"] = None
        return d

    def open(self):
        if self._arr is not None:
            return self._arr
        p = Path(self.path)
        if not p.exists():
            raise InputError(f"no such file: {p}", where=str(p))
        if self.shape_raw is not None:
            from .segment_chunked import RawSlabs

            self._arr = RawSlabs(p, self.shape_raw, self.dtype or "uint8", offset=self.offset)
        elif p.suffix.lower() in (".h5", ".hdf5", ".hdf", ".nxs"):
            import h5py

            f = h5py.File(p, "r")
            if self.dataset is None or self.dataset not in f:
                raise InputError(f"HDF5 dataset {self.dataset!r} not found (has {sorted(f)})", where=str(p))
            self._arr = f[self.dataset]
        else:
            import zarr

            z = zarr.open(str(p), mode="r")
            self._arr = z[self.dataset] if self.dataset else z
        if len(self._arr.shape) != 3:
            raise InputError(f"expected a 3D array, got shape {tuple(self._arr.shape)}", where=str(p))
        return self._arr

    @property
    def shape(self):
        return tuple(self.open().shape)

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    @property
    def chunks(self):
        return getattr(self.open(), "chunks", None)

    def close(self) -> None:
        f = getattr(self._arr, "file", None)
        if f is not None and hasattr(f, "close"):
            f.close()
        self._arr = None

    def __getitem__(self, k):
        return self.open()[k]


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


class _Block:
    """Slices ``b0 .. b1 - 1`` across ``axis`` of an array as the (N, H, W) input of
    :func:`track_slices` (the other two axes in their order, as the in-memory tracer's transpose),
    read ``read_ahead`` slices at a time (a chunked store decompresses each chunk once, not once
    per slice; by default 16 along axis 0, across it the store's chunk extent up to 128)."""

    def __init__(self, arr, b0: int, b1: int, dtype=bool, read_ahead: int | None = None, axis: int = 0,
                 halo: int = 0):
        # halo: slices beyond the block the reads may reach (the grey smoothing along the slices)
        self.arr, self.b0, self.b1, self.dtype, self.axis = arr, int(b0), int(b1), dtype, int(axis)
        self.lo_bound = max(0, self.b0 - int(halo))
        self.hi_bound = min(int(arr.shape[self.axis]), self.b1 + int(halo))
        if read_ahead is None:
            chunks = getattr(arr, "chunks", None)
            read_ahead = 16 if self.axis == 0 or not chunks else min(128, max(16, int(chunks[self.axis])))
        self.ahead = int(read_ahead)
        rest = [n for i, n in enumerate(arr.shape) if i != self.axis]
        self.shape = (int(b1) - int(b0),) + tuple(int(n) for n in rest)
        self._lo, self._buf = -1, None

    def _read(self, lo: int, hi: int) -> np.ndarray:
        if self.axis == 0:
            return np.asarray(self.arr[lo:hi])
        box = (slice(None),) * self.axis + (slice(lo, hi),)
        return np.moveaxis(np.asarray(self.arr[box]), self.axis, 0)

    def __getitem__(self, k):
        i = self.b0 + int(k)
        if self._buf is None or not (self._lo <= i < self._lo + len(self._buf)):
            # the slices tracer's grey path also reads a few slices back: keep them in the window
            lo = max(self.lo_bound, i - 6) if self.dtype is not bool else i
            self._lo, self._buf = lo, self._read(lo, min(self.hi_bound, max(i + 1, lo + self.ahead)))
        a = self._buf[i - self._lo]
        return a.astype(bool, copy=False) if self.dtype is bool else a


class _Piece:
    __slots__ = ("k", "p", "r")

    def __init__(self, k, p, r):
        self.k, self.p, self.r = k, p, r


def _track_block(src, grey_src, b0: int, b1: int, r: float, samp, params: dict, axis: int = 0, levels=None):
    """Track one block of slices across ``axis``; the pieces in compact arrays (slice indices global).
    With grey detection the tracking starts ``WARM_UP`` slices before the block (the points there
    are dropped), so the tracks enter the block established, with the predictions that separate
    touching fibers in a dense pack, and the grey slices are scaled by the whole volume's
    ``levels`` and smoothed along the slices across the block's faces: a block's first slices are
    detected as in the whole volume. On the mask alone the blocks need no warm-up (the harder
    phantom family in 16-slice blocks: the in-memory result with or without)."""
    arr = src.open() if hasattr(src, "open") else src
    w0 = max(0, int(b0) - WARM_UP) if grey_src is not None else int(b0)
    block = _Block(arr, w0, b1, axis=axis)
    grey_t = None
    if grey_src is not None:
        g = grey_src.open() if hasattr(grey_src, "open") else grey_src
        n = int(arr.shape[axis])
        sigma = grey_sigma_along(r)
        halo = max(GREY_HALO, int(np.ceil(3 * sigma)) + 2)
        grey_t = _GreySlices(_Block(g, w0, b1, dtype=None, axis=axis, halo=halo), block, samp, levels=levels,
                             k_range=(-w0, n - 1 - w0), sigma_along=sigma)
    tracks, n_det = track_slices(block, r, samp, grey_t=grey_t, **params)
    out = []
    for t in tracks:
        k = np.asarray(t.k, dtype=np.int32) + w0
        keep = k >= b0
        if keep.any():
            out.append((k[keep], np.asarray(t.p, dtype=np.float32)[keep], np.asarray(t.r, dtype=np.float32)[keep]))
    return out, n_det


#: Slices tracked before each block and dropped (grey detection): the tracks enter the block established.
WARM_UP = 16


#: Slices a block's grey reads reach beyond its faces, at least: the half-width of the smoothing along
#: the slices (3 sigma of :class:`fiberpipe.imaging.trace._GreySlices`, plus its read-back window;
#: more for thicker fibers, :func:`fiberpipe.imaging.trace.grey_sigma_along`).
GREY_HALO = 8


def trace_chunked(src, voxel_size_m, *, expected_radius_m: float | None = None, block: int = 128,
                  scheduler=None, grey=None, progress=None, axis: int | str = "auto", join: dict | None = None,
                  **options) -> Polylines:
    """The slices tracer (:func:`fiberpipe.imaging.trace.trace_slices`) on a mask read slice by
    slice across ``axis`` (the fibers' axis; 0 reads slabs of the storage order, 1 or 2 boxes
    across it), in blocks of ``block`` slices.

    Parameters
    ----------
    src : SliceSource or array-like
        The mask (anything whose ``[k]`` is slice k: an h5py dataset, a zarr array, a memory map);
        a :class:`SliceSource` when a scheduler is given (workers open the file themselves).
    voxel_size_m : float or (dz, dy, dx)
    expected_radius_m : float, optional
        Nominal radius; else estimated from 16 slices.
    block : int
        Slices per block (the unit of work and of memory).
    scheduler : str or dask.distributed.Client, optional
        Dask scheduler address (or client): blocks are tracked on its workers.
    grey : SliceSource or array-like, optional
        The grey volume, for detection on grey (see :func:`fiberpipe.imaging.trace.detect_slice`).
    progress : callable(done_blocks, total_blocks), optional
    axis : int or "auto"
        The slicing axis (0, 1 or 2); ``"auto"``: the volume axis nearest the dominant fiber
        direction of :func:`fiberpipe.imaging.orientation.mask_orientation` on a strided sample
        (read a sampled slice at a time; axis 0 when the sample is too thin to tell).
    join : dict, optional
        ``join_gap_vox``, ``join_offset_vox``, ``join_angle_deg`` of :func:`fiberpipe.imaging.trace.trace`.
    **options
        The tracking fields of :class:`fiberpipe.imaging.trace.SliceOptions` (``max_jump_vox``,
        ``max_skip``, ``gain``, ``min_length_vox``, ``merge_gap_vox``, ``smooth_sigma_vox``,
        ``spacing_vox``, ``peak_threshold``, ``refine``, ``radius_from``); fibers must run within ~45
        degrees of ``axis`` (one slicing axis: no region split). ``radius_from="grey"`` with
        ``grey`` (the dense tracer): the radius from six grey slices
        (:func:`fiberpipe.imaging.dense.estimate_radius_grey`) unless given, and the tracks more
        than 30 degrees off ``axis`` left out and counted in ``meta["oblique"]``
        (:func:`fiberpipe.imaging.trace.drop_oblique`), as in memory.

    Returns
    -------
    Polylines, as :func:`fiberpipe.imaging.trace.trace` (broken pieces joined); ``meta`` adds
    ``blocks``, ``block_slices`` and ``time_track_s``.
    """
    t0 = time.perf_counter()
    o = slice_options(options)
    arr = src.open() if hasattr(src, "open") else src
    shape = tuple(arr.shape)
    if len(shape) != 3:
        raise InputError(f"trace: expected a 3D mask, got shape {shape}")
    if int(block) < 1:
        raise InputError(f"trace: block must be at least 1 slice, got {block!r}")
    v = voxel_size_zyx(voxel_size_m)
    axis = _slicing_axis(arr, v, axis)
    perm = (axis,) + tuple(i for i in range(3) if i != axis)
    vt = v[list(perm)]
    samp = vt[1:] / vt[1:].min()
    levels = None
    if grey is not None:  # one scale for every block: the whole volume's background and fiber levels
        g = grey.open() if hasattr(grey, "open") else grey
        levels = grey_levels(_Block(g, 0, shape[axis], dtype=None, axis=axis, read_ahead=1),
                             _Block(arr, 0, shape[axis], axis=axis, read_ahead=1))
    if expected_radius_m is not None:
        r = float(expected_radius_m) / vt[1:].min()
    elif o.radius_from == "grey" and grey is not None:  # the dense tracer: six slices (and their neighbours) read
        r = grey_radius_of_slices(_Block(arr, 0, shape[axis], axis=axis, read_ahead=1),
                                  _Block(g, 0, shape[axis], dtype=None, axis=axis, read_ahead=1), samp, levels)
    else:
        r = estimate_radius_vox(_Block(arr, 0, shape[axis], axis=axis, read_ahead=1), samp)  # 16 spread slices
    min_distance = max(1, int(round((0.75 if grey is not None else 0.5) * r)))
    o = o._replace(
        max_jump_vox=float(o.max_jump_vox) if o.max_jump_vox is not None else max(2.0, 0.6 * r),
        min_length_vox=max(10.0, 3.0 * r) if o.min_length_vox is None else o.min_length_vox,
        merge_gap_vox=int(max(6, 3 * r)) if o.merge_gap_vox is None else o.merge_gap_vox,
        smooth_sigma_vox=max(1.0, 0.5 * r) if o.smooth_sigma_vox is None else o.smooth_sigma_vox,
        gain=track_gain(grey is not None) if o.gain is None else o.gain)
    params = dict(min_distance=min_distance, peak_threshold=o.peak_threshold, max_jump=o.max_jump_vox,
                  max_skip=o.max_skip, gain=o.gain, refine=o.refine)
    edges = list(range(0, shape[axis], int(block))) + [shape[axis]]
    jobs = list(zip(edges[:-1], edges[1:]))
    results = _track_blocks(src, grey, jobs, (r, samp, params, axis, levels), scheduler, progress)
    t_track = time.perf_counter() - t0
    raw = [_Piece(k, p.astype(np.float64), rr) for res, _ in results for k, p, rr in res]
    n_det = int(sum(n for _, n in results))
    del results
    out, n_merged = finish_tracks(raw, v, perm, r, merge_gap_vox=o.merge_gap_vox, max_jump=o.max_jump_vox,
                                  min_length_vox=o.min_length_vox, smooth_sigma_vox=o.smooth_sigma_vox,
                                  spacing_vox=o.spacing_vox)
    dense = o.radius_from == "grey" and grey is not None
    if dense:  # as in memory: tracks of a +-45 deg ply left out and counted
        out = drop_oblique_into_meta(out, v, axis, grey=grey.open() if hasattr(grey, "open") else grey,
                                     radius_vox=r)
    out.meta.update(method="dense" if dense else "slices", axis=axis, radius_vox_estimate=r, n_detections=n_det, n_tracks_raw=len(raw),
                    n_tracks_merged=n_merged, n_fibers=out.n_fibers, blocks=len(jobs), block_slices=int(block),
                    time_track_s=t_track, time_total_s=time.perf_counter() - t0,
                    params=dict(max_jump_vox=o.max_jump_vox, max_skip=o.max_skip, gain=o.gain,
                                min_length_vox=o.min_length_vox, merge_gap_vox=o.merge_gap_vox,
                                smooth_sigma_vox=o.smooth_sigma_vox, spacing_vox=o.spacing_vox,
                                peak_threshold=o.peak_threshold, min_distance_vox=min_distance))
    return _join(out, voxel_size_m, **(join or {}))


def _slicing_axis(arr, voxel_size_zyx_m, axis) -> int:
    """``axis`` checked, or for ``"auto"`` the volume axis nearest the dominant fiber direction of a
    strided sample (axis 0 when the sample is too thin to tell)."""
    if axis == "auto":
        from .orientation import mask_orientation

        o = mask_orientation(StridedSample(arr), voxel_size_zyx_m)
        axis = {"z": 0, "y": 1, "x": 2}[o["nearest_volume_axis"]] if o.get("n_samples") else 0
    if axis not in (0, 1, 2):
        raise InputError(f"trace: axis must be 0, 1, 2 or 'auto', got {axis!r}")
    return int(axis)


def _track_blocks(src, grey, jobs, block_args: tuple, scheduler, progress) -> list:
    """:func:`_track_block` on every block ``(b0, b1)`` of ``jobs``, in order: here, or on the Dask
    cluster of ``scheduler``; ``block_args`` = (r, samp, params, axis, levels)."""
    client = _client(scheduler)
    if client is not None:
        futures = [client.submit(_track_block, src, grey, b0, b1, *block_args, pure=False) for b0, b1 in jobs]
        return client.gather(futures)
    results = []
    for i, (b0, b1) in enumerate(jobs):
        results.append(_track_block(src, grey, b0, b1, *block_args))
        if progress is not None:
            progress(i + 1, len(jobs))
    return results
