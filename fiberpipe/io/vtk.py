"""VTK output for ParaView: beam meshes as VTU line cells, time series as a ``.pvd`` collection.

meshio writes one VTU per frame; it has no PVD writer, and its XDMF time series keeps the
points fixed (so it cannot show moving fibers), hence the small PVD writer here. Point data
``radius`` lets ParaView's Tube filter (Vary Radius: By Absolute Scalar) draw the fibers at their
true thickness; cell data ``fiber_id`` groups the segments by fiber.
"""

from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import quoteattr

import meshio
import numpy as np

from fiberpipe.artifacts import atomic_path, write_text_atomic


def write_vtu_lines(
    path: str | Path,
    points_m: np.ndarray,
    elements: np.ndarray,
    *,
    point_data: dict[str, np.ndarray] | None = None,
    cell_data: dict[str, np.ndarray] | None = None,
) -> Path:
    """Write 2-node line cells to a VTU file (binary, compressed), atomically.

    Parameters
    ----------
    points_m : (N, 3) float64 ndarray, m
    elements : (E, 2) int ndarray
    point_data : dict of (N, ...) arrays
    cell_data : dict of (E, ...) arrays
    """
    mesh = meshio.Mesh(
        np.asarray(points_m, dtype=np.float64),
        [("line", np.asarray(elements, dtype=np.int64))],
        point_data={k: np.asarray(v) for k, v in (point_data or {}).items()},
        cell_data={k: [np.asarray(v)] for k, v in (cell_data or {}).items()},
    )
    with atomic_path(path, suffix=".vtu") as tmp:
        meshio.write(tmp, mesh, file_format="vtu")
    return Path(path)


def write_pvd(path: str | Path, entries: list[tuple[float, str]]) -> Path:
    """Write a ParaView collection of (time in s, relative VTU file name) entries."""
    lines = ['<?xml version="1.0"?>', '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">', "  <Collection>"]
    for t, name in entries:
        lines.append(f'    <DataSet timestep="{t:.9g}" group="" part="0" file={quoteattr(str(name))}/>')
    lines += ["  </Collection>", "</VTKFile>", ""]
    write_text_atomic(path, "\n".join(lines))
    return Path(path)


def mesh_vtu(path: str | Path, mesh, *, points_m: np.ndarray | None = None, point_data=None, cell_data=None) -> Path:
    """Write a :class:`~fiberpipe.model.mesh.Mesh` (or a deformed frame of it) with radius and fiber_id."""
    pd = {"radius": np.repeat(mesh.radius_m, np.diff(mesh.node_offsets)), "fiber_id": mesh.node_fiber().astype(np.int32)}
    pd.update(point_data or {})
    cd = {"fiber_id": mesh.element_fiber().astype(np.int32)}
    cd.update(cell_data or {})
    return write_vtu_lines(path, mesh.nodes_m if points_m is None else points_m, mesh.elements(), point_data=pd, cell_data=cd)
