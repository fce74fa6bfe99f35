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
from skimage.filters import threshold_otsu

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


def _components(read_slab, n: int, slab: int, struct, full: bool, border: bool):
    """Label every slab, merge across boundaries; returns (per-slab label offsets, root of every
    global label, size per root, border flag per root)."""
    uf = _UnionFind()
    sizes, touches, offsets = [], [], []
    prev_face, prev_off = None, 0
    for a in range(0, n, slab):
        b = min(n, a + slab)
        m = read_slab(a, b)
        lab, k = ndi.label(m, structure=struct)
        off = uf.grow(k)
        offsets.append(off)
        sizes.append(np.bincount(lab.ravel(), minlength=k + 1)[1:])
        if border:
            t = np.zeros(k + 1, dtype=bool)
            for face in (lab[:, 0, :], lab[:, -1, :], lab[:, :, 0], lab[:, :, -1]):
                t[np.unique(face)] = True
            if a == 0:
                t[np.unique(lab[0])] = True
            if b == n:
                t[np.unique(lab[-1])] = True
            touches.append(t[1:])
        if prev_face is not None and k:
            pa, pb = _boundary_pairs(prev_face, lab[0], prev_off, off, full)
            if len(pa):
                uf.union_pairs(pa, pb)
        prev_face, prev_off = lab[-1].copy(), off
        del lab, m
    root = uf.find_all()
    size = np.bincount(root, weights=np.concatenate(sizes) if sizes else None, minlength=len(root))
    touch = None
    if border:
        touch = np.zeros(len(root), dtype=bool)
        np.logical_or.at(touch, root, np.concatenate(touches) if touches else np.zeros(0, bool))
    return offsets, root, size, touch


def segment_chunked(src, out_dataset, *, slab: int = 32, method: str = "otsu", threshold: float | None = None,
                    smooth_sigma_vox: float = 1.0, min_object_vox: int = 64, fill_holes: bool = True,
                    otsu_sample: int = 4_000_000, progress=None) -> dict:
    """Segment ``src`` (Z, Y, X) into the bool dataset ``out_dataset`` (same shape), slab by slab.

    Parameters are those of :func:`fiberpipe.imaging.segment.segment`; ``slab`` is the number of
    slices per slab (memory ~ slab x Y x X x 14 bytes: float32 smoothing, int32 labels, the input).
    Otsu's threshold is computed on a strided subsample of the smoothed volume (every ``step``-th
    slice smoothed with its own halo), as the whole-volume function does.

    Returns the same ``info`` as ``segment`` plus ``time_s`` per pass.
    """
    n, H, W = src.shape
    t0 = time.perf_counter()
    times = {}
    if method == "otsu":
        step = max(1, int(np.ceil((n * H * W / otsu_sample) ** (1.0 / 3.0))))
        vals = [_smoothed_slab(src, k, k + 1, smooth_sigma_vox)[0, ::step, ::step].ravel() for k in range(0, n, step)]
        sample = np.concatenate(vals).astype(np.float64)
        if np.ptp(sample) == 0:
            raise InputError("segment: the volume is constant, nothing to threshold")
        t = float(threshold_otsu(sample))
    elif method == "fixed" and threshold is not None:
        t = float(threshold)
    else:
        raise InputError(f"segment: method {method!r} needs a threshold" if method == "fixed"
                         else f"segment: unknown method {method!r} (use 'otsu' or 'fixed')")
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


class RawSlabs:
    """A headerless raw volume read slab by slab with explicit reads (no memory map, so the pages
    read do not stay resident): ``src[a:b]`` returns slices a..b as an array."""

    def __init__(self, path, shape, dtype):
        self.path = str(path)
        self.shape = tuple(int(s) for s in shape)
        self.dtype = np.dtype(dtype)
        self._slice = int(np.prod(self.shape[1:]))

    def __getitem__(self, key):
        if not isinstance(key, slice) or key.step not in (None, 1):
            raise TypeError("RawSlabs reads contiguous slabs along axis 0 only")
        a, b, _ = key.indices(self.shape[0])
        with open(self.path, "rb") as f:
            f.seek(a * self._slice * self.dtype.itemsize)
            out = np.fromfile(f, dtype=self.dtype, count=(b - a) * self._slice)
        return out.reshape((b - a,) + self.shape[1:])
