"""The yarn specimen (specimen.kind yarn) through `fiberpipe specimen`: packing, twist, determinism, refusals."""

import json
import math

import numpy as np
import pytest
import yaml

from fiberpipe.artifacts import read_fibers
from fiberpipe.errors import ConfigError
from fiberpipe.model.specimen_stats import segment_distances
from fiberpipe.model.virtual_specimen import build_specimen

RADIUS_M = 0.25e-3
LENGTH_M = 15e-3


def yarn(n_fibers=60, volume_fraction=0.6, **yarn_section) -> dict:
    return {
        "name": "yarn", "mesh": {"element_length": "0.3 mm"}, "fiber": {"radius": "0.25 mm"},
        "scene": {"effects": ["contact", "plates", "walls"], "plates": {"axis": "y", "lower": "moving", "upper": "fixed"},
                  "walls": {"x": ["-5 mm", "5 mm"]}, "loading": {"displacement": "1 mm"}},
        "specimen": {"kind": "yarn", "n_fibers": n_fibers, "length": "15 mm", "volume_fraction": volume_fraction,
                     "points_per_fiber": 51, "yarn": yarn_section},
    }


def lines(fibers) -> np.ndarray:
    """(n_fibers, points, 3): every fiber has the same number of points."""
    points = fibers.offsets[1]
    return fibers.points_m.reshape(fibers.n_fibers, points, 3)


def smallest_centre_distance(fibers) -> float:
    """The smallest distance between two fibers' centre lines (every segment pair of every fiber pair)."""
    line = lines(fibers)
    best = np.inf
    for i in range(len(line) - 1):
        d, _, _ = segment_distances(line[i, :-1, None, None], line[i, 1:, None, None],
                                    line[None, i + 1:, :-1], line[None, i + 1:, 1:])
        best = min(best, float(d.min()))
    return best


def test_yarn_is_packed_at_its_volume_fraction_without_overlap(tmp_path):
    # twisted, tilted and wavy: every step of the builder at work
    info = build_specimen(yarn(helix_angle="10 deg", orientation_spread="2 deg", wave_amplitude="0.02 mm",
                               walls=True), tmp_path, where="yarn.yaml", seed=1)
    fibers = read_fibers(tmp_path / "fibers.h5")
    line = lines(fibers)
    # v_f0 measured from the fibers alone: their volume over the circle around them (× L)
    axis_y = 0.5 * info["height_m"]
    outer = float(np.max(np.hypot(line[..., 0], line[..., 1] - axis_y))) + RADIUS_M
    volume = math.pi * RADIUS_M**2 * np.sum(np.linalg.norm(np.diff(line, axis=1), axis=2))
    assert volume / (math.pi * outer**2 * LENGTH_M) == pytest.approx(0.6, rel=0.01)
    assert info["volume_fraction"] == pytest.approx(0.6, rel=0.01)
    # no fiber–fiber overlap beyond the stated 1 % of the radius (specimen.yarn.overlap_tolerance)
    assert smallest_centre_distance(fibers) >= 2 * RADIUS_M - 0.01 * RADIUS_M
    # every fiber between the plates and the walls of the ready config
    ready = yaml.safe_load((tmp_path / "config.yaml").read_text())
    assert ready["scene"]["plates"]["upper_position"] == pytest.approx(info["height_m"])
    assert line[..., 1].min() - RADIUS_M >= 0 and line[..., 1].max() + RADIUS_M <= info["height_m"]
    half = ready["scene"]["walls"]["x"][1]
    assert np.abs(line[..., 0]).max() + RADIUS_M <= half + 1e-12


def test_yarn_without_walls_leaves_them_out_and_compares_with_no_scan(tmp_path):
    raw = yarn(n_fibers=20, volume_fraction=0.4)
    raw["post"] = {"reference_fibers": "scan.h5"}
    build_specimen(raw, tmp_path, where="yarn.yaml", seed=0)
    ready = yaml.safe_load((tmp_path / "config.yaml").read_text())
    assert "walls" not in ready["scene"]["effects"] and "walls" not in ready["scene"]
    assert "reference_fibers" not in ready["post"]


