import numpy as np
import pytest

from fiberpipe.errors import InputError
from fiberpipe.model.mesh import clean_polyline, mesh_polylines
from fiberpipe.polylines import Polylines


def _arc(n=40, radius=20e-3, length=15e-3):
    theta = np.linspace(0, length / radius, n)
    return np.c_[radius * np.sin(theta), np.zeros(n), radius * (1 - np.cos(theta))]


def test_equal_elements_close_to_target_on_a_curved_fiber():
    mesh = mesh_polylines(Polylines.from_list([_arc(), _arc() + [0, 1e-3, 0]], 0.25e-3), 0.3e-3)
    lengths = mesh.element_lengths_m()
    assert mesh.n_fibers == 2 and mesh.n_elements == 100  # 15 mm / 0.3 mm per fiber
    assert np.allclose(lengths, lengths.mean(), rtol=2e-3)
    assert lengths.mean() == pytest.approx(0.3e-3, rel=2e-3)
    # nodes stay on the arc (chord sag of 0.375 mm segments on a 20 mm radius is < 1 um)
    r = np.hypot(mesh.nodes_m[:, 0], mesh.nodes_m[:, 2] - 20e-3)
    assert np.max(np.abs(r - 20e-3)) < 1e-6


def test_connectivity_never_crosses_fibers():
    mesh = mesh_polylines(Polylines.from_list([_arc(), _arc() + [0, 1e-3, 0]], 0.25e-3), 0.3e-3)
    e = mesh.elements()
    fib = mesh.node_fiber()
    assert np.all(fib[e[:, 0]] == fib[e[:, 1]])
    assert np.all(e[:, 1] == e[:, 0] + 1)
    assert list(mesh.elem_offsets) == [0, 50, 100]


def test_duplicate_points_are_cleaned_and_short_fibers_rejected():
    pts = np.repeat(_arc(10), 2, axis=0)  # every point twice: zero-length segments
    assert len(clean_polyline(pts, min_segment_m=1e-9)) == 10
    mesh = mesh_polylines(Polylines.from_list([pts], 0.25e-3), 0.3e-3)
    assert np.all(mesh.element_lengths_m() > 0.29e-3)
    with pytest.raises(InputError, match="shorter than the minimum"):
        mesh_polylines(Polylines.from_list([[[0, 0, 0], [0, 0, 0.4e-3]]], 0.25e-3), 0.3e-3)
    with pytest.raises(InputError, match="positive"):
        mesh_polylines(Polylines.from_list([_arc()], 0.25e-3), -1.0)


def test_overlapping_fibers_are_pushed_apart_without_stretching():
    from fiberpipe.model.mesh import resolve_overlaps

    z = np.linspace(0, 6e-3, 21)
    a = np.c_[np.zeros_like(z), np.zeros_like(z), z]
    b = np.c_[np.full_like(z, 0.46e-3), np.zeros_like(z), z]  # 40 um overlap for r = 0.25 mm
    mesh = mesh_polylines(Polylines.from_list([a, b], 0.25e-3), 0.3e-3)
    lengths = mesh.element_lengths_m()
    info = resolve_overlaps(mesh)
    assert info["max_overlap_before_m"] == pytest.approx(40e-6, rel=1e-6)
    gap = mesh.fiber_nodes(1)[:, 0] - mesh.fiber_nodes(0)[:, 0]
    assert np.all(gap >= 0.5e-3 - 1e-9) and np.all(gap < 0.5e-3 + 1e-6)
    np.testing.assert_allclose(mesh.element_lengths_m(), lengths, rtol=1e-9)  # moved normal to the fibers
    with pytest.raises(InputError, match="overlap"):
        resolve_overlaps(mesh_polylines(Polylines.from_list([a, a + [0.1e-3, 0, 0]], 0.25e-3), 0.3e-3), max_shift_m=50e-6)


def test_zero_length_fiber_says_remove_it_not_refine():
    """Refining mesh.element_length cannot help a fiber whose points all coincide."""
    same = [[1e-3, 2e-3, 3e-3]] * 4
    with pytest.raises(InputError) as err:
        mesh_polylines(Polylines.from_list([_arc(), same], 0.25e-3), 0.3e-3)
    assert str(err.value) == "fiber 1 has zero length (all its points coincide): remove it"
    # a short but real fiber keeps the advice to refine
    with pytest.raises(InputError, match="remove it or refine mesh.element_length"):
        mesh_polylines(Polylines.from_list([[[0, 0, 0], [0, 0, 0.4e-3]]], 0.25e-3), 0.3e-3)


def test_zero_length_inline_polyline_is_a_config_error(write_yaml):
    from fiberpipe.config import load_config
    from fiberpipe.errors import ConfigError

    p = write_yaml('name: z\ninput:\n  polylines:\n    - [[0, 0, 0], ["3 mm", 0, 0]]\n'
                   '    - [["1 mm", 0, 0], ["1 mm", 0, 0]]\nfiber: {radius: "0.25 mm"}\n')
    with pytest.raises(ConfigError, match=r"input.polylines\[1\] has zero length \(all its points coincide\): remove it"):
        load_config(p)
