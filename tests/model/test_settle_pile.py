"""data-samples/make_paper40.py --settle: the deposited pile settled in the solver under gravity
with friction, its settled mid-lines taken as the specimen and the upper plate put on
the settled top."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest


R = 0.25e-3
SCRIPT = Path(__file__).resolve().parents[2] / "data-samples" / "make_paper40.py"


def _make_paper40():
    spec = importlib.util.spec_from_file_location("make_paper40", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def small(small_deposit):
    return small_deposit  # tests/model/conftest.py: the deposit tests' pile


def test_settle_pile_is_deterministic_and_puts_the_plate_on_the_settled_top(small):
    mp = _make_paper40()
    fibers, info = small
    # 2 ms: the lower fibers first sink into the plate penalty's onset (δ_s/2 = 0.5 µm), the pile follows
    a, ia = mp.settle_pile(fibers, info, time_s=2e-3, frames=3, lock="all")
    b, _ = mp.settle_pile(fibers, info, time_s=2e-3, frames=3, lock="all")
    assert np.array_equal(a.points_m, b.points_m)  # one thread: bit for bit
    pts = a.points_m
    assert ia["height_m"] == pytest.approx(float(np.max(pts[:, 1] + R)) + 1e-6, abs=1e-12)
    n, w, L = 12, 1.5e-3, 6e-3
    assert ia["volume_fraction"] == pytest.approx(n * np.pi * R**2 / (w * ia["height_m"]))
    s = ia["settle"]
    assert s["lock_axial"] == "all" and s["mu"] == 0.2 and s["steps"] > 0
    assert 0 < s["max_displacement_m"] < 0.5 * R  # 2 ms of falling at most ≈ 20 µm
    assert ia["height_m"] <= info["height_m"] + 1e-9  # the pile sinks, never rises
    assert s["fiber_contacts"] >= 1


def test_fiber_contacts_counts_touching_pairs_once():
    mp = _make_paper40()
    z = np.linspace(0, 3e-3, 11)
    x = np.concatenate([np.c_[0 * z, 0 * z + R, z], np.c_[0 * z, 0 * z + 3 * R - 1e-8, z],
                        np.c_[0 * z + 5 * R, 0 * z + R, z]])
    off = np.array([0, 11, 22, 33])
    assert mp.fiber_contacts(x, off, R) == 1  # 0–1 touch (10 nm overlap), 2 is 0.75 mm away


def test_command_line_defaults_follow_the_variant():
    """make_paper40's options: the shipped defaults, --wavy's own, and what is given always wins."""
    mp = _make_paper40()
    plain = mp.options([])
    assert (plain.out, plain.candidates, plain.wave_curvature, plain.settle_mass_scaling) == (
        mp.OUT, mp.DEPOSIT_CANDIDATES, 0.0, None)
    wavy = mp.options(["--wavy"])
    for key, (_, w) in mp.VARIANT_DEFAULTS.items():
        assert getattr(wavy, key) == w, key
    given = mp.options(["--wavy", "--settle-time", "0.2", "--out", "elsewhere", "--candidates", "3"])
    assert (given.settle_time, str(given.out), given.candidates) == (0.2, "elsewhere", 3)
    assert given.settle_alpha == mp.WAVY_SETTLE_ALPHA_PER_S
