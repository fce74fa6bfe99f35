"""fiberpipe/_vectorise.py: the vector width numba's code generator is given, and that it changes
the beam forces only by rounding."""

from __future__ import annotations

import os
import subprocess
import sys

import llvmlite.binding as llvm
import numpy as np
import pytest

from fiberpipe import _vectorise

HOST = llvm.get_host_cpu_features().flatten()
AVX512 = "+avx512f" in HOST.split(",")


def test_wide_vectors_only_on_avx512_hosts_and_only_when_the_user_left_the_target_alone():
    host = "+sse2,+avx2,+avx512f,-amx-tile"
    assert _vectorise.wide_vector_features(host, {}) == host + ",-prefer-256-bit"
    assert _vectorise.wide_vector_features("+sse2,+avx2,-avx512f", {}) is None
    assert _vectorise.wide_vector_features(host, {"FIBERPIPE_VECTOR_WIDTH": "256"}) is None
    assert _vectorise.wide_vector_features(host, {"FIBERPIPE_VECTOR_WIDTH": "512"}) == host + ",-prefer-256-bit"
    assert _vectorise.wide_vector_features(host, {"NUMBA_CPU_FEATURES": "+avx2"}) is None
    assert _vectorise.wide_vector_features(host, {"NUMBA_CPU_NAME": "generic"}) is None


def test_the_solver_s_code_generator_runs_with_the_chosen_width():
    import fiberpipe.solver  # noqa: F401  (imports _vectorise before any kernel)
    from numba.core.registry import cpu_target

    features = cpu_target.target_context.codegen()._tm_features
    user_set = any(os.environ.get(k) for k in ("NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES", "FIBERPIPE_VECTOR_WIDTH"))
    if AVX512 and not user_set:
        assert features.endswith(",-prefer-256-bit")
    elif not user_set:
        assert "-prefer-256-bit" not in features


_BEAM_SCRIPT = """
import sys, numpy as np
from fiberpipe.solver import Material, build_model
from fiberpipe.solver._kernels_beam import beam_pass_nodes, new_element_forces, node_beams
s = np.linspace(0.0, 1.0, 41)
nodes = np.c_[3e-3 * s, 2e-4 * np.sin(7 * s), 1e-4 * np.cos(5 * s)]
m = build_model(nodes, np.array([0, 41]), 0.25e-3, Material(youngs_modulus_pa=15e9, density_kg_m3=1380.0, poisson_ratio=0.3))
rng = np.random.default_rng(3)
x = m.nodes_m + 1e-6 * rng.standard_normal(m.nodes_m.shape)
q = m.quats0 + 1e-3 * rng.standard_normal(m.quats0.shape)
q /= np.linalg.norm(q, axis=1)[:, None]
ef = new_element_forces(x.shape[0])
beams = node_beams(m.el_n1, m.el_invL0, m.el_C, m.el_Dk, m.gamma_rest, m.theta_rest, x.shape[0])
se, n_large = beam_pass_nodes(x, q, beams, ef, 0, x.shape[0] - 1)
np.save(sys.argv[1], np.r_[np.array(ef).ravel(), se])
"""


@pytest.mark.skipif(not AVX512, reason="the host has no AVX-512: one vector width only")
def test_512_bit_vectors_change_the_beam_forces_only_by_rounding(tmp_path):
    out = {}
    for width in ("256", "512"):
        env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES")}
        env.update(FIBERPIPE_VECTOR_WIDTH=width, NUMBA_CACHE_DIR=str(tmp_path / f"cache{width}"))
        path = tmp_path / f"ef{width}.npy"
        subprocess.run([sys.executable, "-c", _BEAM_SCRIPT, str(path)], env=env, check=True)
        out[width] = np.load(path)
    a, b = out["256"], out["512"]
    forces, energy = (a[:-1], b[:-1]), (a[-1], b[-1])
    # tolerance: the same formulas per element, so the resultants may differ only where LLVM fuses a
    # multiply-add differently (measured: identical bit for bit); the energy is a sum whose order
    # follows the width (measured: 2e-21 J apart)
    assert np.any(forces[0] != 0.0) and energy[0] > 0.0
    assert np.max(np.abs(forces[0] - forces[1])) <= 1e-13 * np.max(np.abs(forces[0]))
    assert energy[1] == pytest.approx(energy[0], rel=1e-12)
