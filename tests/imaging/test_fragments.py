"""Fragments and gaps: joining the broken pieces of one fiber, cutting folds, dropping short bits."""

import json

import numpy as np
import pytest

from fiberpipe.errors import InputError
from fiberpipe.imaging.fragments import drop_short, join_fragments, split_folds
from fiberpipe.imaging.phantom import render_polylines
from fiberpipe.imaging.segment import segment
from fiberpipe.imaging.trace import trace
from fiberpipe.polylines import Polylines

VS = 1e-5
R = 3 * VS


def _seg(p0, p1, n=40):
    return np.linspace(np.asarray(p0, float), np.asarray(p1, float), n) * VS


def _dist_to_line(p, a, b):
    """Distance of points p (m) to the infinite line through a, b (voxels)."""
    a, b = np.asarray(a, float) * VS, np.asarray(b, float) * VS
    u = (b - a) / np.linalg.norm(b - a)
    q = p - a
    return np.linalg.norm(q - np.outer(q @ u, u), axis=1) / VS


def test_three_pieces_of_one_tilted_fiber_are_joined_in_order():
    d = np.array([0.3, 0.2, 1.0]) / np.linalg.norm([0.3, 0.2, 1.0])
    a = np.zeros(3)
    pieces = [_seg(a + 0 * d, a + 30 * d), _seg(a + 40 * d, a + 70 * d)[::-1], _seg(a + 80 * d, a + 110 * d)]
    pl = Polylines.from_list(pieces, R)
    joined, n = join_fragments(pl, max_gap_m=12 * VS, max_offset_m=3 * VS)
    assert n == 2 and joined.n_fibers == 1
    p = joined.fiber(0)
    # runs from one end to the other, monotonically along d, on the line
    s = p @ d / VS
    assert np.all(np.diff(s) > 0) or np.all(np.diff(s) < 0)
    assert abs(abs(s[-1] - s[0]) - 110) < 1e-6
    assert _dist_to_line(p, a, a + d).max() < 1e-6


@pytest.mark.parametrize("case", ["parallel_offset", "perpendicular", "other_radius", "too_far"])
def test_pieces_that_do_not_continue_each_other_stay_apart(case):
    a = _seg((0, 0, 0), (0, 0, 30))
    b = {
        "parallel_offset": _seg((6, 0, 36), (6, 0, 66)),   # in line? no: 6 voxels to the side
        "perpendicular": _seg((0, 0, 34), (0, 30, 34)),    # close end, at 90 degrees
        "other_radius": _seg((0, 0, 36), (0, 0, 66)),      # collinear but twice as thick
        "too_far": _seg((0, 0, 50), (0, 0, 80)),           # collinear, 20 voxels away
    }[case]
    radius = [R, 2 * R] if case == "other_radius" else [R, R]
    pl = Polylines(np.vstack([a, b]), np.array([0, len(a), len(a) + len(b)]), np.array(radius))
    joined, n = join_fragments(pl, max_gap_m=12 * VS, max_offset_m=3 * VS)
    assert n == 0 and joined.n_fibers == 2


def test_two_parallel_fibers_broken_at_the_same_place_rejoin_each_with_itself():
    # two parallel fibers 2r apart (touching), both broken at z = 30..38: each must join its own piece
    pieces = [_seg((0, 0, 0), (0, 0, 30)), _seg((6, 0, 0), (6, 0, 30)),
              _seg((6, 0, 38), (6, 0, 70)), _seg((0, 0, 38), (0, 0, 70))]
    joined, n = join_fragments(Polylines.from_list(pieces, R), max_gap_m=12 * VS, max_offset_m=3 * VS)
    assert n == 2 and joined.n_fibers == 2
    xs = sorted(float(np.ptp(f[:, 0])) for f in joined)
    assert xs[-1] < 1e-9  # neither jumps across to the other fiber


def test_skeleton_tracer_joins_a_fiber_cut_by_a_dark_stretch():
    d = np.array([0.25, 0.15, 1.0])
    d /= np.linalg.norm(d)
    c = np.array([40.0, 40.0, 50.0])  # x y z, voxels: the volume's centre
    line = np.linspace(-45, 45, 200)[:, None] * d[None, :] + c[None, :]
    truth = Polylines.from_list([line * VS], R)
    vol = render_polylines(truth, (100, 80, 80), VS, blur_sigma_vox=1.0, contrast_to_noise=8.0, seed=1)
    z = np.arange(vol.shape[0])
    vol[(z > 48) & (z < 53)] = 0.0  # background level: a dark stretch 4 slices long cuts the fiber in two
    mask, _ = segment(vol)
    apart = trace(mask, voxel_size_m=VS, method="skeleton", join_gap_vox=0)
    assert apart.n_fibers == 2, apart.meta
    joined = trace(mask, voxel_size_m=VS, method="skeleton")
    assert joined.n_fibers == 1 and joined.meta["n_joins"] == 1
    L = joined.lengths_m()[0] / VS
    assert L > 0.85 * 90, L  # runs (nearly) the full length across the gap
    assert _dist_to_line(joined.fiber(0), c, c + d).max() < 1.5


