"""The solver bench's bundles: the squeezed grid scales laterally and its walls press the outer fibers
as hard as the fibers press each other, whatever the bundle's size."""

import numpy as np
import pytest

from fiberpipe.benchmarks.bench_solver import R, bundle, confining_walls, grid_shape


@pytest.mark.parametrize("n_fibers, shape", [(40, (8, 5)), (160, (16, 10)), (640, (32, 20)), (1000, (40, 25))])
def test_bench_grids_are_the_40_fiber_grid_scaled_laterally(n_fibers, shape):
    assert grid_shape(n_fibers) == shape


@pytest.mark.parametrize("n_fibers", [40, 160])
def test_squeezed_bundle_walls_press_the_outer_fibers_by_half_the_mutual_overlap(n_fibers):
    pitch_r = 1.98
    model = bundle(n_fibers, pitch_r=pitch_r, wave=0.0)
    walls = confining_walls(n_fibers, pitch_r)
    x = np.asarray(model.nodes_m)
    overlap_with_neighbour = (2.0 - pitch_r) * R
    for axis, (low, high) in walls.planes.items():
        c = "xy".index(axis)
        # a fiber's surface beyond each wall by half its overlap with a neighbour
        assert x[:, c].min() - R - low == pytest.approx(-0.5 * overlap_with_neighbour, rel=1e-9)
        assert high - (x[:, c].max() + R) == pytest.approx(-0.5 * overlap_with_neighbour, rel=1e-9)
    assert confining_walls(n_fibers, 2.2) is None
