"""Fiber mid-lines as one flat block of points with CSR-style offsets.

This is the in-memory form of the ``fibers`` artifact (docs/outputs.md): fiber ``i`` is
``points_m[offsets[i]:offsets[i + 1]]``, ordered along the fiber. Coordinates are x y z in metres,
where z is the volume's first (slice) axis scaled by its voxel size, y the second and x the third.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


def resample_arclength(points: np.ndarray, spacing: float) -> np.ndarray:
    """Resample a polyline at a constant arc-length ``spacing``, both ends kept.

    Parameters
    ----------
    points : (n, d) float64 ndarray
    spacing : float, same unit as ``points``

    Returns
    -------
    (k, d) float64 ndarray, k = max(2, round(length / spacing) + 1) equally spaced points along the
    line (zero-length segments are ignored; a polyline of zero length gives its first point).
    """
    p = np.asarray(points, dtype=np.float64)
    if len(p) < 2:
        return p.copy()
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] <= 0:
        return p[:1].copy()
    n = max(2, int(round(s[-1] / spacing)) + 1)
    t = np.linspace(0.0, s[-1], n)
    keep = np.concatenate([[True], seg > 0])
    s, p = s[keep], p[keep]
    return np.stack([np.interp(t, s, p[:, k]) for k in range(p.shape[1])], axis=1)


@dataclass
class Polylines:
    """Fiber mid-lines.

    Attributes
    ----------
    points_m : (P, 3) float64 ndarray, m
        All points, x y z, fibers one after another.
    offsets : (F + 1,) int64 ndarray
        Fiber ``i`` is ``points_m[offsets[i]:offsets[i + 1]]``.
    radius_m : (F,) float64 ndarray, m
        One radius per fiber.
    """

    points_m: np.ndarray
    offsets: np.ndarray
    radius_m: np.ndarray
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        self.points_m = np.ascontiguousarray(self.points_m, dtype=np.float64).reshape(-1, 3)
        self.offsets = np.ascontiguousarray(self.offsets, dtype=np.int64)
        self.radius_m = np.ascontiguousarray(self.radius_m, dtype=np.float64).reshape(-1)
        if self.offsets.ndim != 1 or self.offsets.size < 1 or self.offsets[0] != 0:
            raise ValueError("offsets must be a 1-D array starting at 0")
        if self.offsets[-1] != len(self.points_m) or np.any(np.diff(self.offsets) < 0):
            raise ValueError("offsets must be non-decreasing and end at the number of points")
        if self.radius_m.size != self.n_fibers:
            raise ValueError(f"{self.radius_m.size} radii for {self.n_fibers} fibers")

    @classmethod
    def from_list(cls, fibers, radius_m) -> "Polylines":
        """Build from a list of (n_i, 3) arrays and a scalar or per-fiber radius (m)."""
        fibers = [np.asarray(f, dtype=np.float64).reshape(-1, 3) for f in fibers]
        offsets = np.zeros(len(fibers) + 1, dtype=np.int64)
        offsets[1:] = np.cumsum([len(f) for f in fibers])
        points = np.concatenate(fibers) if fibers else np.zeros((0, 3))
        radius = np.broadcast_to(np.asarray(radius_m, dtype=np.float64), (len(fibers),)).copy()
        return cls(points, offsets, radius)

    @property
    def n_fibers(self) -> int:
        return len(self.offsets) - 1

    def fiber(self, i: int) -> np.ndarray:
        """Points of fiber ``i``, (n_i, 3), m (a view)."""
        return self.points_m[self.offsets[i] : self.offsets[i + 1]]

    def __iter__(self):
        return (self.fiber(i) for i in range(self.n_fibers))

    def __len__(self) -> int:
        return self.n_fibers

    def lengths_m(self) -> np.ndarray:
        """Arc length of each fiber, (F,), m."""
        seg = np.linalg.norm(np.diff(self.points_m, axis=0), axis=1)
        out = np.zeros(self.n_fibers)
        for i in range(self.n_fibers):
            a, b = self.offsets[i], self.offsets[i + 1]
            if b - a > 1:
                out[i] = seg[a : b - 1].sum()
        return out
