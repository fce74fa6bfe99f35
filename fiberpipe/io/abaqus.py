"""Abaqus input file for the beam model (B31 elements, circular sections, elastic material).

meshio's Abaqus writer maps line cells to B31H and writes no section or material, so the file is
written here: one node set and one element set per fiber, a ``*BEAM SECTION, SECTION=CIRC`` per
fiber (its own radius), ``*MATERIAL`` with ``*ELASTIC`` and ``*DENSITY`` (required by
Abaqus/Explicit). The n1 direction of each section is chosen perpendicular to the fiber's mean
direction. The file reads back with ``meshio.read(path)`` (nodes and line cells).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fiberpipe.artifacts import write_text_atomic


def _n1_direction(tangent: np.ndarray) -> np.ndarray:
    t = tangent / (np.linalg.norm(tangent) or 1.0)
    helper = np.array([0.0, 0.0, 1.0]) if abs(t[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    n1 = np.cross(helper, t)
    return n1 / np.linalg.norm(n1)


def write_abaqus_inp(
    path: str | Path,
    mesh,
    *,
    youngs_modulus_pa: float,
    poisson_ratio: float,
    density_kg_m3: float,
    heading: str = "fiberpipe beam model",
) -> Path:
    """Write ``mesh`` as an Abaqus input file in SI units (m, N, Pa, kg/m³).

    Parameters
    ----------
    mesh : fiberpipe.model.mesh.Mesh
    youngs_modulus_pa, poisson_ratio, density_kg_m3 : float
        Linear elastic material shared by all fibers.
    """
    out = ["*HEADING", f"{heading} (SI units: m, N, Pa, kg/m^3)", "*NODE"]
    for i, (x, y, z) in enumerate(mesh.nodes_m, start=1):
        out.append(f"{i}, {x:.9e}, {y:.9e}, {z:.9e}")
    elements = mesh.elements() + 1
    eoff = mesh.elem_offsets
    for f in range(mesh.n_fibers):
        out.append(f"*ELEMENT, TYPE=B31, ELSET=FIBER{f}")
        for e in range(eoff[f], eoff[f + 1]):
            out.append(f"{e + 1}, {elements[e, 0]}, {elements[e, 1]}")
    for f in range(mesh.n_fibers):
        a, b = mesh.node_offsets[f], mesh.node_offsets[f + 1]
        out.append(f"*NSET, NSET=FIBER{f}_NODES, GENERATE")
        out.append(f"{a + 1}, {b}, 1")
    out.append("*ELSET, ELSET=FIBERS")
    names = [f"FIBER{f}" for f in range(mesh.n_fibers)]
    for k in range(0, len(names), 8):
        out.append(", ".join(names[k : k + 8]))
    for f in range(mesh.n_fibers):
        nodes = mesh.fiber_nodes(f)
        n1 = _n1_direction(nodes[-1] - nodes[0])
        out.append(f"*BEAM SECTION, ELSET=FIBER{f}, MATERIAL=FIBER, SECTION=CIRC")
        out.append(f"{mesh.radius_m[f]:.9e}")
        out.append(f"{n1[0]:.6f}, {n1[1]:.6f}, {n1[2]:.6f}")
    out += [
        "*MATERIAL, NAME=FIBER",
        "*ELASTIC",
        f"{youngs_modulus_pa:.9e}, {poisson_ratio:.6f}",
        "*DENSITY",
        f"{density_kg_m3:.9e}",
        "",
    ]
    write_text_atomic(path, "\n".join(out))
    return Path(path)
