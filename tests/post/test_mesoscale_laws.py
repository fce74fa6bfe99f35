"""The mesoscale-law fitter recovers the parameters of curves generated from the laws themselves."""

import math

import numpy as np
import pytest

from fiberpipe.errors import FiberpipeError
from fiberpipe.post.mesoscale_laws import (FitRangeError, fit_gutowski, fit_toll, gutowski_pressure, mesoscale_fits,
                                           van_wyk_pressure)

E_PA = 15e9


@pytest.mark.parametrize("k, n, vf0", [(0.01, 3.0, 0.05), (2e-3, 5.0, 0.12), (0.05, 2.2, 0.2)])
def test_toll_fit_recovers_k_n_v0(k, n, vf0):
    vf = np.linspace(vf0 * 1.15, 0.45, 80)
    fit = fit_toll(vf, van_wyk_pressure(vf, k, n, vf0, E_PA), E_PA)
    assert fit["n"] == pytest.approx(n, rel=1e-3)
    assert fit["k"] == pytest.approx(k, rel=1e-2)
    assert fit["vf0"] == pytest.approx(vf0, rel=1e-3)
    assert fit["points"] == 80 and fit["r2_log"] > 0.9999


def test_toll_fit_with_noise_stays_within_its_scatter():
    rng = np.random.default_rng(3)
    vf = np.linspace(0.08, 0.4, 200)
    p = van_wyk_pressure(vf, 0.01, 3.0, 0.06, E_PA) * np.exp(rng.normal(0, 0.02, vf.size))
    fit = fit_toll(vf, p, E_PA)
    assert abs(fit["n"] - 3.0) < 0.15


@pytest.mark.parametrize("beta, v0, va", [(50.0, 0.45, 0.8), (225.0, 0.5, 0.83), (20.0, 0.3, 0.7)])
def test_gutowski_fit_recovers_as_v0_va_and_beta(beta, v0, va):
    a_s = 3 * math.pi * E_PA / beta**4
    vf = np.linspace(v0 * 1.05, v0 + 0.8 * (va - v0), 80)
    fit = fit_gutowski(vf, gutowski_pressure(vf, a_s, v0, va), E_PA)
    assert fit["v0"] == pytest.approx(v0, rel=1e-3)
    assert fit["va"] == pytest.approx(va, rel=1e-3)
    assert fit["a_s_pa"] == pytest.approx(a_s, rel=1e-2)
    assert fit["beta"] == pytest.approx(beta, rel=3e-3)


def test_fit_range_with_fewer_points_than_parameters_is_one_line_error():
    vf = np.linspace(0.1, 0.4, 50)
    p = van_wyk_pressure(vf, 0.01, 3.0, 0.05, E_PA)
    with pytest.raises(FitRangeError) as info:
        fit_toll(vf, p, E_PA, vf_range=(0.2, 0.205))
    message = str(info.value)
    assert "\n" not in message and "fewer than the 3 parameters" in message and message.startswith("post:")
    assert isinstance(info.value, FiberpipeError)


def test_post_summary_records_a_refused_fit_instead_of_failing():
    fits = mesoscale_fits([0.1, 0.2], [1.0, 2.0], E_PA)
    assert "fewer than the 3 parameters" in fits["toll"]["error"]
    assert "fewer than the 3 parameters" in fits["gutowski"]["error"]
