"""Skeleton-graph tracer: for crossing, non-aligned fibers and for QA (``trace(method="skeleton")``).

Fibers touching along their length thin to one skeleton line between them; this method cannot
separate them (use ``method="slices"``).
"""

from __future__ import annotations

import itertools
import time

import networkx as nx
import numpy as np

from ..errors import InputError
from ..polylines import Polylines
from ._util import resample_polyline, smooth_polyline, voxel_size_zyx, voxel_to_xyz_m

# the 13 "forward" offsets of the 26-neighbourhood (each undirected edge once)
_OFFSETS = np.array([o for o in itertools.product((-1, 0, 1), repeat=3) if o > (0, 0, 0)])


def skeleton_graph(skeleton: np.ndarray) -> tuple[nx.Graph, np.ndarray]:
    """26-connected voxel graph of a skeleton.

    Returns
    -------
    graph : networkx.Graph
        Node ``i`` is skeleton voxel ``coords[i]``; edges join 26-neighbours.
    coords : (N, 3) int64 ndarray
        Voxel indices (z, y, x) of the skeleton voxels.
    """
    # Strategy: sorted linear indices + searchsorted find each voxel's forward neighbours in
    # O(N log N) without a dense label volume.
    coords = np.argwhere(skeleton)
    shape = np.array(skeleton.shape)
    lin = np.ravel_multi_index(coords.T, skeleton.shape)  # argwhere is in C order: lin is sorted
    G = nx.Graph()
    G.add_nodes_from(range(len(coords)))
    for off in _OFFSETS:
        nb = coords + off
        ok = np.all((nb >= 0) & (nb < shape), axis=1)
        idx = np.flatnonzero(ok)
        nlin = np.ravel_multi_index(nb[idx].T, skeleton.shape)
        pos = np.searchsorted(lin, nlin)
        pos = np.minimum(pos, len(lin) - 1)
        hit = lin[pos] == nlin
        G.add_edges_from(zip(idx[hit].tolist(), pos[hit].tolist()))
    return G, coords


def _branches(G: nx.Graph):
    """Split a skeleton graph into branches between end points and junction clusters.

    Returns
    -------
    branches : list of (a, b, path)
        ``a``/``b``: terminal ids (("e", voxel) for an end point, ("j", cluster) for a junction
        cluster), ``path``: list of voxel node ids from a to b (terminal voxels included).
    jcentre : dict cluster -> list of voxel ids
    """
    deg = dict(G.degree())
    junction = [n for n, d in deg.items() if d >= 3]
    cluster_of = {}
    jvox = {}
    for c, comp in enumerate(nx.connected_components(G.subgraph(junction))):
        for n in comp:
            cluster_of[n] = c
        jvox[c] = list(comp)

    def term(n):
        if n in cluster_of:
            return ("j", cluster_of[n])
        if deg[n] <= 1:
            return ("e", n)
        return None

    branches = []
    seen_edges = set()
    for n in G.nodes:
        t = term(n)
        if t is None:
            continue
        if deg[n] == 0:
            branches.append((t, t, [n]))
            continue
        for m in G.neighbors(n):
            if (n, m) in seen_edges:
                continue
            if m in cluster_of and t[0] == "j" and cluster_of[m] == t[1]:
                continue  # inside one junction cluster
            path = [n, m]
            seen_edges.add((n, m))
            seen_edges.add((m, n))
            prev, cur = n, m
            while term(cur) is None:
                nxt = [q for q in G.neighbors(cur) if q != prev]
                if not nxt:
                    break
                prev, cur = cur, nxt[0]
                path.append(cur)
                seen_edges.add((prev, cur))
                seen_edges.add((cur, prev))
            branches.append((t, term(cur) or ("e", cur), path))
    # pure cycles (every voxel of degree 2): one branch each
    covered = {v for _, _, p in branches for v in p}
    for comp in nx.connected_components(G):
        if comp & covered:
            continue
        start = next(iter(comp))
        path = [start]
        prev, cur = None, start
        while True:
            nxt = [q for q in G.neighbors(cur) if q != prev and q not in path[-2:]]
            if not nxt or nxt[0] == start:
                break
            prev, cur = cur, nxt[0]
            path.append(cur)
        branches.append((("e", start), ("e", path[-1]), path))
    return branches, jvox