def test_yarn_is_the_same_for_the_same_seed_and_differs_for_another(tmp_path):
    raw = yarn(n_fibers=30, volume_fraction=0.5, helix_angle="5 deg", orientation_spread="3 deg")
    points = []
    for name, seed in (("a", 2), ("b", 2), ("c", 3)):
        build_specimen(raw, tmp_path / name, where="yarn.yaml", seed=seed)
        points.append(read_fibers(tmp_path / name / "fibers.h5").points_m)
    assert np.array_equal(points[0], points[1])
    assert not np.allclose(points[0], points[2])


def test_helix_angle_measured_from_the_built_fibers_is_the_asked_one(tmp_path):
    info = build_specimen(yarn(volume_fraction=0.5, helix_angle="15 deg"), tmp_path, where="yarn.yaml", seed=0)
    line = lines(read_fibers(tmp_path / "fibers.h5"))
    centred = line - np.array([0.0, 0.5 * info["height_m"], 0.0])
    tangent = np.diff(centred, axis=1)
    mid = 0.5 * (centred[:, 1:] + centred[:, :-1])
    rho = np.hypot(mid[..., 0], mid[..., 1])
    tan_alpha = np.hypot(tangent[..., 0], tangent[..., 1]) / tangent[..., 2]
    # a helix: tan α = 2πT ρ (least squares through the origin over every segment)
    two_pi_twist = float(np.sum(tan_alpha * rho) / np.sum(rho**2))
    # the surface: the fiber surfaces' outer radius, R = √(ab)
    surface = float(np.max(rho)) + RADIUS_M
    assert math.degrees(math.atan(two_pi_twist * surface)) == pytest.approx(15.0, abs=0.3)
    # the turn between the ends: 2πT L, the same twist read another way
    turn = np.unwrap(np.arctan2(centred[..., 1], centred[..., 0]), axis=1)
    outer = rho.mean(axis=1) > 0.5 * surface  # away from the axis, where the angle is well defined
    assert np.median(turn[outer, -1] - turn[outer, 0]) == pytest.approx(two_pi_twist * LENGTH_M, rel=0.02)


def test_a_volume_fraction_beyond_jamming_is_refused_in_one_line_with_the_densest_reached(tmp_path, monkeypatch):
    monkeypatch.setattr("fiberpipe.model.specimen_yarn.MAX_DISC_SWEEPS", 3000)  # jammed sooner than the default
    with pytest.raises(ConfigError) as caught:
        build_specimen(yarn(volume_fraction=0.9), tmp_path / "x", where="yarn.yaml", seed=0)
    message = str(caught.value)
    assert message.startswith("yarn.yaml:") and "\n" not in message
    assert "specimen.volume_fraction = 0.9 cannot be packed" in message
    reached = float(message.split("v_f0 reached is ≈ ")[1].split(" ")[0])
    # random discs jam near 0.82–0.85 in the bulk (O'Hern et al. 2003); 60 in a circle, below
    assert 0.7 < reached < 0.86
    assert not (tmp_path / "x" / "fibers.h5").exists()


def test_yarn_specimen_json_records_the_twist_and_packing(tmp_path):
    build_specimen(yarn(n_fibers=20, volume_fraction=0.4, twist_per_length=20.0), tmp_path, where="yarn.yaml", seed=0)
    info = json.loads((tmp_path / "specimen.json").read_text())
    assert info["kind"] == "yarn" and info["twist"]["turns_per_m"] == 20.0
    a, b = info["semi_axes_m"]
    assert math.tan(math.radians(info["twist"]["surface_helix_angle_deg"])) == pytest.approx(2 * math.pi * 20.0 * a)


def test_elliptical_yarn_has_its_aspect_ratio_and_volume_fraction(tmp_path):
    info = build_specimen(yarn(n_fibers=40, volume_fraction=0.5, aspect_ratio=2.5), tmp_path, where="yarn.yaml", seed=0)
    a, b = info["semi_axes_m"]
    assert a / b == pytest.approx(2.5)
    line = lines(read_fibers(tmp_path / "fibers.h5"))
    # every fiber surface inside the ellipse (a, b) centred between the plates
    x, y = line[..., 0], line[..., 1] - 0.5 * info["height_m"]
    assert np.max((x / (a - RADIUS_M)) ** 2 + (y / (b - RADIUS_M)) ** 2) <= 1 + 1e-9
    volume = math.pi * RADIUS_M**2 * np.sum(np.linalg.norm(np.diff(line, axis=1), axis=2))
    assert volume / (math.pi * a * b * LENGTH_M) == pytest.approx(0.5, rel=0.01)
