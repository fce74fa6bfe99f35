"""A NaN in the state stops the run with a diagnosis, even though the kernels use fastmath (which
lets the compiler drop an in-loop NaN test)."""

import numpy as np
import pytest

from fiberpipe.errors import SimulationDiverged
from fiberpipe.solver import Damping, Material, State, build_model
from fiberpipe.solver.integrator import SimulationSettings, simulate


def test_nan_in_the_state_is_detected_and_diagnosed():
    z = np.linspace(0, 3e-3, 11)
    m = build_model(np.c_[0 * z, 0 * z, z], np.array([0, 11]), 0.25e-3, Material(15e9, 1380.0, 0.3))
    st = State.at_rest(m)
    st.v[5, 0] = np.nan
    with pytest.raises(SimulationDiverged, match="NaN"):
        simulate(m, [Damping(1e3)], SimulationSettings(end_time_s=1e-5, output_frames=2), state=st)
