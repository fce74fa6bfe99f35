"""An undamped free fiber keeps the energy of a tiny kick (the discrete beam is conservative).

Known limit (docs/results.md, "A solver limit found with the wavy fibers"): for a large rest
curvature per element (the wavy variant's 2 mm waves: ≈ 0.07 rad per 0.3 mm element) the discrete
moments are the gradient of the bending energy only to O(|θ|²), and the kinetic energy of a 1e-24 J
kick grows to ~1e-9 J in 11 ms at any time step. That case is an expected failure (strict: it will
flag when the beam is fixed); the shipped, nearly straight fibers must keep the kick's energy.
"""

from pathlib import Path

import numpy as np
import pytest

from fiberpipe.artifacts import read_fibers
from fiberpipe.config import load_config
from fiberpipe.model.mesh import mesh_polylines
from fiberpipe.polylines import Polylines
from fiberpipe.solver.build import build_simulation
from fiberpipe.solver.integrator import Integrator, choose_time_step
from fiberpipe.solver.state import State

ROOT = Path(__file__).resolve().parents[2]


def _kick_growth(fibers_h5: Path, fiber: int, lock: bool) -> float:
    """Kinetic energy after 11 ms over the kick's, one free fiber, α = 0, no gravity or contact."""
    fib = read_fibers(fibers_h5)
    cfg = load_config(ROOT / "configs" / "paper-40.yaml",
                      {"scene.effects": ["constraints"] if lock else [], "scene.damping.alpha": "0 1/s"})
    mesh = mesh_polylines(Polylines.from_list([fib.fiber(fiber)], 0.25e-3), cfg.mesh.element_length,
                          radius_m=cfg.fiber.radius)
    model, effects, settings = build_simulation(mesh, cfg)
    dt, _ = choose_time_step(model, effects, settings)
    st = State.at_rest(model)
    st.v[:] = 1e-9 * np.random.default_rng(0).normal(size=st.v.shape)
    if lock:
        st.v[:, 2] = 0.0
    ke0 = 0.5 * np.sum(model.mass[:, None] * st.v**2)
    Integrator(model, effects, dt, history_rows=10, history_every=10**9).advance(st, int(round(11e-3 / dt)))
    return float(0.5 * np.sum(model.mass[:, None] * st.v**2) / ke0)


@pytest.mark.parametrize("fiber", [3, 20])
def test_shipped_fibers_keep_the_kick_energy(fiber):
    assert _kick_growth(ROOT / "data-samples" / "paper-40" / "fibers.h5", fiber, lock=True) < 10.0


@pytest.mark.xfail(strict=True, reason="discrete beam not exactly conservative at large rest curvature "
                                       "per element (docs/results.md)")
def test_wavy_fiber_keeps_the_kick_energy():
    assert _kick_growth(ROOT / "data-samples" / "paper-40-wavy" / "fibers.h5", 3, lock=True) < 10.0
