"""The six-fiber conservation scene: four parallel fibers on a fixed plate between walls, two on top
crossing them at ±Φ, pressed by a line load, undamped and frictionless.

Nothing dissipates, so the state functions (the leapfrog kinetic term ½ v_{n−½}·M v_{n+½}, the
strain energy ALLSE and the stored contact potential of plates, walls and fibers) may not exceed the
loads' work f·(x_n − x0): :func:`energy_excess` is the largest excess over the history rows, a
fraction of max|W|. Used by ``tests/solver/test_contact_energy_balance.py`` and
``benchmarks/bench_step_energy.py`` of a source checkout.
"""

from __future__ import annotations

import math

import numpy as np

from ..solver import Loads, Material, Plates, SimulationSettings, Walls, build_model, choose_time_step
from ..solver._kernels_boundary import DEFAULT_ONSET_FRACTION
from .energy_residual import recorded_simulate as simulate
from ..solver.terms.base import DEFAULT_PENALTY_FACTOR
from ..solver.terms.loads import LineLoad
from .case_config import contact_hook

RADIUS_M = 0.25e-3
MATERIAL = Material(15e9, 1380.0, 0.3)
GAP_M = 0.5e-6

#: the laws the scene checks, as ``(name, keyword arguments of make_law)``: every built-in law, the
#: crossed law at 90°, the linear law at 1e9 N/m² and the study's scaled-stiffness presets
LAWS = [("hertz_oriented", {}), ("hertz_parallel", {}), ("linear", {"stiffness": 1e9}),
        ("hertz_crossed", {"phi_deg": 90.0}), ("scaled_stiffness", {"preset": "table1_phi6"}),
        ("scaled_stiffness", {"preset": "table1_parallel"}), ("scaled_stiffness", {"preset": "table3_identified"})]


def six_fibers_law(name, kw):
    """The law as a config builds it: with the schema's blend length (the patch criterion)."""
    from ..config import ContactConfig
    from ..solver.laws import make_law

    return make_law(name, E_pa=15e9, nu=0.3, blend_length_m=float(ContactConfig().blend_length), **kw)


def law_label(name, kw) -> str:
    """``name`` with its preset, angle or stiffness: ``scaled_stiffness table1_phi6``."""
    return " ".join([name] + [str(v) if k == "preset" else f"{k}={v:g}" for k, v in kw.items()])


def six_fibers(L=6e-3, n_el=20, phi_deg=3.0, lift_m=0.0):
    """``(model, pitch [m])``: the fibers of 6 mm in 20 elements, the top two lifted until their
    smallest surface gap to the lower ones is ``GAP_M`` (plus ``lift_m``, a perturbation for
    ensembles of this chaotic scene)."""
    R = RADIUS_M
    pitch = 2 * R + GAP_M
    s = np.linspace(-0.5, 0.5, n_el + 1)
    fibers = [np.c_[L / 2 + s * L, np.full_like(s, GAP_M + R + k * pitch), np.full_like(s, R + GAP_M)]
              for k in range(4)]
    ph = math.radians(phi_deg)
    for yc, sg in ((GAP_M + R + 0.5 * pitch, 1.0), (GAP_M + R + 2.5 * pitch, -1.0)):
        f = np.c_[L / 2 + s * L * math.cos(ph), yc + sg * s * L * math.sin(ph), np.zeros_like(s)]
        tt = np.linspace(0, 1, 400)[:, None]
        pts = f[0] + tt * (f[-1] - f[0])
        dy = np.abs(pts[:, 1][:, None] - np.array([g[0, 1] for g in fibers])[None, :]).min(axis=1)
        dz = np.sqrt(np.maximum((2 * R + GAP_M) ** 2 - dy**2, 0.0))
        f[:, 2] = R + GAP_M + float(dz.max()) + lift_m
        fibers.append(f)
    off = np.cumsum([0] + [len(f) for f in fibers])
    return build_model(np.vstack(fibers), off, R, MATERIAL), pitch


def six_fibers_run(law, q_n_per_m, *, t_end_s=2e-3, dt_safety=0.9, lift_m=0.0,
                   penalty_factor=DEFAULT_PENALTY_FACTOR, onset_fraction=DEFAULT_ONSET_FRACTION, steps=None):
    """``(model, SimulationResult)`` of the scene with line load ``q_n_per_m`` on the top two fibers
    (``penalty_factor``, ``onset_fraction``: the plate's and walls' penalty, :class:`fiberpipe.solver.Plates`;
    ``steps``: run that many steps instead of ``t_end_s``)."""
    m, pitch = six_fibers(lift_m=lift_m)
    planes = dict(penalty_factor=penalty_factor, onset_fraction=onset_fraction)

    def effects():
        return [Loads([LineLoad(4, (0, 0, -q_n_per_m)), LineLoad(5, (0, 0, -q_n_per_m))]),
                Plates(axis="z", lower="fixed", upper="none", lower_position_m=0.0, **planes),
                Walls({"y": (0.0, 4 * pitch + GAP_M)}, **planes), contact_hook(m, law=law)]

    settings = SimulationSettings(end_time_s=t_end_s, output_frames=3, history_every=100, dt_safety=dt_safety)
    if steps is not None:
        dt = choose_time_step(m, effects(), settings)[0]
        settings = SimulationSettings(end_time_s=steps * dt, output_frames=3, history_every=max(1, steps // 400),
                                      dt_safety=dt_safety)
    eff = effects()
    return m, simulate(m, eff, settings)


def energy_excess(res) -> tuple[float, np.ndarray]:
    """(max over the history rows of (state energy − loads' work)/max|W|, the kinetic energy per row);
    refuses a run without contact (it would test nothing)."""
    h = res.history
    ke, se, st, wk = (h[f"energy/{k}"] for k in ("kinetic_leapfrog", "strain", "contact_stored", "external"))
    if not (st.max() > 0 and h["contacts"].max() > 0):
        raise ValueError("no contact in the six-fiber run: the check tests nothing")
    return float(np.max((ke + se + st - wk) / np.max(np.abs(wk)))), ke
