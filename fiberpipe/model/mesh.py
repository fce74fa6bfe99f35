"""Mesh fiber mid-lines into 2-node beam elements.

All fibers share one flat node array; fiber ``i`` owns ``nodes_m[node_offsets[i]:node_offsets[i+1]]``
and its elements join consecutive nodes, so element connectivity is implicit in the offsets.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from fiberpipe.errors import InputError
from fiberpipe.polylines import Polylines, resample_arclength


@dataclass
class Mesh:
    """Beam mesh of a fiber bundle.

    Attributes
    ----------
    nodes_m : (N, 3) float64 ndarray, m
        Node coordinates, fibers one after another.
    node_offsets : (F + 1,) int64 ndarray
        Fiber ``i`` owns nodes ``node_offsets[i]:node_offsets[i + 1]``.
    radius_m : (F,) float64 ndarray, m
        Radius of each fiber's circular section.
    """

    nodes_m: np.ndarray
    node_offsets: np.ndarray
    radius_m: np.ndarray

    def __post_init__(self):
        self.nodes_m = np.ascontiguousarray(self.nodes_m, dtype=np.float64).reshape(-1, 3)
        self.node_offsets = np.ascontiguousarray(self.node_offsets, dtype=np.int64)
        self.radius_m = np.ascontiguousarray(self.radius_m, dtype=np.float64).reshape(-1)
        counts = np.diff(self.node_offsets)
        if self.node_offsets[0] != 0 or self.node_offsets[-1] != len(self.nodes_m):
            raise ValueError("node_offsets must start at 0 and end at the number of nodes")
        if np.any(counts < 2):
            raise ValueError("every fiber needs at least 2 nodes (1 element)")
        if len(self.radius_m) != self.n_fibers:
            raise ValueError("one radius per fiber is needed")

    @property
    def n_fibers(self) -> int:
        return len(self.node_offsets) - 1

    @property
    def n_nodes(self) -> int:
        return len(self.nodes_m)

    @property
    def n_elements(self) -> int:
        return self.n_nodes - self.n_fibers

    @property
    def elem_offsets(self) -> np.ndarray:
        """Fiber ``i`` owns elements ``elem_offsets[i]:elem_offsets[i + 1]``, (F + 1,) int64."""
        return self.node_offsets - np.arange(self.n_fibers + 1, dtype=np.int64)

    def elements(self) -> np.ndarray:
        """Element connectivity, (E, 2) int64 node indices."""
        first = np.ones(self.n_nodes, dtype=bool)
        first[self.node_offsets[1:] - 1] = False  # the last node of a fiber starts no element
        start = np.flatnonzero(first)
        return np.stack([start, start + 1], axis=1).astype(np.int64)

    def element_fiber(self) -> np.ndarray:
        """Fiber index of each element, (E,) int64."""
        return np.repeat(np.arange(self.n_fibers, dtype=np.int64), np.diff(self.elem_offsets))

    def element_radius_m(self) -> np.ndarray:
        """Radius of each element, (E,) float64, m."""
        return self.radius_m[self.element_fiber()]

    def node_fiber(self) -> np.ndarray:
        """Fiber index of each node, (N,) int64."""
        return np.repeat(np.arange(self.n_fibers, dtype=np.int64), np.diff(self.node_offsets))

    def fiber_nodes(self, i: int) -> np.ndarray:
        return self.nodes_m[self.node_offsets[i] : self.node_offsets[i + 1]]

    def element_lengths_m(self) -> np.ndarray:
        e = self.elements()
        return np.linalg.norm(self.nodes_m[e[:, 1]] - self.nodes_m[e[:, 0]], axis=1)

    def as_polylines(self) -> Polylines:
        return Polylines(self.nodes_m.copy(), self.node_offsets.copy(), self.radius_m.copy())


def clean_polyline(points_m: np.ndarray, *, min_segment_m: float) -> np.ndarray:
    """Drop duplicate points and segments shorter than ``min_segment_m``.

    Parameters
    ----------
    points_m : (n, 3) float64 ndarray, m
    min_segment_m : float, m

    Returns
    -------
    (k, 3) float64 ndarray, m, with k <= n; the end points are kept.
    """
    pts = np.asarray(points_m, dtype=np.float64)
    if len(pts) < 2:
        return pts
    keep = [0]
    for i in range(1, len(pts)):
        if np.linalg.norm(pts[i] - pts[keep[-1]]) >= min_segment_m:
            keep.append(i)
    if keep[-1] != len(pts) - 1:
        # The end point is kept; the point before it is dropped if it is too close.
        if len(keep) > 1 and np.linalg.norm(pts[-1] - pts[keep[-1]]) < min_segment_m:
            keep[-1] = len(pts) - 1
        else:
            keep.append(len(pts) - 1)
    return pts[keep]


def resample_polyline(points_m: np.ndarray, element_length_m: float, *, smooth_sigma_m: float = 0.0):
    """Resample a polyline into equal-length elements close to ``element_length_m``.

    # Strategy: optionally smooth the points along the arc length (Gaussian, sigma in metres),
    # then place n + 1 nodes at equal arc-length spacing, n = round(length / element_length),
    # by linear interpolation of the cumulative chord length. Equal elements keep the stable
    # time step uniform along the fiber.

    Parameters
    ----------
    points_m : (n, 3) float64 ndarray, m
    element_length_m : float, m
    smooth_sigma_m : float, m, optional

    Returns
    -------
    (k + 1, 3) float64 ndarray, m
    """
    pts = np.asarray(points_m, dtype=np.float64)
    if smooth_sigma_m > 0 and len(pts) > 4:
        mean_step = np.linalg.norm(np.diff(pts, axis=0), axis=1).sum() / (len(pts) - 1)
        sigma = smooth_sigma_m / mean_step
        if sigma > 0.3:
            inner = gaussian_filter1d(pts, sigma, axis=0, mode="nearest")
            inner[0], inner[-1] = pts[0], pts[-1]
            pts = inner
    return resample_arclength(pts, element_length_m)


def short_fibers(polylines: Polylines, min_fiber_length_m: float) -> np.ndarray:
    """Indices of the fibers shorter than ``min_fiber_length_m`` (m), the ones the mesh stage drops
    (``mesh.min_fiber_length``) instead of refusing the whole input, (k,) int64."""
    return np.flatnonzero(polylines.lengths_m() < min_fiber_length_m)


def mesh_polylines(
    polylines: Polylines,
    element_length_m: float = 0.3e-3,
    *,
    smooth_sigma_m: float = 0.0,
    min_fiber_length_m: float | None = None,
    radius_m: float | None = None,
    max_turn_rad: float = np.deg2rad(120.0),
) -> Mesh:
    """Mesh each polyline into 2-node beam elements of about ``element_length_m``.

    Parameters
    ----------
    polylines : Polylines
        Fiber mid-lines, m.
    element_length_m : float, m
        Target element length (the study's 0.3 mm by default).
    smooth_sigma_m : float, m
        Gaussian smoothing of the mid-line along its arc length before resampling.
    min_fiber_length_m : float, m, optional
        Fibers shorter than this are rejected (default: two elements).
    radius_m : float, m, optional
        Overrides the traced radius of every fiber (``fiber.radius`` in a config).

    Raises
    ------
    InputError
        For a non-positive element length, a degenerate fiber, or no fibers at all.
    """
    if not element_length_m > 0:
        raise InputError(f"mesh.element_length must be positive, got {element_length_m!r} m")
    if polylines.n_fibers == 0:
        raise InputError("no fibers to mesh")
    min_len = 2 * element_length_m if min_fiber_length_m is None else min_fiber_length_m
    nodes, offsets = [], [0]
    lengths = polylines.lengths_m()
    for i, pts in enumerate(polylines):
        if not np.all(np.isfinite(pts)):
            raise InputError(f"fiber {i} has non-finite coordinates")
        pts = clean_polyline(pts, min_segment_m=1e-3 * element_length_m)
        if not lengths[i] >= 1e-3 * element_length_m:  # below the cleaning tolerance: one point
            raise InputError(f"fiber {i} has zero length (all its points coincide): remove it")
        if len(pts) < 2 or lengths[i] < min_len:
            raise InputError(
                f"fiber {i} is {lengths[i] * 1e3:.3g} mm long, shorter than the minimum "
                f"{min_len * 1e3:.3g} mm (two elements); remove it or refine mesh.element_length"
            )
        res = resample_polyline(pts, element_length_m, smooth_sigma_m=smooth_sigma_m)
        seg = np.diff(res, axis=0)
        if len(seg) > 1:
            u = seg / np.linalg.norm(seg, axis=1, keepdims=True)
            turn = np.arccos(np.clip(np.sum(u[:-1] * u[1:], axis=1), -1.0, 1.0))
            k = int(np.argmax(turn))
            if turn[k] > max_turn_rad:
                raise InputError(
                    f"fiber {i} turns by {np.rad2deg(turn[k]):.0f} deg at node {k + 1} "
                    f"({np.rad2deg(max_turn_rad):.0f} deg at most): a fiber folded on itself is a tracing "
                    "artefact; smooth it (mesh.smooth_sigma) or remove it"
                )
        nodes.append(res)
        offsets.append(offsets[-1] + len(res))
    radius = polylines.radius_m if radius_m is None else np.full(polylines.n_fibers, radius_m)
    if np.any(~(radius > 0)):
        raise InputError("every fiber radius must be positive")
    return Mesh(np.concatenate(nodes), np.asarray(offsets, dtype=np.int64), radius)


def plane_penetration(x_m, radius_m, axis: int, position_m: float, sign: float) -> np.ndarray:
    """How far each node's fiber surface reaches past a rigid plane, m (> 0: inside it).

    ``sign = +1`` a lower plane (the fibers belong above ``position_m`` along ``axis``), ``−1`` an
    upper one. ``x_m`` (N, 3) node positions, ``radius_m`` (N,) their fibers' radii.
    """
    return radius_m - sign * (x_m[:, axis] - position_m)


def resolve_overlaps(mesh: Mesh, *, tolerance_m: float = 1e-7, max_iterations: int = 200, max_shift_m: float | None = None,
                     planes: tuple = ()) -> dict:
    """Push apart fibers that overlap in the rest geometry, in place (a strain-free adjustment).

    Traced mid-lines of touching fibers come out a fraction of a voxel too close, so the penalty
    contact would start with stored energy and throw the fibers apart at t = 0. Abaqus makes the
    same "strain-free adjustment" of initial overclosures; here it is done on the mesh, the rest
    shape of the beams, before anything is simulated.

    # Strategy: find node pairs of different fibers closer than r_i + r_j (k-d tree), move both
    # nodes apart by half the overlap along their separation projected normal to the fiber
    # tangent (so fibers are not stretched), repeat until the largest overlap is below
    # ``tolerance_m``. Nodes of quasi-parallel fibers sit at similar arc lengths, so node pairs
    # see the overlaps; a 10 % margin catches the segments between them. Nodes whose surface
    # crosses one of ``planes`` (the scene's plates and walls) are moved back inside along the
    # plane normal in the same iterations, so both kinds of overlap are cleared together: a fiber
    # that starts 0.3 µm inside a plate would otherwise be thrown off it by the plane penalty at the
    # first step (≈ 1e-5 J of kinetic energy for the paper-40 specimen, kept for ever at α = 0).

    Parameters
    ----------
    planes : sequence of ``(axis, position_m, sign)`` — rigid planes: ``sign = +1`` a lower plane
        (nodes must keep ``x[axis] − r ≥ position``), ``−1`` an upper one (``x[axis] + r ≤ position``).

    Returns
    -------
    dict with ``max_overlap_before_m``, ``max_overlap_after_m``, ``max_shift_m``, ``iterations``,
    ``plane_overlap_before_m`` (largest initial penetration of a fiber surface into a plane).
    """
    from scipy.spatial import cKDTree

    x = mesh.nodes_m
    x0 = x.copy()
    fib = mesh.node_fiber()
    r = mesh.radius_m[fib]
    reach = 2 * float(mesh.radius_m.max()) * 1.1
    # unit tangents per node (central differences inside a fiber)
    def tangents(x):
        t = np.zeros_like(x)
        for i in range(mesh.n_fibers):
            a, b = mesh.node_offsets[i], mesh.node_offsets[i + 1]
            t[a:b] = np.gradient(x[a:b], axis=0)
        return t / np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-300)

    def clear_planes(x):
        worst = 0.0
        for axis, pos, sign in planes:
            pen = plane_penetration(x, r, axis, pos, sign)
            worst = max(worst, float(pen.max()) if len(pen) else 0.0)
            over = pen > 0.0
            x[over, axis] += sign * (pen[over] + tolerance_m)
        return worst

    plane_before = max(clear_planes(x), 0.0)
    before = None
    it = 0
    worst = 0.0
    for it in range(1, max_iterations + 1):
        pairs = cKDTree(x).query_pairs(reach, output_type="ndarray")
        if len(pairs) == 0:
            worst = 0.0
            break
        pairs = pairs[fib[pairs[:, 0]] != fib[pairs[:, 1]]]
        d = x[pairs[:, 1]] - x[pairs[:, 0]]
        dist = np.linalg.norm(d, axis=1)
        overlap = r[pairs[:, 0]] + r[pairs[:, 1]] - dist
        bad = overlap > tolerance_m
        worst = float(overlap.max()) if len(overlap) else 0.0
        if before is None:
            before = max(worst, 0.0)
        if not bad.any():
            break
        t = tangents(x)
        shift = np.zeros_like(x)
        count = np.zeros(len(x))
        for k, (i, j) in enumerate(pairs[bad]):
            n = d[bad][k]
            n = n - 0.5 * (np.dot(n, t[i]) * t[i] + np.dot(n, t[j]) * t[j])
            nn = np.linalg.norm(n)
            if nn < 1e-300:
                continue
            s = 0.5 * (overlap[bad][k] + tolerance_m) * n / nn
            shift[i] -= s
            shift[j] += s
            count[i] += 1
            count[j] += 1
        # a node in several overlapping pairs gets the mean push, not the sum (no overshoot)
        x += shift / np.maximum(count, 1)[:, None]
        clear_planes(x)
    moved = float(np.max(np.linalg.norm(x - x0, axis=1))) if len(x) else 0.0
    if max_shift_m is not None and moved > max_shift_m:
        raise InputError(
            f"fibers overlap by up to {float(before or 0.0) * 1e6:.3g} um (each other) and "
            f"{plane_before * 1e6:.3g} um (plates/walls) in the input; resolving that moved nodes by "
            f"{moved * 1e6:.3g} um (more than mesh.max_overlap_shift); check the tracing, the radius and "
            "the plate/wall positions"
        )
    return {"max_overlap_before_m": float(before or 0.0), "max_overlap_after_m": max(worst, 0.0), "max_shift_m": moved,
            "iterations": it, "plane_overlap_before_m": plane_before}
