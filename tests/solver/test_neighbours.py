"""Cell list + Verlet list against a brute-force all-pairs reference (the code never loops over all pairs)."""

import os

import numpy as np
import pytest

from _contact_geometry import LE, R
from fiberpipe.solver.geometry import segment_distance2
from fiberpipe.solver.neighbours import VerletList, build_pairs, max_displacement_exceeds, segment_arclength


def random_bundle(n_fib, n_el, seed, box=2.5e-3):
    """Quasi-parallel wavy fibers along x, random positions in a box (overlaps allowed)."""
    rng = np.random.default_rng(seed)
    xs, segs, fib = [], [], []
    off = 0
    for k in range(n_fib):
        y0, z0 = rng.uniform(0, box, 2)
        th = rng.normal(0, 0.15, 2)
        s = np.arange(n_el + 1) * LE
        amp = rng.uniform(0, 0.3e-3)
        xf = np.stack([s, y0 + th[0] * s + amp * np.sin(s / 2e-3 + k), z0 + th[1] * s], axis=1)
        if k % 7 == 3:  # a U-turned fiber: far parts of the same fiber can touch
            half = n_el // 2
            xf[half:, 0] = xf[half, 0] - (xf[half:, 0] - xf[half, 0])
            xf[half:, 1] += np.linspace(0, 2 * R, n_el + 1 - half)
        xs.append(xf)
        segs += [[off + i, off + i + 1] for i in range(n_el)]
        fib += [k] * n_el
        off += n_el + 1
    seg = np.array(segs, np.int64)
    fib = np.array(fib, np.int64)
    x = np.vstack(xs)
    return x, seg, np.full(len(seg), R), fib


def brute_force(x, seg, rad, fib, arc, skin, s_excl):
    out = set()
    for i in range(len(seg)):
        for j in range(i + 1, len(seg)):
            if set(seg[i]) & set(seg[j]):
                continue
            if fib[i] == fib[j] and max(arc[i, 0], arc[j, 0]) - min(arc[i, 1], arc[j, 1]) < s_excl:
                continue
            a0, a1, b0, b1 = x[seg[i, 0]], x[seg[i, 1]], x[seg[j, 0]], x[seg[j, 1]]
            d2, _, _ = segment_distance2(a0, a1, b0, b1, a1 - a0, b1 - b0)
            if d2 < (rad[i] + rad[j] + skin) ** 2:
                out.add((i, j))
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_same_pairs_as_brute_force(seed):
    x, seg, rad, fib = random_bundle(14, 12, seed)
    arc = segment_arclength(seg, fib, x)
    skin = 0.1e-3
    vl = VerletList(seg, rad, fib, arc, skin_m=skin, capacity=4)  # tiny capacity: growth path
    vl.build(x)
    got = {tuple(p) for p in vl.pairs[: vl.n_pairs]}
    ref = brute_force(x, seg, rad, fib, arc, skin, vl.s_excl_m)
    assert got == ref and len(ref) > 20
    k = vl.keys[: vl.n_pairs]
    assert np.all(np.diff(k) > 0) and np.all(k == vl.pairs[: vl.n_pairs, 0] * len(seg) + vl.pairs[: vl.n_pairs, 1])
    # same-fiber contacts between far parts exist in the U-turned fibers
    same = [(i, j) for i, j in ref if fib[i] == fib[j]]
    assert len(same) > 0


def test_overflow_returns_needed_count():
    x, seg, rad, fib = random_bundle(10, 10, 5)
    arc = segment_arclength(seg, fib, x)
    pairs = np.zeros((2, 2), np.int64)
    keys = np.zeros(2, np.int64)
    n = build_pairs(x, seg, rad, fib, arc, 1e-4, 5e-4, pairs, keys)
    big = np.zeros((1000, 2), np.int64)
    n2 = build_pairs(x, seg, rad, fib, arc, 1e-4, 5e-4, big, np.zeros(1000, np.int64))
    assert n == -n2 and n2 > 2


def test_rebuild_cadence_half_skin():
    x, seg, rad, fib = random_bundle(6, 8, 3)
    vl = VerletList(seg, rad, fib, segment_arclength(seg, fib, x), skin_m=0.1e-3)
    assert vl.update(x) and vl.n_builds == 1
    y = x.copy()
    y[5, 1] += 0.049e-3  # < skin/2
    assert not vl.update(y) and vl.n_builds == 1
    y[7, 2] += 0.051e-3  # another node > skin/2
    assert vl.update(y) and vl.n_builds == 2
    assert not max_displacement_exceeds(y, vl.x_ref, 0.05e-3)


