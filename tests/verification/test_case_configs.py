"""Each case of docs/verification.md is a config in configs/verify/. Every verification case has a config that
validates, and its runner takes the material, geometry and scene values from it: a modified copy of
the config must show up in what the case hands to ``simulate`` (spied; nothing runs)."""

import math
import shutil

import numpy as np
import pytest
import yaml

from fiberpipe.config import load_config
from fiberpipe.solver import Damping, Gravity, LineLoad, Loads, Plates, PointLoad, Walls
from fiberpipe.verification import case_config, cases, contact_cases
from fiberpipe.verification.__main__ import ALL_CASES
from fiberpipe.verification.case_config import CASE_CONFIGS, CONFIG_DIR

NO_CONFIG = {"sliding_parallel"}  # not a docs/verification.md case: two element lengths and an initial velocity


def test_every_case_has_a_config_that_validates():
    assert set(CASE_CONFIGS) == set(ALL_CASES) - NO_CONFIG
    for name, file in CASE_CONFIGS.items():
        cfg = load_config(CONFIG_DIR / file)
        assert cfg.input.polylines and cfg.fiber.radius and cfg.material.youngs_modulus, name
        assert not cfg.scene.warnings(), (file, cfg.scene.warnings())


class _Stop(Exception):
    pass


def _modified_copy(tmp_path, name):
    """configs/verify copied to tmp_path, the case's config changed: density × 1.25, E × 1.1 (not for
    the crossed cases, whose reference K values hold for E = 15 GPa only), fibers shifted by +1 mm along x,
    damping α × 2, loads × 1.5, μ = 0.3, gravity × 1.1. Returns the modified, validated config."""
    for p in CONFIG_DIR.glob("*.yaml"):
        shutil.copy(p, tmp_path / p.name)
    path = tmp_path / CASE_CONFIGS[name]
    cfg = load_config(path)  # SI values (units resolved, extends: merged)
    raw = yaml.safe_load(path.read_text())
    sc = cfg.scene
    raw["material"] = {"youngs_modulus": cfg.material.youngs_modulus * (1.0 if "crossed" in name else 1.1),
                       "poisson_ratio": cfg.material.poisson_ratio_value, "density": cfg.material.density * 1.25}
    raw["input"] = {"polylines": [[[p[0] + 1e-3, p[1], p[2]] for p in pl] for pl in cfg.input.polylines]}
    scene = raw.setdefault("scene", {})
    if "damping" in sc.effects:
        scene["damping"] = {"alpha": 2 * sc.damping.alpha, "beta": 0.0}
    if "loads" in sc.effects:
        scene["loads"] = [{k: v for k, v in {"fiber": ld.fiber, "at": ld.at,
                                              "force": None if ld.force is None else [1.5 * f for f in ld.force],
                                              "line_force": None if ld.line_force is None else
                                              [1.5 * f for f in ld.line_force]}.items() if v is not None}
                          for ld in sc.loads]
    if "friction" in sc.effects:
        scene["friction"] = {"mu": 0.3}
    if "gravity" in sc.effects:
        scene["gravity"] = {"acceleration": [1.1 * g for g in sc.gravity.acceleration]}
    path.write_text(yaml.safe_dump(raw))
    return load_config(path)


