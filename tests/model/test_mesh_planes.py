"""The mesh stage's strain-free adjustment also clears the scene's plates and walls."""

from __future__ import annotations

import numpy as np
import pytest

from fiberpipe.errors import InputError
from fiberpipe.model.mesh import Mesh, resolve_overlaps

R = 0.25e-3


def _mesh(lines):
    nodes = np.vstack(lines)
    off = np.cumsum([0] + [len(x) for x in lines])
    return Mesh(nodes, off, np.full(len(lines), R))


def test_nodes_inside_a_plate_are_moved_out_and_reported():
    z = np.linspace(0, 3e-3, 11)
    top = np.column_stack([np.zeros_like(z), 1e-3 - R + 0.3e-6 * np.sin(z / 3e-3 * np.pi), z])
    m = _mesh([top])
    out = resolve_overlaps(m, planes=[(1, 1e-3, -1.0), (1, 0.0, 1.0), (0, -1e-3, 1.0), (0, 1e-3, -1.0)])
    assert out["plane_overlap_before_m"] == pytest.approx(0.3e-6, rel=1e-3)
    assert np.all(m.nodes_m[:, 1] + R <= 1e-3 + 1e-15)
    # only the penetrating nodes moved, and only along the plate normal, by the penetration (+ tolerance)
    assert np.allclose(m.nodes_m[:, [0, 2]], top[:, [0, 2]])
    assert np.max(top[:, 1] - m.nodes_m[:, 1]) == pytest.approx(0.3e-6 + 1e-7, rel=1e-3)


def test_plane_and_fiber_overlaps_are_cleared_together():
    """A fiber pressed between a wall and another fiber: both constraints hold afterwards."""
    z = np.linspace(0, 3e-3, 11)
    a = np.column_stack([np.full_like(z, -1e-3 + R - 0.5e-6), np.zeros_like(z), z])   # in the wall
    b = np.column_stack([np.full_like(z, -1e-3 + 3 * R - 1.5e-6), np.zeros_like(z), z])  # overlaps a
    m = _mesh([a, b])
    resolve_overlaps(m, planes=[(0, -1e-3, 1.0)])
    x = m.nodes_m
    assert np.all(x[:, 0] - R >= -1e-3 - 1e-15)
    gap = x[11:, 0] - x[:11, 0]
    assert np.all(gap >= 2 * R - 1e-7 - 1e-12)


def test_a_plate_far_inside_the_fibers_is_refused():
    z = np.linspace(0, 3e-3, 11)
    m = _mesh([np.column_stack([np.zeros_like(z), np.zeros_like(z), z])])
    with pytest.raises(InputError, match="plates/walls"):
        resolve_overlaps(m, planes=[(1, 0.1e-3, 1.0)], max_shift_m=50e-6)


def _cfg(tmp_path, upper_mm):
    from fiberpipe.config import load_config

    p = tmp_path / "c.yaml"
    p.write_text(f"""name: t
input: {{fibers: f.h5}}
fiber: {{radius: "0.25 mm"}}
scene:
  effects: [plates, walls]
  plates: {{axis: y, lower: moving, upper: fixed, lower_position: "0 mm", upper_position: "{upper_mm} mm"}}
  walls: {{x: ["-1 mm", "1 mm"]}}
  loading: {{displacement: "0.1 mm", velocity: "1000 mm/min"}}
""")
    return load_config(p)


@pytest.mark.parametrize("upper_mm, moved", [(1.0 - 0.3e-3, True), (1.0 - 0.1, False)])
def test_simulate_stage_clears_only_shallow_plane_overlaps(tmp_path, upper_mm, moved):
    """0.3 µm inside the upper plate: moved out; 0.1 mm inside: left for the scene check to report."""
    from fiberpipe.stages.simulate import clear_scene_planes

    z = np.linspace(0, 3e-3, 11)
    m = _mesh([np.column_stack([np.zeros_like(z), np.full_like(z, 1e-3 - R), z])])
    x0 = m.nodes_m.copy()
    depth = clear_scene_planes(m, _cfg(tmp_path, upper_mm))
    assert depth == pytest.approx(1e-3 - upper_mm * 1e-3, rel=1e-6)
    if moved:
        assert np.all(m.nodes_m[:, 1] + R <= upper_mm * 1e-3 + 1e-15)
    else:
        assert np.array_equal(m.nodes_m, x0)
