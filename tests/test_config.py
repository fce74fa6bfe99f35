import pytest

from fiberpipe.config import load_config
from fiberpipe.errors import ConfigError

TIP = """
name: tip
input:
  polylines:
    - [[0, 0, 0], ["15 mm", 0, 0]]
material: {youngs_modulus: "15 GPa", poisson_ratio: 0.3, density: "1380 kg/m^3"}
fiber: {radius: "0.25 mm"}
scene:
  effects: [clamps, loads, damping]
  clamps: [{fiber: 0, at: start}]
  loads: [{fiber: 0, at: end, force: [0, 0, -1e-3]}]
  damping: {alpha: "2000 1/s"}
  loading: {velocity: "1000 mm/min"}
"""


def test_units_are_converted_to_si(write_yaml):
    cfg = load_config(write_yaml(TIP))
    assert cfg.material.youngs_modulus == pytest.approx(15e9)
    assert cfg.fiber.radius == pytest.approx(0.25e-3)
    assert cfg.input.polylines[0][1] == pytest.approx([0.015, 0, 0])
    assert cfg.scene.damping.alpha == pytest.approx(2000)
    assert cfg.scene.loading.velocity == pytest.approx(1 / 60)
    assert cfg.scene.loads[0].force == pytest.approx([0, 0, -1e-3])  # "1e-3" is a string in YAML 1.1


def test_extends_overrides_and_resolves_paths(tmp_path, write_yaml):
    write_yaml(TIP, "base.yaml")
    sub = tmp_path / "variants"
    sub.mkdir()
    (sub / "v.yaml").write_text("extends: ../base.yaml\nscene: {damping: {alpha: 10}}\npost: {reference_fibers: ref.h5}\n")
    cfg = load_config(sub / "v.yaml")
    assert cfg.scene.damping.alpha == 10
    assert cfg.scene.clamps[0].fiber == 0  # kept from the base
    assert cfg.post.reference_fibers == str((sub / "ref.h5").resolve())


@pytest.mark.parametrize(
    "patch, expected",
    [
        ("scene: {dampng: {alpha: 1}}", "unknown key 'scene.dampng' (did you mean 'damping'?)"),
        ("material: {youngs_modulus: '15 kg'}", "'material.youngs_modulus'"),
        ("material: {youngs_modulus: -3}", "youngs_modulus must be positive"),
        ("solver: {dt_safety: 1.5}", "dt_safety must be in (0, 1]"),
        ("solver: {threads: 100000}", "solver.threads is 100000, more than the"),
        ("scene: {friction: {mu: -0.1}}", "friction.mu must be >= 0"),
        ("fiber: {radius: '-0.25 mm'}", "fiber.radius must be positive"),
        ("scene: {contact: {law: hertz_paralel}}", "'scene.contact.law'"),
        ("solver: {output_frames: many}", "'solver.output_frames'"),
        ("mesh: {element_length: '0.3 parsec/s'}", "'mesh.element_length'"),
    ],
)
def test_bad_values_name_the_key(tmp_path, write_yaml, patch, expected):
    write_yaml(TIP, "base.yaml")
    p = write_yaml("extends: base.yaml\n" + patch + "\n", "bad.yaml")
    with pytest.raises(ConfigError) as err:
        load_config(p)
    assert expected in str(err.value)
    assert "bad.yaml" in str(err.value)


def test_not_yaml_missing_and_empty(tmp_path, write_yaml):
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_config(write_yaml("a: [\n", "broken.yaml"))
    with pytest.raises(ConfigError, match="not found"):
        load_config(tmp_path / "nope.yaml")
    with pytest.raises(ConfigError, match="empty"):
        load_config(write_yaml("", "empty.yaml"))
    with pytest.raises(ConfigError, match="mapping"):
        load_config(write_yaml("- 1\n- 2\n", "list.yaml"))
    with pytest.raises(ConfigError, match="exactly one of input"):
        load_config(write_yaml("name: x\ninput: {}\n", "noinput.yaml"))


def test_extends_cycle_is_an_error(write_yaml):
    write_yaml("extends: b.yaml\n", "a.yaml")
    p = write_yaml("extends: a.yaml\n", "b.yaml")
    with pytest.raises(ConfigError, match="cycle"):
        load_config(p)


def test_effect_warnings(write_yaml):
    cfg = load_config(write_yaml(TIP.replace("[clamps, loads, damping]", "[clamps, loads, damping, friction]")))
    assert any("friction cannot act" in w for w in cfg.scene.warnings())


