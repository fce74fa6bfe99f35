"""An undamped free fiber keeps the energy of a tiny kick (the discrete beam is conservative).

For a large rest curvature per element (the wavy variant's 2 mm waves: up to ≈ 0.2 rad per 0.3 mm
element) the first-order moment pair of the earlier kernel was the gradient of the strain energy only
to O(|θ|) and the kinetic energy of a 1e-24 J kick grew to ~1e-9 J in 11 ms at any time step; the
kernel's moments are now the exact gradient for elements with a curved rest shape (test_beam_solver's
finite-difference check); straight ones (rest rotation ≤ 1e-3 rad, the shipped fibers) keep the
cheaper first-order pair and must keep the kick's energy too.
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


def test_wavy_fiber_keeps_the_kick_energy():
    assert _kick_growth(ROOT / "data-samples" / "paper-40-wavy" / "fibers.h5", 3, lock=True) < 10.0


def _qmul(a, b):
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def _qexp(v):
    t = np.linalg.norm(v)
    return np.concatenate([[np.cos(t / 2)], np.sin(t / 2) * v / t]) if t > 0 else np.array([1.0, 0, 0, 0])


@pytest.mark.parametrize("n_nodes", [9, 81])  # ≈ 0.5 and 0.05 rad of rest rotation per element
def test_beam_forces_are_the_exact_energy_gradient(n_nodes):
    """Nodal forces and moments = −∂W/∂(x, φ) (spatial spins, R ← exp(δφ) R) of a strongly curved,
    deformed helix, by central differences of the kernel's strain energy."""
    from fiberpipe.solver import Material, build_model
    from fiberpipe.solver._kernels_beam import beam_forces
    s = np.linspace(0, 1.2 * 2 * np.pi, n_nodes)
    x0 = np.column_stack([2e-3 * np.cos(s), 2e-3 * np.sin(s), 6e-3 * s / (2 * np.pi)])
    m = build_model(x0, [0, n_nodes], 0.25e-3, Material(15e9, 1380.0, 0.3))
    rng = np.random.default_rng(2)
    x = m.nodes_m + 2e-6 * rng.normal(size=m.nodes_m.shape)
    q = np.array([_qmul(_qexp(0.02 * rng.normal(size=3)), qq) for qq in m.quats0])

    def run(xx, qq):
        f = np.zeros_like(xx)
        mo = np.zeros_like(xx)
        se, _ = beam_forces(xx, qq, m.el_n1, m.el_invL0, m.el_C, m.el_Dk, m.gamma_rest, m.theta_rest,
                            f, mo, True, 0.0, np.zeros((0, 6)))
        return se, f, mo

    _, f, mo = run(x, q)
    fd_f = np.zeros_like(f)
    fd_m = np.zeros_like(mo)
    hx, hr = 1e-10, 1e-7
    for i in range(n_nodes):
        for c in range(3):
            d = np.zeros(3)
            d[c] = 1.0
            fd_f[i, c] = -(run(x + hx * np.outer(np.arange(n_nodes) == i, d), q)[0]
                           - run(x - hx * np.outer(np.arange(n_nodes) == i, d), q)[0]) / (2 * hx)
            qp = q.copy()
            qm = q.copy()
            qp[i] = _qmul(_qexp(hr * d), q[i])
            qm[i] = _qmul(_qexp(-hr * d), q[i])
            fd_m[i, c] = -(run(x, qp)[0] - run(x, qm)[0]) / (2 * hr)
    assert np.abs(f - fd_f).max() < 1e-6 * np.abs(fd_f).max()
    assert np.abs(mo - fd_m).max() < 1e-6 * np.abs(fd_m).max()
