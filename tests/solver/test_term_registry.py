"""A new physical term is one class with its jitted eval plus one registry line: springs tying every
node to its rest position, defined here, run from a YAML config through ``fiberpipe run``, and its
force and its energy slot checked against their formulas (the worked example of docs/solver.md)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pytest
import yaml
from numba import njit

from fiberpipe.artifacts import read_artifact
from fiberpipe.config import Section
from fiberpipe.solver import TERMS, Term, register_term
from fiberpipe.solver.layout import ACC_PW, ACC_STORED

G = 9.81        # m/s²
RATE = 1.6e8    # 1/s², the springs' stiffness per kg of node mass (ω = 12.6e3 rad/s)


class SpringsConfig(Section):
    """``scene.springs``: the stiffness per kg of node mass [N/(m·kg) = 1/s²]."""

    stiffness_per_kg: float = 1e6


class SpringsData(NamedTuple):
    stiffness: np.ndarray  # (N,) N/m per node, c m_i
    x0: np.ndarray         # (N, 3) m, rest positions
    energy: np.ndarray     # (1,) J, the springs' energy ½ Σ k_i |x_i − x0_i|² (the energy slot)


@njit(cache=False)
def _springs_eval(x, q, v, w, f, mom, acc, t, dt, data):
    """f_i −= k_i (x_i − x0_i); the springs' energy to their slot and to the stored energy, their work
    on the fibers (−ΔE) to ALLPW."""
    e = 0.0
    for i in range(x.shape[0]):
        k = data.stiffness[i]
        for c in range(3):
            d = x[i, c] - data.x0[i, c]
            f[i, c] -= k * d
            e += 0.5 * k * d * d
    acc[ACC_STORED] += e
    acc[ACC_PW] -= e - data.energy[0]
    data.energy[0] = e
    return 0


class Springs(Term):
    """Springs of stiffness c m_i tying node i to its rest position (a foundation per unit mass)."""

    name = "springs"
    config_block = SpringsConfig
    energies = ("springs",)
    eval = staticmethod(_springs_eval)

    def __init__(self, stiffness_per_kg: float):
        if not stiffness_per_kg > 0:
            raise ValueError(f"springs.stiffness_per_kg must be > 0, got {stiffness_per_kg}")
        self.stiffness_per_kg = float(stiffness_per_kg)

    @classmethod
    def from_config(cls, scene_cfg, model, cfg):
        return cls(scene_cfg.block("springs").stiffness_per_kg)

    def setup(self, model, scene):
        return SpringsData(self.stiffness_per_kg * np.asarray(model.mass, dtype=np.float64),
                           np.array(model.nodes_m, dtype=np.float64), np.zeros(1))


@pytest.fixture
def springs_term():
    register_term()(Springs)  # the one registry line
    yield Springs
    TERMS.pop(Springs.name)


def _hanging_fiber(rate: float) -> dict:
    """A free 3 mm fiber under gravity, held by the springs and damped critically."""
    return {
        "name": "springs",
        "input": {"polylines": [[[0, 0, 0], ["3 mm", 0, 0]]]},
        "mesh": {"element_length": "0.3 mm", "resolve_overlaps": False},
        "material": {"youngs_modulus": "15 GPa", "poisson_ratio": 0.3, "density": "1380 kg/m^3"},
        "fiber": {"radius": "0.25 mm"},
        "scene": {"effects": ["springs", "gravity", "damping"],
                  "springs": {"stiffness_per_kg": rate},
                  "gravity": {"acceleration": [0, 0, -G]},
                  "damping": {"alpha": f"{2 * rate ** 0.5} 1/s"}},
        "solver": {"end_time": "2 ms", "output_frames": 2},
        "post": {"plots": False},
    }


def test_registered_term_runs_from_yaml_and_gives_its_formula(springs_term, tmp_path):
    from _scenes import cli

    cfg = tmp_path / "springs.yaml"
    cfg.write_text(yaml.safe_dump(_hanging_fiber(RATE)))
    res = cli("--quiet", "run", cfg, "--out", tmp_path / "run", "--to", "simulate")
    assert res.exit_code == 0, res.output
    sim = read_artifact(tmp_path / "run" / "simulation.h5", "simulation")
    x = np.asarray(sim["frames/positions"])
    dz = x[-1, :, 2] - x[0, :, 2]
    # the force: at rest k_i dz_i = m_i g with k_i = c m_i, so every node hangs by g/c (a rigid
    # translation: the beam carries nothing)
    assert dz == pytest.approx(np.full_like(dz, -G / RATE), rel=1e-6)
    # the energy slot: ½ Σ c m_i dz² = ½ (g²/c) Σ m_i, the fiber's mass ρ A L
    mass = 1380.0 * np.pi * 0.25e-3 ** 2 * 3e-3
    energy = np.asarray(sim["history/energy/springs"])
    assert energy[-1] == pytest.approx(0.5 * G * G / RATE * mass, rel=1e-6)
    # and the books close: the springs' work is booked as contact work (ALLPW)
    total = np.asarray(sim["history/energy/total"])
    assert abs(total[-1]) < 1e-6 * energy[-1]


def test_an_unregistered_term_is_refused_naming_the_key(tmp_path):
    from _scenes import cli

    cfg = tmp_path / "springs.yaml"
    cfg.write_text(yaml.safe_dump(_hanging_fiber(RATE)))
    res = cli("run", cfg, "--out", tmp_path / "run")
    assert res.exit_code != 0
    assert "scene.effects" in res.output and "springs" in res.output and "Traceback" not in res.output


def test_a_term_block_is_validated_by_its_section(springs_term, tmp_path):
    from _scenes import cli

    bad = _hanging_fiber(RATE)
    bad["scene"]["springs"] = {"stiffnes_per_kg": RATE}
    cfg = tmp_path / "springs.yaml"
    cfg.write_text(yaml.safe_dump(bad))
    res = cli("run", cfg, "--out", tmp_path / "run")
    assert res.exit_code != 0
    assert "scene.springs.stiffnes_per_kg" in res.output and "Traceback" not in res.output


@njit(cache=False)
def _allocating_springs_eval(x, q, v, w, f, mom, acc, t, dt, data):
    """The springs' eval computing its displacements into a fresh array (an allocation)."""
    d = x - data.x0
    for i in range(x.shape[0]):
        for c in range(3):
            f[i, c] -= data.stiffness[i] * d[i, c]
    return 0