def test_stage_hash_tracks_only_its_sections(write_yaml, tmp_path):
    a = load_config(write_yaml(TIP, "a.yaml"))
    b = load_config(write_yaml(TIP.replace('"2000 1/s"', '"3000 1/s"'), "b.yaml"))
    assert a.section_sha256("mesh", "material") == b.section_sha256("mesh", "material")
    assert a.section_sha256("scene") != b.section_sha256("scene")


AXIAL = """
name: axial
input:
  polylines:
    - [[0, "0.25 mm", 0], [0, "0.25 mm", "3 mm"]]
fiber: {radius: "0.25 mm"}
mesh: {element_length: "0.3 mm"}
scene:
  effects: [gravity, damping, constraints]
  gravity: {acceleration: [0, "-9.81 m/s^2", "-2000 m/s^2"]}
  damping: {alpha: "3000 1/s"}
  constraints: {lock_axial: LOCK}
solver: {end_time: "2 ms", output_frames: 2}
"""


def test_constraints_round_trip_and_validation(write_yaml):
    from fiberpipe.config import validate_config

    cfg = load_config(write_yaml(AXIAL.replace("LOCK", "ends")))
    assert cfg.scene.constraints.lock_axial == "ends" and cfg.scene.constraints.axis == "z"
    again = validate_config(cfg.model_dump(mode="json"))
    assert again.scene.constraints == cfg.scene.constraints and again.sha256() == cfg.sha256()
    # listed without a block: the defaults (every node, along z)
    bare = load_config(write_yaml(AXIAL.replace("  constraints: {lock_axial: LOCK}\n", ""), "bare.yaml"))
    assert bare.scene.constraints.lock_axial == "all"
    with pytest.raises(ConfigError, match="scene.constraints.lock_axial"):
        load_config(write_yaml(AXIAL.replace("LOCK", "middle"), "bad.yaml"))
    with pytest.raises(ConfigError, match="unknown key 'scene.constraints.lock'"):
        load_config(write_yaml(AXIAL.replace("lock_axial: LOCK", "lock: all"), "bad2.yaml"))
    unlisted = load_config(write_yaml(AXIAL.replace("gravity, damping, constraints", "gravity, damping")
                                      .replace("LOCK", "all"), "unlisted.yaml"))
    assert any("scene.constraints is configured but not listed" in w for w in unlisted.scene.warnings())


@pytest.mark.parametrize("lock", ["all", "ends", None])
def test_axial_lock_holds_a_fiber_under_an_axial_load(write_yaml, lock):
    """A fiber along z pulled along z by a body force: locked (every node, or its two ends) it does
    not move along z, while it still sags under the y load; unlocked it slides."""
    import numpy as np

    from fiberpipe.model.mesh import Mesh
    from fiberpipe.solver import simulate
    from fiberpipe.solver.build import build_simulation

    text = AXIAL.replace("LOCK", lock or "all")
    if lock is None:
        text = text.replace("gravity, damping, constraints", "gravity, damping")
    cfg = load_config(write_yaml(text))
    x = np.zeros((11, 3))
    x[:, 1] = 0.25e-3
    x[:, 2] = np.linspace(0, 3e-3, 11)
    model, effects, settings = build_simulation(Mesh(x, np.array([0, 11]), np.array([0.25e-3])), cfg)
    res = simulate(model, effects, settings)
    d = np.asarray(res.frames_positions[-1]) - x
    assert np.all(d[:, 1] < -1e-9)  # falls along y (free)
    if lock is None:
        assert np.all(d[:, 2] < -1e-4)  # slides about 2000 m/s² / α × 2 ms ≈ 1.3 mm
    elif lock == "all":
        assert np.max(np.abs(d[:, 2])) == 0.0
    else:
        assert d[0, 2] == 0.0 and d[-1, 2] == 0.0
        assert np.max(np.abs(d[:, 2])) < 1e-9  # the fiber's axial stiffness holds the rest


def test_duplicate_key_is_refused_with_its_line_and_file(tmp_path, write_yaml):
    p = write_yaml("name: a\n" + TIP.lstrip("\n"), "dup.yaml")  # 'name:' at lines 1 and 2
    with pytest.raises(ConfigError) as err:
        load_config(p)
    assert str(err.value).startswith(f"duplicate key 'name' at line 2 of {p}")
    # nested, in a flow mapping on one line
    p = write_yaml(TIP.replace('fiber: {radius: "0.25 mm"}', 'fiber: {radius: "0.25 mm", radius: "0.3 mm"}'), "flow.yaml")
    with pytest.raises(ConfigError, match=r"duplicate key 'radius' at line 7 of .*flow.yaml"):
        load_config(p)
    # also in a file pulled in by extends:, named as that file
    base = write_yaml(TIP.replace("scene:\n", "scene:\n  damping: {alpha: 1}\n"), "base.yaml")
    child = write_yaml("extends: base.yaml\nname: child\n", "child.yaml")
    with pytest.raises(ConfigError, match=rf"duplicate key 'damping' at line \d+ of {base}"):
        load_config(child)


