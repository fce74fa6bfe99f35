"""The measures of cases 5–7 on synthetic runs whose answers are known: the loop's energy terms,
the turning point, the curve change at half speed, K_e/S_e over the loaded phase, Janssen's ratio."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from fiberpipe.validation.friction_cycles import cycle_overrides, loop_figures, turning_row
from fiberpipe.validation.janssen import janssen_figures
from fiberpipe.validation.quasi_static import curve_change, kinetic_over_strain


def synthetic_run(travel, force_upper, energy=None, walls=None, specimen=None, mu=0.2):
    history = {"time": np.arange(len(travel), dtype=float),
               "plate_displacement": np.column_stack([travel, np.zeros_like(travel)]),
               "plate_force": np.column_stack([force_upper * 1.1, force_upper]),
               "wall_force": walls if walls is not None else np.zeros((len(travel), 4))}
    config = SimpleNamespace(scene=SimpleNamespace(friction=SimpleNamespace(mu=mu)))
    return SimpleNamespace(simulation=SimpleNamespace(history=history, energy=energy or {}), specimen=specimen or {},
                           config=config, summary={})


def test_loop_figures_take_the_terms_from_the_turning_point_on():
    travel = np.array([0.0, 1.0, 2.0, 1.5, 1.2, 1.6, 2.0])
    ramp = np.arange(7.0)
    energy = {"external": 10 * ramp, "friction": 3 * ramp, "damping": 2 * ramp, "strain": 4 * ramp,
              "contact_stored": 0.5 * ramp, "kinetic": 0.5 * ramp}
    run = synthetic_run(travel, np.linspace(0, 6, 7), energy)
    assert turning_row(run) == 2
    f = loop_figures(run)
    assert f["work_J"] == pytest.approx(40.0) and f["dissipated_J"] == pytest.approx(20.0)
    assert f["stored_change_J"] == pytest.approx(20.0) and f["force_at_turn_N"] == pytest.approx(2.0)


def test_turning_row_is_the_first_turn_when_its_row_falls_short_of_the_end():
    travel = np.array([0.0, 1.0, 2.0 * (1 - 2e-8), 1.5, 1.2, 1.6, 2.0])  # the turn's row sampled just before it
    run = synthetic_run(travel, np.linspace(0, 6, 7))
    assert turning_row(run) == 2


def test_cycle_path_goes_to_the_strain_back_to_0_6_and_again():
    o = cycle_overrides(0.6, 10e-3)
    assert o["scene.loading.path"] == pytest.approx([6e-3, 3.6e-3, 6e-3])
    assert o["scene.loading.displacement"] == pytest.approx(6e-3) and o["specimen.strain"] is None


def test_curve_change_and_kinetic_ratio():
    travel = np.linspace(0, 1, 101)
    base = synthetic_run(travel, 10 * travel, {"kinetic": np.full(101, 1e-3), "strain": np.linspace(0, 1, 101)})
    slow = synthetic_run(travel, 10 * travel * 1.03)
    assert curve_change(base, slow) == pytest.approx(0.03 * 0.95, rel=0.02)  # the last window's mean, 0.95 of max
    # loaded phase: force above 1 % of its peak, i.e. from the second row, where S_e = 0.01
    assert kinetic_over_strain(base) == pytest.approx(1e-3 / 0.02, rel=1e-9)


def test_janssen_ratio_from_the_measured_lateral_coefficient():
    n = 100
    walls = np.tile([2.0, 2.0, 0.0, 0.0], (n, 1))
    spec = {"height_m": 5e-3, "width_m": 2e-3, "depth_m": 10e-3}
    run = synthetic_run(np.full(n, 1e-3), np.full(n, 1.0), walls=walls, specimen=spec)
    f = janssen_figures(run)
    sigma_h = 2.0 / (4e-3 * 10e-3)
    sigma_v = 0.5 * (1.1 + 1.0) / (2e-3 * 10e-3)
    assert f["K"] == pytest.approx(sigma_h / sigma_v)
    assert f["ratio_measured"] == pytest.approx(1.0 / 1.1)
    assert f["ratio_janssen"] == pytest.approx(math.exp(-2 * 0.2 * f["K"] * 4e-3 / 2e-3))


def test_kinetic_sources_split_the_carried_fibers_from_an_event():
    from fiberpipe.validation.quasi_static import carried_kinetic_energy, kinetic_sources

    n = 101
    travel = np.linspace(0, 1e-3, n)
    force = np.where(travel > 0.5e-3, travel * 1e4, 0.0)  # the load starts at row 51
    strain = np.where(travel > 0.5e-3, (travel - 0.5e-3) * 10.0, 0.0)
    config = SimpleNamespace(material=SimpleNamespace(density=1000.0), fiber=SimpleNamespace(radius=1e-3),
                             solver=SimpleNamespace(mass_scaling=4.0), scene=SimpleNamespace(
                                 loading=SimpleNamespace(velocity=0.5), friction=SimpleNamespace(mu=0.2)))
    spec = {"generator": {"n_fibers": 10}, "length_m": 0.01}
    run = synthetic_run(travel, force, specimen=spec)
    run.config = config
    carried = 0.5 * 10 * 1000.0 * math.pi * 1e-6 * 0.01 * 4.0 * 0.25
    assert carried_kinetic_energy(run) == pytest.approx(carried)
    kinetic = np.full(n, 0.3 * carried)
    kinetic[80] = 5 * carried  # an event: more than every fiber at the plate's speed
    run.simulation.energy.update({"kinetic": kinetic, "strain": strain})
    k = kinetic_sources(run)
    assert k["start_carried_share"] == pytest.approx(0.3)
    assert k["start_ratio"] == pytest.approx(0.3 * carried / strain[51])
    assert k["largest_over_carried"] == pytest.approx(5.0)


def test_refinement_row_compares_the_halved_mesh_fit_with_the_case_s(monkeypatch):
    import fiberpipe.validation.compaction_runs as runs
    from fiberpipe.validation.network_cases import refinement_row

    def fitted(beta, r2):
        return SimpleNamespace(seed=0, config=SimpleNamespace(mesh=SimpleNamespace(element_length=5e-4)),
                               summary={"mesoscale_laws": {"gutowski": {"beta": beta, "r2_log": r2}}})

    asked = {}

    def fake_compact(name, seed, work=None, overrides=None):
        asked.update(overrides)
        return fitted(110.0, 0.95)

    monkeypatch.setattr(runs, "compact", fake_compact)
    row = refinement_row("4", "wavy-bundle.yaml", fitted(100.0, 0.97), "gutowski", "beta", 0.3)
    assert asked == {"mesh.element_length": pytest.approx(2.5e-4)}
    assert row.reference == 100.0 and row.error == pytest.approx(0.1) and row.passed
    monkeypatch.setattr(runs, "compact", lambda *a, **k: fitted(110.0, 0.5))  # the fine fit does not hold
    assert not refinement_row("4", "wavy-bundle.yaml", fitted(100.0, 0.97), "gutowski", "beta", 0.3).passed


def test_convergence_row_judges_the_figure_s_change_on_the_case_s_scale(monkeypatch):
    import fiberpipe.validation.compaction_runs as runs
    from fiberpipe.validation.network_cases import convergence_row, exponent_of

    travel = np.linspace(0, 1e-3, 101)

    def fitted(n, r2, scale=1.0):
        run = synthetic_run(travel, 10 * travel * scale)
        run.seed = 0
        run.summary = {"mesoscale_laws": {"toll": {"n": n, "r2_log": r2}}}
        return run

    asked = {}

    def fake_compact(name, seed, work=None, overrides=None):
        asked.update(overrides)
        return fitted(5.5, 0.99, scale=1.02)

    monkeypatch.setattr(runs, "compact", fake_compact)
    row = convergence_row("3", "planar-mat.yaml", fitted(5.0, 0.99), {"solver.mass_scaling": 1}, "the physical mass",
                          exponent_of, "n", 1 / 3, scale=5.0)
    assert asked == {"solver.mass_scaling": 1}
    assert row.measured == pytest.approx(0.1) and row.passed  # |5.5 − 5| / 5 within 1/3
    assert "F(U) change 0.0" in row.note  # 2 % of the load, the last window's mean 0.95 of the largest
    monkeypatch.setattr(runs, "compact", lambda *a, **k: fitted(7.0, 0.99))
    assert not convergence_row("3", "planar-mat.yaml", fitted(5.0, 0.99), {}, "x", exponent_of, "n", 1 / 3,
                               scale=5.0).passed  # |7 − 5| / 5 = 0.4
    monkeypatch.setattr(runs, "compact", lambda *a, **k: fitted(5.0, 0.5))  # the finer fit does not hold
    assert not convergence_row("3", "planar-mat.yaml", fitted(5.0, 0.99), {}, "x", exponent_of, "n", 1 / 3,
                               scale=5.0).passed
