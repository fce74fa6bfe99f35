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


@pytest.mark.parametrize("gauss_points", [2, 4])
def test_the_field_is_the_runs_contact_pass(gauss_points):
    """Two parallel fibers pressed 1 µm that overlap only over the last 50 µm of their ends, where
    the line part's Gauss points sample the overlap coarsely: the field is the force of the run's
    contact pass with the config's Gauss points (and differs from the other count's)."""
    from fiberpipe.solver import Material, build_model
    from fiberpipe.solver.laws import law_from_config
    from fiberpipe.verification.contact_cases import pair_force

    R, L = 0.25e-3, 3e-3
    s = np.linspace(0.0, L, 11)
    a = np.c_[s, 0 * s, 0 * s]
    b = np.c_[s + L - 0.05e-3, 0 * s, 0 * s + 2 * R - 1e-6]
    mesh = mesh_polylines(Polylines.from_list([a, b], R), 0.3e-3)
    contact = {"law": "hertz_oriented", "gauss_points": gauss_points}
    cfg = validate_config({"input": {"fibers": "x"}, "scene": {"effects": ["contact"], "contact": contact}})
    out = frame_contact_forces(mesh, mesh.nodes_m[None], cfg.scene, cfg.material)
    fib = mesh.node_fiber()
    model = build_model(mesh.nodes_m, [0, int(np.sum(fib == 0)), mesh.nodes_m.shape[0]], R,
                        Material(15e9, 1380.0, 0.3))
    law = law_from_config(cfg.scene.contact, cfg.material)
    ref = pair_force(model, mesh.nodes_m, law, 0, 1, n_gauss=gauss_points)
    other = pair_force(model, mesh.nodes_m, law, 0, 1, n_gauss=6 - gauss_points)
    got = out["contact_force"][0][fib == 1].sum(0)
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-15)
    assert np.linalg.norm(ref - other) > 1e-3 * np.linalg.norm(ref)  # the two differ here
