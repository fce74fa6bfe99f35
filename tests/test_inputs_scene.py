"""Scene requirements: what the config alone decides is refused at validation (before any stage
writes a file); fiber and node indices, known only after meshing, are refused at build time with
a message naming the config key."""

import numpy as np
import pytest

from fiberpipe.config import load_config
from fiberpipe.errors import ConfigError, FiberpipeError

BASE = """name: scene
input:
  polylines:
    - [[0, 0, 0], ["3 mm", 0, 0]]
fiber: {radius: "0.25 mm"}
mesh: {element_length: "0.3 mm"}
"""


@pytest.mark.parametrize(
    "scene, expected",
    [
        ("scene: {effects: [plates]}", "scene.plates.lower is moving but there is no scene.loading"),
        ("scene: {effects: [plates], plates: {lower: fixed, upper: moving}}",
         "scene.plates.upper is moving but there is no scene.loading"),
        ("scene: {effects: [plates], loading: {velocity: '1000 mm/min'}}",
         "scene.loading.displacement must be > 0 for the moving plate (scene.plates.lower)"),
        ("scene: {effects: [plates], plates: {lower: none, upper: none}}", "are both none"),
        ("scene: {effects: [plates], plates: {lower_position: '2 mm', upper_position: '1 mm'}, "
         "loading: {displacement: '1 mm'}}", "lower_position (0.002 m) must be below scene.plates.upper_position"),
        ("scene: {effects: [walls]}\nsolver: {end_time: '1 ms'}", "scene.effects lists walls but scene.walls gives no planes"),
        ("scene: {effects: [drives], drives: [{fiber: 0, displacement: [0, 0, 0], velocity: 1}]}",
         "scene.drives[0].displacement is zero"),
        ("scene: {effects: [clamps], clamps: [{fiber: 1}]}\nsolver: {end_time: '1 ms'}",
         "scene.clamps[0].fiber = 1: input.polylines has 1 fiber (indices 0..0)"),
        ("scene: {effects: [loads], loads: [{fiber: 0, line_force: [0, 0, 1]}, {fiber: 5, at: end, force: [0, 0, 1]}]}"
         "\nsolver: {end_time: '1 ms'}", "scene.loads[1].fiber = 5: input.polylines has 1 fiber"),
    ],
)
def test_scene_requirements_are_config_errors(write_yaml, scene, expected):
    p = write_yaml(BASE + scene + "\n", "bad.yaml")
    with pytest.raises(ConfigError) as err:
        load_config(p)
    msg = str(err.value)
    assert expected in msg and str(p) in msg and "\n" not in msg
    assert "'scene': scene." not in msg  # the key is named once


@pytest.mark.parametrize(
    "scene",
    [
        "scene: {effects: [plates], loading: {displacement: '1 mm', velocity: '1000 mm/min'}}",
        "scene: {effects: [plates], plates: {lower: fixed, upper: none}}\nsolver: {end_time: '1 ms'}",
        "scene: {effects: [plates, drives], plates: {lower: fixed, upper: none}, "
        "drives: [{fiber: 0, displacement: [0, 0, '-0.3 mm'], velocity: '1000 mm/min'}]}",
        "solver: {end_time: '1 ms'}",
        "",  # no scene: no simulation, nothing to require
    ],
)
def test_valid_scenes_still_load(write_yaml, scene):
    load_config(write_yaml(BASE + scene + "\n", "ok.yaml"))


def test_ignored_loading_and_zero_damping_are_warned(write_yaml):
    cfg = load_config(write_yaml(BASE + "scene: {effects: [damping], loading: {displacement: '1 mm'}}\n"
                                 "solver: {end_time: '1 ms'}\n", "warn.yaml"))
    w = cfg.scene.warnings()
    assert any("scene.loading is configured but no plate is moving" in x for x in w)
    assert any("scene.damping.alpha and beta are 0" in x for x in w)


def _model(n_fibers=1, nodes=11):
    from fiberpipe.solver.model import Material, build_model

    x = np.zeros((n_fibers * nodes, 3))
    for f in range(n_fibers):
        x[f * nodes:(f + 1) * nodes, 0] = np.linspace(0, 3e-3, nodes)
        x[f * nodes:(f + 1) * nodes, 1] = f * 1e-3
    off = np.arange(n_fibers + 1) * nodes
    return build_model(x, off, np.full(n_fibers, 0.25e-3), Material(15e9, 1380.0, 0.3))


@pytest.mark.parametrize(
    "make, expected",
    [
        ("clamps", "scene.clamps[0].fiber = 99: the model has 1 fiber (indices 0..0)"),
        ("clamp_at", "scene.clamps[1].at = 11: fiber 0 has 11 nodes (indices 0..10, or -11..-1 from the end"),
        ("clamp_at_word", "scene.clamps[0].at = 'middle': give start, end or a node index"),
        ("point_load", "scene.loads[0].at = -12: fiber 0 has 11 nodes"),
        ("line_load", "scene.loads[1].fiber = 2: the model has 1 fiber (indices 0..0)"),
        ("drive", "scene.drives[0].fiber = 1: the model has 1 fiber (indices 0..0)"),
    ],
)
def test_indices_known_after_meshing_name_the_config_key(make, expected):
    from fiberpipe.solver.terms import (Clamp, Clamps, Drive, Drives, LineLoad, Loads, PointLoad,
                                          SceneArrays)

    model = _model()
    effect = {
        "clamps": lambda: Clamps([Clamp(np.int64(99), "start")]),
        "clamp_at": lambda: Clamps([Clamp(0, "end"), Clamp(0, 11)]),
        "clamp_at_word": lambda: Clamps([Clamp(0, "middle")]),
        "point_load": lambda: Loads([PointLoad(0, [0, 0, 1.0], -12)]),
        "line_load": lambda: Loads([PointLoad(0, [0, 0, 1.0], -11), LineLoad(2, [0, 0, 1.0])]),
        "drive": lambda: Drives([Drive(1, [0, 0, -1e-4], 0.01)]),
    }[make]()
    with pytest.raises(FiberpipeError) as err:
        effect.setup(model, SceneArrays(model, 1.0))
    assert str(err.value) == expected or str(err.value).startswith(expected)


def test_build_simulation_names_the_clamp_key(write_yaml):
    """A config whose fibers are not known at validation (here: the mesh has fewer fibers than the
    polylines the config was checked against) is refused when the scene is built, naming the key."""
    from fiberpipe.model.mesh import Mesh
    from fiberpipe.solver.build import build_simulation

    text = BASE.replace('    - [[0, 0, 0], ["3 mm", 0, 0]]\n',
                        '    - [[0, 0, 0], ["3 mm", 0, 0]]\n    - [[0, "1 mm", 0], ["3 mm", "1 mm", 0]]\n')
    cfg = load_config(write_yaml(text + "scene: {effects: [clamps], clamps: [{fiber: 1}]}\n"
                                 "solver: {end_time: '1 ms'}\n"))
    x = np.zeros((11, 3))
    x[:, 0] = np.linspace(0, 3e-3, 11)
    with pytest.raises(FiberpipeError, match=r"scene\.clamps\[0\]\.fiber = 1: the model has 1 fiber \(indices 0\.\.0\)"):
        build_simulation(Mesh(x, np.array([0, 11]), np.array([0.25e-3])), cfg)
