"""The literature's specimens (specimen.kind network_3d, planar_mat, wavy_bundle) through `fiberpipe specimen`."""

import math

import numpy as np
import pytest

from fiberpipe.artifacts import read_fibers
from fiberpipe.config import load_config
from fiberpipe.errors import ConfigError
from fiberpipe.model.specimen_networks import orientation_averages, toll_contacts_per_fiber
from fiberpipe.model.specimen_stats import segment_distances
from fiberpipe.model.virtual_specimen import build_specimen


def base(kind: str, **specimen) -> dict:
    return {
        "name": "net", "mesh": {"element_length": "0.5 mm"}, "fiber": {"radius": "0.25 mm"},
        "scene": {"effects": ["contact", "plates", "walls"], "plates": {"axis": "y", "lower": "moving", "upper": "fixed"},
                  "walls": {"x": ["-5 mm", "5 mm"]}, "loading": {"displacement": "1 mm"}},
        "specimen": {"kind": kind, "n_fibers": 40, "length": "8 mm", "width": "10 mm", "depth": "10 mm",
                     "volume_fraction": 0.05, "settle": {"enabled": False}, **specimen},
    }


def min_clearance(fibers) -> float:
    pts, off = fibers.points_m, fibers.offsets
    best = np.inf
    for i in range(fibers.n_fibers):
        a = pts[off[i]:off[i + 1]]
        for j in range(i + 1, fibers.n_fibers):
            b = pts[off[j]:off[j + 1]]
            d, _, _ = segment_distances(a[:-1, None], a[1:, None], b[None, :-1], b[None, 1:])
            best = min(best, float(d.min()))
    return best


@pytest.mark.parametrize("kind", ["network_3d", "planar_mat"])
def test_network_specimen_fills_its_cell_at_the_target_without_overlap(kind, tmp_path):
    info = build_specimen(base(kind), tmp_path, where="test", seed=3)
    fibers = read_fibers(tmp_path / "fibers.h5")
    r = 0.25e-3
    assert fibers.n_fibers == 40
    solid = 40 * math.pi * r**2 * 8e-3
    assert solid / (10e-3 * info["height_m"] * 10e-3) == pytest.approx(0.05, rel=1e-9)
    assert info["volume_fraction"] == pytest.approx(0.05, rel=1e-9)
    assert min_clearance(fibers) >= 2 * r + 0.9e-6
    p = fibers.points_m
    assert p[:, 0].min() >= -5e-3 + r and p[:, 0].max() <= 5e-3 - r
    assert p[:, 1].min() >= r and p[:, 1].max() <= info["height_m"] - r
    assert p[:, 2].min() >= r and p[:, 2].max() <= 10e-3 - r
    cfg = load_config(tmp_path / "config.yaml")
    assert cfg.scene.walls.z == pytest.approx([0.0, 10e-3]) and cfg.scene.walls.x == pytest.approx([-5e-3, 5e-3])
    assert cfg.scene.plates.upper_position == pytest.approx(info["height_m"])
    if kind == "planar_mat":
        assert np.ptp(p[:, 1].reshape(40, -1), axis=1).max() < 1e-12  # every fiber horizontal


def test_orientation_averages_of_isotropic_and_planar_directions():
    """Toll's averages: isotropic 3D ⟨|sin γ|⟩ = π/4, ⟨|cos γ|⟩ = 1/2; planar isotropic both 2/π."""
    rng = np.random.default_rng(0)
    iso = orientation_averages(rng.normal(size=(2000, 3)))
    assert iso["f_mean_abs_sin"] == pytest.approx(math.pi / 4, abs=0.01)
    assert iso["g_mean_abs_cos"] == pytest.approx(0.5, abs=0.01)
    angle = rng.uniform(0, math.pi, 2000)
    planar = orientation_averages(np.column_stack([np.cos(angle), 0 * angle, np.sin(angle)]))
    assert planar["f_mean_abs_sin"] == pytest.approx(2 / math.pi, abs=0.01)
    assert planar["g_mean_abs_cos"] == pytest.approx(2 / math.pi, abs=0.01)


def test_toll_contacts_tend_to_the_excluded_volume_result_for_slender_isotropic_fibers():
    """N_c = 4v[(2/π)(L/d) f + g + 1] with f = π/4, g = 1/2 → 2 v L/d (Dodson's 2 A c_vol) as L/d grows."""
    assert toll_contacts_per_fiber(0.1, 1e4, math.pi / 4, 0.5) / (2 * 0.1 * 1e4) == pytest.approx(1.0, rel=1e-3)