def _direction_out(pts: np.ndarray, r: float) -> np.ndarray:
    """Unit direction of a branch leaving its first point (a junction).

    The skeleton bends toward the junction over about one radius (thinning of the merged
    cross-section), so the direction is the principal axis of the branch points between 1.5 r and
    6 r from the junction, oriented away from it.
    """
    d = np.linalg.norm(pts - pts[0], axis=1)
    sel = (d >= 1.5 * r) & (d <= 6.0 * r)
    if sel.sum() < 3:
        sel = d > 0
    if not sel.any():
        return np.zeros(3)
    q = pts[sel]
    away = q.mean(axis=0) - pts[0]
    if sel.sum() >= 3:
        _, _, vt = np.linalg.svd(q - q.mean(axis=0), full_matrices=False)
        u = vt[0]
        if np.dot(u, away) < 0:
            u = -u
        return u
    n = np.linalg.norm(away)
    return away / n if n > 0 else away


def trace_skeleton(mask: np.ndarray, voxel_size_m, *, skeleton: np.ndarray | None = None,
                   radius_vox: np.ndarray | None = None, expected_radius_m: float | None = None,
                   prune_length_vox: float | None = None, max_turn_deg: float = 45.0,
                   min_length_vox: float | None = None, smooth_sigma_vox: float | None = None,
                   spacing_vox: float = 1.0) -> Polylines:
    """Trace fibers along the skeleton graph.

    Parameters
    ----------
    mask : (Z, Y, X) bool ndarray
    voxel_size_m : float or (dz, dy, dx), m
    skeleton, radius_vox : (Z, Y, X) ndarrays, optional
        From :func:`fiberpipe.imaging.skeleton.skeletonize` (computed if not given).
    expected_radius_m : float, optional
        Nominal radius, m (default: median of ``radius_vox`` on the skeleton).
    prune_length_vox : float
        End branches (spurs) shorter than this are removed (default 2 r).
    max_turn_deg : float
        Two branches at a junction are joined into one fiber only if the fiber would turn by
        less than this angle there.
    min_length_vox : float
        Shorter fibers are dropped (default 2 r).
    smooth_sigma_vox : float
        Gaussian smoothing along the fiber, in points (default max(1, r/2)).
    spacing_vox : float
        Resampling step, voxels.

    Returns
    -------
    Polylines (x y z, m) with per-fiber radius (median of ``radius_vox`` along the path, m).
    """
    # Strategy: voxel graph (26-connectivity, networkx) -> branches between end points and
    # junction clusters -> spurs (end branches shorter than ~2 r, the thinning's response to
    # surface bumps) pruned, repeatedly -> at each junction, branches paired greedily by
    # direction continuity (outgoing directions most nearly opposite, turn below max_turn_deg) ->
    # paired branches chained into fibers -> smoothed and resampled.
    from .skeleton import skeletonize

    t0 = time.perf_counter()
    v = voxel_size_zyx(voxel_size_m)
    if skeleton is None or radius_vox is None:
        skeleton, radius_vox = skeletonize(mask, voxel_size_m=v)
    if not skeleton.any():
        raise InputError("trace: the skeleton is empty")
    G, coords = skeleton_graph(skeleton)
    rad_at = radius_vox[tuple(coords.T)].astype(np.float64)
    r = float(expected_radius_m / v.min()) if expected_radius_m else float(np.median(rad_at))
    r = max(r, 1.0)
    prune = 2.0 * r if prune_length_vox is None else float(prune_length_vox)
    min_len = 2.0 * r if min_length_vox is None else float(min_length_vox)
    sigma = max(1.0, 0.5 * r) if smooth_sigma_vox is None else float(smooth_sigma_vox)
    scale = v / v.min()
    pts_all = coords * scale  # isotropic units (smallest voxel size)

    branches, _ = _branches(G)

    def blen(p):
        q = pts_all[p]
        return float(np.linalg.norm(np.diff(q, axis=0), axis=1).sum()) if len(q) > 1 else 0.0

    B = _prune_spurs([list(b) for b in branches], blen, prune)
    link = _pair_at_junctions(B, pts_all, r, max_turn_deg)
    fibers = _chain_branches(B, link)
    out_f, out_r = [], []
    for path in fibers:
        if len(path) < 2 or blen(path) < min_len:
            continue
        q = pts_all[path]
        q = smooth_polyline(q, sigma)
        zyx = q / scale
        out_f.append(resample_polyline(voxel_to_xyz_m(zyx, v), spacing_vox * v.min()))
        out_r.append(float(np.median(rad_at[path])) * v.min())
    res = Polylines.from_list(out_f, np.asarray(out_r) if out_r else 0.0)
    res.meta.update(method="skeleton", radius_vox_estimate=r, n_skeleton_voxels=len(coords),
                    n_branches=len(branches), n_branches_pruned=len(B), n_fibers=len(out_f),
                    time_total_s=time.perf_counter() - t0,
                    params=dict(prune_length_vox=prune, max_turn_deg=max_turn_deg,
                                min_length_vox=min_len, smooth_sigma_vox=sigma, spacing_vox=spacing_vox))
    return res


