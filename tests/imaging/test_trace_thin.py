"""dominant_axis on thin volumes: the structure-tensor subsample keeps at least 3 samples along
every axis (np.gradient needs 2), whatever the stride the voxel budget asks for elsewhere."""

import numpy as np
import pytest

from fiberpipe.imaging import trace as trace_mod
from fiberpipe.imaging.trace import dominant_axis


def _thin_mask(shape, thin_axis=0):
    """Fibers along x (axis 2), 7 voxels wide, spaced 12 along the other in-plane axis."""
    z, y, x = shape
    m = np.zeros((z, y, x), bool)
    for c in range(20, y - 20, 12):
        m[1:-1, c - 3:c + 4, 10:-10] = True
    return m if thin_axis == 0 else np.ascontiguousarray(m.transpose(1, 0, 2))


@pytest.mark.parametrize("thin_axis", [0, 1])
def test_thin_volume_is_subsampled_without_losing_its_thin_axis(thin_axis):
    # 3 x 600 x 600 voxels with a budget of 40 000: a single stride would be 3, leaving 1 sample
    # along the thin axis (np.gradient: "Shape of array too small")
    mask = _thin_mask((3, 600, 600), thin_axis)
    ax, d = dominant_axis(mask, 1.0, max_voxels=40_000)
    assert ax == 2 and abs(d[2]) > 0.99


def test_thin_volume_at_the_default_budget():
    # (3, 2400, 2400): 17 M voxels > 8 x the default 2 M, the size at which the old common
    # stride (3) cut the 3-voxel axis to a single sample
    mask = _thin_mask((3, 2400, 2400))
    ax, d = dominant_axis(mask, 1.0)
    assert ax == 2 and abs(d[2]) > 0.99


def test_the_subsample_keeps_three_samples_and_about_the_budget(monkeypatch):
    seen = {}
    real = trace_mod.ndi.gaussian_filter

    def spy(a, sigma):
        seen["shape"] = a.shape
        return real(a, sigma)

    monkeypatch.setattr(trace_mod.ndi, "gaussian_filter", spy)
    for shape, budget in [((3, 600, 600), 40_000), ((5, 600, 600), 40_000), ((4, 900, 7), 1_000),
                          ((120, 120, 120), 2_000_000), ((200, 200, 200), 100_000)]:
        dominant_axis(np.ones(shape, bool), 1.0, max_voxels=budget)
        sub = seen["shape"]
        assert min(sub) >= 3 or sub == shape, (shape, sub)
        assert all(s >= min(3, n) for s, n in zip(sub, shape)), (shape, sub)
        # the budget a capped axis leaves goes to the others: not far above it, nor far below
        assert np.prod(sub) <= 2 * budget, (shape, sub)
        if np.prod(shape) > budget:
            assert np.prod(sub) >= budget / 8, (shape, sub)
