"""placement="deposit" of fiberpipe.model.specimen.cassette_specimen: a gravity-deposited loose
pile: no overlaps, inside the cassette, every fiber supported on both sides of its
centre of mass (or on the plate), the upper plate touching the top, the study's statistics; and
the shipped data-samples/paper-40 specimen, which is made with it."""

import json
from pathlib import Path

import numpy as np
import pytest

from fiberpipe.model.specimen import cassette_specimen
from fiberpipe.model.specimen_stats import segment_distances, specimen_statistics

R = 0.25e-3
GAP = 1e-6
SAMPLE = Path(__file__).resolve().parents[2] / "data-samples" / "paper-40"
SIGMA = float(np.deg2rad(6.0) / np.sqrt(np.pi))


def _supports(pts, z_tol=0.3e-3, touch=GAP + 0.1e-6):
    """For each fiber (F, n, 3, all on the same z grid): the z of the points where it touches a
    fiber below it or the lower plate (y = 0), and whether they straddle its centre of mass."""
    n_f, n = pts.shape[:2]
    zmid = 0.5 * (pts[0, 0, 2] + pts[0, -1, 2])
    out = []
    for k in range(n_f):
        zs = list(pts[k, pts[k, :, 1] - R <= touch, 2])  # on the plate
        for j in range(n_f):
            if j == k:
                continue
            a0, a1 = pts[k, :-1][:, None], pts[k, 1:][:, None]
            b0, b1 = pts[j, :-1][None], pts[j, 1:][None]
            d, s, t = segment_distances(a0, a1, b0, b1)
            hit = d - 2 * R <= touch
            if not hit.any():
                continue
            pa = a0 + s[..., None] * (a1 - a0)
            pb = b0 + t[..., None] * (b1 - b0)
            below = hit & (pb[..., 1] < pa[..., 1])  # j holds k up
            zs += list(pa[below][:, 2])
        zs = np.asarray(zs)
        ok = zs.size > 0 and zs.min() <= zmid + z_tol and zs.max() >= zmid - z_tol
        out.append((zs, bool(ok)))
    return out


@pytest.fixture(scope="module")
def small(small_deposit):
    return small_deposit  # tests/model/conftest.py: n_fibers=12, seed=1, tilt SIGMA, candidates=2, top="pile"


def test_small_deposit_is_a_supported_pile_without_overlaps(small):
    fibers, info = small
    pts = fibers.points_m.reshape(12, 25, 3)
    st = specimen_statistics(fibers, box_min_m=info["box_min_m"], box_max_m=info["box_max_m"])
    assert st["min_gap_m"] >= GAP - 1e-9  # no overlap: closest centre lines ≥ 2r + 1 µm
    assert st["min_gap_m"] <= GAP + 0.1e-6  # and some fibers touch (at the clearance)
    assert st["max_outside_m"] <= 1e-12  # inside the cassette (walls, plates)
    assert pts[:, :, 1].min() - R >= GAP - 1e-12
    top = (pts[:, :, 1] + R).max()
    assert info["height_m"] - top == pytest.approx(GAP, abs=1e-12)  # the upper plate touches the top
    assert info["deposit"]["fibers_at_upper_plate"] >= 1
    assert info["deposit"]["fibers_on_lower_plate"] >= 1
    assert info["deposit"]["contacts"] >= 12  # a contact network, not a lattice of free fibers
    for k, (zs, ok) in enumerate(_supports(pts)):
        assert ok, f"fiber {k} is not supported on both sides of its centre of mass: {zs}"


def test_deposit_is_deterministic_and_other_placements_unchanged(small):
    fibers, _ = small
    again, _ = cassette_specimen(n_fibers=12, width_m=1.5e-3, length_m=6e-3, points_per_fiber=25, seed=1,
                                 placement="deposit", tilt_rad=SIGMA, curvature_per_m=0.384, candidates=2,
                                 top="pile")
    assert np.array_equal(fibers.points_m, again.points_m)
    with pytest.raises(ValueError):
        cassette_specimen(placement="deposit", top="ceiling")


