import numpy as np
import pytest

from fiberpipe.errors import InputError
from fiberpipe.imaging.phantom import make_phantom, render_polylines
from fiberpipe.imaging._util import xyz_m_to_voxel


def test_phantom_geometry_and_determinism():
    vol, truth = make_phantom(n_fibers=20, shape=(80, 80, 80), radius_vox=4.0, seed=5)
    vol2, truth2 = make_phantom(n_fibers=20, shape=(80, 80, 80), radius_vox=4.0, seed=5)
    assert vol.dtype == np.float32 and vol.shape == (80, 80, 80)
    assert np.array_equal(vol, vol2) and np.array_equal(truth.points_m, truth2.points_m)
    assert truth.n_fibers == 20 and np.allclose(truth.radius_m, 4 * truth.meta["voxel_size_m"])
    # default voxel size: 0.5 mm diameter fibers
    assert np.isclose(2 * truth.radius_m[0], 0.5e-3)
    touching = truth.meta["touching"]
    assert touching.sum() == 2 * round(20 / 3 / 2)
    # one point per slice, no two fibers overlap, touching pairs at exactly 2 r
    vs = truth.meta["voxel_size_m"]
    P = np.stack([xyz_m_to_voxel(f, vs) for f in truth])  # (F, Z, 3) z y x
    assert P.shape == (20, 80, 3)
    d = np.linalg.norm(P[:, None, :, 1:] - P[None, :, :, 1:], axis=-1).min(axis=2)
    np.fill_diagonal(d, np.inf)
    assert d.min() >= 8.0 - 1e-9
    assert np.sum(np.isclose(d, 8.0)) == touching.sum()  # symmetric pairs


def test_render_matches_phantom_and_contrast():
    vol, truth = make_phantom(n_fibers=10, shape=(60, 60, 60), contrast_to_noise=0, blur_sigma_vox=0,
                              seed=2)
    again = render_polylines(truth, vol.shape, truth.meta["voxel_size_m"], blur_sigma_vox=0,
                             contrast_to_noise=None)
    # rendering the (clipped) truth reproduces the phantom away from the end slices
    assert np.abs(again[8:-8] - vol[8:-8]).max() < 1e-5
    assert vol.max() == pytest.approx(1.0) and vol.min() == 0.0
    noisy = render_polylines(truth, vol.shape, truth.meta["voxel_size_m"], blur_sigma_vox=0,
                             contrast_to_noise=4.0, seed=1)
    assert np.std(noisy[vol == 0]) == pytest.approx(0.25, rel=0.05)
    u16 = render_polylines(truth, vol.shape, truth.meta["voxel_size_m"], dtype="uint16")
    assert u16.dtype == np.uint16


def test_too_many_fibers_is_an_input_error():
    with pytest.raises(InputError, match="cannot place"):
        make_phantom(n_fibers=200, shape=(40, 40, 40), radius_vox=5, max_attempts=200)


def test_fibers_that_do_not_fit_the_shape_are_an_input_error():
    """shape (10, 10, 10) with radius 8 voxels failed inside numpy ("high - low < 0")."""
    from fiberpipe.imaging.phantom import min_cross_section_vox

    with pytest.raises(InputError) as err:
        make_phantom(n_fibers=1, shape=(10, 10, 10), radius_vox=8)
    msg = str(err.value)
    assert "radius 8 voxels do not fit the 10x10 (y x) cross-section" in msg and "at least 19 voxels" in msg
    assert "at most 3.5" in msg and "high - low" not in msg
    assert min_cross_section_vox(8) == 19
    vol, truth = make_phantom(n_fibers=1, shape=(10, 19, 19), radius_vox=8, waviness_vox=0, max_tilt=0)
    assert vol.shape == (10, 19, 19) and truth.n_fibers == 1
    with pytest.raises(InputError, match="shape must be 3 positive sizes"):
        make_phantom(n_fibers=1, shape=(10, 0, 10), radius_vox=2)
    with pytest.raises(InputError, match="radius_vox must be positive"):
        make_phantom(n_fibers=1, shape=(10, 10, 10), radius_vox=0)


def test_config_refuses_a_phantom_whose_fibers_do_not_fit(write_yaml):
    from fiberpipe.config import load_config
    from fiberpipe.errors import ConfigError

    p = write_yaml("name: p\ninput:\n  phantom: {shape: [10, 10, 10], radius_vox: 8}\n")
    with pytest.raises(ConfigError) as err:
        load_config(p)
    msg = str(err.value)
    assert msg.startswith(f"{p}: input.phantom.radius_vox = 8 voxels does not fit input.phantom.shape")
    assert "at least 19 voxels" in msg and "at most 3.5" in msg
    load_config(write_yaml("name: p\ninput:\n  phantom: {shape: [10, 19, 19], radius_vox: 8}\n", "ok.yaml"))