def test_yaml_merge_keys_may_still_be_overridden(write_yaml):
    text = TIP.replace("fiber: {radius: \"0.25 mm\"}", "_r: &r {radius: \"0.25 mm\"}\nfiber: {<<: *r, radius: \"0.3 mm\"}")
    from fiberpipe.config import load_raw

    data = load_raw(write_yaml(text, "merge.yaml"))
    assert data["fiber"] == {"radius": "0.3 mm"}


PHANTOM = """
name: ph
input:
  phantom: {n_fibers: 2, shape: [40, 24, 24], radius_vox: 3}
"""


def test_skeleton_tracer_with_skeletonize_disabled_is_refused(write_yaml):
    p = write_yaml(PHANTOM + "skeletonize: {enabled: false}\ntrace: {method: skeleton}\n", "sk.yaml")
    with pytest.raises(ConfigError) as err:
        load_config(p)
    msg = str(err.value)
    assert "sk.yaml" in msg
    assert "skeletonize.enabled is false but trace.method is skeleton" in msg
    assert "trace.method: slices" in msg


@pytest.mark.parametrize("extra", [
    "trace: {method: skeleton}\n",
    "skeletonize: {enabled: true}\ntrace: {method: skeleton}\n",
    "skeletonize: {enabled: false}\ntrace: {method: slices}\n",
    "skeletonize: {enabled: true}\n",
])
def test_consistent_skeletonize_and_trace_settings_are_accepted(write_yaml, extra):
    cfg = load_config(write_yaml(PHANTOM + extra, "ok.yaml"))
    assert cfg.trace.method in ("auto", "slices", "skeleton")


def test_friction_stiffness_takes_units_and_a_misspelt_law_gets_a_suggestion():
    from fiberpipe.config import validate_config
    from fiberpipe.errors import ConfigError

    base = {"name": "a", "input": {"fibers": "x.h5"}}
    c = validate_config({**base, "scene": {"effects": ["contact", "friction"], "friction": {"stiffness": "10 N/mm"}}})
    assert c.scene.friction.stiffness == pytest.approx(1e4)
    with pytest.raises(ConfigError, match="did you mean 'hertz_oriented'"):
        validate_config({**base, "scene": {"effects": ["contact"], "contact": {"law": "hertz_orientd"}}})


def test_the_plane_penalty_defaults_of_the_schema_are_the_solvers():
    from fiberpipe.config import PlatesConfig, WallsConfig
    from fiberpipe.solver._kernels_boundary import DEFAULT_ONSET_FRACTION
    from fiberpipe.solver.terms import Plates, Walls
    from fiberpipe.solver.terms.base import DEFAULT_PENALTY_FACTOR

    for schema in (PlatesConfig(), WallsConfig()):
        assert schema.penalty_factor == DEFAULT_PENALTY_FACTOR and schema.onset_fraction == DEFAULT_ONSET_FRACTION
    assert Walls().onset_fraction == Plates(lower="fixed").onset_fraction == DEFAULT_ONSET_FRACTION


def test_a_plane_onset_outside_its_range_is_refused():
    from fiberpipe.errors import FiberpipeError
    from fiberpipe.solver.terms import Walls

    with pytest.raises(FiberpipeError, match="onset_fraction"):
        Walls({"y": (0.0, 1.0)}, onset_fraction=0.0)


def test_set_dotted_indexes_lists_and_refuses_keys_that_cannot_be_set():
    """One setter for --set, --param and study sweeps: an integer part indexes a list, missing
    sections are created, a key that walks into a value or past a list's end is a ConfigError."""
    from fiberpipe.config import set_dotted

    raw = {"scene": {"drives": [{"velocity": "1 mm/min"}]}, "mesh": {"element_length": "0.3 mm"}}
    set_dotted(raw, "scene.drives.0.velocity", "2 mm/min")
    set_dotted(raw, "solver.threads", 2)
    assert raw["scene"]["drives"] == [{"velocity": "2 mm/min"}] and raw["solver"] == {"threads": 2}
    with pytest.raises(ConfigError, match=r"'scene.drives.3.velocity': 'scene.drives' is a list of 1; '3' is not"):
        set_dotted(raw, "scene.drives.3.velocity", "1 mm/min")
    with pytest.raises(ConfigError, match=r"'mesh.element_length.x': 'mesh.element_length' is a value"):
        set_dotted(raw, "mesh.element_length.x", 1)
