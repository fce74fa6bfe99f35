"""Length defaults that follow the scan: with only ``input.voxel_size`` given, a scan at 1 um and at
30 um per voxel runs through segment, trace and mesh, the minimum fiber length, element length and
overlap shift derived from the traced radius; the bad scans are one line each."""

import json

import numpy as np
import pytest

from fiberpipe.config import ELEMENT_LENGTH_DIAMETERS, MIN_FIBER_LENGTH_DIAMETERS, load_config
from fiberpipe.errors import InputError
from fiberpipe.imaging.io import save_volume_tif
from fiberpipe.imaging.phantom import make_phantom
from fiberpipe.pipeline import run_pipeline

RADIUS_VOX = 3.0


def _scan(tmp_path, voxel_size_m, volume=None):
    if volume is None:
        volume, _ = make_phantom(n_fibers=8, shape=(60, 40, 40), radius_vox=RADIUS_VOX, voxel_size_m=voxel_size_m,
                                 contrast_to_noise=5.0, seed=3, dtype="uint8")
    path = tmp_path / "scan.tif"
    save_volume_tif(path, volume, voxel_size_m)
    return path


@pytest.mark.parametrize("voxel_um", [1.0, 30.0])
def test_a_scan_at_any_voxel_size_runs_with_only_its_voxel_size(tmp_path, write_yaml, voxel_um):
    """The study's defaults (0.3 mm elements, 0.6 mm shortest fiber) would drop every fiber of the
    1 um scan; derived from the traced radius they keep all 8 at both scales, and the element is
    0.6 fiber diameters."""
    vs = voxel_um * 1e-6
    path = _scan(tmp_path, vs)
    cfg = load_config(write_yaml(f"input: {{volume: {path}, voxel_size: {voxel_um} um}}\n"
                                 "skeletonize: {enabled: false}\ntrace: {pictures: false}\n"))
    run_pipeline(cfg, tmp_path / "run", to_stage="mesh")
    st = json.loads((tmp_path / "run" / "summary.json").read_text())["stages"]
    radius_m = st["trace"]["median_radius_m"]
    assert abs(radius_m / vs - RADIUS_VOX) < 0.5, radius_m / vs
    assert st["trace"]["fibers"] == 8 and st["trace"]["dropped_short_fibers"] == 0
    assert st["trace"]["min_length_m"] == pytest.approx(MIN_FIBER_LENGTH_DIAMETERS * 2 * radius_m)
    assert st["mesh"]["fibers"] == 8
    element = ELEMENT_LENGTH_DIAMETERS * 2 * radius_m
    assert st["mesh"]["mean_element_length_m"] == pytest.approx(element, rel=0.1)


def test_set_lengths_win_over_the_derived_ones(tmp_path, write_yaml):
    vs = 30e-6
    path = _scan(tmp_path, vs)
    cfg = load_config(write_yaml(f"input: {{volume: {path}, voxel_size: 30 um}}\nskeletonize: {{enabled: false}}\n"
                                 "trace: {pictures: false, min_length: 0.5 mm}\nmesh: {element_length: 0.2 mm}\n"))
    run_pipeline(cfg, tmp_path / "run", to_stage="mesh")
    st = json.loads((tmp_path / "run" / "summary.json").read_text())["stages"]
    assert st["trace"]["min_length_m"] == pytest.approx(0.5e-3)
    assert st["mesh"]["mean_element_length_m"] == pytest.approx(0.2e-3, rel=0.1)


def test_the_study_radius_keeps_the_study_element_length(write_yaml):
    """fiber.radius 0.25 mm: the derived element is the study's 0.3 mm (0.6 diameters)."""
    cfg = load_config(write_yaml("input: {volume: x.tif, voxel_size: 15 um}\nfiber: {radius: 0.25 mm}\n"))
    assert cfg.mesh.element_length == pytest.approx(0.3e-3)


def test_a_voxel_size_that_makes_the_fibers_thinner_than_one_and_a_half_voxels_is_one_line(tmp_path, write_yaml):
    vs = 30e-6
    path = _scan(tmp_path, vs)
    # fibers 6 voxels across at 30 um, declared 20 um across: the voxel size is wrong by a factor ~9
    cfg = load_config(write_yaml(f"input: {{volume: {path}, voxel_size: 30 um}}\nfiber: {{radius: 10 um}}\n"
                                 "skeletonize: {enabled: false}\n"))
    with pytest.raises(InputError, match=r"input.voxel_size = 30 um makes the fibers \(fiber.radius = 10 um\) 0.67 "
                                         r"voxels across, thinner than 1.5") as err:
        run_pipeline(cfg, tmp_path / "run", to_stage="trace")
    assert "\n" not in str(err.value)


def test_a_volume_without_a_fiber_phase_is_one_line(tmp_path, write_yaml):
    rng = np.random.default_rng(0)
    noise = rng.normal(100, 1, size=(40, 32, 32)).clip(0, 255).astype(np.uint8)
    path = _scan(tmp_path, 10e-6, noise)
    cfg = load_config(write_yaml(f"input: {{volume: {path}, voxel_size: 10 um}}\n"))
    with pytest.raises(InputError) as err:
        run_pipeline(cfg, tmp_path / "run", to_stage="trace")
    msg = str(err.value)
    assert "\n" not in msg and "scan.tif" in msg and "no fiber phase" in msg and "input.volume" in msg, msg


def test_a_scan_whose_every_fiber_is_below_the_minimum_length_is_one_line(tmp_path, write_yaml):
    vs = 30e-6
    path = _scan(tmp_path, vs)
    cfg = load_config(write_yaml(f"input: {{volume: {path}, voxel_size: 30 um}}\nskeletonize: {{enabled: false}}\n"
                                 "trace: {pictures: false, min_length: 5 mm}\n"))
    with pytest.raises(InputError, match=r"all 8 fibers are shorter than trace.min_length = 5 mm") as err:
        run_pipeline(cfg, tmp_path / "run", to_stage="trace")
    assert "\n" not in str(err.value)
