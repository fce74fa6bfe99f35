"""Dense-composite phantom (v_f 0.6, thin fibers touching on all sides, a cross ply lying in the
slices) and the slices tracer on it: grey detection, regions along another axis."""

import numpy as np
import pytest

from fiberpipe.imaging.accuracy import trace_accuracy
from fiberpipe.imaging.orientation import axis_regions
from fiberpipe.imaging.phantom_dense import make_dense_phantom, pack_disks
from fiberpipe.imaging.segment import segment
from fiberpipe.imaging.trace import trace
from fiberpipe.polylines import Polylines

SMALL = dict(shape=(60, 64, 64), radius_vox=3.0, contrast_to_noise=2.5, cross_ply_fraction=0.3)


@pytest.fixture(scope="module")
def dense():
    vol, truth = make_dense_phantom(seed=3, **SMALL)
    mask, _ = segment(vol)
    return vol, truth, mask


def _subset(p, idx):
    return Polylines.from_list([p.fiber(int(i)) for i in idx], np.asarray(p.radius_m)[idx])


def test_disk_packing_reaches_the_fraction_without_overlap():
    """pack_disks at area fraction 0.6: no pair closer than 2 r (within the tolerance), most disks touching."""
    rng = np.random.default_rng(0)
    r, lo, hi = 3.0, (4.0, 4.0), (56.0, 56.0)
    n = int(round(0.6 * 58.0 * 58.0 / (np.pi * r * r)))
    c = pack_disks(n, r, lo, hi, rng)
    from scipy.spatial import cKDTree

    d, _ = cKDTree(c).query(c, k=2)
    assert d[:, 1].min() >= 2 * r - 0.05
    assert np.mean(d[:, 1] < 2 * r + 0.25) >= 0.7
    assert np.all((c >= lo) & (c <= hi))


def test_dense_phantom_geometry(dense):
    """Fibers run through the whole volume along their axis, per-ply fraction near 0.6, touching, no overlap."""
    vol, truth, _ = dense
    m = truth.meta
    vs = m["voxel_size_m"]
    assert m["n_cross"] > 0 and m["n_main"] > 0
    assert m["min_surface_gap_vox"] >= -0.2
    assert m["contact_fraction"] >= 0.6
    for p, a in zip(truth, m["axis_zyx"]):
        zyx = p[:, ::-1] / vs
        assert zyx[:, a].min() <= 0.5 and zyx[:, a].max() >= SMALL["shape"][a] - 1.5
    # the rendered volume agrees: fiber voxels (grey above the mid level after denoising) make
    # roughly the fibers' volume share
    from scipy.ndimage import gaussian_filter

    g = gaussian_filter(vol.astype(np.float32), 1.0)
    mid = 0.5 * 65535
    assert abs(np.mean(g > mid) - m["fiber_volume_fraction"]) < 0.08


def test_axis_regions_find_the_cross_ply(dense):
    """The share of the mask classed along x matches the cross ply's share of the fiber volume."""
    vol, truth, mask = dense
    labels, fr = axis_regions(mask, 1.0, grey=vol, radius_vox=3.0)
    m = truth.meta
    true_cross = m["n_cross"] * SMALL["shape"][2] / (m["n_cross"] * SMALL["shape"][2] + m["n_main"] * SMALL["shape"][0])
    assert abs(fr[2] - true_cross) < 0.06, fr
    assert fr[1] < 0.02
    # the cross ply sits at high y: nearly all x-class voxels there
    ys = np.nonzero(labels == 2)[1]
    split = round(SMALL["shape"][1] * (1 - SMALL["cross_ply_fraction"]))
    assert np.mean(ys >= split - 3) > 0.95


def test_grey_tracer_follows_every_fiber_of_both_plies(dense):
    """Grey detection + cross ply along its own axis: recall/precision >= 0.98, mean error <= 0.5, whole lengths."""
    vol, truth, mask = dense
    vs = truth.meta["voxel_size_m"]
    f = trace(mask, voxel_size_m=vs, grey=vol, expected_radius_m=3.0 * vs)
    acc = trace_accuracy(f, truth, voxel_size_m=vs)
    assert acc["recall"] >= 0.98 and acc["precision"] >= 0.98, acc
    assert acc["mean_error_vox"] <= 0.5, acc
    assert acc["coverage"] >= 0.95 and acc["n_split"] == 0, acc
    assert f.meta["off_axis"]["x"]["fibers"] >= 0.95 * truth.meta["n_cross"]


def test_cross_ply_left_out_is_counted_and_no_track_crosses_it(dense):
    """off_axis='drop': the cross ply gives no track, its share is reported, the main ply is whole."""
    vol, truth, mask = dense
    vs = truth.meta["voxel_size_m"]
    f = trace(mask, voxel_size_m=vs, grey=vol, expected_radius_m=3.0 * vs, off_axis="drop")
    info = f.meta["off_axis"]["x"]
    assert info["fibers"] == 0 and info["action"] == "left out" and info["volume_fraction"] > 0.15
    main = _subset(truth, np.flatnonzero(truth.meta["axis_zyx"] == 0))
    acc = trace_accuracy(f, main, voxel_size_m=vs)
    assert acc["recall"] >= 0.98 and acc["precision"] >= 0.98, acc


def test_mask_only_tracer_loses_the_dense_pack(dense):
    """Why the grey path exists: on the binary mask alone the merged cross-sections are not separated."""
    vol, truth, mask = dense
    vs = truth.meta["voxel_size_m"]
    f = trace(mask, voxel_size_m=vs, expected_radius_m=3.0 * vs, off_axis="none")
    acc = trace_accuracy(f, truth, voxel_size_m=vs)
    assert acc["recall"] < 0.9, acc


