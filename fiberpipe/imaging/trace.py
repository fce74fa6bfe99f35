"""Tracing: fiber mask (and optionally its skeleton) -> one mid-line polyline per fiber.

Two methods (docs/imaging.md):

- ``slices`` (default): fiber centres found slice by slice across the dominant fiber axis and linked
  between slices. Works for quasi-parallel fibers that touch along their length, which a 3D
  skeleton merges into one line (see docs/imaging.md).
- ``skeleton``: a graph of the 3D skeleton, spurs pruned, junctions resolved by direction
  continuity. Right for crossing, non-aligned fibers; wrong for long parallel contacts.
"""

from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np
from scipy import ndimage as ndi
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree
from skimage.feature import peak_local_max

from ..errors import InputError
from ..polylines import Polylines
from .io import MIN_VOXELS_PER_AXIS
from ._util import resample_polyline, smooth_polyline, voxel_size_zyx, voxel_to_xyz_m

_BIG = 1e9


# ----------------------------------------------------------------------------------------------
# dominant axis and radius estimate
# ----------------------------------------------------------------------------------------------
def dominant_axis(mask: np.ndarray, voxel_size_m=1.0, *, max_voxels: int = 2_000_000):
    """Mean fiber direction of a mask from its structure tensor.

    Parameters
    ----------
    mask : (Z, Y, X) bool ndarray
    voxel_size_m : float or (dz, dy, dx), m
    max_voxels : int
        The tensor is computed on a strided subsample of about this many voxels (a view, no copy
        of the full volume).

    Returns
    -------
    axis : int
        Volume axis (0, 1 or 2) closest to the mean fiber direction.
    direction_zyx : (3,) float64 ndarray
        Unit mean fiber direction, ordered z y x.
    """
    # Strategy: the gradient of a bundle of cylinders is perpendicular to their axes, so the
    # eigenvector of the summed gradient outer product (the structure tensor) with the smallest
    # eigenvalue is the mean fiber direction.
    v = voxel_size_zyx(voxel_size_m)
    # One stride per axis, each keeping at least MIN_VOXELS_PER_AXIS (3) samples along its axis
    # (np.gradient needs 2; a thin volume such as (3, 3000, 3000) had its thin axis cut to 1); the
    # voxel budget a capped axis leaves is spread over the others.
    step = np.ones(3, dtype=int)
    free = [i for i in range(3)]
    budget = float(max_voxels)
    while free:
        s = max(1, int(np.ceil((np.prod([mask.shape[i] for i in free], dtype=float) / budget)
                               ** (1.0 / len(free)))))
        cap = {i: max(1, (mask.shape[i] - 1) // (MIN_VOXELS_PER_AXIS - 1)) for i in free}
        capped = [i for i in free if s > cap[i]]
        if not capped:
            step[free] = s
            break
        for i in capped:
            step[i] = cap[i]
            budget = max(1.0, budget / -(-mask.shape[i] // cap[i]))
            free.remove(i)
    sub = ndi.gaussian_filter(mask[::step[0], ::step[1], ::step[2]].astype(np.float32), 1.0)
    g = np.gradient(sub, *(v * step / v.min()))
    J = np.empty((3, 3))
    for i in range(3):
        for j in range(i, 3):
            J[i, j] = J[j, i] = float(np.sum(g[i] * g[j], dtype=np.float64))
    w, vecs = np.linalg.eigh(J)
    d = vecs[:, 0]
    return int(np.argmax(np.abs(d))), d / np.linalg.norm(d)


def _slice(mask_t: np.ndarray, k: int) -> np.ndarray:
    return mask_t[k]


def estimate_radius_vox(mask_t: np.ndarray, samp: np.ndarray, *, n_slices: int = 16) -> float:
    """Typical fiber radius (voxels) from 2D EDT maxima in a few slices of the (reoriented) mask.

    Returns the median ridge value of the in-plane distance transform minus half a voxel (a binary
    disc of radius r has an EDT maximum of about r + 0.5).
    """
    ks = np.unique(np.linspace(0, mask_t.shape[0] - 1, n_slices).round().astype(int))
    vals = []
    for k in ks:
        sl = _slice(mask_t, k)
        if not sl.any():
            continue
        edt = ndi.distance_transform_edt(sl, sampling=samp)
        pk = peak_local_max(edt, min_distance=2, threshold_abs=1.0, exclude_border=False)
        if len(pk):
            vals.append(edt[pk[:, 0], pk[:, 1]])
    if not vals:
        raise InputError("trace: no fiber cross-sections found in the mask")
    v = np.concatenate(vals)
    top = np.percentile(v, 90)
    return float(max(0.5, np.median(v[v >= 0.5 * top])))


# ----------------------------------------------------------------------------------------------
# per-slice detection
# ----------------------------------------------------------------------------------------------
def _refine_centroids(sl: np.ndarray, peaks: np.ndarray, R: float, samp: np.ndarray, n_iter: int = 2):
    """Sub-voxel centres: centroid of the mask pixels within ``R`` of a peak and nearer to it than
    to any other peak (a local Voronoi cell), iterated with the refined sites.

    Parameters
    ----------
    sl : (H, W) bool ndarray
    peaks : (n, 2) int ndarray, pixel indices
    R : float
        Window radius in units of the smallest in-plane pixel size (a bit more than the fiber
        radius, so a whole cross-section is inside).
    samp : (2,) float ndarray
        Pixel size along rows and columns, relative to the smallest one.

    Returns
    -------
    (n, 2) float64 ndarray, pixel index coordinates.
    """
    # Strategy: the EDT maximum of a fiber that touches a neighbour is pulled toward the contact
    # (the blurred neck adds material there) and is quantised to whole pixels. The centroid of the
    # fiber's own pixels, cut from its neighbours by the bisector between centres, uses the whole
    # boundary (~2 pi r pixels), so it is sub-voxel and nearly unbiased for touching pairs.
    from ._kernels import voronoi_centroids

    n = len(peaks)
    sites = peaks.astype(np.float64)
    hw = int(np.ceil(R / samp.min())) + 1
    k_nb = min(7, n)
    w = np.ascontiguousarray(sl, dtype=np.float32)
    for _ in range(n_iter):
        if k_nb > 1:
            _, nb = cKDTree(sites * samp).query(sites * samp, k=k_nb)
        else:
            nb = np.arange(n)[:, None]
        sites = voronoi_centroids(w, sites, np.ascontiguousarray(nb, dtype=np.int64), float(R), hw,
                                  float(samp[0]), float(samp[1]))
    return sites


def fit_centres(grey: np.ndarray, centres: np.ndarray, r_vox: float, samp: np.ndarray, *, n_iter: int = 5):
    """Sub-voxel centres of touching fibers in a grey slice (background 0, fiber 1): blurred disks of
    radius ``r_vox`` fitted to the slice together by least squares (the kernel
    :func:`fiberpipe.imaging._kernels.fit_disk_centres`), from the centroid estimates ``centres``.

    Why: a centroid of each fiber's Voronoi cell reads the blurred edge of its neighbours (a
    pixel's grey near a contact belongs to both fibers), which pulls touching centres toward each
    other by a few tenths of a voxel; a model of all disks at once assigns every pixel's grey to
    the disks that make it (template matching, as Avizo's cylinder correlation, but joint). The
    fitted amplitudes (fiber grey 1) tell a fiber from a candidate between fibers: the blurred grey
    peaks in the gap between three touching fibers too, but a disk there explains little of it.

    Returns the centres (n, 2) and the amplitudes (n,).
    """
    from ._kernels import fit_disk_centres
    from .dense import FIT_SIGMA_VOX

    start = np.ascontiguousarray(centres, dtype=np.float64)
    c, amplitude, _ = fit_disk_centres(np.ascontiguousarray(grey, dtype=np.float32), start, np.ones(len(centres)),
                                       float(r_vox), FIT_SIGMA_VOX, float(samp[0]), float(samp[1]), int(n_iter), True)
    # a disk that ran off (a neighbour missing from the model, another region's grey) keeps its centroid
    far = np.linalg.norm((c - start) * samp, axis=1) > MAX_FIT_SHIFT_RADII * r_vox
    c[far] = start[far]
    return c, amplitude


#: The farthest a fitted centre may move from its centroid estimate, in radii.
MAX_FIT_SHIFT_RADII = 0.3
#: Fitted disks below this amplitude (the fibers' grey is 1) are no fiber: half the contrast, the
#: grey detection's own threshold.
MIN_FIT_AMPLITUDE = 0.5


def _nms(points: np.ndarray, radius: np.ndarray, samp: np.ndarray) -> np.ndarray:
    """Greedy non-maximum suppression in priority order (row order of ``points``).

    A point is dropped if it lies within ``radius[j]`` of an earlier kept point ``j``. Returns the
    boolean keep mask.
    """
    n = len(points)
    keep = np.ones(n, dtype=bool)
    if n < 2:
        return keep
    tree = cKDTree(points * samp)
    rmax = float(radius.max())
    for i, nb in enumerate(tree.query_ball_point(points * samp, rmax)):
        if not keep[i]:
            continue
        for j in nb:
            if j > i and keep[j]:
                d = np.linalg.norm((points[j] - points[i]) * samp)
                if d < radius[i]:
                    keep[j] = False
    return keep


def _local_maxima(img: np.ndarray, min_distance: int, threshold: float, within: np.ndarray | None = None):
    """Pixels that are the maximum of their (2 min_distance + 1)^2 window and above ``threshold``
    (``within`` a mask if given), as (n, 2) indices.

    ``skimage.feature.peak_local_max`` finds the same maxima, then enforces the spacing among them
    with a KD-tree pass per batch that dominates the cost on a slice of 10^4 fibers; the callers
    suppress candidates closer than a radius themselves (:func:`_nms`), so that pass is not needed.
    """
    mx = ndi.maximum_filter(img, size=2 * int(min_distance) + 1, mode="constant", cval=-np.inf)
    pk = (img == mx) & (img > threshold)
    if within is not None:
        pk &= within
    return np.argwhere(pk)


def detect_slice(sl: np.ndarray, r_vox: float, samp: np.ndarray, *, min_distance: int,
                 peak_threshold: float, seeds: np.ndarray | None = None, refine: bool = True,
                 smooth_edt: bool = True, seed_nms: float = 1.2, peak_nms: float = 1.0,
                 grey: np.ndarray | None = None, min_spacing_radii: float | None = None):
    """Fiber centres in one 2D mask slice (or, given ``grey``, in the grey slice within the mask).

    Parameters
    ----------
    sl : (H, W) bool ndarray
        Mask slice.
    r_vox : float
        Expected fiber radius, pixels (smallest in-plane pixel size).
    samp : (2,) float ndarray
        Relative pixel sizes along rows and columns.
    min_distance : int
        ``peak_local_max`` spacing, pixels.
    peak_threshold : float
        Smallest EDT value at a centre, in units of ``r_vox``.
    seeds : (m, 2) float ndarray, optional
        Predicted centres (pixel indices) of fibers already tracked, in priority order. They are
        refined like peaks and win over EDT peaks within ``seed_nms * r_vox``.
    refine : bool or "fit"
        Sub-voxel centroid refinement; "fit": then the joint disk fit (:func:`fit_centres`, grey).
    smooth_edt : bool
        Blur the EDT (sigma 1 pixel) before looking for maxima.
    seed_nms, peak_nms : float
        Suppression radii (units of ``r_vox``) around a seed and around a higher EDT peak.
    grey : (H, W) float ndarray, optional
        The denoised grey slice scaled to background 0 and fiber 1. Candidates are then the maxima
        of the grey slice blurred over half a radius (a blob filter) inside the mask, centres the
        grey-weighted centroids, and ``peak_threshold`` is in units of the contrast. For dense
        packs, where the binary mask merges touching fibers into one region and its EDT has no
        maximum per fiber.
    min_spacing_radii : float, optional
        On grey, the closest two refined centres may lie (radii; default
        :data:`MIN_CENTRE_SPACING_RADII`); 0: only converged duplicates dropped (the grey radius
        estimate's detection, :func:`grey_radius_of_slices`).

    Returns
    -------
    centres : (n, 2) float64 ndarray, pixel indices (row, col)
    ridge : (n,) float64 ndarray
        EDT value at each centre (units of the smallest in-plane pixel size).
    source : (n,) int64 ndarray
        Index of the seed a centre came from, -1 for a new EDT peak.
    """
    # Strategy: candidates are the tracks' predicted positions (seeds) and the maxima of the 2D
    # EDT. EDT maxima alone miss fibers in tight clusters: the filled concave corner between three
    # touching fibers holds the highest EDT value and the ridge of a neighbour climbs into it, so
    # that neighbour has no maximum of its own. Seeds are kept first, EDT maxima only where no
    # seed is near; every survivor is moved to the centroid of its own pixels (local Voronoi cell),
    # which converges to the cross-section's centre; centres that converge onto each other or
    # leave the fiber (EDT below threshold) are dropped.
    empty = (np.zeros((0, 2)), np.zeros(0), np.zeros(0, dtype=np.int64))
    if not sl.any():
        return empty
    H, W = sl.shape
    if grey is not None:
        # candidates: a Laplacian-of-Gaussian blob filter at half a radius
        # (_grey_candidates); no seeds: a prediction kept where its fiber shows no maximum lets a
        # track live on noise (its Voronoi cell always has a centroid) and lags its centre, while
        # the Laplacian separates touching fibers, so a missed slice is a gap the linking closes
        pk, sm, edt = _grey_candidates(grey, sl, r_vox, samp, peak_threshold)
        thr, seeds = peak_threshold, None
    else:
        edt = ndi.distance_transform_edt(sl, sampling=samp)
        # A light blur of the EDT breaks the ties of its discrete ridge (flat tops, a ridge along the
        # contact of two touching fibers), which otherwise give several maxima per fiber.
        sm = ndi.gaussian_filter(edt, 1.0, mode="constant") if smooth_edt else edt
        thr = peak_threshold * r_vox
        pk = _local_maxima(sm, min_distance, thr)
        pk = pk[np.argsort(-sm[pk[:, 0], pk[:, 1]], kind="stable")] if len(pk) else pk.reshape(0, 2)
    if seeds is None:
        seeds = np.zeros((0, 2))
    seeds = np.asarray(seeds, dtype=np.float64).reshape(-1, 2)
    # seeds outside the slice or off the mask are not candidates
    sr = np.clip(np.rint(seeds).astype(np.int64), [0, 0], [H - 1, W - 1])
    seed_ok = ((seeds[:, 0] > -0.5) & (seeds[:, 0] < H - 0.5) & (seeds[:, 1] > -0.5)
               & (seeds[:, 1] < W - 0.5) & sl[sr[:, 0], sr[:, 1]])
    seed_idx = np.flatnonzero(seed_ok)
    cand = np.concatenate([seeds[seed_idx], pk.astype(np.float64)])
    source = np.concatenate([seed_idx, -np.ones(len(pk), dtype=np.int64)])
    if len(cand) == 0:
        return empty
    spacing = 0.0
    if grey is not None:  # no two fibers closer than MIN_CENTRE_SPACING_RADII (see there)
        spacing = MIN_CENTRE_SPACING_RADII if min_spacing_radii is None else float(min_spacing_radii)
    rad = np.where(source >= 0, seed_nms * r_vox, peak_nms * r_vox)
    keep = _nms(cand, rad, samp)
    cand, source = cand[keep], source[keep]
    c, source = _refine(sl, grey, cand, source, r_vox, samp, refine, spacing) if refine else (cand, source)
    ci = np.clip(np.rint(c).astype(np.int64), [0, 0], [H - 1, W - 1])
    ridge = edt[ci[:, 0], ci[:, 1]]
    ok = (ridge >= thr) & sl[ci[:, 0], ci[:, 1]]
    if grey is not None:  # the radius of a grey detection is the expected one
        ridge = np.full(len(ridge), float(r_vox))
    return c[ok], ridge[ok], source[ok]


#: The closest two centres of the grey detection may lie, in fiber radii. Fibers do not overlap, so
#: the centres of two touching fibers of radius r lie 2 r apart; 1.5 r still keeps two fibers each a
#: quarter thinner than the estimate (which runs 3-13 % low on dense packs). Two maxima closer than
#: this are one fiber seen twice: where the scan's noise is correlated across the slice (streaks
#: along x over about two voxels on the real cross-ply example), a streak through a fiber of r ~ 2.5
#: splits its Laplacian response into two maxima about 1.0-1.6 r apart, and a track following each
#: leaves the fiber in two pieces side by side, one of which ends where the other goes on.
MIN_CENTRE_SPACING_RADII = 1.5
#: Scale of the Laplacian-of-Gaussian blob filter of the grey detection, in fiber radii.
LOG_SIGMA_RADII = 0.5
#: In-slice blur (pixels) of the grey level that a centre must reach (``peak_threshold``).
LEVEL_SIGMA_VOX = 0.5


def _grey_candidates(grey, sl, r_vox: float, samp, peak_threshold: float):
    """Candidate fiber centres in a grey slice (background 0, fiber 1): the local maxima of the
    negative Laplacian of Gaussian at :data:`LOG_SIGMA_RADII` radii inside the mask, whose grey
    level (blurred over :data:`LEVEL_SIGMA_VOX`) reaches ``peak_threshold``, by decreasing response.
    Returns the candidates (n, 2), the response and the level image.

    Why the Laplacian (Lindeberg 1998, scale-space blob detection) at half a radius rather than
    r / sqrt(2), the scale that matches an isolated disk: in a dense pack the dark matrix between
    touching fibers lies about one radius from each centre, and a filter whose negative surround
    reaches there separates the neighbours; the plain blur of the grey (a smoothing filter with no
    surround) merges two touching fibers of r < 3 into one maximum once the scanner's blur is added
    (on the dense family at r = 2.7, CNR 4.4: 65 % of the fibers found per slice against 99.6 %).
    """
    response = -ndi.gaussian_laplace(grey, LOG_SIGMA_RADII * r_vox / samp, mode="nearest")
    level = ndi.gaussian_filter(grey, LEVEL_SIGMA_VOX / samp, mode="nearest")
    pk = _local_maxima(response, max(1, int(round(LOG_SIGMA_RADII * r_vox))), 0.0, sl)
    pk = pk[level[pk[:, 0], pk[:, 1]] >= peak_threshold]
    return pk[np.argsort(-response[pk[:, 0], pk[:, 1]], kind="stable")], response, level


def _refine(sl, grey, cand, source, r_vox: float, samp, refine, spacing_radii: float = 0.0):
    """Sub-voxel centres of the candidates (:func:`detect_slice`): the centroids of their Voronoi
    cells; on grey, centroids closer than ``spacing_radii`` radii are one fiber, so the
    later (lower-response) one is dropped and the others' centroids taken again without its cut; then
    (``refine="fit"``, grey) the joint disk fit, fitted disks below :data:`MIN_FIT_AMPLITUDE` dropped;
    candidates that converged onto an earlier (higher-priority) one are duplicates and dropped."""
    w = sl if grey is None else np.clip(grey, 0.0, 1.0)
    c = _refine_centroids(w, cand, r_vox + (2.0 if grey is None else 1.0), samp)
    if grey is not None and spacing_radii > 0 and len(c):
        # on the refined centres, not the raw maxima: a maximum in the gap between three touching
        # fibers lies 2 / sqrt(3) = 1.15 r from each and, at the higher response, would suppress them
        apart = _nms(c, np.full(len(c), spacing_radii * r_vox), samp)
        if not apart.all():
            c, source = _refine_centroids(w, c[apart], r_vox + 1.0, samp), source[apart]
    if refine == "fit" and grey is not None and len(c):
        # the grey of another region (a cross ply beside this one) is no fiber of this slice's model
        near = ndi.binary_dilation(sl, iterations=2)
        c, amplitude = fit_centres(np.where(near, grey, 0.0), c, r_vox, samp)
        c, source = c[amplitude >= MIN_FIT_AMPLITUDE], source[amplitude >= MIN_FIT_AMPLITUDE]
    keep = _nms(c, np.full(len(c), 0.5 * r_vox), samp)
    return c[keep], source[keep]


# ----------------------------------------------------------------------------------------------
# linking
# ----------------------------------------------------------------------------------------------
class _Track:
    __slots__ = ("k", "p", "r", "v", "last_k", "last_p")

    def __init__(self, k, p, r):
        self.k = [k]
        self.p = [p]
        self.r = [r]
        self.v = np.zeros(2)
        self.last_k = k
        self.last_p = p  # the filtered position the prediction starts from

    def predict(self, k):
        return self.last_p + self.v * (k - self.last_k)

    def update(self, p, gap: int, gain: float) -> None:
        """An alpha-beta filter (the steady-state Kalman filter of a constant-velocity motion;
        Kalata 1984): position and velocity move by ``gain`` and ``gain^2 / (2 - gain)`` of the
        innovation. A detection off its fiber for a slice (a noise peak, two touching fibers
        merged into one) then moves the prediction by half its error and the velocity by a sixth,
        so the track still meets its fiber in the next slice. The first step sets the velocity."""
        predicted = self.last_p + self.v * gap
        innovation = p - predicted
        if len(self.k) == 1:
            self.v, self.last_p = (p - self.last_p) / gap, p
            return
        self.v = self.v + gain * gain / (2.0 - gain) * innovation / gap
        self.last_p = predicted + gain * innovation


def assign_within(a: np.ndarray, b: np.ndarray, lim: np.ndarray) -> list[tuple[int, int]]:
    """One-to-one assignment of points ``a`` to points ``b`` minimising the summed distance, a
    pair allowed only within ``lim[i]`` of ``a[i]``: the most pairs, then the least total distance.

    Strategy: the allowed pairs form a sparse bipartite graph; its connected components are
    independent problems, each solved by the Hungarian algorithm
    (``scipy.optimize.linear_sum_assignment``) on its own small matrix (forbidden pairs at a large
    cost), and lone pairs directly. The dense matrix of all pairs would be n x m (17 000 fibers
    per slice of a 2000^2 scan: 2.3 GB and O(n^3)).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n, m = len(a), len(b)
    if n == 0 or m == 0:
        return []
    nbs = cKDTree(b).query_ball_point(a, np.asarray(lim, dtype=np.float64))
    ii = np.repeat(np.arange(n), [len(x) for x in nbs])
    if len(ii) == 0:
        return []
    jj = np.fromiter((j for x in nbs for j in x), dtype=np.int64, count=len(ii))
    d = np.linalg.norm(a[ii] - b[jj], axis=1)
    g = coo_matrix((np.ones(len(ii)), (ii, n + jj)), shape=(n + m, n + m))
    _, lab = connected_components(g, directed=False)
    comp = lab[ii]
    # components of one edge are one pair
    sizes = np.bincount(comp, minlength=lab.max() + 1)
    out = [(int(i), int(j)) for i, j in zip(ii[sizes[comp] == 1], jj[sizes[comp] == 1])]
    multi = np.flatnonzero(sizes[comp] > 1)
    if len(multi):
        order = multi[np.argsort(comp[multi], kind="stable")]
        cuts = np.flatnonzero(np.diff(comp[order])) + 1
        for grp in np.split(order, cuts):
            ri, rinv = np.unique(ii[grp], return_inverse=True)
            cj, cinv = np.unique(jj[grp], return_inverse=True)
            C = np.full((len(ri), len(cj)), _BIG)
            C[rinv, cinv] = d[grp]
            rows, cols = linear_sum_assignment(C)
            out.extend((int(ri[r]), int(cj[c])) for r, c in zip(rows, cols) if C[r, c] < _BIG)
    return out


def track_slices(mask_t: np.ndarray, r_vox: float, samp: np.ndarray, *, min_distance: int,
                 peak_threshold: float, max_jump: float, max_skip: int, gain: float,
                 refine: bool = True, progress=None, grey_t=None):
    """Detect centres slice by slice and link them into tracks.

    Parameters
    ----------
    mask_t : (N, H, W) bool ndarray
        Mask with the slicing axis first (a transposed view is fine: slices are read one at a time).
    r_vox : float
        Expected fiber radius, pixels.
    samp : (2,) float ndarray
        Relative in-plane pixel sizes.
    min_distance, peak_threshold, refine
        See :func:`detect_slice`.
    max_jump : float
        Largest distance between a track's predicted position and a detection, pixels (grows with
        the square root of the number of slices since the track's last detection).
    max_skip : int
        Slices a track may miss before it ends.
    gain : float in (0, 1]
        Position gain of each track's alpha-beta filter (:meth:`_Track.update`).
    progress : callable(done, total), optional
    grey_t : _GreySlices, optional
        The grey volume, same axis order as ``mask_t``: detection on grey (see :func:`detect_slice`).

    Returns
    -------
    tracks : list of _Track
    n_detections : int
    """
    # Strategy: a track predicts its position in slice k from its filtered position and velocity
    # (an alpha-beta filter, _Track.update). Predictions seed the detection (see detect_slice), then predictions and
    # detections are matched by the Hungarian algorithm on distance, pairs farther than max_jump
    # being forbidden. Unmatched detections start tracks; tracks unmatched for more than max_skip
    # slices end.
    tracks: list[_Track] = []
    active: list[_Track] = []
    n_det = 0
    n = mask_t.shape[0]
    for k in range(n):
        active = [t for t in active if k - t.last_k - 1 <= max_skip]
        # older (longer) tracks first: they win a contested position
        active.sort(key=lambda t: -len(t.k))
        pred = np.array([t.predict(k) for t in active]).reshape(-1, 2)
        P, Rr, _src = detect_slice(mask_t[k], r_vox, samp, min_distance=min_distance,
                                   peak_threshold=peak_threshold, seeds=pred, refine=refine,
                                   grey=None if grey_t is None else grey_t[k])
        n_det += len(P)
        used = np.zeros(len(P), dtype=bool)
        if active and len(P):
            gap = np.array([k - t.last_k for t in active], dtype=np.float64)
            lim = max_jump * np.sqrt(gap)
            for i, j in assign_within(pred * samp, P * samp, lim):
                t = active[i]
                g = k - t.last_k
                t.update(P[j], g, gain)
                t.k.append(k)
                t.p.append(P[j])
                t.r.append(Rr[j])
                t.last_k = k
                used[j] = True
        for j in np.flatnonzero(~used):
            t = _Track(k, P[j], Rr[j])
            tracks.append(t)
            active.append(t)
        if progress is not None:
            progress(k + 1, n)
    return tracks, n_det


class _GreySlices:
    """Denoised, normalised grey slices of a (transposed) volume, made one at a time: a Gaussian
    over the neighbouring slices (sigma ``sigma_along``) and in the slice (``sigma_in``), then
    scaled so the background is 0 and the fibers 1 (their medians outside and inside the mask,
    from a strided sample)."""

    def __init__(self, grey_t, mask_t, samp, *, sigma_along: float = 1.0, sigma_in: float = 0.7, levels=None,
                 k_range=None):
        # levels: (background, fiber) grey levels measured elsewhere (a chunked trace measures them
        # once on the whole volume, so every block is scaled alike); k_range: the slice indices the
        # smoothing along the slices may read (a block's reach into its neighbours), default its own
        self.g, self.samp = grey_t, samp
        self.lo, self.hi = grey_levels(grey_t, mask_t) if levels is None else (float(levels[0]), float(levels[1]))
        if not self.hi > self.lo:
            raise InputError("trace: the grey volume has no contrast between the mask and the rest")
        self.k_range = (0, grey_t.shape[0] - 1) if k_range is None else (int(k_range[0]), int(k_range[1]))
        h = int(np.ceil(3 * sigma_along))
        self.offsets = np.arange(-h, h + 1)
        w = np.exp(-0.5 * (self.offsets / sigma_along) ** 2) if sigma_along > 0 else (self.offsets == 0) * 1.0
        self.w = w / w.sum()
        self.sigma_in = sigma_in

    def __getitem__(self, k: int) -> np.ndarray:
        ks = np.clip(k + self.offsets, *self.k_range)
        acc = np.zeros(self.g.shape[1:], dtype=np.float32)
        for kk, w in zip(ks, self.w):
            acc += np.float32(w) * np.asarray(self.g[kk], dtype=np.float32)
        if self.sigma_in > 0:
            acc = ndi.gaussian_filter(acc, self.sigma_in / self.samp, mode="nearest")
        acc -= self.lo
        acc /= self.hi - self.lo
        return acc


#: Gaussian smoothing of the grey volume along the slicing axis while tracing, in fiber radii (at
#: least one slice).
SIGMA_ALONG_RADII = 0.5


def grey_sigma_along(r_vox: float) -> float:
    """The smoothing (slices) of the grey slices along the fibers while tracing: half a radius, at
    least one slice.

    Why: a fiber is straight over a few diameters, so averaging the slices over half a radius each
    side adds signal and averages the noise (on the dense family's noisiest seed, CNR 2.1 at
    r = 3.6, it gives 0.99 precision where one slice gives 0.95), while a fiber tilted by 10
    degrees moves only 0.1 radius across that depth."""
    return max(1.0, SIGMA_ALONG_RADII * float(r_vox))


def grey_levels(grey_t, mask_t) -> tuple[float, float]:
    """The background and fiber grey levels: the medians of the grey values outside and inside the
    mask on 16 slices spread along axis 0."""
    n = grey_t.shape[0]
    ks = range(0, n, max(1, n // 16))
    fg = np.concatenate([np.asarray(grey_t[k], dtype=np.float32)[np.asarray(mask_t[k])] for k in ks])
    bg = np.concatenate([np.asarray(grey_t[k], dtype=np.float32)[~np.asarray(mask_t[k])] for k in ks])
    return (float(np.median(bg)) if len(bg) else 0.0), (float(np.median(fg)) if len(fg) else 1.0)


def _end_fit(k: np.ndarray, p: np.ndarray, at_end: bool, n: int):
    """Position and slope (per slice) at one end of a track from a line fit to its last n points."""
    sel = slice(-n, None) if at_end else slice(0, n)
    kk, pp = k[sel].astype(np.float64), p[sel]
    if len(kk) < 2:
        return pp[-1 if at_end else 0], np.zeros(2)
    A = np.column_stack([kk - kk.mean(), np.ones_like(kk)])
    coef, *_ = np.linalg.lstsq(A, pp, rcond=None)
    slope = coef[0]
    k0 = kk[-1] if at_end else kk[0]
    return coef[1] + slope * (k0 - kk.mean()), slope


#: Slices by which the end of a track may overlap the start of the track that continues it: a track
#: that took a wrong detection in its last slices (a noise peak beside its fiber) ends there while a
#: new track picks the fiber up; the earlier piece is cut where the later one starts.
MERGE_MAX_OVERLAP = 2


#: A tracked point farther than this many radii from the running median of its track (over about
#: two radii of slices each side) is an outlier: dropped before pieces are merged, its slice
#: filled from its neighbours.
OUTLIER_RADII = 0.5


def _drop_outliers(piece, samp, max_offset_vox: float, window: int):
    """The piece (k, p, r) without the points farther than ``max_offset_vox`` from the median of
    the positions within ``window // 2`` slices of them (at least 3 each side).

    Why: a detection of two touching fibers merged into one (a ring artefact bridging their
    contact, noise) lies about a radius from both centres; a track that takes it for a slice or
    two, typically its last ones before it ends, is pulled off its fiber there, and its end then
    no longer points to the piece that continues the fiber. The median over a few radii of slices
    ignores such points (up to half of its window), and a fiber's own path, straight at that
    scale, stays within a few tenths of a voxel of it.
    """
    k, p, r = piece
    if len(k) < 3:
        return piece
    h = max(3, window // 2)
    median = np.array([np.median(p[max(0, i - h):i + h + 1], axis=0) for i in range(len(k))])
    ok = np.linalg.norm((p - median) * samp, axis=1) <= max_offset_vox
    if ok.sum() < 2:
        return piece
    return k[ok], p[ok], r[ok]


#: The most slices cut from either end of a piece before pieces are merged (:func:`_trim_ends`):
#: the slices a track may miss before it ends (the slices tracer's ``max_skip``).
MAX_END_TRIM = 3


def _trim_ends(piece, samp, max_offset_vox: float, n_fit: int, max_trim: int = MAX_END_TRIM):
    """The piece (k, p, r) without its last (and first) points that lie farther than
    ``max_offset_vox`` from the line through the ``n_fit`` points before them, up to ``max_trim``
    at each end, and the number cut at the start and at the end.

    Why: a track ends because its detections left its fiber: where the scan's noise is correlated
    across the slice, a noise streak moves the fiber's detection by half a radius to a radius for
    two or three slices, the track follows it (the alpha-beta filter halves each error, it does not
    ignore it), and ends there; a new track picks the fiber up, its first detections as displaced.
    Those few points are the majority of the few a running median sees at a track's end, so
    :func:`_drop_outliers` keeps them, and they tilt the line each end is extrapolated along (on a
    dense phantom with such noise, 3 of 4 split fibers were pieces one slice apart whose last or
    first two or three points lay 1-2.5 voxels off the fiber). The fiber's own course before them,
    straight over a few radii, shows which points left it."""
    k, p, r = piece
    if len(k) < n_fit + max_trim + 2:
        return piece, 0, 0

    def off_line(body: slice, tail: slice) -> np.ndarray:
        slope, offset = np.polyfit(k[body].astype(np.float64), p[body], 1)
        return np.linalg.norm((p[tail] - (np.outer(k[tail], slope) + offset)) * samp, axis=1) > max_offset_vox

    n = len(k)
    end_off = off_line(slice(n - max_trim - n_fit, n - max_trim), slice(n - max_trim, n))
    hi = n - max_trim + int(np.argmax(end_off)) if end_off.any() else n
    start_off = off_line(slice(max_trim, max_trim + n_fit), slice(0, max_trim))
    lo = int(np.flatnonzero(start_off)[-1]) + 1 if start_off.any() else 0
    if hi - lo < 2:
        return piece, 0, 0
    return (k[lo:hi], p[lo:hi], r[lo:hi]), lo, n - hi


def merge_pieces(tracks, samp, *, max_gap: int, max_dist: float, fit_n: int, max_overlap: int = MERGE_MAX_OVERLAP,
                 outlier_vox: float | None = None, max_trim: int = MAX_END_TRIM):
    """Join track pieces whose end and start continue each other (after a detection gap, or
    overlapping by up to ``max_overlap`` slices), after dropping every point farther than
    ``outlier_vox`` from its track's running median (:func:`_drop_outliers`) and up to
    ``max_trim`` end points that left the track's course (:func:`_trim_ends`) when given (the gap
    then counted from the points before the cut).

    Returns a list of (k (m,), p (m, 2), r (m,)) arrays, one per merged track.
    """
    # Strategy: for every end of a track and start of a later track within max_gap slices, both
    # pieces are extrapolated linearly (fit over fit_n slices) to the other's end; the mean miss
    # distance is the cost. A start at or before the end (an overlap) is compared with the earlier
    # piece cut before it. Pairs are accepted greedily by increasing cost under max_dist, each end
    # and start at most once, then chained.
    arr = [(np.asarray(t.k), np.asarray(t.p), np.asarray(t.r)) for t in tracks]
    n = len(arr)
    cut_start, cut_end = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
    if outlier_vox is not None:
        arr = [_drop_outliers(a, samp, outlier_vox, fit_n) for a in arr]
        if max_trim > 0:
            trimmed = [_trim_ends(a, samp, outlier_vox, fit_n, max_trim) for a in arr]
            arr = [t[0] for t in trimmed]
            cut_start[:] = [t[1] for t in trimmed]
            cut_end[:] = [t[2] for t in trimmed]
    if n == 0:
        return []
    k0 = np.array([a[0][0] for a in arr])
    k1 = np.array([a[0][-1] for a in arr])
    ends = [_end_fit(a[0], a[1], True, fit_n) for a in arr]
    starts = [_end_fit(a[0], a[1], False, fit_n) for a in arr]
    cand = []
    # only starts near an end can continue it: |pe - ps| <= d1 + |se| g and d1 <= 2 c, so a ball of
    # 2 max_dist (1 + 0.1 max_gap) + |se| max_gap around the end holds every candidate (a KD-tree
    # query instead of all later starts: tens of thousands of tracks start at a block boundary)
    ps_all = np.array([st[0] for st in starts]) * samp
    tree = cKDTree(ps_all)
    for i in range(n):
        reach = max_gap + 2 * max_trim
        R = 2.0 * max_dist * (1.0 + 0.1 * reach) + float(np.linalg.norm(ends[i][1] * samp)) * reach
        for j in tree.query_ball_point(ends[i][0] * samp, R):
            g = k0[j] - k1[i]
            too_far = g > max_gap + cut_end[i] + cut_start[j]  # the gap before the end points were cut
            if too_far or g < 1 - max_overlap or j == i or k1[j] <= k1[i] or k0[j] <= k0[i] + 1:
                continue
            pe, se = ends[i]
            if g < 1:  # overlap: the earlier piece's end fitted on its slices before the later start
                before = arr[i][0] < k0[j]
                pe, se = _end_fit(arr[i][0][before], arr[i][1][before], True, fit_n)
                g = k0[j] - arr[i][0][before][-1]
            ps, ss = starts[j]
            d1 = np.linalg.norm((pe + se * g - ps) * samp)
            d2 = np.linalg.norm((ps - ss * g - pe) * samp)
            c = 0.5 * (d1 + d2)
            if c < max_dist * (1.0 + 0.1 * g):
                cand.append((c, i, j))
    cand.sort()
    nxt = -np.ones(n, dtype=np.int64)
    has_prev = np.zeros(n, dtype=bool)
    for c, i, j in cand:
        if nxt[i] < 0 and not has_prev[j]:
            nxt[i] = j
            has_prev[j] = True
    out = []
    for i in range(n):
        if has_prev[i]:
            continue
        chain = [i]
        while nxt[chain[-1]] >= 0:
            chain.append(int(nxt[chain[-1]]))
        # each piece up to the next one's start (an overlap cut)
        cut = [arr[a][0] < (k0[b] if b >= 0 else np.inf) for a, b in zip(chain, chain[1:] + [-1])]
        out.append(tuple(np.concatenate([arr[a][q][c] for a, c in zip(chain, cut)]) for q in range(3)))
    return out


def _remove_duplicates(tracks, samp, dist: float, n_samples: int = 16):
    """Drop a track that runs within ``dist`` of a longer one over most of its overlap.

    Only tracks passing within 2 ``dist`` of a track at one of ``n_samples`` evenly spaced slices of
    it are compared (per-slice KD-trees); a duplicate is within ``dist`` on at least a quarter of
    its slices, so the samples find it.
    """
    n = len(tracks)
    if n == 0:
        return []
    K = np.concatenate([t[0] for t in tracks])
    P = np.concatenate([t[1] for t in tracks]) * samp
    ids = np.repeat(np.arange(n), [len(t[0]) for t in tracks])
    order_k = np.argsort(K, kind="stable")
    Ks = K[order_k]
    queries: dict[int, list[tuple[int, np.ndarray]]] = {}
    for i, (k, p, _) in enumerate(tracks):
        for q in np.unique(np.linspace(0, len(k) - 1, min(n_samples, len(k))).round().astype(int)):
            queries.setdefault(int(k[q]), []).append((i, p[q] * samp))
    near = [set() for _ in range(n)]
    for kq, qs in queries.items():
        a, b = np.searchsorted(Ks, kq), np.searchsorted(Ks, kq, side="right")
        sel = order_k[a:b]
        tree = cKDTree(P[sel])
        for (i, pt), hits in zip(qs, tree.query_ball_point(np.array([q[1] for q in qs]), 2.0 * dist)):
            near[i].update(int(ids[sel[h]]) for h in hits)
    order = sorted(range(n), key=lambda i: -len(tracks[i][0]))
    kept, is_kept = [], np.zeros(n, dtype=bool)
    for i in order:
        k, p, _ = tracks[i]
        dup = False
        for j in (j for j in near[i] if is_kept[j] and j != i):
            kj, pj, _ = tracks[j]
            common, ia, ib = np.intersect1d(k, kj, assume_unique=True, return_indices=True)
            if len(common) < 0.5 * len(k):
                continue
            d = np.linalg.norm((p[ia] - pj[ib]) * samp, axis=1)
            if np.median(d) < dist:
                dup = True
                break
        if not dup:
            kept.append(i)
            is_kept[i] = True
    return [tracks[i] for i in sorted(kept)]


def finish_tracks(raw, v, perm, r: float, *, merge_gap_vox: int, max_jump: float, min_length_vox: float,
                  smooth_sigma_vox: float, spacing_vox: float) -> tuple[Polylines, int]:
    """Raw tracks (objects with ``k``, ``p``, ``r``) -> fibers: pieces merged across gaps, short
    and duplicate tracks dropped, skipped slices filled, smoothed along the track, back to the
    volume's axis order (``perm``) and metres, resampled by arc length. Returns the fibers and the
    number of merged tracks."""
    vt = v[list(perm)]
    samp = vt[1:] / vt[1:].min()
    merged = merge_pieces(raw, samp, max_gap=merge_gap_vox, max_dist=max_jump, fit_n=int(max(5, 2 * r)),
                          outlier_vox=OUTLIER_RADII * r)
    long_ = [t for t in merged if t[0][-1] - t[0][0] + 1 >= min_length_vox]
    long_ = _remove_duplicates(long_, samp, dist=0.5 * r)
    fibers, radii = [], []
    for k, p, rr in long_:
        # fill skipped slices linearly, then smooth along the track and resample by arc length
        kk = np.arange(k[0], k[-1] + 1)
        pts = np.column_stack([kk, np.interp(kk, k, p[:, 0]), np.interp(kk, k, p[:, 1])])
        pts[:, 1:] = smooth_polyline(pts[:, 1:], smooth_sigma_vox)
        zyx = np.empty_like(pts)
        zyx[:, list(perm)] = pts  # back to the volume's axis order
        xyz = voxel_to_xyz_m(zyx, v)
        fibers.append(resample_polyline(xyz, spacing_vox * v.min()))
        radii.append(max(0.5, float(np.median(rr))) * vt[1:].min())
    return Polylines.from_list(fibers, np.asarray(radii) if radii else 0.0), len(merged)


class SliceOptions(NamedTuple):
    """Options of the slices tracer (:func:`trace`, ``method="slices"`` or ``"dense"``); ``None``
    means scaled by the radius r (voxels)."""

    max_jump_vox: float | None = None     # max(2, 0.6 r)
    max_skip: int = 3
    gain: float | None = None             # the tracks' alpha-beta filter: 0.5 on grey, 1 on the mask
    min_length_vox: float | None = None   # max(10, 3 r)
    merge_gap_vox: int | None = None      # max(6, 3 r)
    smooth_sigma_vox: float | None = None  # max(1, r / 2)
    spacing_vox: float = 1.0
    peak_threshold: float = 0.5
    refine: bool | str = True             # True: Voronoi centroids; "fit": + joint disk fit (grey)
    off_axis: str = "trace"
    off_axis_min_fraction: float = 0.02
    radius_from: str = "mask"             # "grey": the dense tracer's radius (dense.estimate_radius_grey)


def track_gain(on_grey: bool) -> float:
    """The default position gain of the tracks' alpha-beta filter (:meth:`_Track.update`): 0.5 on
    the grey volume, 1 (each track predicted from its last detection) on the mask alone.

    Why two: on the mask the predictions seed the detection and each centre is refined from its
    seed, so a filtered prediction would make the centres depend on the track's history (a block
    of the chunked tracer starts without one); on grey the centres come from the image alone, and
    the filter only keeps a track on its fiber through a slice where its detection is off."""
    return 0.5 if on_grey else 1.0


def slice_options(options: dict) -> SliceOptions:
    """:class:`SliceOptions` from keyword options, an unknown name a one-line InputError."""
    unknown = sorted(set(options) - set(SliceOptions._fields))
    if unknown:
        raise InputError(f"trace: unknown option {unknown[0]!r} of the slices tracer (known: "
                         f"{', '.join(SliceOptions._fields)})")
    return SliceOptions(**options)


def trace_slices(mask: np.ndarray, voxel_size_m, *, expected_radius_m: float | None = None,
                 axis: int | str = "auto", grey: np.ndarray | None = None, progress=None,
                 **options) -> Polylines:
    """Slice-wise tracer; see :func:`trace` (``method="slices"``) for the parameters; ``options``:
    the fields of :class:`SliceOptions`."""
    t0 = time.perf_counter()
    o = slice_options(options)
    v = voxel_size_zyx(voxel_size_m)
    if axis == "auto":
        ax, direction = dominant_axis(mask, v)
    else:
        ax, direction = int(axis), None
    if o.radius_from == "grey" and expected_radius_m is None:
        if grey is None:
            raise InputError("trace: the dense tracer reads the grey volume (grey=)")
        expected_radius_m = grey_radius_vox(mask, grey, v, ax) * float(v[[i for i in range(3) if i != ax]].min())
    if o.off_axis != "none":
        opts = dict(expected_radius_m=expected_radius_m, progress=progress, grey=grey,
                    **o._replace(off_axis="none")._asdict())
        split = _trace_axis_regions(mask, voxel_size_m, ax, direction, o.off_axis, o.off_axis_min_fraction, opts)
        if split is not None:
            split.meta["time_total_s"] = time.perf_counter() - t0
            return split
    perm = (ax,) + tuple(i for i in range(3) if i != ax)
    mask_t = mask.transpose(perm)  # a view: slices across the fibers
    vt = v[list(perm)]
    samp = vt[1:] / vt[1:].min()
    r = float(expected_radius_m) / vt[1:].min() if expected_radius_m is not None else estimate_radius_vox(mask_t, samp)
    o = o._replace(
        max_jump_vox=float(o.max_jump_vox) if o.max_jump_vox is not None else max(2.0, 0.6 * r),
        min_length_vox=o.min_length_vox if o.min_length_vox is not None else max(10.0, 3.0 * r),
        merge_gap_vox=o.merge_gap_vox if o.merge_gap_vox is not None else int(max(6, 3 * r)),
        smooth_sigma_vox=o.smooth_sigma_vox if o.smooth_sigma_vox is not None else max(1.0, 0.5 * r),
        gain=o.gain if o.gain is not None else track_gain(grey is not None))
    min_distance = max(1, int(round(0.5 * r)))
    grey_t = None
    if grey is not None:
        if grey.shape != mask.shape:
            raise InputError(f"trace: the grey volume's shape {grey.shape} differs from the mask's {mask.shape}")
        grey_t = _GreySlices(grey.transpose(perm), mask_t, samp, sigma_along=grey_sigma_along(r))
        min_distance = max(1, int(round(0.75 * r)))
    raw, n_det = track_slices(mask_t, r, samp, min_distance=min_distance,
                              peak_threshold=o.peak_threshold, max_jump=o.max_jump_vox, max_skip=o.max_skip,
                              gain=o.gain, refine=o.refine, progress=progress, grey_t=grey_t)
    t_det = time.perf_counter() - t0
    out, n_merged = finish_tracks(raw, v, perm, r, merge_gap_vox=o.merge_gap_vox, max_jump=o.max_jump_vox,
                                  min_length_vox=o.min_length_vox, smooth_sigma_vox=o.smooth_sigma_vox,
                                  spacing_vox=o.spacing_vox)
    if o.radius_from == "grey":
        out = drop_oblique_into_meta(out, v, ax, grey=grey, radius_vox=r)
    out.meta.update(method="dense" if o.radius_from == "grey" else "slices", axis=ax, direction_zyx=direction,
                    radius_vox_estimate=r, n_detections=n_det, n_tracks_raw=len(raw), n_tracks_merged=n_merged,
                    n_fibers=out.n_fibers, time_detect_s=t_det, time_total_s=time.perf_counter() - t0,
                    params=dict(max_jump_vox=o.max_jump_vox, max_skip=o.max_skip, gain=o.gain,
                                min_length_vox=o.min_length_vox, merge_gap_vox=o.merge_gap_vox,
                                smooth_sigma_vox=o.smooth_sigma_vox, spacing_vox=o.spacing_vox,
                                peak_threshold=o.peak_threshold, min_distance_vox=min_distance))
    return out


def grey_radius_vox(mask: np.ndarray, grey: np.ndarray, voxel_size_zyx_m: np.ndarray, ax: int) -> float:
    """The fiber radius (pixels across ``ax``) of a dense pack, from its grey slices
    (:func:`fiberpipe.imaging.dense.estimate_radius_grey`, started from the mask's estimate)."""
    from .orientation import axis_regions

    # on the fibers along ax only: a cross ply's stripes in these slices are no cross-sections
    labels, fractions = axis_regions(mask, voxel_size_zyx_m, grey=grey)
    if max(fractions[b] for b in range(3) if b != ax) >= 0.02:
        mask = mask & (labels == ax)
    perm = (ax,) + tuple(i for i in range(3) if i != ax)
    mask_t = mask.transpose(perm)
    vt = voxel_size_zyx_m[list(perm)]
    samp = vt[1:] / vt[1:].min()
    return grey_radius_of_slices(mask_t, grey.transpose(perm), samp)


def grey_radius_of_slices(mask_t, grey_t, samp: np.ndarray, levels=None) -> float:
    """The grey radius (:func:`fiberpipe.imaging.dense.estimate_radius_grey`) of slices with the
    fibers' axis first (arrays, or blocks read slice by slice), started from the mask's estimate;
    ``levels``: the grey levels of :class:`_GreySlices` when measured elsewhere."""
    from .dense import estimate_radius_grey

    r0 = estimate_radius_vox(mask_t, samp)

    def detect(sl, g, r):
        # every maximum a radius apart: a trial radius below the fibers' shows two per fiber, and the
        # score must see them to reject it (a minimum spacing would hide them)
        return detect_slice(sl, r, samp, min_distance=max(1, int(round(0.75 * r))), peak_threshold=0.5, grey=g,
                            min_spacing_radii=0.0)[0]

    return estimate_radius_grey(_GreySlices(grey_t, mask_t, samp, levels=levels), mask_t, samp, r0, detect)


def _trace_axis_regions(mask, voxel_size_m, ax: int, direction, off_axis: str, min_fraction: float,
                        opts: dict) -> Polylines | None:
    """The slices tracer on a scan whose fibers run along more than one volume axis (a cross ply,
    a woven tow lying in the slices): the mask is split by the local fiber axis
    (:func:`fiberpipe.imaging.orientation.axis_regions`) and each region of at least
    ``min_fraction`` of the fiber volume is traced along its own axis (``off_axis="trace"``) or
    left out (``"drop"``). ``None`` when the fibers run along one axis only.

    Why: fibers lying in the slice plane cut every slice in long stripes; read as cross-sections
    they give tracks along the slicing axis that are no fibers.
    """
    from .orientation import axis_regions

    if off_axis not in ("trace", "drop"):
        raise InputError(f"trace: unknown off_axis {off_axis!r} (use 'trace' or 'drop')")
    r = opts.get("expected_radius_m")
    r_vox = None if r is None else float(r) / float(voxel_size_zyx(voxel_size_m).min())
    labels, fr = axis_regions(mask, voxel_size_m, grey=opts.get("grey"), radius_vox=r_vox)
    others = [b for b in range(3) if b != ax and fr[b] >= min_fraction]
    if not others:
        return None
    main = mask & ~np.isin(labels, others)
    parts = [trace_slices(main, voxel_size_m, axis=ax, **opts)]
    del main
    info = {}
    for b in others:
        if off_axis == "trace":
            sub = mask & (labels == b)
            parts.append(trace_slices(sub, voxel_size_m, axis=b, **opts))
            del sub
        info["zyx"[b]] = region_info(fr[b], parts[-1] if off_axis == "trace" else None)
    add_oblique(info, parts)
    return combine_region_parts(parts, info, direction_zyx=direction)


def region_info(volume_fraction: float, traced: Polylines | None) -> dict:
    """What ``off_axis`` reports for a region along another volume axis: its share of the fiber
    volume, the fibers traced along its axis (``traced``; None: left out) and, when any, the tracks
    of it left out as oblique (``oblique``: a region whose every track runs off its axis is
    reported with a count, not traced)."""
    out = {"volume_fraction": round(float(volume_fraction), 4), "fibers": int(traced.n_fibers) if traced else 0,
           "action": "traced along its own axis" if traced is not None else "left out"}
    if traced is not None and "oblique" in traced.meta:
        out["oblique"] = int(traced.meta["oblique"]["fibers"])
    return out


def add_oblique(info: dict, parts: list) -> None:
    """``info["oblique"]``: the tracks :func:`drop_oblique` left out of the regions' ``parts``,
    summed (fibers, voxels of track), when any."""
    oblique = [p.meta["oblique"] for p in parts if "oblique" in p.meta]
    if oblique:
        info["oblique"] = {"fibers": sum(x["fibers"] for x in oblique),
                           "length_vox": round(sum(x["length_vox"] for x in oblique), 1),
                           "action": oblique[0]["action"]}
        if any("by_structure" in x for x in oblique):
            info["oblique"]["by_structure"] = sum(x.get("by_structure", 0) for x in oblique)


#: The dense tracer keeps a track only within this angle (degrees) of its slicing axis.
DENSE_MAX_TILT_DEG = 30.0


def drop_oblique(fibers: Polylines, voxel_size_zyx_m, axis: int, max_tilt_deg: float = DENSE_MAX_TILT_DEG):
    """The dense tracer's fibers without those running farther than ``max_tilt_deg`` from the
    slicing ``axis`` (end to end), and what was left out: ``fibers``, ``length_vox`` (their traced
    length, voxels), ``action``.

    Why: the dense detection looks for round cross-sections of the fiber radius; a fiber tilted by
    theta cuts the slices in ellipses 1 / cos(theta) long (1.15 at 30 degrees, 1.41 at 45) and
    moves tan(theta) voxels per slice, so a ply at +-45 degrees in a laminate comes out as short
    fragments along the slicing axis that are no fibers of the scan along it (on the real cross-ply
    example, 217 pieces 31 slices long in the median, 36-43 degrees off z). They are reported, not
    traced.
    """
    v_xyz = np.asarray(voxel_size_zyx_m, dtype=np.float64)[::-1]
    keep, dropped_length = [], 0.0
    for i in range(fibers.n_fibers):
        p = fibers.fiber(i) / v_xyz
        d = p[-1] - p[0]
        length = float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())
        norm = float(np.linalg.norm(d))
        if norm > 0 and np.degrees(np.arccos(min(1.0, abs(d[2 - axis]) / norm))) > max_tilt_deg:
            dropped_length += length
        else:
            keep.append(i)
    info = {"fibers": fibers.n_fibers - len(keep), "length_vox": round(dropped_length, 1),
            "action": f"left out (tracks more than {max_tilt_deg:g} deg off the slicing axis: a ply the slices cannot follow)"}
    return _kept(fibers, keep), info



def _kept(fibers: Polylines, keep: list) -> Polylines:
    """The fibers ``keep`` of ``fibers`` (``fibers`` itself when it keeps them all), with its meta."""
    if len(keep) == fibers.n_fibers:
        return fibers
    radii = np.broadcast_to(np.asarray(fibers.radius_m, dtype=np.float64), (fibers.n_fibers,))[keep]
    out = Polylines.from_list([fibers.fiber(i) for i in keep], radii if len(keep) else 0.0)
    out.meta.update(fibers.meta)
    return out

def drop_oblique_into_meta(fibers: Polylines, voxel_size_zyx_m, axis: int, grey=None,
                           radius_vox: float | None = None) -> Polylines:
    """:func:`drop_oblique`, then, given ``grey`` (anything read by boxes) and ``radius_vox``, the
    tracks whose grey structure runs more than :data:`DENSE_MAX_TILT_DEG` off ``axis``
    (:func:`fiberpipe.imaging.dense.structure_direction`); what was left out in ``meta["oblique"]``
    (and ``meta["off_axis"]``) when anything: ``fibers``, ``length_vox``, ``by_structure`` (the
    tracks the second test left out)."""
    out, oblique = drop_oblique(fibers, voxel_size_zyx_m, axis)
    if grey is not None and radius_vox is not None and out.n_fibers:
        out, by_structure = _drop_oblique_structure(out, grey, voxel_size_zyx_m, axis, radius_vox)
        oblique["fibers"] += by_structure["fibers"]
        oblique["length_vox"] = round(oblique["length_vox"] + by_structure["length_vox"], 1)
        oblique["by_structure"] = by_structure["fibers"]
    if oblique["fibers"]:
        out.meta["oblique"] = oblique
        out.meta.setdefault("off_axis", {"oblique": oblique})
    return out


def _drop_oblique_structure(fibers: Polylines, grey, voxel_size_zyx_m, axis: int, radius_vox: float):
    """The fibers whose grey structure (:func:`fiberpipe.imaging.dense.structure_direction`) runs
    within :data:`DENSE_MAX_TILT_DEG` of ``axis``, and what was left out (``fibers``,
    ``length_vox``)."""
    from .dense import structure_direction

    v = np.asarray(voxel_size_zyx_m, dtype=np.float64)
    keep, dropped_length = [], 0.0
    for i in range(fibers.n_fibers):
        zyx = fibers.fiber(i)[:, ::-1] / v
        d = structure_direction(grey, zyx, radius_vox, v)
        tilt = np.degrees(np.arccos(min(1.0, abs(d[axis]) / max(float(np.linalg.norm(d)), 1e-12))))
        if tilt > DENSE_MAX_TILT_DEG:
            dropped_length += float(np.linalg.norm(np.diff(zyx, axis=0), axis=1).sum())
        else:
            keep.append(i)
    info = {"fibers": fibers.n_fibers - len(keep), "length_vox": round(dropped_length, 1)}
    return _kept(fibers, keep), info


def combine_region_parts(parts: list, info: dict, **meta) -> Polylines:
    """The fibers of the regions of a cross ply, traced each along its own axis, as one set: the main
    axis' part first (its ``meta`` kept), ``off_axis`` = ``info`` (per other axis: volume fraction,
    fibers, action), ``n_fibers_main_axis``."""
    fibers = [f for p in parts for f in p]
    radii = np.concatenate([np.broadcast_to(np.asarray(p.radius_m, dtype=np.float64), (p.n_fibers,)) for p in parts])
    out = Polylines.from_list(fibers, radii if len(fibers) else 0.0)
    out.meta.update(parts[0].meta)
    out.meta.update(n_fibers=len(fibers), n_fibers_main_axis=parts[0].n_fibers, off_axis=info, **meta)
    return out


def trace(mask: np.ndarray, *, voxel_size_m, method: str = "slices", skeleton: np.ndarray | None = None,
          radius_vox: np.ndarray | None = None, expected_radius_m: float | None = None,
          **options) -> Polylines:
    """Trace one mid-line per fiber.

    Parameters
    ----------
    mask : (Z, Y, X) bool ndarray
        Fiber mask (from :func:`fiberpipe.imaging.segment.segment`).
    voxel_size_m : float or (dz, dy, dx)
        Voxel size, m.
    method : {"slices", "skeleton"}
        ``slices``: per-slice centres across the dominant axis, linked between slices (for
        quasi-parallel, touching fibers). ``skeleton``: graph of the 3D skeleton (crossing fibers).
    skeleton, radius_vox : (Z, Y, X) ndarrays, optional
        Output of :func:`fiberpipe.imaging.skeleton.skeletonize`, for ``method="skeleton"``
        (computed from ``mask`` if not given).
    expected_radius_m : float, optional
        Nominal fiber radius, m; estimated from the mask when not given.
    **options
        Method options. ``slices``: ``axis`` ("auto" or 0/1/2), ``max_jump_vox`` (default
        max(2, 0.6 r)), ``max_skip`` (3 slices), ``gain`` (0.5, the tracks' alpha-beta filter), ``min_length_vox``
        (max(10, 3 r)), ``merge_gap_vox`` (max(6, 3 r)), ``smooth_sigma_vox`` (max(1, r/2)),
        ``spacing_vox`` (1), ``peak_threshold`` (0.5, in units of r), ``refine`` (True),
        ``progress`` (callable(done, total)), ``off_axis`` ("trace": regions of at least
        ``off_axis_min_fraction`` (0.02) of the fiber volume whose fibers run along another volume
        axis, such as a cross ply lying in the slices, are traced along their own axis; "drop":
        left out, counted in ``meta["off_axis"]``; "none": one axis only). ``skeleton``: see
        :func:`fiberpipe.imaging.skeleton_trace.trace_skeleton`. Both: ``join_gap_vox`` (max(4, 4 r);
        0 turns joining off), ``join_offset_vox`` (max(1.5, r)), ``join_angle_deg`` (25), the bounds
        of :func:`fiberpipe.imaging.fragments.join_fragments`, which chains the broken pieces of
        one fiber after tracing.

    Returns
    -------
    Polylines
        Mid-lines (x y z, m), resampled at ``spacing_vox`` voxels, and one radius per fiber (m);
        ``.meta`` holds the method, the parameters used and counts.
    """
    if mask.ndim != 3:
        raise InputError(f"trace: expected a 3D mask, got shape {mask.shape}")
    if mask.dtype != bool:
        mask = mask.astype(bool)
    if not mask.any():
        raise InputError("trace: the mask is empty")
    join = {k: options.pop(k) for k in ("join_gap_vox", "join_offset_vox", "join_angle_deg") if k in options}
    if method == "slices":
        out = trace_slices(mask, voxel_size_m, expected_radius_m=expected_radius_m, **options)
    elif method == "dense":
        if options.get("grey") is None:
            raise InputError("trace: method 'dense' finds the fiber centres in the grey volume: pass grey=")
        out = trace_slices(mask, voxel_size_m, expected_radius_m=expected_radius_m, radius_from="grey", **options)
    elif method == "skeleton":
        from .skeleton_trace import trace_skeleton

        out = trace_skeleton(mask, voxel_size_m, skeleton=skeleton, radius_vox=radius_vox,
                             expected_radius_m=expected_radius_m, **options)
    else:
        raise InputError(f"trace: unknown method {method!r} (use 'slices', 'dense' or 'skeleton')")
    return _join(out, voxel_size_m, **join)


def _join(fibers: Polylines, voxel_size_m, *, join_gap_vox: float | None = None,
          join_offset_vox: float | None = None, join_angle_deg: float | None = None) -> Polylines:
    """Join broken pieces of one fiber (:func:`fiberpipe.imaging.fragments.join_fragments`) with
    bounds scaled by the radius estimate r: gap max(4, 4 r), offset max(1.5, r) voxels, 25 deg."""
    from .fragments import join_fragments

    vmin = float(voxel_size_zyx(voxel_size_m).min())
    r = float(fibers.meta.get("radius_vox_estimate") or 1.0)
    gap = max(4.0, 4.0 * r) if join_gap_vox is None else float(join_gap_vox)
    off = max(1.5, r) if join_offset_vox is None else float(join_offset_vox)
    ang = 25.0 if join_angle_deg is None else float(join_angle_deg)
    n_before = fibers.n_fibers
    joined, n_joins = join_fragments(fibers, max_gap_m=gap * vmin, max_offset_m=off * vmin, max_angle_deg=ang)
    joined.meta.update(n_fibers=joined.n_fibers, n_fibers_before_join=n_before, n_joins=n_joins,
                       join=dict(gap_vox=gap, offset_vox=off, angle_deg=ang))
    return joined