def test_wavy_bundle_has_the_span_and_rise_it_was_given(tmp_path):
    raw = base("wavy_bundle", n_fibers=12, width="3 mm", depth="9 mm", volume_fraction=0.3,
               wave={"span": "2 mm", "rise": "0.1 mm"})
    raw["scene"]["walls"] = {"x": ["-1.5 mm", "1.5 mm"]}
    info = build_specimen(raw, tmp_path, where="test", seed=1)
    fibers = read_fibers(tmp_path / "fibers.h5")
    assert info["wave"]["beta"] == pytest.approx(20.0)
    off = fibers.offsets
    for i in range(fibers.n_fibers):
        f = fibers.points_m[off[i]:off[i + 1]]
        assert np.ptp(f[:, 1]) == pytest.approx(0.1e-3, rel=0.02)  # the rise, sampled every quarter span or finer
        assert np.ptp(f[:, 0]) == 0.0 and np.ptp(f[:, 2]) == pytest.approx(8e-3)
    assert min_clearance(fibers) >= 2 * 0.25e-3 + 0.9e-6


@pytest.mark.parametrize("change, key", [
    ({"width": "0.9 mm"}, "specimen.width = 0.9 mm is narrower than two fiber diameters"),
    ({"depth": "0.9 mm"}, "specimen.depth = 0.9 mm is narrower than two fiber diameters"),
    ({"length": "1.5 mm"}, "mesh.element_length = 0.5 mm: the mesh cannot resolve it"),
    ({"volume_fraction": 0.8}, "specimen.volume_fraction = 0.8 makes the cell"),
    ({"n_fibers": 400, "volume_fraction": 0.3}, "random addition placed"),
])
def test_bad_network_specimens_are_refused_in_one_line_naming_the_key(change, key, tmp_path, monkeypatch):
    monkeypatch.setattr("fiberpipe.model.specimen_networks.MAX_DRAWS_PER_FIBER", 300)  # a full cell fails sooner
    with pytest.raises(ConfigError) as info:
        build_specimen(base("network_3d", **change), tmp_path / "x", where="net.yaml", seed=0)
    message = str(info.value)
    assert key in message and "\n" not in message and message.startswith("net.yaml:")


@pytest.mark.parametrize("kind, change, key", [
    ("planar_mat", {"width": "0.9 mm"}, "specimen.width = 0.9 mm is narrower than two fiber diameters"),
    ("wavy_bundle", {"width": "0.8 mm", "depth": "9 mm", "wave": {"span": "2 mm", "rise": "0.1 mm"}},
     "specimen.width = 0.8 mm is narrower than two fiber diameters"),
    ("wavy_bundle", {"length": "1.5 mm", "depth": "9 mm", "wave": {"span": "2 mm", "rise": "0.1 mm"}},
     "mesh.element_length = 0.5 mm: the mesh cannot resolve it"),
    ("planar_mat", {"length": "20 mm"}, "specimen.length = 20 mm does not fit the cell"),
    ("wavy_bundle", {"depth": "8 mm", "wave": {"span": "2 mm", "rise": "0.1 mm"}}, "specimen.depth = 8 mm cannot hold"),
])
def test_bad_mat_and_bundle_cells_are_refused_in_one_line_naming_the_key(kind, change, key, tmp_path):
    """A cell narrower than two fiber diameters, an aspect ratio the mesh cannot resolve (fewer than
    four elements per fiber), a fiber longer than its cell: one line naming the key."""
    with pytest.raises(ConfigError) as info:
        build_specimen(base(kind, **change), tmp_path / "x", where="net.yaml", seed=0)
    message = str(info.value)
    assert key in message and "\n" not in message and message.startswith("net.yaml:")


def test_wavy_span_the_mesh_cannot_resolve_is_refused(tmp_path):
    raw = base("wavy_bundle", width="3 mm", depth="9 mm", volume_fraction=0.3, wave={"span": "1 mm", "rise": "0.1 mm"})
    with pytest.raises(ConfigError, match="specimen.wave.span = 1 mm spans 2 elements"):
        build_specimen(raw, tmp_path, where="net.yaml", seed=0)
