"""The smooth-waviness option of the deposit placement (``wave_curvature_per_m``: Table 4
read as 1/mm): the waves' projected curvature is the one asked for, converged in the point spacing,
the wavy pile has no overlaps and stays in the cassette, and without the option nothing changes."""

import numpy as np
import pytest

from fiberpipe.model.specimen import _wave_offsets, cassette_specimen
from fiberpipe.model.specimen_stats import specimen_statistics
from fiberpipe.post.geometry import projected_curvature

R = 0.25e-3
GAP = 1e-6
SIGMA = float(np.deg2rad(3.0) / np.sqrt(np.pi))
KW = dict(n_fibers=12, width_m=1.5e-3, length_m=6e-3, points_per_fiber=25, seed=1, placement="deposit",
          tilt_rad=SIGMA, curvature_per_m=0.384, candidates=1, top="pile")


def _curv(w, z):
    return projected_curvature(np.c_[w, np.zeros_like(z), z], np.array([0, len(z)]), "xz")


def test_wave_offsets_hit_the_curvature_and_converge_with_the_spacing():
    z = np.linspace(0.0, 15e-3, 61)
    w = _wave_offsets(np.random.default_rng(3), 4, z, 240.0, (1.8e-3, 2.5e-3), 2)
    assert w.shape == (4, 61, 2)
    # the same waves on a finer grid (same draws): the curve's own curvature is the target ...
    zf = np.linspace(0.0, 15e-3, 481)
    wf = _wave_offsets(np.random.default_rng(3), 4, zf, 240.0, (1.8e-3, 2.5e-3), 2)
    # (the same curve: only the scale, fitted on a finer grid, differs by < 1 %)
    np.testing.assert_allclose(wf[:, ::8], w, rtol=0, atol=0.01 * np.abs(w).max())
    for k in range(4):
        for c in range(2):
            assert _curv(wf[k, :, c], zf) == pytest.approx(240.0, rel=0.005)
            # ... and 0.25 mm points measure it a few per cent low (2 mm waves)
            assert 0.9 * 240 < _curv(w[k, :, c], z) < 240.0
    # small: amplitudes of tens of µm; slopes up to ≈ 20° where the two modes add (6.4° rms)
    assert 10e-6 < np.abs(w).max() < 150e-6
    assert np.abs(np.diff(w, axis=1) / np.diff(z)[None, :, None]).max() < 0.35


def test_small_wavy_deposit_has_no_overlaps_and_the_asked_curvature():
    fibers, info = cassette_specimen(**KW, wave_curvature_per_m=240.0, wave_lengths_m=(1.8e-3, 2.5e-3), wave_modes=2)
    st = specimen_statistics(fibers, box_min_m=info["box_min_m"], box_max_m=info["box_max_m"])
    assert st["min_gap_m"] >= GAP - 1e-9 and st["min_gap_m"] <= GAP + 0.1e-6
    assert st["max_outside_m"] <= 1e-12
    assert info["deposit"]["wave_curvature_per_m"] == 240.0 and info["deposit"]["wave_modes"] == 2
    for plane in ("xz", "yz"):  # + the 0.384 1/m arc and the 0.25 mm spacing (≈ −5 %)
        assert st[f"curvature_{plane}_per_m"] == pytest.approx(240.0, rel=0.08)
    assert info["deposit"]["contacts"] >= 12
    again, _ = cassette_specimen(**KW, wave_curvature_per_m=240.0, wave_lengths_m=(1.8e-3, 2.5e-3), wave_modes=2)
    assert np.array_equal(fibers.points_m, again.points_m)


def test_no_waviness_is_the_plain_deposit_bit_for_bit():
    plain, _ = cassette_specimen(**KW)
    zero, info = cassette_specimen(**KW, wave_curvature_per_m=0.0, wave_lengths_m=(1e-3, 2e-3), wave_modes=5)
    assert np.array_equal(plain.points_m, zero.points_m)
    assert "wave_curvature_per_m" not in info["deposit"]
