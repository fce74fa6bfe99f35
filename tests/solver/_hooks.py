"""A stand-in contact hook shared by the solver tests (a module, not a test file). Each hook kernel
gets its own specialisation of the step loop, compiled once per process (seconds, uncached): the
tests that only need some hook share this one."""

import numpy as np
from numba import njit

from fiberpipe.solver.layout import ACC_PW


@njit(cache=True)
def lift(x, q, v, w, f, mom, acc, t, dt, data):
    """A fake contact pass: the force data[0][0] [N] along z on every node, its work booked as
    contact work (a hook adding into f books its own); reports data[0][1] contacts."""
    f[:, 2] += data[0][0]
    acc[ACC_PW] += data[0][0] * np.sum(v[:, 2]) * dt
    return int(data[0][1])