def test_list_valid_until_rebuild():
    """Between rebuilds (every node moves < skin/2), every pair in contact is in the list."""
    x, seg, rad, fib = random_bundle(12, 10, 7)
    arc = segment_arclength(seg, fib, x)
    skin = 0.1e-3
    vl = VerletList(seg, rad, fib, arc, skin_m=skin)
    vl.build(x)
    rng = np.random.default_rng(1)
    y = x + rng.uniform(-1, 1, x.shape) * (0.499 * skin / np.sqrt(3))
    assert not vl.needs_rebuild(y)
    touching = brute_force(y, seg, rad, fib, arc, 0.0, vl.s_excl_m)
    assert touching <= {tuple(p) for p in vl.pairs[: vl.n_pairs]}


def test_scales_linearly():
    """Build time per segment roughly independent of N (cell list, no all-pairs loop)."""
    import time

    times = []
    for nf in (40, 320):
        x, seg, rad, fib = random_bundle(nf, 50, 11, box=2.5e-3 * np.sqrt(nf / 40))
        vl = VerletList(seg, rad, fib, segment_arclength(seg, fib, x), skin_m=0.05e-3)
        vl.build(x)
        t = time.perf_counter()
        for _ in range(3):
            vl.build(x)
        times.append((time.perf_counter() - t) / 3 / len(seg))
    assert times[1] < 3.0 * times[0]


@pytest.mark.skipif(not os.environ.get("FIBERPIPE_TEST_THREADS"),
                    reason="runs on two threads in test_contact_schedule's process of its own (one compile)")
def test_threaded_build_lists_the_serial_builds_pairs():
    """solver.threads > 1 builds the list in prange tasks of consecutive segments, each into its own
    share of the buffer, joined in task order: the same pairs and keys as the serial build, bit for
    bit, with two threads running the tasks; a buffer too small for the fullest task's share asks for
    enough (−needed), and a buffer of that size gets the list."""
    import numba

    from fiberpipe.solver.neighbours import SEGMENT_TASK_MIN, SEGMENT_TASKS, build_pairs_threads

    assert numba.get_num_threads() == int(os.environ["FIBERPIPE_TEST_THREADS"])
    n_fib = SEGMENT_TASKS * SEGMENT_TASK_MIN // 40
    x, seg, rad, fib = random_bundle(n_fib, 40, 4, box=2.5e-3 * np.sqrt(n_fib / 14))
    arc = segment_arclength(seg, fib, x)
    lists = []
    for build in (build_pairs, build_pairs_threads):
        n = build(x, seg, rad, fib, arc, 0.05e-3, 0.5e-3, np.zeros((8, 2), np.int64), np.zeros(8, np.int64))
        assert n < -8
        pairs, keys = np.full((-n, 2), -1, np.int64), np.zeros(-n, np.int64)
        n = build(x, seg, rad, fib, arc, 0.05e-3, 0.5e-3, pairs, keys)
        lists.append((pairs[:n], keys[:n]))
    (p1, k1), (p2, k2) = lists
    assert len(p1) > 4 * len(seg) // 10 and np.array_equal(p1, p2) and np.array_equal(k1, k2)
    assert np.all(np.diff(k1) > 0)


def test_the_cell_grid_is_bounded_by_the_segment_count_however_far_apart_the_segments():
    """Memory O(E): a few segments spread over a metre get at most 4 E + 64 cells (the cells grow),
    not (1 m / h)³; two segments a metre apart are no candidates."""
    from fiberpipe.solver.neighbours import _cell_grid

    h, nc, tot = _cell_grid(np.zeros(3), np.ones(3), 1e-3, 100)
    assert tot == int(np.prod(nc)) and tot <= 4 * 100 + 64 and h >= 1e-3
    x = np.array([[0.0, 0, 0], [LE, 0, 0], [1.0, 1.0, 1.0], [1.0 + LE, 1.0, 1.0]])
    seg = np.array([[0, 1], [2, 3]], np.int64)
    pairs, keys = np.zeros((4, 2), np.int64), np.zeros(4, np.int64)
    n = build_pairs(x, seg, np.full(2, R), np.array([0, 1], np.int64), np.zeros((2, 2)), 0.05e-3, 0.0, pairs, keys)
    assert n == 0