def test_shipped_paper40_is_the_deposited_pile():
    from fiberpipe.artifacts import read_fibers

    fibers = read_fibers(SAMPLE / "fibers.h5")
    info = json.loads((SAMPLE / "specimen.json").read_text())
    assert info["generator"]["placement"] == "deposit"
    assert info["generator"]["settle"]["lock_axial"] == "all"  # then settled in the solver (make_paper40 --settle)
    pts = fibers.points_m.reshape(40, -1, 3)
    st = specimen_statistics(fibers, box_min_m=info["box_min_m"], box_max_m=info["box_max_m"])
    assert fibers.n_fibers == 40
    # settled: fibers press on each other under their weight only (penetrations of nanometres)
    assert st["min_gap_m"] >= -0.1e-6 and st["max_outside_m"] <= 1e-9
    assert info["settle"]["kinetic_energy_end_J"] < 1e-12 and info["settle"]["fiber_contacts"] >= 40
    assert 0.36 < info["volume_fraction"] < 0.40  # the study's 37.7 %: see the sample's README
    assert info["height_m"] - (pts[:, :, 1] + R).max() == pytest.approx(GAP, abs=1e-9)
    assert 4.5 < st["phi_mean_deg"] < 7.5  # the study's Φ_average = 6°
    assert st["curvature_xz_per_m"] == pytest.approx(0.2445, rel=0.15)  # Table 4: 0.241, 0.248
    assert st["curvature_yz_per_m"] == pytest.approx(0.2445, rel=0.15)
    assert info["deposit"]["contacts"] >= 40
    # no rigid-body support check here: settled with every node's z locked, a fiber is also held
    # by its axial stiffness (z fixed, a turn in y-z stretches it), as in the study's scene
    # the config's upper plate sits on the pile
    import yaml

    cfg = yaml.safe_load((SAMPLE.parents[1] / "configs" / "paper-40.yaml").read_text())
    upper = cfg["scene"]["plates"]["upper_position"]
    assert float(upper.split()[0]) * 1e-3 == pytest.approx(info["height_m"], abs=1e-7)


@pytest.mark.slow
def test_shipped_paper40_rests_under_gravity():
    """Meshed and simulated 5 ms under gravity alone (α = 300 1/s, so that a fiber without support
    falls ≈ 79 µm), no node should move by more than 0.1 r. The pile as placed failed this
    (115 µm); settled in the solver (make_paper40 --settle) it passes: data-samples/paper-40/README.md."""
    from fiberpipe.artifacts import read_fibers
    from fiberpipe.config import load_config
    from fiberpipe.model.mesh import mesh_polylines
    from fiberpipe.stages.simulate import settle_under_gravity

    cfg = load_config(SAMPLE.parents[1] / "configs" / "paper-40.yaml",
                      {"solver.settle_time": "5 ms", "scene.damping.alpha": "300 1/s"})
    mesh = mesh_polylines(read_fibers(SAMPLE / "fibers.h5"), cfg.mesh.element_length, radius_m=cfg.fiber.radius)
    assert settle_under_gravity(mesh, cfg)["max_displacement_m"] < 0.1 * R


def _pair_geometry_numpy(x, y, X, Y, z, need, reach=2):
    """The deposit's pair geometry written with numpy's vectorised segment distances (the reference
    for the jitted loop: the same operations, so the same numbers to the bit)."""
    m, ns = len(X), len(z) - 1
    p = np.stack([x, y, z], axis=1)
    q = np.stack([X, Y, np.broadcast_to(z, X.shape)], axis=2)
    i = np.repeat(np.arange(ns), 2 * reach + 1)
    kk = i + np.tile(np.arange(-reach, reach + 1), ns)
    ok = (kk >= 0) & (kk < ns)
    i, kk = i[ok], kk[ok]
    a0, a1 = p[i][None], p[i + 1][None]
    b0, b1 = q[:, kk], q[:, kk + 1]
    d, s, t = segment_distances(a0, a1, b0, b1)
    pa = a0 + s[..., None] * (a1 - a0)
    pb = b0 + t[..., None] * (b1 - b0)
    nvec = (pa - pb) / np.maximum(d, 1e-300)[..., None]
    return (d - need).ravel(), nvec.reshape(-1, 3), pa[..., 2].ravel(), np.repeat(np.arange(m), len(i))


def test_pair_geometry_equals_numpy_segment_distances_to_the_bit():
    from fiberpipe.model.specimen import _pair_geometry

    rng = np.random.default_rng(3)
    z = np.linspace(0.0, 15e-3, 31)
    for trial in range(40):
        m = int(rng.integers(1, 12))
        x = np.cumsum(rng.normal(0, 1e-5, z.size)) + rng.normal(0, 1e-3)
        y = np.cumsum(rng.normal(0, 1e-5, z.size))
        X = np.cumsum(rng.normal(0, 1e-5, (m, z.size)), axis=1) + rng.normal(0, 1e-3, (m, 1))
        Y = np.cumsum(rng.normal(0, 1e-5, (m, z.size)), axis=1)
        if trial % 4 == 0:  # a parallel neighbour: segments' closest points at their ends (clamped)
            X[0], Y[0] = x, y + 2 * R + GAP
        got = _pair_geometry(x, y, X, Y, z, 2 * R + GAP)
        want = _pair_geometry_numpy(x, y, X, Y, z, 2 * R + GAP)
        for g, w in zip(got, want):
            assert np.array_equal(g, w)
