"""Segmentation of volumes larger than memory, slab by slab along axis 0, with bounded memory.

The result equals :func:`fiberpipe.imaging.segment.segment` on the whole volume (same smoothing,
threshold, 26-connected small-object removal and 6-connected hole filling), but only a slab of
``slab`` slices (plus a smoothing halo) is in memory at a time. The input is any array that can be
sliced along axis 0 without reading the rest (a ``numpy.memmap`` of a raw or MetaImage file, an
h5py dataset, a zarr array); the mask goes into a chunked HDF5 dataset.

Connected components across slabs: each slab is labelled on its own, the labels of voxels that
touch across a slab boundary are merged with a union-find, and a second pass relabels each slab
(the labelling is deterministic) and keeps or drops every component by its merged size (objects)
or by whether it reaches the volume's border (background cavities, filled).
"""

from __future__ import annotations

import time

import numpy as np
from scipy import ndimage as ndi

from ..errors import InputError

_S26 = np.ones((3, 3, 3), dtype=bool)
_S6 = ndi.generate_binary_structure(3, 1)


class _UnionFind:
    def __init__(self):
        self.parent = np.zeros(0, dtype=np.int64)

    def grow(self, n: int) -> int:
        start = len(self.parent)
        self.parent = np.concatenate([self.parent, np.arange(start, start + n, dtype=np.int64)])
        return start

    def find_all(self) -> np.ndarray:
        p = self.parent
        while True:
            q = p[p]
            if np.array_equal(q, p):
                return p
            p = q

    def union_pairs(self, a: np.ndarray, b: np.ndarray) -> None:
        # vectorised: repeatedly hang the larger root under the smaller until the pairs agree
        while True:
            r = self.find_all()
            self.parent = r
            ra, rb = r[a], r[b]
            diff = ra != rb
            if not diff.any():
                return
            lo, hi = np.minimum(ra[diff], rb[diff]), np.maximum(ra[diff], rb[diff])
            np.minimum.at(self.parent, hi, lo)


def _smoothed_slab(src, a: int, b: int, sigma: float) -> np.ndarray:
    """Slices a..b of the smoothed volume (float32), computed from a..b plus a 4 sigma halo."""
    n = src.shape[0]
    h = int(np.ceil(4.0 * sigma)) if sigma > 0 else 0
    lo, hi = max(0, a - h), min(n, b + h)
    block = np.asarray(src[lo:hi])
    if block.dtype.kind == "f" and not np.isfinite(block).all():  # the whole-volume reader's check, per slab
        bad = int(np.count_nonzero(~np.isfinite(block)))
        raise InputError(f"segment: the volume has {bad} NaN or infinite voxels in slices {lo}..{hi - 1}")
    if sigma > 0:
        out = ndi.gaussian_filter(block, sigma, output=np.float32, mode="nearest")
    else:
        out = block.astype(np.float32)
    return out[a - lo : b - lo]


def _boundary_pairs(prev_face: np.ndarray, cur_face: np.ndarray, offset_prev: int, offset_cur: int,
                    full: bool) -> tuple[np.ndarray, np.ndarray]:
    """Global label pairs joined across a slab boundary (26-connected if ``full``, else 6)."""
    H, W = cur_face.shape
    shifts = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1)] if full else [(0, 0)]
    A, B = [], []
    for dy, dx in shifts:
        p = prev_face[max(0, dy) : H + min(0, dy), max(0, dx) : W + min(0, dx)]
        c = cur_face[max(0, -dy) : H + min(0, -dy), max(0, -dx) : W + min(0, -dx)]
        both = (p > 0) & (c > 0)
        if both.any():
            A.append(p[both].astype(np.int64) - 1 + offset_prev)
            B.append(c[both].astype(np.int64) - 1 + offset_cur)
    if not A:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    # one int64 key per pair (labels < 2**31): a 1D unique, far faster than unique(axis=0)
    key = np.unique((np.concatenate(A) << 31) | np.concatenate(B))
    return key >> 31, key & ((1 << 31) - 1)


def _slab_stats(m: np.ndarray, struct, border: bool, first: bool, last: bool):
    """One slab's components: (count, size of each, border flag of each or None, labels of its
    first and last slice)."""
    lab, k = ndi.label(m, structure=struct)
    sizes = np.bincount(lab.ravel(), minlength=k + 1)[1:]
    touch = None
    if border:
        t = np.zeros(k + 1, dtype=bool)
        for face in (lab[:, 0, :], lab[:, -1, :], lab[:, :, 0], lab[:, :, -1]):
            t[np.unique(face)] = True
        if first:
            t[np.unique(lab[0])] = True
        if last:
            t[np.unique(lab[-1])] = True
        touch = t[1:]
    return k, sizes, touch, lab[0].copy(), lab[-1].copy()