def _prune_spurs(B: list, blen, prune: float) -> list:
    """Branches ``[a, b, path]`` less the spurs (end branches shorter than ``prune`` at a junction
    of three or more), repeatedly: removing one can turn a junction into a pass-through."""
    for _ in range(4):
        count = {}
        for a, b, p in B:
            for t in (a, b):
                if t[0] == "j":
                    count[t] = count.get(t, 0) + 1
        keep = []
        removed = False
        for a, b, p in B:
            spur = (a[0] == "e") != (b[0] == "e")
            jn = b if a[0] == "e" else a
            if spur and blen(p) < prune and count.get(jn, 0) >= 3:
                removed = True
                count[jn] -= 1
                continue
            keep.append([a, b, p])
        B = keep
        if not removed:
            break
    return B


def _pair_at_junctions(B: list, pts_all: np.ndarray, r: float, max_turn_deg: float) -> dict:
    """At each junction, branch ends paired greedily by direction continuity (outgoing directions
    most nearly opposite, the fiber turning by less than ``max_turn_deg``): ``link[(i, side)]`` is
    the branch end that continues branch i's end ``side`` (0: first point, 1: last)."""
    ends_at = {}
    for i, (a, b, p) in enumerate(B):
        if a[0] == "j":
            ends_at.setdefault(a, []).append((i, 0))
        if b[0] == "j":
            ends_at.setdefault(b, []).append((i, 1))
    link = {}
    cos_max = -np.cos(np.deg2rad(max_turn_deg))
    for lst in ends_at.values():
        dirs = [_direction_out(pts_all[B[i][2] if side == 0 else B[i][2][::-1]], r) for i, side in lst]
        cand = sorted((float(np.dot(dirs[u], dirs[w])), u, w) for u in range(len(lst)) for w in range(u + 1, len(lst))
                      if lst[u][0] != lst[w][0] and float(np.dot(dirs[u], dirs[w])) <= cos_max)  # no loop branch
        used = set()
        for c, u, w in cand:
            if u in used or w in used:
                continue
            used.update((u, w))
            link[lst[u]] = lst[w]
            link[lst[w]] = lst[u]
    return link


def _chain_branches(B: list, link: dict) -> list:
    """The fibers as voxel paths: linked branches chained, each chain from a free end, then the
    closed chains."""
    visited = set()
    fibers = []

    def walk(i, side_in):
        """Follow from branch i entered at end side_in; returns the voxel path."""
        path = []
        while i not in visited:
            visited.add(i)
            p = B[i][2] if side_in == 0 else B[i][2][::-1]
            path.extend(p if not path else p[1:])
            out_end = (i, 1 - side_in)
            if out_end not in link:
                break
            i, side_in = link[out_end]
        return path

    order = sorted(range(len(B)), key=lambda i: ((0, 0) in link or (i, 0) in link) + ((i, 1) in link))
    for i in order:
        if i in visited:
            continue
        # start from a free end if this chain has one
        if (i, 0) not in link:
            fibers.append(walk(i, 0))
        elif (i, 1) not in link:
            fibers.append(walk(i, 1))
    for i in range(len(B)):  # closed chains
        if i not in visited:
            fibers.append(walk(i, 0))
    return fibers
