"""Fiber-position error: the pruned one-to-one matching against the full cost matrix."""

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from fiberpipe.polylines import resample_arclength
from fiberpipe.post.positions import ReferenceMidlines, position_error


def _full_matrix_matching(sim_points, sim_offsets, ref_points, ref_offsets):
    """The reference: every simulated fiber's mean node distance to every densified reference line,
    then the Hungarian method on the whole matrix (the densification step as position_error's)."""
    step = max(float(np.median(np.linalg.norm(np.diff(ref_points, axis=0), axis=1))) / 10, 1e-9)
    trees = [cKDTree(resample_arclength(ref_points[ref_offsets[j]:ref_offsets[j + 1]], step))
             for j in range(len(ref_offsets) - 1)]
    cost = np.array([[np.mean(t.query(sim_points[sim_offsets[i]:sim_offsets[i + 1]])[0]) for t in trees]
                     for i in range(len(sim_offsets) - 1)])
    rows, cols = linear_sum_assignment(cost)
    return list(zip(rows.tolist(), cols.tolist())), cost[rows, cols]


def _wavy_bundle(centres_xy, rng, n_nodes=31, length=15e-3, amplitude=0.1e-3):
    """Quasi-parallel wavy fibers along z through the given (x, y) centres."""
    z = np.linspace(0.0, length, n_nodes)
    lines = []
    for cx, cy in centres_xy:
        k, phase = rng.uniform(1.0, 3.0), rng.uniform(0, 2 * np.pi)
        wave = amplitude * np.sin(2 * np.pi * k * z / length + phase)
        lines.append(np.column_stack([cx + wave, cy + 0.5 * wave, z]))
    return np.concatenate(lines), np.arange(len(lines) + 1) * n_nodes


def test_matching_equals_the_full_cost_matrix_on_a_shifted_shuffled_bundle():
    rng = np.random.default_rng(3)
    grid = np.array([(0.55e-3 * i, 0.5e-3 * j) for i in range(8) for j in range(6)])
    ref_points, ref_offsets = _wavy_bundle(grid, rng)
    # each fiber moved by up to a fiber spacing (compaction-like: mostly down), then shuffled
    n = len(grid)
    order = rng.permutation(n)
    shift = np.column_stack([rng.normal(0, 0.2e-3, n), rng.uniform(-0.6e-3, 0.0, n), np.zeros(n)])
    sim = [ref_points[ref_offsets[f]:ref_offsets[f + 1]] + shift[f] for f in order]
    sim_points, sim_offsets = np.concatenate(sim), np.arange(n + 1) * 31
    err = position_error(sim_points, sim_offsets, ref_points, ref_offsets)
    matched, costs = _full_matrix_matching(sim_points, sim_offsets, ref_points, ref_offsets)
    assert err["matched"] == matched
    np.testing.assert_allclose([err["per_fiber_m"][r] for r, _ in matched], costs, rtol=1e-12)


def test_matching_takes_far_reference_lines_when_the_near_ones_are_taken():
    # ten simulated fibers crowd around the first three of ten reference lines in a row: seven
    # of them must be matched to lines beyond their four nearest boxes, computed once the assignment asks
    rng = np.random.default_rng(5)
    ref_points, ref_offsets = _wavy_bundle([(1e-3 * i, 0.0) for i in range(10)], rng)
    sim_points, sim_offsets = _wavy_bundle([(0.2e-3 * i, 0.1e-3) for i in range(10)], rng)
    reference = ReferenceMidlines(ref_points, ref_offsets)
    err = position_error(sim_points, sim_offsets, reference=reference)
    matched, costs = _full_matrix_matching(sim_points, sim_offsets, ref_points, ref_offsets)
    assert err["matched"] == matched
    np.testing.assert_allclose([err["per_fiber_m"][r] for r, _ in matched], costs, rtol=1e-12)
    assert err["max_m"] > 5e-3  # the last simulated fibers really went to the far lines


def test_a_prepared_reference_gives_the_same_result_as_the_raw_polylines():
    rng = np.random.default_rng(7)
    ref_points, ref_offsets = _wavy_bundle([(0.6e-3 * i, 0.0) for i in range(6)], rng)
    sim_points = ref_points + np.array([0.0, -0.1e-3, 0.0])
    a = position_error(sim_points, ref_offsets, ref_points, ref_offsets)
    b = position_error(sim_points, ref_offsets, reference=ReferenceMidlines(ref_points, ref_offsets))
    assert a["matched"] == b["matched"] == [(i, i) for i in range(6)]
    assert a["mean_m"] == b["mean_m"] and a["p95_m"] == b["p95_m"]
    np.testing.assert_allclose(a["mean_m"], 0.1e-3, rtol=0.02)


def test_distances_to_a_line_equal_the_nearest_densified_point_by_brute_force():
    # a curled line (it turns back on itself, so a block far along the line can hold the nearest
    # point) and points all around it
    rng = np.random.default_rng(11)
    s = np.linspace(0.0, 3 * np.pi, 40)
    line = np.column_stack([np.cos(s), np.sin(s), 0.05 * s]) * 1e-3
    ref = ReferenceMidlines(line, np.array([0, len(line)]))
    dense = resample_arclength(line, ref.step_m)
    queries = rng.uniform(-1.5e-3, 1.5e-3, (500, 3))
    brute = np.sqrt(((queries[:, None, :] - dense[None]) ** 2).sum(axis=2)).min(axis=1)
    np.testing.assert_allclose(ref.distances(queries, 0), brute, rtol=1e-14, atol=0.0)
