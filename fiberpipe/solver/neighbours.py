"""O(N) neighbour search for segment–segment contact: cell list → Verlet list with a skin.

Rule (``docs/contact.md``):

* Broad phase: uniform cubic cells over segment midpoints, cell edge ``h ≥ L_max + 2 r_max + skin``
  (two segments whose closest distance is < r_i + r_j + skin have midpoints closer than that), the
  27 neighbouring cells are scanned; the cell grid is capped at ``4 E`` cells (h grows if needed).
  Counting sort into cells, no all-pairs loop: O(E) for bounded density.
* Narrow filter (a "tight" Verlet list): keep a pair if the segments' closest distance is
  ``< r_i + r_j + skin`` at build time.
* Exclusions: pairs sharing a node, and pairs of the same fiber whose curvilinear gap (reference
  arclength between their nearest ends) is ``< s_excl`` (default ``2 r``; a fiber folding back on
  itself needs at least ``π r`` of arc to touch, so nothing physical is lost). Far-apart parts of
  the same fiber may contact.
* Rebuild when the largest nodal displacement since the last build exceeds ``skin/2`` (every point
  of a segment moves at most as far as its farthest node, so no pair can come from beyond the skin
  into contact before that).

Output: ``pairs (P, 2) int64`` with ``i < j``, sorted by the key ``i·E + j`` (so friction history can
be carried across rebuilds by ``searchsorted``, see :mod:`fiberpipe.solver.friction`). The kernel
writes into a preallocated buffer and returns ``−needed`` when it is too small; :class:`VerletList`
grows it and retries. ``build_pairs_threads`` (``solver.threads`` > 1) lists the same pairs from
``prange`` tasks of consecutive segments, each segment's partners sorted as they are found, so the
tasks' lists joined in task order are the list in key order (no sort of the whole list).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .._tasks import task_count
from ._specialise import specialise
from .geometry import segment_distance2


@njit(cache=True, fastmath=True, error_model="numpy")
def max_displacement2_speed2(x, x_ref, v):
    """Largest squared distance [m²] of a node from ``x_ref`` (the positions at the last build) and
    the largest squared node speed [m²/s²] of ``v`` (0 if ``v`` has no rows), in one pass.

    The contact hook uses both every step: the first for the rebuild test, the second for the path
    bound of its per-pair skip (:func:`fiberpipe.solver.contact_potential.contact_forces_pot`).
    """
    m = 0.0
    vm = 0.0
    has_v = v.shape[0] == x.shape[0]
    for i in range(x.shape[0]):
        d0 = x[i, 0] - x_ref[i, 0]
        d1 = x[i, 1] - x_ref[i, 1]
        d2 = x[i, 2] - x_ref[i, 2]
        q = d0 * d0 + d1 * d1 + d2 * d2
        if q > m:
            m = q
        if has_v:
            u = v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1] + v[i, 2] * v[i, 2]
            if u > vm:
                vm = u
    return m, vm


# _nrt=True: it allocates (its empty v), and the contact hook that calls it runs without reference
# counts, which a callee inherits unless it sets its own
@njit(cache=True, fastmath=True, error_model="numpy", _nrt=True)
def max_displacement2(x, x_ref):
    """Largest squared distance [m²] of a node from ``x_ref`` (the positions at the last build)."""
    return max_displacement2_speed2(x, x_ref, np.empty((0, 3)))[0]


@njit(cache=True, fastmath=True, error_model="numpy")
def max_displacement_exceeds(x, x_ref, limit):
    """True if any node moved more than ``limit`` [m] from ``x_ref`` (the positions at the last build)."""
    return max_displacement2(x, x_ref) > limit * limit


@njit(cache=True, error_model="numpy")
def _all_finite_bits(x):
    """True if no entry of ``x`` (N, 3) is NaN or ±inf, decided on the IEEE-754 exponent bits (an
    integer test that fastmath cannot assume away)."""
    buf = np.empty(1)
    bits = buf.view(np.int64)
    for i in range(x.shape[0]):
        for c in range(x.shape[1]):
            buf[0] = x[i, c]
            if (bits[0] >> 52) & 0x7FF == 0x7FF:
                return False
    return True


@njit(cache=True, inline="always")
def pair_key(i, j, ne):
    """The key of segment pair (i, j) among ``ne`` segments, ``i·E + j``: the list's order and the
    friction history's look-up when the list is rebuilt."""
    return i * ne + j


