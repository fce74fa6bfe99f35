"""fiberpipe.model.specimen_stats: the study's specimen statistics (neighbour angle Φ, Table-4
projected curvature) on hand-built geometry, and the cassette specimen built to match them."""

import numpy as np
import pytest

from fiberpipe.model.specimen import cassette_specimen
from fiberpipe.model.specimen_stats import neighbour_orientations, segment_distances, specimen_statistics
from fiberpipe.polylines import Polylines

R = 0.25e-3


def _line(direction, centre, length=15e-3, n=61):
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    s = np.linspace(-length / 2, length / 2, n)
    return np.asarray(centre, float) + s[:, None] * d


@pytest.mark.parametrize("phi_deg", [2.0, 6.0, 10.0, 30.0])
def test_two_straight_lines_at_a_known_angle(phi_deg):
    a = np.deg2rad(phi_deg)
    gap = 0.55e-3  # centre lines 1.1 diameters apart at their crossing: neighbours
    f1 = _line([0, 0, 1], [0, 0, 0])
    f2 = _line([np.sin(a), 0, np.cos(a)], [0, gap, 0])  # turned about y, offset along y
    nb = neighbour_orientations(Polylines.from_list([f1, f2], R))
    assert list(nb["i"]) == [0] and list(nb["j"]) == [1]
    assert nb["distance_m"][0] == pytest.approx(gap, rel=1e-9)
    assert nb["phi_deg"][0] == pytest.approx(phi_deg, abs=1e-6)
    # reversed direction of one fiber: fibers have no direction, Φ stays in [0, 90°]
    nb = neighbour_orientations(Polylines.from_list([f1, f2[::-1]], R))
    assert nb["phi_deg"][0] == pytest.approx(phi_deg, abs=1e-6)


def test_lines_farther_than_the_reach_are_not_neighbours():
    f1 = _line([0, 0, 1], [0, 0, 0])
    f2 = _line([0, 0, 1], [0, 0.61e-3, 0])  # 1.22 diameters apart
    f3 = _line([0, 0, 1], [0.59e-3, 0, 0])  # 1.18 diameters from f1, 0.85 mm from f2
    nb = neighbour_orientations(Polylines.from_list([f1, f2, f3], R))
    assert [(int(i), int(j)) for i, j in zip(nb["i"], nb["j"])] == [(0, 2)]
    assert nb["phi_deg"][0] == pytest.approx(0.0, abs=1e-6)
    assert neighbour_orientations(Polylines.from_list([f1, f2], R), reach_diameters=1.25)["i"].size == 1


def test_segment_distances_against_brute_force():
    rng = np.random.default_rng(0)
    a0, a1, b0, b1 = (rng.normal(size=(200, 3)) for _ in range(4))
    d, s, t = segment_distances(a0, a1, b0, b1)
    u = np.linspace(0, 1, 401)
    pa = a0[:, None] + u[None, :, None] * (a1 - a0)[:, None]
    pb = b0[:, None] + u[None, :, None] * (b1 - b0)[:, None]
    # the 401 x 401 point distances of each pair, ten pairs at a time (all 200 at once: 770 MB)
    brute = np.concatenate([np.linalg.norm(pa[k:k + 10, :, None] - pb[k:k + 10, None, :], axis=-1).min(axis=(1, 2))
                            for k in range(0, len(pa), 10)])
    assert np.all(d <= brute + 1e-12) and np.allclose(d, brute, atol=2e-3)
    assert np.allclose(np.linalg.norm(a0 + s[:, None] * (a1 - a0) - b0 - t[:, None] * (b1 - b0), axis=1), d)


@pytest.mark.parametrize("plane", ["xz", "yz"])
def test_circle_arc_of_known_curvature(plane):
    kappa = 0.25  # 1/m, the study's Table 4 order of magnitude (radius 4 m)
    theta = np.linspace(-7.5e-3 * kappa, 7.5e-3 * kappa, 61)  # a 15 mm long arc
    bend = (1 - np.cos(theta)) / kappa
    along = np.sin(theta) / kappa
    arc = np.c_[bend, np.zeros_like(bend), along] if plane == "xz" else np.c_[np.zeros_like(bend), bend, along]
    other = "yz" if plane == "xz" else "xz"
    st = specimen_statistics(Polylines.from_list([arc], R))
    assert st[f"curvature_{plane}_per_m"] == pytest.approx(kappa, rel=1e-6)
    assert st[f"curvature_{other}_per_m"] == pytest.approx(0.0, abs=1e-9)
    assert st["neighbour_pairs"] == 0


def test_specimen_statistics_box_and_overlap():
    f1 = _line([0, 0, 1], [0, 1e-3, 7.5e-3])
    f2 = _line([0, 0, 1], [0, 1.45e-3, 7.5e-3])  # overlapping by 50 um
    st = specimen_statistics(Polylines.from_list([f1, f2], R), box_min_m=[-1.5e-3, 0, 0], box_max_m=[1.5e-3, 1.6e-3, 15e-3])
    assert st["max_overlap_m"] == pytest.approx(50e-6, rel=1e-6)
    assert st["volume_fraction"] == pytest.approx(2 * np.pi * R**2 / (3e-3 * 1.6e-3), rel=1e-9)
    assert st["max_outside_m"] == pytest.approx(1.45e-3 + R - 1.6e-3)  # the top fiber pokes 0.1 mm out


def test_rigid_cassette_specimen_matches_the_study_statistics():
    sigma = np.deg2rad(6.0) / np.sqrt(np.pi)
    fibers, info = cassette_specimen(seed=0, placement="rigid", tilt_rad=sigma, curvature_per_m=0.384)
    st = specimen_statistics(fibers, box_min_m=info["box_min_m"], box_max_m=info["box_max_m"])
    assert fibers.n_fibers == 40
    assert 4.5 < st["phi_mean_deg"] < 7.5  # the study's Φ_average = 6° (range 2–10°)
    assert st["curvature_xz_per_m"] == pytest.approx(0.2445, rel=0.1)  # Table 4: 0.241, 0.248
    assert st["curvature_yz_per_m"] == pytest.approx(0.2445, rel=0.1)
    assert st["max_overlap_m"] < -0.9e-6  # 1 um clear
    assert st["max_outside_m"] <= 1e-12
    assert st["volume_fraction"] == pytest.approx(0.377, rel=5e-3)
    assert info["relaxation"]["min_centre_line_distance_m"] >= 2 * R + 1e-6 - 1e-9


def test_push_placement_is_the_original_specimen():
    a, _ = cassette_specimen(seed=0)
    b, _ = cassette_specimen(seed=0, placement="push", curvature_per_m=0.5)  # curvature: rigid only
    assert np.array_equal(a.points_m, b.points_m)
    with pytest.raises(ValueError):
        cassette_specimen(placement="lattice")