def _merge(stats, full: bool, border: bool):
    """Merge the slabs' components (``stats``: :func:`_slab_stats` of every slab, in slab order)
    across the boundaries; returns (per-slab label offsets, root of every global label, size per
    root, border flag per root)."""
    uf = _UnionFind()
    sizes, touches, offsets = [], [], []
    prev_face, prev_off = None, 0
    for k, size, touch, first_face, last_face in stats:
        off = uf.grow(k)
        offsets.append(off)
        sizes.append(size)
        if border:
            touches.append(touch)
        if prev_face is not None and k:
            pa, pb = _boundary_pairs(prev_face, first_face, prev_off, off, full)
            if len(pa):
                uf.union_pairs(pa, pb)
        prev_face, prev_off = last_face, off
    root = uf.find_all()
    size = np.bincount(root, weights=np.concatenate(sizes) if sizes else None, minlength=len(root))
    touch = None
    if border:
        touch = np.zeros(len(root), dtype=bool)
        np.logical_or.at(touch, root, np.concatenate(touches) if touches else np.zeros(0, bool))
    return offsets, root, size, touch


def _components(read_slab, n: int, slab: int, struct, full: bool, border: bool):
    """Label every slab (read one at a time), merge across boundaries (see :func:`_merge`)."""
    def stats():
        for a in range(0, n, slab):
            b = min(n, a + slab)
            yield _slab_stats(read_slab(a, b), struct, border, a == 0, b == n)

    return _merge(stats(), full, border)


def segment_chunked(src, out_dataset, *, slab: int = 32, method: str = "otsu", threshold: float | None = None,
                    smooth_sigma_vox: float = 1.0, min_object_vox: int = 64, fill_holes: bool = True,
                    otsu_sample: int = 4_000_000, progress=None, scheduler=None) -> dict:
    """Segment ``src`` (Z, Y, X) into the bool dataset ``out_dataset`` (same shape), slab by slab.

    Parameters are those of :func:`fiberpipe.imaging.segment.segment`; ``slab`` is the number of
    slices per slab (memory ~ slab x Y x X x 14 bytes: float32 smoothing, int32 labels, the input).
    Otsu's threshold is computed on a strided subsample of the smoothed volume (every ``step``-th
    slice smoothed with its own halo), as the whole-volume function does.

    ``scheduler`` (a Dask scheduler address or client; ``src`` then a
    :class:`~fiberpipe.imaging.trace_chunked.SliceSource`): the slabs run on its workers, see
    :func:`_segment_on_cluster`; the mask is the same voxel for voxel.

    Returns the same ``info`` as ``segment`` plus ``time_s`` per pass.
    """
    if scheduler is not None:
        from ._dask import connect

        with connect(scheduler) as client:
            return _segment_on_cluster(client, src, out_dataset, slab=slab, method=method, threshold=threshold,
                                       smooth_sigma_vox=smooth_sigma_vox, min_object_vox=min_object_vox,
                                       fill_holes=fill_holes, otsu_sample=otsu_sample, progress=progress)
    n, H, W = src.shape
    t0 = time.perf_counter()
    times = {}
    if method == "otsu":
        step = _otsu_step(src.shape, otsu_sample)
        sample = _otsu_sample(src, list(range(0, n, step)), smooth_sigma_vox, step)
        t = _otsu(sample)
    else:
        t = _fixed(method, threshold)
    times["threshold"] = time.perf_counter() - t0
    # pass 1: smoothed > t into the output
    t1 = time.perf_counter()
    for a in range(0, n, slab):
        b = min(n, a + slab)
        out_dataset[a:b] = _smoothed_slab(src, a, b, smooth_sigma_vox) > t
        if progress is not None:
            progress(b, n)
    times["threshold_pass"] = time.perf_counter() - t1
    # pass 2: small 26-connected objects
    t2 = time.perf_counter()
    n_comp = None
    if min_object_vox > 1:
        offs, root, size, _ = _components(lambda a, b: out_dataset[a:b], n, slab, _S26, True, False)
        keep_root = size >= min_object_vox
        for i, a in enumerate(range(0, n, slab)):
            b = min(n, a + slab)
            m = out_dataset[a:b]
            lab, k = ndi.label(m, structure=_S26)
            keep = np.concatenate([[False], keep_root[root[offs[i] : offs[i] + k]]])
            out_dataset[a:b] = keep[lab]
        n_comp = int(len(np.unique(root[keep_root[root]]))) if len(root) else 0
    times["objects"] = time.perf_counter() - t2
    # pass 3: cavities (6-connected background not reaching the border) filled
    t3 = time.perf_counter()
    if fill_holes:
        offs, root, _, touch = _components(lambda a, b: ~out_dataset[a:b], n, slab, _S6, False, True)
        for i, a in enumerate(range(0, n, slab)):
            b = min(n, a + slab)
            m = out_dataset[a:b]
            lab, k = ndi.label(~m, structure=_S6)
            hole = np.concatenate([[False], ~touch[root[offs[i] : offs[i] + k]]])
            if hole.any():
                out_dataset[a:b] = m | hole[lab]
    times["holes"] = time.perf_counter() - t3
    n_fg = 0
    for a in range(0, n, slab):
        n_fg += int(np.count_nonzero(out_dataset[a : min(n, a + slab)]))
    if n_fg == 0:
        raise InputError(f"segment: the mask is empty (threshold {t:.6g}); check the threshold or invert")
    return {"method": method, "threshold": t, "volume_fraction": n_fg / (n * H * W),
            "n_components": n_comp, "smooth_sigma_vox": float(smooth_sigma_vox),
            "min_object_vox": int(min_object_vox), "slab": int(slab),
            "time_s": {k: round(v, 2) for k, v in times.items()}}