def test_drop_short_keeps_order_and_reports_indices():
    pl = Polylines.from_list([_seg((0, 0, 0), (0, 0, 50)), _seg((9, 0, 0), (9, 0, 5)), _seg((20, 0, 0), (20, 0, 30))], R)
    kept, dropped = drop_short(pl, 10 * VS)
    assert list(dropped) == [1] and kept.n_fibers == 2
    assert np.allclose(kept.fiber(1), pl.fiber(2))


def test_a_hairpin_is_cut_into_two_fibers_the_mesh_accepts():
    from fiberpipe.model.mesh import mesh_polylines, resample_polyline

    el = 0.3e-3
    down = np.linspace([0, 0, 3e-3], [0, 0, 0], 60)
    up = np.linspace([0.05e-3, 0, 0], [0.05e-3, 0, 3e-3], 60)
    hairpin = np.vstack([down, up])
    pl = Polylines.from_list([hairpin], 0.05e-3)
    with pytest.raises(InputError, match="turns by"):
        mesh_polylines(pl, el)
    cut, n = split_folds(pl, lambda p: resample_polyline(p, el), max_turn_deg=90.0)
    assert n >= 1 and cut.n_fibers == n + 1
    mesh_polylines(cut, el, min_fiber_length_m=0.0)  # no fold left
    assert abs(cut.lengths_m().sum() - Polylines.from_list([hairpin], 0.05e-3).lengths_m().sum()) < 1e-9


# -- the stages: trace.min_length and mesh.min_fiber_length drop short fibers instead of stopping --


def _volume_with_a_short_fiber(tmp_path):
    from fiberpipe.imaging.io import save_volume_tif

    vs = 20e-6  # 0.3 mm elements = 15 voxels; 2 elements = 30 voxels
    fibers = [_seg((15, 15, 2), (15, 15, 77)) / VS * vs, _seg((35, 15, 2), (35, 15, 77)) / VS * vs,
              _seg((15, 35, 30), (15, 35, 42)) / VS * vs]  # the last is 12 voxels = 0.24 mm long
    vol = render_polylines(Polylines.from_list(fibers, 3 * vs), (80, 50, 50), vs, blur_sigma_vox=0.7,
                           contrast_to_noise=10.0, seed=2, dtype=np.uint8)
    p = tmp_path / "vol.tif"
    save_volume_tif(p, vol, vs)
    return p


def test_trace_stage_drops_short_fibers_with_a_warning_and_a_count(tmp_path, write_yaml, caplog):
    from fiberpipe.config import MIN_FIBER_LENGTH_DIAMETERS, load_config
    from fiberpipe.pipeline import run_pipeline

    vol = _volume_with_a_short_fiber(tmp_path)
    cfg = load_config(write_yaml(f"input: {{volume: {vol}}}\ntrace: {{method: slices}}\nskeletonize: {{enabled: false}}\n"))
    with caplog.at_level("WARNING", logger="fiberpipe"):
        run_pipeline(cfg, tmp_path / "run")
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    tr = summary["stages"]["trace"]
    assert tr["fibers"] == 2 and tr["dropped_short_fibers"] == 1
    assert tr["min_length_m"] == pytest.approx(MIN_FIBER_LENGTH_DIAMETERS * 2 * tr["median_radius_m"])  # 3 d
    assert summary["stages"]["mesh"]["fibers"] == 2
    assert any("trace.min_length" in r.getMessage() for r in caplog.records)
    # trace.min_length: 0 keeps it (the mesh stage then drops it by its own rule)
    cfg = load_config(write_yaml(f"input: {{volume: {vol}}}\ntrace: {{method: slices, min_length: 0, min_length_vox: 5}}\n"
                                 "skeletonize: {enabled: false}\n"))
    run_pipeline(cfg, tmp_path / "run0")
    s0 = json.loads((tmp_path / "run0" / "summary.json").read_text())["stages"]
    assert s0["trace"]["fibers"] == 3 and s0["trace"]["dropped_short_fibers"] == 0
    assert s0["mesh"]["fibers"] == 2 and s0["mesh"]["dropped_short_fibers"] == 1


