"""A new contact law is one class with its jitted force functions plus one registry entry: a toy
linear penalty with its own name, registered here, run from a YAML config through ``fiberpipe run``,
and its force checked against its formula (the worked example of docs/solver.md)."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from numba import njit

from fiberpipe.artifacts import read_artifact
from fiberpipe.solver import laws


@njit(cache=False)
def _toy_line(law_id, params, delta, r1, r2):
    """p = k δ [N/m] and its energy per length ½ k δ² [J/m]."""
    if delta <= 0.0:
        return 0.0, 0.0
    return params[0] * delta, 0.5 * params[0] * delta * delta


@njit(cache=False)
def _toy_point(law_id, params, delta, r1, r2, phi):
    """F = k ℓ_ref δ [N] (a crossing carries the line law over ℓ_ref)."""
    if delta <= 0.0:
        return 0.0, 0.0
    k = params[0] * params[1]
    return k * delta, 0.5 * k * delta * delta


@njit(cache=False)
def _toy_weight_point(law_id, params, delta, r1, r2, phi):
    """Point share 0: the toy law is distributed only."""
    f, e = _toy_point(law_id, params, delta, r1, r2, phi)
    return 0.0, f, e


class ToyLinearLaw(laws.ContactLaw):
    """p = k δ per unit length, k = ``contact.stiffness`` in N/m²."""

    name = "toy_linear"
    kernels = (_toy_line, _toy_point, _toy_weight_point)

    def __init__(self, stiffness_n_per_m2: float, **kw):
        super().__init__(**kw)
        if not stiffness_n_per_m2 > 0:
            raise ValueError(f"toy_linear: stiffness must be > 0, got {stiffness_n_per_m2}")
        self.stiffness_n_per_m2 = float(stiffness_n_per_m2)

    @classmethod
    def check_config(cls, cfg):
        if cfg.stiffness is None:
            raise ValueError("contact.law 'toy_linear' needs contact.stiffness (N/m²)")

    @classmethod
    def from_config(cls, cfg, *, E_pa, nu):
        return cls(float(cfg.stiffness), E_pa=E_pa, nu=nu)

    def params(self):
        return np.array([self.stiffness_n_per_m2, self.ref_length_m])


@pytest.fixture
def toy_law():
    laws.register_law(ToyLinearLaw)
    yield ToyLinearLaw
    laws.LAWS.pop(ToyLinearLaw.name)


def _pressed_pair(stiffness: float, line_load: float) -> dict:
    """Two parallel 3 mm fibers, the lower clamped at every node, the upper pressed onto it."""
    return {
        "name": "toy-law",
        "input": {"polylines": [[[0, 0, "0.25 mm"], ["3 mm", 0, "0.25 mm"]],
                                [[0, 0, "0.75 mm"], ["3 mm", 0, "0.75 mm"]]]},
        "mesh": {"element_length": "0.3 mm", "resolve_overlaps": False},
        "material": {"youngs_modulus": "15 GPa", "poisson_ratio": 0.3, "density": "1380 kg/m^3"},
        "fiber": {"radius": "0.25 mm"},
        "scene": {"effects": ["contact", "clamps", "loads", "damping"],
                  "contact": {"law": "toy_linear", "stiffness": stiffness},
                  "clamps": [{"fiber": 0, "at": k} for k in range(11)],
                  "loads": [{"fiber": 1, "line_force": [0, 0, -line_load]}],
                  "damping": {"alpha": "2e6 1/s"}},
        "solver": {"end_time": "0.3 ms", "output_frames": 2},
        "post": {"plots": False},
    }


@pytest.mark.slow  # compiles the contact pass and a step loop for the toy law: ~40 s (make test-all)
def test_registered_law_runs_from_yaml_and_gives_its_formula(toy_law, tmp_path):
    from _scenes import cli

    k, q = 1e9, 66.0  # N/m², N/m: the law's δ = q/k = 66 nm
    cfg = tmp_path / "toy.yaml"
    cfg.write_text(yaml.safe_dump(_pressed_pair(k, q)))
    res = cli("--quiet", "run", cfg, "--out", tmp_path / "run", "--to", "simulate")
    assert res.exit_code == 0, res.output
    sim = read_artifact(tmp_path / "run" / "simulation.h5", "simulation")
    x = np.asarray(sim["frames/positions"])[-1]
    n = x.shape[0] // 2
    gap = x[n + 1:2 * n - 1, 2] - x[1:n - 1, 2]     # centre-line distance at the interior nodes
    delta = 2 * 0.25e-3 - gap
    # static equilibrium: the contact line load k δ balances the applied q at every interior node
    assert k * delta == pytest.approx(np.full_like(delta, q), rel=0.01)


def test_unregistered_law_is_refused_with_the_choices(tmp_path):
    from _scenes import cli

    cfg = tmp_path / "toy.yaml"
    cfg.write_text(yaml.safe_dump(_pressed_pair(1e9, 66.0)))
    res = cli("run", cfg, "--out", tmp_path / "run")
    assert res.exit_code != 0
    assert "toy_linear" in res.output and "hertz_oriented" in res.output and "Traceback" not in res.output