def _otsu_step(shape, otsu_sample: int) -> int:
    n, H, W = shape
    return max(1, int(np.ceil((n * H * W / otsu_sample) ** (1.0 / 3.0))))


def _otsu_sample(src, ks, sigma: float, step: int) -> np.ndarray:
    """The smoothed volume at slices ``ks``, every ``step``-th voxel across (Otsu's sample)."""
    vals = [_smoothed_slab(src, k, k + 1, sigma)[0, ::step, ::step].ravel() for k in ks]
    return np.concatenate(vals).astype(np.float64) if vals else np.zeros(0)


def _otsu(sample: np.ndarray) -> float:
    from .segment import otsu_threshold

    return otsu_threshold(sample)


def _fixed(method: str, threshold) -> float:
    if method == "fixed" and threshold is not None:
        return float(threshold)
    raise InputError(f"segment: method {method!r} needs a threshold" if method == "fixed"
                     else f"segment: unknown method {method!r} (use 'otsu' or 'fixed')")


# -- the slabs on a Dask cluster: every task recomputes its slab's mask from the input, so workers
# -- never read what the caller writes (one HDF5 file is not written and read by several processes)


def _slab_mask(src, a: int, b: int, p: dict, keep=None, hole=None) -> np.ndarray:
    """Slab a..b of the mask after the passes whose decisions are given: the threshold, then the
    kept objects (``keep``: per label of the slab's 26-connected labelling), then the filled
    cavities (``hole``: per label of the slab's 6-connected background labelling)."""
    arr = src.open() if hasattr(src, "open") else src
    m = _smoothed_slab(arr, a, b, p["sigma"]) > p["t"]
    if keep is not None:
        lab, _ = ndi.label(m, structure=_S26)
        m = np.concatenate([[False], keep])[lab]
    if hole is not None:
        lab, _ = ndi.label(~m, structure=_S6)
        m = m | np.concatenate([[False], hole])[lab]
    return m


def _task_sample(src, ks, sigma: float, step: int) -> np.ndarray:
    return _otsu_sample(src.open() if hasattr(src, "open") else src, ks, sigma, step)


def _task_objects(src, a: int, b: int, n: int, p: dict):
    return _slab_stats(_slab_mask(src, a, b, p), _S26, False, a == 0, b == n)


def _task_holes(src, a: int, b: int, n: int, p: dict, keep):
    return _slab_stats(~_slab_mask(src, a, b, p, keep), _S6, True, a == 0, b == n)


def _task_final(src, a: int, b: int, p: dict, keep, hole):
    m = _slab_mask(src, a, b, p, keep, hole)
    return np.packbits(m.ravel()), m.shape, int(np.count_nonzero(m))


def _in_order(client, futures):
    """The futures' results in submission order, each released once read (the caller merges the
    slabs in order; the rest wait on the workers, not in the caller's memory)."""
    for fut in futures:
        res = fut.result()
        fut.release()
        yield res