@pytest.mark.parametrize("off_axis", ["trace", "drop"])
def test_trace_stage_on_a_cross_ply_picks_slices_and_reports_the_cross_ply(tmp_path, write_yaml, caplog, dense, off_axis):
    """The stage: auto picks dense (a dense pack along volume axes), which reads the volume, one warning, counts in summary.json."""
    import json

    from fiberpipe.config import load_config
    from fiberpipe.imaging.io import save_volume_tif
    from fiberpipe.pipeline import run_pipeline

    vol, truth, _ = dense
    vs = truth.meta["voxel_size_m"]
    p = tmp_path / "ply.tif"
    save_volume_tif(p, vol, vs)
    cfg = load_config(write_yaml(
        f"input: {{volume: {p}}}\nfiber: {{radius: {3.0 * vs * 1e6:.6g} um}}\nskeletonize: {{enabled: false}}\n"
        f"trace: {{grey: true, off_axis: {off_axis}, min_length: 0, pictures: false}}\n"))
    with caplog.at_level("WARNING", logger="fiberpipe"):
        run_pipeline(cfg, tmp_path / "run", to_stage="trace")
    tr = json.loads((tmp_path / "run" / "summary.json").read_text())["stages"]["trace"]
    assert tr["method"] == "dense" and tr["aligned_fraction_45deg_mask"] < 0.9
    info = tr["off_axis"]["x"]
    msgs = [r.getMessage() for r in caplog.records if "across the slicing axis" in r.getMessage()]
    assert len(msgs) == 1 and "\n" not in msgs[0] and "trace.off_axis" in msgs[0]
    if off_axis == "trace":
        assert info["fibers"] >= 0.95 * truth.meta["n_cross"]
        assert tr["fibers"] >= 0.98 * truth.n_fibers
    else:
        assert info["fibers"] == 0 and info["action"] == "left out"
        assert abs(tr["fibers"] - truth.meta["n_main"]) <= 0.02 * truth.meta["n_main"]


def test_a_misaligned_wavy_ply_keeps_its_fibers_apart_and_inside():
    """The main ply tilted by 3 degrees and wavy by 1 voxel: the true mid-lines' mean direction is 3
    degrees off z (within 0.3), the packing still has no overlap beyond 0.2 voxel, every fiber runs
    through the whole volume inside it."""
    from fiberpipe.imaging.phantom_dense import make_dense_phantom

    vol, truth = make_dense_phantom(shape=(80, 64, 64), radius_vox=3.0, cross_ply_fraction=0.0, misalignment_deg=3.0,
                                    waviness_vox=1.0, contrast_to_noise=4.0, seed=5, dtype="float32")
    vs = truth.meta["voxel_size_m"]
    chords = np.array([truth.fiber(i)[-1] - truth.fiber(i)[0] for i in range(truth.n_fibers)])
    mean = chords.sum(axis=0) / np.linalg.norm(chords.sum(axis=0))
    assert abs(np.degrees(np.arccos(abs(mean[2]))) - 3.0) < 0.3
    assert truth.meta["min_surface_gap_vox"] > -0.2
    pts = np.concatenate([truth.fiber(i) for i in range(truth.n_fibers)]) / vs
    assert pts.min() >= 0 and pts[:, 0].max() <= 63 and pts[:, 1].max() <= 63
    assert all(abs(truth.fiber(i)[-1, 2] / vs - 79) < 0.5 for i in range(truth.n_fibers))


def test_rings_and_cupping_change_the_grey_as_declared():
    """Cupping c darkens the fibers at the rotation axis to 1 - c of their grey (the border keeps
    1); a ring is a thin circle of its contrast in every slice."""
    from fiberpipe.imaging.phantom_dense import ScanArtefacts, make_dense_phantom

    kw = dict(shape=(20, 64, 64), radius_vox=3.0, cross_ply_fraction=0.0, contrast_to_noise=1e6, seed=1, dtype="float32")
    clean, truth = make_dense_phantom(**kw)
    cupped, _ = make_dense_phantom(**kw, artefacts=ScanArtefacts(cupping=0.2))
    ratio = cupped[:, 28:36, 28:36] / np.where(clean[:, 28:36, 28:36] > 0.5, clean[:, 28:36, 28:36], np.nan)
    assert abs(np.nanmean(ratio) - 0.8) < 0.01
    ringed, _ = make_dense_phantom(**kw, artefacts=ScanArtefacts(ring_contrast=0.3, n_rings=1))
    diff = ringed - clean
    assert np.allclose(diff[0], diff[-1]) and 0.25 < np.abs(diff).max() < 0.35
    assert np.mean(np.abs(diff[0]) > 0.05) < 0.15  # a thin circle, not a shade


def test_the_dense_family_draws_within_its_declared_ranges():
    from fiberpipe.imaging.phantom_dense import DENSE_FAMILY, make_dense_family_phantom

    for seed in (0, 1):
        _, truth = make_dense_family_phantom(seed, shape=(24, 100, 100))
        m = truth.meta
        for key in ("radius_vox", "contrast_to_noise", "misalignment_deg", "waviness_vox"):
            lo, hi = DENSE_FAMILY[key]
            assert lo <= m[key] <= hi, (key, m[key])
        assert m["n_cross"] > 0 and m["contact_fraction"] > 0.5