@pytest.mark.parametrize("name", sorted(CASE_CONFIGS))
def test_runner_uses_its_config(name, tmp_path, monkeypatch):
    new = _modified_copy(tmp_path, name)
    monkeypatch.setattr(case_config, "CONFIG_DIR", tmp_path)
    seen, hooks = {}, []

    def spy(model, effects, settings, **kw):
        seen.update(model=model, effects=effects, settings=settings)
        raise _Stop

    real_hook = contact_cases.contact_hook

    def hook_spy(model, **kw):
        hooks.append(kw)
        return real_hook(model, **kw)

    monkeypatch.setattr(cases, "simulate", spy)
    monkeypatch.setattr(contact_cases, "simulate", spy)
    monkeypatch.setattr(contact_cases, "contact_hook", hook_spy)
    with pytest.raises(_Stop):
        ALL_CASES[name](quick=True)
    m, eff = seen["model"], seen["effects"]

    mat = new.material
    assert m.material.youngs_modulus_pa == pytest.approx(mat.youngs_modulus, rel=1e-12)
    assert m.material.density_kg_m3 == pytest.approx(mat.density, rel=1e-12)
    assert np.allclose(m.el_radius, new.fiber.radius, rtol=1e-12)
    assert np.allclose(m.el_L0, new.mesh.element_length, rtol=0.2)
    assert m.n_fibers == len(new.input.polylines)
    for k, pl in enumerate(new.input.polylines):  # every fiber starts where its polyline does (x shifted)
        assert m.nodes_m[m.node_offsets[k], 0] == pytest.approx(pl[0][0], abs=1e-12), k
    assert seen["settings"].dt_safety == new.solver.dt_safety

    by_type = {type(e): e for e in eff}
    sc = new.scene
    if "damping" in sc.effects:
        assert by_type[Damping].alpha_per_s == pytest.approx(sc.damping.alpha)
    if "gravity" in sc.effects:
        assert np.allclose(by_type[Gravity].acceleration_m_s2, sc.gravity.acceleration)
    if "loads" in sc.effects:
        got = by_type[Loads].loads
        assert len(got) == len(sc.loads)
        for g, ld in zip(got, sc.loads):
            if ld.line_force is not None:
                assert isinstance(g, LineLoad) and np.allclose(g.force_n_per_m, ld.line_force)
            else:
                assert isinstance(g, PointLoad) and np.allclose(g.force_n, ld.force) and g.at == ld.at
    if "walls" in sc.effects:
        assert by_type[Walls].planes == {"y": tuple(sc.walls.y)}
    if "plates" in sc.effects:
        p = by_type[Plates]
        assert (p.axis, p.lower, p.upper, p.lower_position_m) == (sc.plates.axis, sc.plates.lower, sc.plates.upper,
                                                                  sc.plates.lower_position)
    if "friction" in sc.effects:  # fiber–fiber friction in the contact hook, plane friction in the planes' terms
        mus = [h["mu"] for h in hooks if "contact" in sc.effects]
        mus += [by_type[kind].mu for kind in (Plates, Walls) if kind in by_type]
        assert mus and all(mu == pytest.approx(0.3) for mu in mus)
    if "contact" in sc.effects:
        law = hooks[0]["law"]
        e_star = mat.youngs_modulus / (2 * (1 - mat.poisson_ratio_value**2))
        assert law.name == sc.contact.law and law.params()[0] == pytest.approx(e_star, rel=1e-12)


def test_crossed_case_refuses_another_fiber(tmp_path, monkeypatch):
    for p in CONFIG_DIR.glob("*.yaml"):
        shutil.copy(p, tmp_path / p.name)
    path = tmp_path / CASE_CONFIGS["contact_crossed_6"]
    path.write_text(path.read_text() + 'material: {youngs_modulus: "10 GPa", poisson_ratio: 0.3, density: 1380}\n')
    monkeypatch.setattr(case_config, "CONFIG_DIR", tmp_path)
    with pytest.raises(ValueError, match="E = 15 GPa"):
        ALL_CASES["contact_crossed_6"](quick=True)


def test_config_values_are_the_study_fiber():
    """The shipped configs all hold the study's fiber and mesh (docs/verification.md), which the tables quote."""
    for name in CASE_CONFIGS:
        s = case_config.case_setup(name)
        assert (s.E, s.nu, s.rho, s.r, s.element_length) == pytest.approx((15e9, 0.3, 1380.0, 0.25e-3, 0.3e-3)), name
    s = case_config.case_setup("three_beam_static")
    (a, _), (b, _), _ = s.fibers()
    assert math.degrees(math.atan2(a[1] - b[1], a[2] - b[2])) == pytest.approx(30.0, abs=1e-9)