def _segment_on_cluster(client, src, out_dataset, *, slab: int, method: str, threshold, smooth_sigma_vox: float,
                        min_object_vox: int, fill_holes: bool, otsu_sample: int, progress=None) -> dict:
    """:func:`segment_chunked` with the slabs on a Dask cluster.

    The same passes and decisions as in one process: Otsu's sample (groups of sampled slices per
    task), then per slab the 26-connected objects (label counts, sizes and boundary faces come
    back; the caller merges them across slabs with the same union-find, in slab order, so every
    label gets the same global number), then the 6-connected background of the kept objects, then
    the final slab, returned bit-packed and written by the caller. A task rebuilds its slab's mask
    from the input with the decisions made so far (smoothing and labelling are deterministic), so
    the mask equals the one-process mask voxel for voxel; the price is up to three smoothings per
    slab instead of one."""
    n, H, W = src.shape
    p = {"sigma": float(smooth_sigma_vox)}
    times = {}
    t0 = time.perf_counter()
    if method == "otsu":
        step = _otsu_step(src.shape, otsu_sample)
        ks = list(range(0, n, step))
        groups = [ks[i:i + 8] for i in range(0, len(ks), 8)]
        futs = [client.submit(_task_sample, src, g, p["sigma"], step, pure=False) for g in groups]
        p["t"] = _otsu(np.concatenate(list(_in_order(client, futs))))
    else:
        p["t"] = _fixed(method, threshold)
    times["threshold"] = time.perf_counter() - t0
    slabs = [(a, min(n, a + slab)) for a in range(0, n, slab)]
    keeps = [None] * len(slabs)
    n_comp = None
    t2 = time.perf_counter()
    if min_object_vox > 1:
        futs = [client.submit(_task_objects, src, a, b, n, p, pure=False) for a, b in slabs]
        offs, root, size, _ = _merge(_in_order(client, futs), True, False)
        keep_root = size >= min_object_vox
        keeps = [keep_root[root[o:e]] for o, e in zip(offs, offs[1:] + [len(root)])]
        n_comp = int(len(np.unique(root[keep_root[root]]))) if len(root) else 0
    times["objects"] = time.perf_counter() - t2
    holes = [None] * len(slabs)
    t3 = time.perf_counter()
    if fill_holes:
        futs = [client.submit(_task_holes, src, a, b, n, p, kp, pure=False) for (a, b), kp in zip(slabs, keeps)]
        offs, root, _, touch = _merge(_in_order(client, futs), False, True)
        holes = [~touch[root[o:e]] for o, e in zip(offs, offs[1:] + [len(root)])]
    times["holes"] = time.perf_counter() - t3
    t4 = time.perf_counter()
    futs = [client.submit(_task_final, src, a, b, p, kp, hl, pure=False)
            for (a, b), kp, hl in zip(slabs, keeps, holes)]
    n_fg = 0
    for (a, b), (bits, shp, cnt) in zip(slabs, _in_order(client, futs)):
        out_dataset[a:b] = np.unpackbits(bits, count=int(np.prod(shp))).reshape(shp).astype(bool)
        n_fg += cnt
        if progress is not None:
            progress(b, n)
    times["write"] = time.perf_counter() - t4
    if n_fg == 0:
        raise InputError(f"segment: the mask is empty (threshold {p['t']:.6g}); check the threshold or invert")
    return {"method": method, "threshold": p["t"], "volume_fraction": n_fg / (n * H * W),
            "n_components": n_comp, "smooth_sigma_vox": float(smooth_sigma_vox),
            "min_object_vox": int(min_object_vox), "slab": int(slab),
            "time_s": {k: round(v, 2) for k, v in times.items()}}


class RawSlabs:
    """A headerless raw volume read slab by slab with explicit reads (no memory map, so the pages
    read do not stay resident): ``src[a:b]`` returns slices a..b as an array, ``src[k]`` slice k;
    a box ``src[a:b, y0:y1, x0:x1]`` reads slices a..b a few at a time and keeps the box (the
    chunked tracer's blocks along y or x). ``offset``: bytes before the voxels (a MetaImage
    ``.mha`` header, a ``.npy`` header)."""

    #: bytes read at once when a box spans many slices
    READ_BYTES = 64 << 20

    def __init__(self, path, shape, dtype, offset: int = 0):
        self.path = str(path)
        self.shape = tuple(int(s) for s in shape)
        self.dtype = np.dtype(dtype)
        self.offset = int(offset)
        self._slice = int(np.prod(self.shape[1:]))

    @property
    def ndim(self) -> int:
        return 3

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    def _read(self, a: int, b: int) -> np.ndarray:
        with open(self.path, "rb") as f:
            f.seek(self.offset + a * self._slice * self.dtype.itemsize)
            out = np.fromfile(f, dtype=self.dtype, count=(b - a) * self._slice)
        return out.reshape((b - a,) + self.shape[1:])

    def __getitem__(self, key):
        key = key if isinstance(key, tuple) else (key,)
        k0, rest = key[0], key[1:]
        if isinstance(k0, (int, np.integer)):
            k = int(k0) + (self.shape[0] if k0 < 0 else 0)
            return self._read(k, k + 1)[0][rest]
        if not isinstance(k0, slice) or k0.step not in (None, 1):
            raise TypeError("RawSlabs reads contiguous slabs along axis 0 only")
        a, b, _ = k0.indices(self.shape[0])
        if not rest:
            return self._read(a, b)
        step = max(1, self.READ_BYTES // max(1, self._slice * self.dtype.itemsize))
        parts = [self._read(c, min(b, c + step))[(slice(None),) + rest] for c in range(a, b, step)]
        return np.concatenate(parts) if parts else self._read(a, a)[(slice(None),) + rest]