def _build_pairs(x, seg_nodes, seg_radius, seg_fiber, seg_arc, skin, s_excl, pairs_out, keys_out):
    """Build the Verlet list of candidate segment pairs.

    Parameters
    ----------
    x : (N, 3) float64, m. seg_nodes : (E, 2) int64. seg_radius : (E,) float64, m.
    seg_fiber : (E,) int64 — fiber id of each segment.
    seg_arc : (E, 2) float64, m — reference arclength of each segment's two ends along its fiber.
    skin : float, m. s_excl : float, m — same-fiber curvilinear exclusion gap.
    pairs_out : (C, 2) int64, keys_out : (C,) int64 — out (capacity C).

    Returns
    -------
    n : int — number of pairs written (sorted by key ``i·E + j``), or ``−needed`` if C < needed.

    ``build_pairs`` runs the segments in one task; ``build_pairs_threads`` (``solver.threads`` > 1)
    in ``prange`` tasks of consecutive segments once there are ``SEGMENT_TASK_MIN`` for each, with
    the same list: each task lists its segments' pairs in key order into its own share of
    ``pairs_out``, and the shares are joined in task order.
    """
    ne = seg_nodes.shape[0]
    if ne == 0:
        return 0
    mid, lo, hi, lmax, rmax = _midpoints(x, seg_nodes, seg_radius)
    # A diverging step can leave non-finite positions: the cell indices below would then be
    # garbage (and the writes into the cell arrays out of bounds). Build no pairs; the step loop's
    # divergence check reports the run with its diagnosis. The test reads the bits: this function
    # is inlined into the fastmath step loop, where LLVM may assume floats are never NaN and drop a
    # float test (it did: the guard passed alone and failed inside the solver batch).
    if not _all_finite_bits(x):
        return 0
    h, nc, tot = _cell_grid(lo, hi, lmax + 2.0 * rmax + skin, ne)
    cell_of, start, items = _bin_segments(mid, lo, h, nc, tot)
    cap = pairs_out.shape[0]
    # a prange body takes tuples built here, not ones nested in another structure
    segs = (seg_nodes, seg_radius, seg_fiber, seg_arc)
    grid = (cell_of, start, items, nc, h * h)
    cuts = (skin, s_excl)
    n_tasks = task_count(ne, SEGMENT_TASK_MIN, SEGMENT_TASKS) if _THREADS else 1
    if n_tasks == 1:
        n = _pairs_of_segments((0, ne), x, segs, mid, grid, cuts, pairs_out, (0, cap))
        if n > cap:
            return -n
    else:
        share = cap // n_tasks
        counts = np.empty(n_tasks, np.int64)
        _pairs_in_tasks(x, segs, mid, grid, cuts, pairs_out, share, counts)
        n = 0
        most = 0
        for task in range(n_tasks):
            n += counts[task]
            most = max(most, counts[task])
        if most > share:  # a capacity whose every share holds the fullest task's pairs
            return -max(n, most * n_tasks)
        n = _join_shares(pairs_out, counts, share)
    for k in range(n):
        keys_out[k] = pair_key(pairs_out[k, 0], pairs_out[k, 1], ne)
    return n


