"""The energy residual starts from the whole stored energy at t = 0: two fibers whose small initial
overlap acts at once (below the release threshold) start with a stored contact potential, which
the damping then takes; the state-function residual counts it as the start, not as created."""

import numpy as np

from fiberpipe.solver import Damping, Material, SimulationSettings, build_model, simulate
from fiberpipe.verification.case_config import contact_hook

R = 0.25e-3


def test_an_initial_overlap_acting_at_once_is_in_the_residual_start():
    s = np.linspace(0.0, 3e-3, 11)
    overlap = 0.02 * R  # below the 5 % of r that would be released: acts at once
    x = np.vstack([np.c_[s, 0 * s, 0 * s], np.c_[s, 0 * s + 2 * R - overlap, 0 * s]])
    m = build_model(x, np.array([0, 11, 22]), R, Material(15e9, 1380.0, 0.3))
    res = simulate(m, [Damping(1e5), contact_hook(m)], SimulationSettings(end_time_s=2e-4, output_frames=3))
    h = res.history
    assert h["energy/contact_stored"][0] > 1e-5 and h["energy/contact_stored"][-1] < 1e-3 * h["energy/contact_stored"][0]
    # the stored energy of the start goes into the damping: without it in the start the residual read
    # 1.01 from the first row; measured 4e-4 there, and 0.030 at the end (the leapfrog's error on the
    # violent release of a 5 µm overlap)
    assert abs(h["energy/residual"][0]) < 1e-2
    assert np.max(np.abs(h["energy/residual"])) < 5e-2, np.max(np.abs(h["energy/residual"]))
