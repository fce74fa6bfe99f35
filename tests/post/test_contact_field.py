"""Contact forces evaluated on frames: equal and opposite, zero when apart, Johnson when pressed."""

import numpy as np
import pytest

from fiberpipe.config import validate_config
from fiberpipe.model.mesh import mesh_polylines
from fiberpipe.polylines import Polylines
from fiberpipe.post.contact_field import frame_contact_forces
from fiberpipe.solver.laws import hertz_parallel_line


def test_pressed_parallel_fibers_carry_the_johnson_line_load():
    R, delta = 0.25e-3, 1e-6
    z = np.linspace(0, 3e-3, 11)
    a = np.c_[0 * z, 0 * z, z]
    mesh = mesh_polylines(Polylines.from_list([a, a + [2 * R - delta, 0, 0]], R), 0.3e-3)
    apart = mesh.nodes_m + np.where(mesh.node_fiber()[:, None] == 1, [[0.1e-3, 0, 0]], 0.0)
    frames = np.stack([mesh.nodes_m, apart])
    cfg = validate_config({"input": {"fibers": "x"}, "scene": {"effects": ["contact"], "contact": {"law": "hertz_parallel"}}})
    out = frame_contact_forces(mesh, frames, cfg.scene, cfg.material)
    f = out["contact_force"][0]
    fib = mesh.node_fiber()
    np.testing.assert_allclose(f[fib == 0].sum(0), -f[fib == 1].sum(0), atol=1e-12)  # equal and opposite
    E_star = 15e9 / (2 * (1 - 0.3**2))
    p = hertz_parallel_line(delta, E_star, R, R)
    p = p[0] if isinstance(p, tuple) else p
    assert -f[fib == 0, 0].sum() == pytest.approx(p * 3e-3, rel=0.02)
    assert out["contacts"][0] > 0 and out["max_penetration"][0] == pytest.approx(delta, rel=1e-6)
    assert out["contacts"][1] == 0 and np.all(out["contact_force"][1] == 0)