def _pairs_in_tasks(x, segs, mid, grid, cuts, pairs_out, share, counts):
    """:func:`_pairs_of_segments` in ``counts.shape[0]`` ``prange`` tasks of consecutive segments,
    task k into rows ``k·share …`` of ``pairs_out``, its count into ``counts[k]``."""
    n_tasks = counts.shape[0]
    ne = segs[0].shape[0]
    for task in prange(n_tasks):
        counts[task] = _pairs_of_segments((task * ne // n_tasks, (task + 1) * ne // n_tasks), x, segs, mid, grid,
                                          cuts, pairs_out, (task * share, share))


@njit(cache=True, error_model="numpy")
def _join_shares(pairs, counts, share):
    """The tasks' pairs, task after task from row 0 (each share moves down or stays: rows are read
    before they are overwritten); returns their number."""
    n = 0
    for task in range(counts.shape[0]):
        base = task * share
        for k in range(counts[task]):
            pairs[n, 0] = pairs[base + k, 0]
            pairs[n, 1] = pairs[base + k, 1]
            n += 1
    return n


@njit(cache=True, error_model="numpy")
def _pairs_of_segments(span, x, segs, mid, grid, cuts, pairs_out, share):
    """The pairs (i, j), j > i, of the segments i in ``span = (first, end)``, in key order, into
    rows ``base … base + capacity − 1`` of ``pairs_out`` (``share = (base, capacity)``); returns
    their number (beyond the capacity: counted, not written)."""
    seg_nodes, seg_radius, seg_fiber, seg_arc = segs
    cell_of, start, items, nc, h2 = grid
    skin, s_excl = cuts
    base, cap = share
    n = 0
    ta = np.empty(3)
    tb = np.empty(3)
    a0 = np.empty(3)
    a1 = np.empty(3)
    b0 = np.empty(3)
    b1 = np.empty(3)
    for i in range(span[0], span[1]):
        first = n
        cid = cell_of[i]
        iz = cid % nc[2]
        iy = (cid // nc[2]) % nc[1]
        ix = cid // (nc[1] * nc[2])
        ia0 = seg_nodes[i, 0]
        ia1 = seg_nodes[i, 1]
        for c in range(3):
            a0[c] = x[ia0, c]
            a1[c] = x[ia1, c]
            ta[c] = a1[c] - a0[c]
        for dx in range(-1, 2):
            jx = ix + dx
            if jx < 0 or jx >= nc[0]:
                continue
            for dy in range(-1, 2):
                jy = iy + dy
                if jy < 0 or jy >= nc[1]:
                    continue
                for dz in range(-1, 2):
                    jz = iz + dz
                    if jz < 0 or jz >= nc[2]:
                        continue
                    cj = (jx * nc[1] + jy) * nc[2] + jz
                    for q in range(start[cj], start[cj + 1]):
                        j = items[q]
                        if j <= i:
                            continue
                        jb0 = seg_nodes[j, 0]
                        jb1 = seg_nodes[j, 1]
                        if jb0 == ia0 or jb0 == ia1 or jb1 == ia0 or jb1 == ia1:
                            continue
                        if seg_fiber[j] == seg_fiber[i]:
                            gap = max(seg_arc[i, 0], seg_arc[j, 0]) - min(seg_arc[i, 1], seg_arc[j, 1])
                            if gap < s_excl:
                                continue
                        dm = 0.0
                        for c in range(3):
                            dm += (mid[j, c] - mid[i, c]) ** 2
                        if dm > h2:
                            continue
                        for c in range(3):
                            b0[c] = x[jb0, c]
                            b1[c] = x[jb1, c]
                            tb[c] = b1[c] - b0[c]
                        cut = seg_radius[i] + seg_radius[j] + skin
                        d2, s, t = segment_distance2(a0, a1, b0, b1, ta, tb)
                        if d2 < cut * cut:
                            if n < cap:
                                pairs_out[base + n, 0] = i
                                pairs_out[base + n, 1] = j
                            n += 1
        if n <= cap:
            _sort_partners(pairs_out, base + first, base + n)
    return n


@njit(cache=True, error_model="numpy", inline="always")
def _sort_partners(pairs, first, end):
    """Rows ``first … end − 1`` (one segment's pairs, a few dozen at most) in ascending order of
    their second segment: an insertion sort (numba's ``np.sort`` costs seconds of compile time)."""
    for k in range(first + 1, end):
        j = pairs[k, 1]
        m = k - 1
        while m >= first and pairs[m, 1] > j:
            pairs[m + 1, 1] = pairs[m, 1]
            m -= 1
        pairs[m + 1, 1] = j


@njit(cache=True, error_model="numpy")
def _midpoints(x, seg_nodes, seg_radius):
    """``(mid (E, 3), lo (3,), hi (3,), longest segment, largest radius)`` of the segments at ``x``."""
    ne = seg_nodes.shape[0]
    mid = np.empty((ne, 3))
    lmax = 0.0
    rmax = 0.0
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for e in range(ne):
        a = seg_nodes[e, 0]
        b = seg_nodes[e, 1]
        l2 = 0.0
        for c in range(3):
            m = 0.5 * (x[a, c] + x[b, c])
            mid[e, c] = m
            l2 += (x[b, c] - x[a, c]) ** 2
            lo[c] = min(lo[c], m)
            hi[c] = max(hi[c], m)
        lmax = max(lmax, math.sqrt(l2))
        rmax = max(rmax, seg_radius[e])
    return mid, lo, hi, lmax, rmax


@njit(cache=True, error_model="numpy")
def _cell_grid(lo, hi, h, ne):
    """``(cell size, cells per axis (3,), cells)``: cells of at least ``h`` over [lo, hi], grown by
    1.26 until there are at most 4 E + 64."""
    nc = np.empty(3, np.int64)
    while True:
        tot = 1
        for c in range(3):
            nc[c] = max(1, int((hi[c] - lo[c]) / h) + 1)
            tot *= nc[c]
        if tot <= 4 * ne + 64:
            break
        h *= 1.26
    return h, nc, tot


@njit(cache=True, error_model="numpy")
def _bin_segments(mid, lo, h, nc, tot):
    """Counting sort of the segments into the cells by midpoint: ``(cell of each segment, CSR
    offsets of the cells (tot + 1,), the segments cell after cell)``."""
    ne = mid.shape[0]
    cell_of = np.empty(ne, np.int64)
    start = np.zeros(tot + 1, np.int64)
    for e in range(ne):
        ix = max(0, min(int((mid[e, 0] - lo[0]) / h), nc[0] - 1))
        iy = max(0, min(int((mid[e, 1] - lo[1]) / h), nc[1] - 1))
        iz = max(0, min(int((mid[e, 2] - lo[2]) / h), nc[2] - 1))
        cid = (ix * nc[1] + iy) * nc[2] + iz
        cell_of[e] = cid
        start[cid + 1] += 1
    for c in range(tot):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    items = np.empty(ne, np.int64)
    for e in range(ne):
        cid = cell_of[e]
        items[fill[cid]] = e
        fill[cid] += 1
    return cell_of, start, items


#: segments per task of the threaded build at least (fewer: one task); a task of 2048 segments
#: takes about 1.5 ms, far above the cost of starting it
SEGMENT_TASK_MIN = 2048
#: tasks of the threaded build at most (numba deals a parallel loop's tasks out to its threads up
#: front: 8 tasks leave a thread whose core is busy less to catch up than 2)
SEGMENT_TASKS = 8
_THREADS = False
# Not cached: a parfor kernel linked into a step loop compiled in another process crashes its cache
# entry (see _kernels_beam.beam_pass_fibers); only the solver.threads > 1 contact step uses them. The
# parallel loop is kept to its own small function: numba's parfor passes take seconds on a large one.
# The serial build binds the tasks' loop compiled serially (prange as range), never the parfor.
_pairs_in_tasks_parallel = njit(cache=False, error_model="numpy", parallel=True)(_pairs_in_tasks)
_pairs_in_tasks = njit(cache=True, error_model="numpy")(_pairs_in_tasks)
build_pairs = njit(cache=True, error_model="numpy")(_build_pairs)
build_pairs_threads = specialise(_build_pairs, "build_pairs_threads",
                                 {"_THREADS": True, "_pairs_in_tasks": _pairs_in_tasks_parallel}, cache=False,
                                 error_model="numpy")


def segment_arclength(seg_nodes: np.ndarray, seg_fiber: np.ndarray, x_ref: np.ndarray) -> np.ndarray:
    """Reference arclength (E, 2) of each segment's ends along its fiber (segments in fiber order)."""
    seg_nodes = np.asarray(seg_nodes)
    L = np.linalg.norm(x_ref[seg_nodes[:, 1]] - x_ref[seg_nodes[:, 0]], axis=1)
    arc = np.empty((len(seg_nodes), 2))
    acc = 0.0
    for e in range(len(seg_nodes)):
        if e == 0 or seg_fiber[e] != seg_fiber[e - 1]:
            acc = 0.0
        arc[e, 0] = acc
        acc += L[e]
        arc[e, 1] = acc
    return arc


class VerletList:
    """Verlet list of candidate segment pairs with skin, rebuilt on demand (skin/2 rule).

    Keeps, between steps: ``pairs`` (C, 2), ``keys`` (C,), ``n_pairs``, ``x_ref`` (positions at
    the last build). ``update(x)`` rebuilds if needed and returns True when it did.
    """

    def __init__(self, seg_nodes, seg_radius, seg_fiber, seg_arc, skin_m: float, s_excl_m: float | None = None,
                 capacity: int | None = None):
        self.seg_nodes = np.ascontiguousarray(seg_nodes, dtype=np.int64)
        self.seg_radius = np.ascontiguousarray(seg_radius, dtype=np.float64)
        self.seg_fiber = np.ascontiguousarray(seg_fiber, dtype=np.int64)
        self.seg_arc = np.ascontiguousarray(seg_arc, dtype=np.float64)
        if not skin_m > 0:
            raise ValueError(f"skin must be > 0 m, got {skin_m}")
        self.skin_m = float(skin_m)
        self.s_excl_m = float(2.0 * self.seg_radius.max() if s_excl_m is None else s_excl_m)
        cap = capacity if capacity is not None else 16 * max(len(self.seg_nodes), 1)
        self.pairs = np.zeros((cap, 2), np.int64)
        self.keys = np.zeros(cap, np.int64)
        self.n_pairs = 0
        self.x_ref = None
        self.n_builds = 0

    def build(self, x):
        x = np.ascontiguousarray(x, dtype=np.float64)
        while True:
            n = build_pairs(x, self.seg_nodes, self.seg_radius, self.seg_fiber, self.seg_arc, self.skin_m,
                            self.s_excl_m, self.pairs, self.keys)
            if n >= 0:
                break
            cap = int(-n * 1.5) + 16
            self.pairs = np.zeros((cap, 2), np.int64)
            self.keys = np.zeros(cap, np.int64)
        self.n_pairs = n
        self.x_ref = x.copy()
        self.n_builds += 1

    def needs_rebuild(self, x) -> bool:
        return self.x_ref is None or bool(max_displacement_exceeds(x, self.x_ref, 0.5 * self.skin_m))

    def update(self, x) -> bool:
        if self.needs_rebuild(x):
            self.build(x)
            return True
        return False
