"""Traced fibers as an Avizo / Amira SpatialGraph (``.am``, AmiraMesh ASCII).

A SpatialGraph is vertices, edges between two vertices, and per edge a polyline of points (the
edge's end vertices repeated as its first and last point), with per-point attributes. Each fiber
is one edge between its two end vertices; ``Thickness`` is the fiber radius at every point (the
point attribute Avizo's skeletonization writes and its SpatialGraph views draw tubes from).
Coordinates in micrometres (``Parameters { Units { Coordinates "µm" } }``), x y z.

Layout (AmiraMesh 3D ASCII 2.0): ``define VERTEX n``, ``define EDGE m``, ``define POINT p``; the
data declarations ``VERTEX { float[3] VertexCoordinates } @1``, ``EDGE { int[2] EdgeConnectivity }
@2``, ``EDGE { int NumEdgePoints } @3``, ``POINT { float[3] EdgePointCoordinates } @4``,
``POINT { float Thickness } @5``; then each ``@k`` followed by its values, one item a line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fiberpipe.artifacts import write_text_atomic


def write_avizo_spatialgraph(path: str | Path, fibers) -> Path:
    """Write ``fibers`` (:class:`~fiberpipe.polylines.Polylines`, m) as an Avizo SpatialGraph,
    atomically: fiber i is edge i from vertex 2i (its first point) to vertex 2i + 1 (its last)."""
    um = 1e6
    n = fibers.n_fibers
    lines = [fibers.fiber(i) * um for i in range(n)]
    radius = np.broadcast_to(np.asarray(fibers.radius_m, float), (n,)) * um
    vertices = np.array([p for line in lines for p in (line[0], line[-1])]).reshape(-1, 3)
    counts = [len(line) for line in lines]
    out = ["# AmiraMesh 3D ASCII 2.0", "", f"define VERTEX {2 * n}", f"define EDGE {n}", f"define POINT {sum(counts)}", "",
           "Parameters {", '    ContentType "HxSpatialGraph",', '    Units {', '        Coordinates "µm"', "    }", "}", "",
           "VERTEX { float[3] VertexCoordinates } @1", "EDGE { int[2] EdgeConnectivity } @2",
           "EDGE { int NumEdgePoints } @3", "POINT { float[3] EdgePointCoordinates } @4", "POINT { float Thickness } @5",
           "", "# Data section follows", "@1"]
    out += [f"{x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices]
    out += ["", "@2"] + [f"{2 * i} {2 * i + 1}" for i in range(n)]
    out += ["", "@3"] + [str(c) for c in counts]
    out += ["", "@4"] + [f"{x:.6f} {y:.6f} {z:.6f}" for line in lines for x, y, z in line]
    out += ["", "@5"] + [f"{radius[i]:.6f}" for i in range(n) for _ in range(counts[i])]
    write_text_atomic(path, "\n".join(out) + "\n")
    return Path(path)
