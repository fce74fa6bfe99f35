import numpy as np
import pytest

from fiberpipe.model.specimen import cassette_specimen


@pytest.fixture(scope="session")
def small_deposit():
    """A small gravity-deposited pile (12 fibers of 6 mm in a 1.5 mm cassette, the study's tilt and
    curvature, two trial drops per fiber, the upper plate on its top): (Polylines, info). Shared by
    the deposit and settling tests, which only read it."""
    return cassette_specimen(n_fibers=12, width_m=1.5e-3, length_m=6e-3, points_per_fiber=25, seed=1,
                             placement="deposit", tilt_rad=float(np.deg2rad(6.0) / np.sqrt(np.pi)),
                             curvature_per_m=0.384, candidates=2, top="pile")