def test_an_eval_that_does_not_choose_reference_counts_gets_a_copy_that_keeps_them():
    """The step loop's body runs without numba's reference counts, which a callee inherits unless it
    chooses its own: a term's eval that does not choose is called through a copy that keeps them
    (so it may allocate); one that chooses (the contact term's) or is inlined is called as it is."""
    from fiberpipe.solver._kernels_integrate import _with_counts
    from fiberpipe.solver.terms.contact import contact_step
    from fiberpipe.solver.terms.planes import eval_plane_friction

    copy = _with_counts(_allocating_springs_eval, "allocating_springs_counted")
    assert copy is not _allocating_springs_eval and copy.targetoptions["_nrt"] is True
    assert copy.py_func.__code__ is _allocating_springs_eval.py_func.__code__
    assert _with_counts(contact_step, "contact") is contact_step
    assert _with_counts(eval_plane_friction, "plane_friction") is eval_plane_friction


@pytest.mark.slow
def test_a_term_eval_that_allocates_runs_in_the_step_loop():
    """The step loop's body runs without numba's reference counts; a term's eval that allocates (and
    does not choose them itself) still compiles and runs, and gives the same forces as one that does
    not (the same positions to the last bit after the fiber falls under gravity against them)."""
    from fiberpipe.solver import Gravity, Material, SimulationSettings, build_model, simulate

    s = np.linspace(0.0, 1.0, 6)[:, None]
    model = build_model(s * np.array([3e-3, 0.0, 0.0]), np.array([0, 6]), 0.25e-3, Material(15e9, 1380.0, 0.3))

    class AllocatingSprings(Springs):
        eval = staticmethod(_allocating_springs_eval)

    finals = []
    for term in (Springs(RATE), AllocatingSprings(RATE)):
        result = simulate(model, [Gravity((0.0, -G, 0.0)), term], SimulationSettings(end_time_s=2e-6, output_frames=2))
        finals.append(result.frames_positions[-1])
    assert np.abs(finals[0] - model.nodes_m).max() > 0.0  # the nodes moved
    assert np.array_equal(finals[0], finals[1])