def test_mesh_stage_drops_short_given_fibers_and_refuses_when_the_scene_names_fibers(tmp_path, write_yaml):
    from fiberpipe.config import load_config
    from fiberpipe.errors import InputError
    from fiberpipe.pipeline import run_pipeline

    lines = "[[[0, 0, 0], [0, 0, '3 mm']], [[1e-3, 0, 0], [1e-3, 0, '0.4 mm']], [[2e-3, 0, 0], [2e-3, 0, '3 mm']]]"
    cfg = load_config(write_yaml(f"input: {{polylines: {lines}}}\nfiber: {{radius: 0.1 mm}}\n"))
    run_pipeline(cfg, tmp_path / "run")
    m = json.loads((tmp_path / "run" / "summary.json").read_text())["stages"]["mesh"]
    assert m["fibers"] == 2 and m["dropped_short_fibers"] == 1
    cfg = load_config(write_yaml(f"input: {{polylines: {lines}}}\nfiber: {{radius: 0.1 mm}}\nmesh: {{min_fiber_length: 0.3 mm}}\n",
                                 "keep.yaml"))
    run_pipeline(cfg, tmp_path / "keep")
    assert json.loads((tmp_path / "keep" / "summary.json").read_text())["stages"]["mesh"]["fibers"] == 3
    cfg = load_config(write_yaml(f"input: {{polylines: {lines}}}\nfiber: {{radius: 0.1 mm}}\n"
                                 "scene: {effects: [clamps], clamps: [{fiber: 2}]}\nsolver: {end_time: 1e-6}\n", "clamp.yaml"))
    with pytest.raises(InputError, match="renumbers the fibers scene.clamps"):
        run_pipeline(cfg, tmp_path / "clamp", to_stage="mesh")
    cfg = load_config(write_yaml(f"input: {{polylines: {lines}}}\nfiber: {{radius: 0.1 mm}}\nmesh: {{min_fiber_length: 5 mm}}\n",
                                 "all.yaml"))
    with pytest.raises(InputError, match="all 3 fibers are shorter than mesh.min_fiber_length"):
        run_pipeline(cfg, tmp_path / "all")


def test_a_tiff_folder_of_a_short_fiber_suspension_runs_through_mesh_with_default_settings(tmp_path, write_yaml):
    import tifffile

    from fiberpipe.config import load_config
    from fiberpipe.imaging.phantom import make_short_fiber_phantom
    from fiberpipe.pipeline import run_pipeline

    vol, truth = make_short_fiber_phantom(shape=(60, 120, 180), n_fibers=80, radius_vox=2.7, length_vox=(30, 100), seed=6)
    folder = tmp_path / "slices"
    folder.mkdir()
    for k, sl in enumerate(vol):
        tifffile.imwrite(folder / f"slice_{k}.tif", sl)
    cfg = load_config(write_yaml(f"input: {{volume: {folder}, voxel_size: 10 um}}\n"))
    run_pipeline(cfg, tmp_path / "run")
    st = json.loads((tmp_path / "run" / "summary.json").read_text())["stages"]
    assert st["trace"]["method"] == "skeleton" and st["trace"]["dropped_short_fibers"] > 0
    long_true = int((truth.lengths_m() >= st["trace"]["min_length_m"]).sum())
    assert 0.5 * long_true <= st["mesh"]["fibers"] <= 1.5 * long_true, (st["mesh"]["fibers"], long_true)


def test_an_unset_trace_min_length_is_named_by_what_it_defaults_to():
    """mesh.element_length: 0.3 (metres, a unit forgotten) makes the default trace.min_length 0.6 m:
    the error says where that value came from, not only the key the user never set."""
    from fiberpipe.errors import InputError
    from fiberpipe.polylines import Polylines
    from fiberpipe.stages.trace import drop_short_fibers

    fibers = Polylines(np.array([[0, 0, 0], [0, 0, 2e-3], [1e-3, 0, 0], [1e-3, 0, 2e-3]]), np.array([0, 2, 4]),
                       np.array([1e-4, 1e-4]))
    with pytest.raises(InputError, match=r"trace.min_length = 600 mm \(unset: two mesh.element_length; a length "
                                         r"without a unit is in metres\) \(longest 2 mm\)"):
        drop_short_fibers(fibers, 0.6, "trace.min_length", "two mesh.element_length")
    with pytest.raises(InputError, match=r"trace.min_length = 600 mm \(longest 2 mm\)"):
        drop_short_fibers(fibers, 0.6, "trace.min_length")
