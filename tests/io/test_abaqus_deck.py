"""The Abaqus/Explicit deck of a scene (``fiberpipe export abaqus``, ``model.inp``): it passes an
independent keyword checker (tests/io/inp_syntax.py), holds the scene's settings (checked against
the config and the solver's own definitions), and its mesh reads back with meshio."""

import math
from pathlib import Path

import meshio
import numpy as np
import pytest
from click.testing import CliRunner

from fiberpipe.bench import config_mesh
from fiberpipe.cli import main
from fiberpipe.config import load_config
from fiberpipe.io.abaqus import abaqus_deck, pressure_overclosure

from inp_syntax import check, parse

REPO = Path(__file__).resolve().parents[2]

SCENE = """
name: deck
input:
  polylines:
    - [[0, 0.25e-3, 0], [0, 0.25e-3, 3.0e-3]]
    - [[0.6e-3, 0.25e-3, 0], [0.6e-3, 0.25e-3, 3.0e-3]]
    - [[0.3e-3, 0.74e-3, 0], [0.3e-3, 0.74e-3, 3.0e-3]]
mesh: {element_length: "0.3 mm"}
material: {youngs_modulus: "15 GPa", poisson_ratio: 0.3, density: "1380 kg/m^3"}
fiber: {radius: "0.25 mm"}
scene:
  effects: [gravity, damping, contact, friction, plates, walls, constraints]
  gravity: {acceleration: [0, "-9.81 m/s^2", 0]}
  damping: {alpha: "1e5 1/s", beta: "0 s"}
  contact: CONTACT
  friction: {mu: 0.2}
  plates: {axis: y, lower: moving, upper: fixed}
  walls: {x: ["-0.5 mm", "1.1 mm"]}
  constraints: {lock_axial: all}
  loading: {displacement: "0.1 mm", velocity: "1000 mm/min", ramp: smooth, ramp_fraction: 0.02}
solver: {dt_safety: 0.95, output_frames: 5}
"""


def _scene(write_yaml, contact="{law: hertz_oriented}"):
    from fiberpipe.model.mesh import mesh_polylines
    from fiberpipe.polylines import Polylines
    cfg = load_config(write_yaml(SCENE.replace("CONTACT", contact)))
    lines = [np.asarray(p, float) for p in cfg.input.polylines]
    mesh = mesh_polylines(Polylines.from_list(lines, [cfg.fiber.radius] * len(lines)), cfg.mesh.element_length,
                          radius_m=cfg.fiber.radius)
    return cfg, mesh


def _kw(kws, name, **params):
    return [k for k in kws if k.name == name and all(k.params.get(p) == v for p, v in params.items())]


def test_the_checker_can_fail():
    good = "*HEADING\nx\n*PART, NAME=P\n*NODE\n1, 0, 0, 0\n2, 1, 0, 0\n*ELEMENT, TYPE=B31, ELSET=E\n1, 1, 2\n*END PART\n" \
           "*STEP\n*DYNAMIC, EXPLICIT\n, 1.\n*END STEP\n"
    assert check(good)[0] == []
    for bad, why in [
        (good.replace("*HEADING", "*HEADIN"), "unknown keyword"),
        (good.replace("*PART, NAME=P", "*PART"), "required parameter NAME"),
        (good.replace("1, 1, 2", "1, 1, 3"), "node 3 not defined"),
        (good.replace("TYPE=B31", "TYPE=C3D8"), "TYPE=C3D8"),
        (good.replace("*END PART\n", ""), "not allowed here"),
        (good.replace(", 1.", ", -1."), "time period"),
        (good.replace("*END STEP\n", "*BOUNDARY\nNOSUCHSET, 1, 1\n*END STEP\n"), "NOSUCHSET not defined"),
    ]:
        problems = check(bad)[0]
        assert any(why in p for p in problems), (why, problems)


def test_paper40_deck_passes_the_checker():
    cfg = load_config(REPO / "configs" / "paper-40.yaml")
    text, figures = abaqus_deck(cfg, config_mesh(cfg))
    problems, model = check(text)
    assert problems == [], "\n".join(problems[:20])
    kws = model.keywords
    assert len(_kw(kws, "ELEMENT", TYPE="B31")) == 40  # one element set per fiber
    assert len(_kw(kws, "BEAM SECTION", SECTION="CIRC")) == 40
    assert len(_kw(kws, "RIGID BODY")) == 4  # two plates, two walls
    assert len(_kw(kws, "AMPLITUDE", DEFINITION="SMOOTH STEP")) == 1
    assert figures["contact_fit_error_full_scale"] < 1e-2


def test_deck_holds_the_scene(write_yaml):
    cfg, mesh = _scene(write_yaml)
    text, figures = abaqus_deck(cfg, mesh)
    assert check(text)[0] == []
    kws = parse(text)
    # fibers: B31, one element set per fiber with its elements, circular sections of each radius
    for f in range(3):
        (el,) = _kw(kws, "ELEMENT", ELSET=f"FIBER{f}")
        got = np.array([[int(x) for x in r] for _, r in el.data])
        want = mesh.elements()[mesh.elem_offsets[f]:mesh.elem_offsets[f + 1]] + 1
        np.testing.assert_array_equal(got[:, 1:], want)
        (sec,) = _kw(kws, "BEAM SECTION", ELSET=f"FIBER{f}")
        assert float(sec.data[0][1][0]) == pytest.approx(0.25e-3, rel=1e-9)
    # material: density and the mass-proportional damping of scene.damping
    (dmp,) = _kw(kws, "DAMPING")
    assert float(dmp.params["ALPHA"]) == pytest.approx(1e5) and float(dmp.params["BETA"]) == 0
    (den,) = _kw(kws, "DENSITY")
    assert float(den.data[0][1][0]) == pytest.approx(1380)
    # gravity as GRAV: magnitude and direction
    (dl,) = [k for k in _kw(kws, "DLOAD") if k.data[0][1][1] == "GRAV"]
    assert [float(x) for x in dl.data[0][1][2:]] == pytest.approx([9.81, 0, -1, 0])
    # step: the solver's own loading time (fiberpipe.solver.terms.planes.Plates)
    from fiberpipe.solver.terms import Plates
    T = Plates(axis="y", displacement_m=1e-4, velocity_m_s=1 / 60, ramp="smooth", ramp_fraction=0.02).loading_time_s
    (dyn,) = _kw(kws, "DYNAMIC")
    assert float(dyn.data[0][1][1]) == pytest.approx(T, rel=1e-9) and dyn.params["SCALE FACTOR"] == "0.95"
    # friction and the tabular law
    assert [float(k.data[0][1][0]) for k in _kw(kws, "FRICTION")] == [0.2, 0.2]
    assert len(_kw(kws, "SURFACE BEHAVIOR", **{"PRESSURE-OVERCLOSURE": "TABULAR"})) == 1
    # axial lock: every fiber node's z fixed
    bnd = [r for k in _kw(kws, "BOUNDARY") if "TYPE" not in k.params for _, r in k.data]
    assert ["FIBERS-1.ALL_NODES", "3", "3"] in bnd
    # history output: the six energies and each plate's reaction
    (en,) = _kw(kws, "ENERGY OUTPUT")
    assert {"ALLKE", "ALLSE", "ALLPW", "ALLFD", "ALLVD", "ALLWK"} <= {x for _, r in en.data for x in r}
    outs = {k.params.get("NSET"): [x for _, r in k.data for x in r] for k in _kw(kws, "NODE OUTPUT") if "NSET" in k.params}
    assert outs == {"FIBERS-1.RP_PLATE_LOWER": ["RF2", "U2"], "FIBERS-1.RP_PLATE_UPPER": ["RF2", "U2"]}


def _smooth_step_integral(pts, t_end, n=200_001):
    """∫ a(t) dt of Abaqus' SMOOTH STEP amplitude (a = a0 + (a1 − a0) ξ³(10 − 15ξ + 6ξ²) between points)."""
    t = np.linspace(0, t_end, n)
    a = np.empty_like(t)
    for i, x in enumerate(t):
        k = max(j for j in range(len(pts)) if pts[j][0] <= x or j == 0)
        if k == len(pts) - 1:
            a[i] = pts[-1][1]
            continue
        (t0, a0), (t1, a1) = pts[k], pts[k + 1]
        xi = (x - t0) / (t1 - t0)
        a[i] = a0 + (a1 - a0) * xi**3 * (10 - 15 * xi + 6 * xi**2)
    return float(np.trapezoid(a, t) if hasattr(np, "trapezoid") else np.trapz(a, t))


def test_moving_plate_travels_the_loading_displacement_at_the_plateau_speed(write_yaml):
    cfg, mesh = _scene(write_yaml)
    text, _ = abaqus_deck(cfg, mesh)
    problems, model = check(text)
    pts = model.amplitudes["PLATE_VELOCITY"]
    (vel,) = _kw(model.keywords, "BOUNDARY", TYPE="VELOCITY")
    rp, dof, _, v = vel.data[0][1]
    assert (rp, dof) == ("FIBERS-1.RP_PLATE_LOWER", "2") and float(v) == pytest.approx(1 / 60)
    assert max(a for _, a in pts) == 1.0
    T = float(_kw(model.keywords, "DYNAMIC")[0].data[0][1][1])
    assert float(v) * _smooth_step_integral(pts, T) == pytest.approx(1e-4, rel=1e-6)


def test_plates_and_walls_sit_where_the_solver_puts_them(write_yaml):
    cfg, mesh = _scene(write_yaml)
    text, _ = abaqus_deck(cfg, mesh)
    kws = parse(text)
    surf = {k.params["NAME"]: k for k in _kw(kws, "SURFACE", TYPE="CYLINDER")}
    y = mesh.nodes_m[:, 1]
    expected = {"PLATE_LOWER": (1, y.min() - 0.25e-3, +1), "PLATE_UPPER": (1, y.max() + 0.25e-3, -1),
                "WALL_X_LO": (0, -0.5e-3, +1), "WALL_X_HI": (0, 1.1e-3, -1)}
    assert set(surf) == set(expected)
    for name, (ax, pos, sign) in expected.items():
        a_b = np.array([float(x) for x in surf[name].data[0][1]])
        c = np.array([float(x) for x in surf[name].data[1][1]])
        a, b = a_b[:3], a_b[3:]
        assert a[ax] == pytest.approx(pos, abs=1e-12) and b[ax] == pytest.approx(pos, abs=1e-12)
        x_loc, z_loc = b - a, c - a
        normal = np.cross(z_loc, x_loc)  # the profile's direction x' turned 90° about the generator z'
        assert normal[ax] == pytest.approx(sign) and np.count_nonzero(np.abs(normal) > 1e-12) == 1


def test_scaled_stiffness_preset_is_the_exact_eq1_table(write_yaml):
    from fiberpipe.solver.laws import ScaledStiffnessLaw
    cfg, mesh = _scene(write_yaml, "{law: scaled_stiffness, preset: table1_phi6}")
    tab = pressure_overclosure(cfg, mesh)
    law = ScaledStiffnessLaw.preset("table1_phi6")
    area = 2 * 0.25e-3 * float(np.mean(mesh.element_lengths_m()))  # per contact: F / (2R l_e)
    h = np.array([r[1] for r in tab.rows])
    p = np.array([r[0] for r in tab.rows])
    np.testing.assert_allclose(h, np.arange(len(h)) * law.d_m, rtol=1e-12)
    np.testing.assert_allclose(p * area, law.native_force(h), rtol=1e-9, atol=1e-18)
    mid = 0.5 * (h[1:] + h[:-1])  # piecewise linear: exact between the rows too
    np.testing.assert_allclose(np.interp(mid, h, p) * area, law.native_force(mid), rtol=1e-9, atol=1e-18)
    assert tab.fit_error_full_scale == 0


@pytest.mark.parametrize("contact, check_law", [
    ("{law: hertz_crossed, angle: '10 deg'}", "crossed"),
    ("{law: hertz_parallel}", "parallel"),
])
def test_hertz_tables_fit_the_law_and_state_the_error(write_yaml, contact, check_law):
    from fiberpipe.verification.contact_cases import johnson_line_load
    from fiberpipe.solver.laws import HertzCrossedLaw
    cfg, mesh = _scene(write_yaml, contact)
    tab = pressure_overclosure(cfg, mesh)
    h = np.array([r[1] for r in tab.rows])
    p = np.array([r[0] for r in tab.rows])
    if check_law == "crossed":
        K = HertzCrossedLaw(10.0).stiffness()  # the solver's tabulated K(10°)
        exact = K * h**1.5 / (2 * 0.25e-3 * float(np.mean(mesh.element_lengths_m())))
    else:
        exact = np.array([0.0] + [johnson_line_load(x) for x in h[1:]]) / (2 * 0.25e-3)
    np.testing.assert_allclose(p[1:], exact[1:], rtol=2e-4)
    assert 0 < tab.fit_error_full_scale < 1e-2 and tab.fit_error_relative < 2e-2
    text, figures = abaqus_deck(cfg, mesh)
    assert f"{100 * tab.fit_error_full_scale:.3g} % of full scale" in text


def test_mesh_reads_back_with_meshio(write_yaml, tmp_path):
    cfg, mesh = _scene(write_yaml)
    text, figures = abaqus_deck(cfg, mesh)
    (tmp_path / "model.inp").write_text(text)
    back = meshio.read(tmp_path / "model.inp")
    n = mesh.n_nodes
    np.testing.assert_allclose(back.points[:n], mesh.nodes_m, rtol=1e-8, atol=1e-15)
    assert len(back.points) == n + len(figures["planes"])  # the reference nodes follow the fibers'
    cells = np.concatenate([c.data for c in back.cells if c.type == "line"])
    np.testing.assert_array_equal(cells, mesh.elements())
    for f in range(mesh.n_fibers):
        assert f"FIBER{f}" in back.cell_sets


def test_mesh_stage_writes_the_deck_and_export_writes_it_anywhere(write_yaml, tmp_path):
    cfg_path = write_yaml(SCENE.replace("CONTACT", "{law: hertz_oriented}"))
    r = CliRunner().invoke(main, ["--quiet", "export", "abaqus", str(cfg_path), "--run", str(tmp_path / "run"),
                                  "--out", str(tmp_path / "deck.inp")])
    assert r.exit_code == 0, r.output
    staged = (tmp_path / "run" / "model.inp").read_text()
    assert staged == (tmp_path / "deck.inp").read_text()
    assert check(staged)[0] == []


def test_a_scene_without_a_time_period_is_a_one_line_error(write_yaml, tmp_path):
    cfg_path = write_yaml("name: still\ninput:\n  polylines: [[[0, 0, 0], [3.0e-3, 0, 0]]]\nfiber: {radius: '0.25 mm'}\n"
                          "scene: {effects: [gravity]}\n")
    r = CliRunner().invoke(main, ["export", "abaqus", str(cfg_path), "--run", str(tmp_path / "run")])
    assert r.exit_code != 0
    assert "solver.end_time" in r.output and "Traceback" not in r.output
    # the mesh stage falls back to the mesh alone
    mesh_only = (tmp_path / "run" / "model.inp").read_text()
    assert "*STEP" not in mesh_only and "*ELEMENT, TYPE=B31" in mesh_only
    assert math.isfinite(len(mesh_only))


def test_simulate_rewrites_the_deck_with_the_scene_it_ran(write_yaml, tmp_path):
    """The mesh stage's cache does not follow the scene; the simulate stage writes model.inp again."""
    base = (REPO / "configs" / "verify" / "cantilever-small.yaml").read_text().replace("end_time: \"4 ms\"", "end_time: \"0.05 ms\"")
    assert "0.05 ms" in base
    out = tmp_path / "run"
    for alpha in ("9000 1/s", "7000 1/s"):
        cfg_path = write_yaml(base.replace('alpha: "9000 1/s"', f'alpha: "{alpha}"'), "c.yaml")
        r = CliRunner().invoke(main, ["--quiet", "run", str(cfg_path), "--out", str(out), "--to", "simulate"])
        assert r.exit_code == 0, r.output
    (dmp,) = _kw(parse((out / "model.inp").read_text()), "DAMPING")
    assert float(dmp.params["ALPHA"]) == pytest.approx(7000)


@pytest.mark.parametrize("ramp", ["smooth", "linear"])
def test_a_loading_path_is_the_plate_velocity_amplitude(write_yaml, ramp):
    """scene.loading.path: the deck's plate velocity reaches each entry in turn at the solver's times."""
    from fiberpipe.config import load_config
    from fiberpipe.solver.terms import Plates

    cfg, mesh = _scene(write_yaml)
    path = ["0.1 mm", "0.04 mm", "0.115 mm"]
    cfg = load_config(cfg.source_path, {"scene.loading": {"path": path, "hold": "2 ms", "velocity": "1000 mm/min",
                                                          "ramp": ramp}})
    text, _ = abaqus_deck(cfg, mesh)
    problems, model = check(text)
    assert not problems, problems
    pts = model.amplitudes["PLATE_VELOCITY"]
    times = [t for t, _ in pts]
    assert all(b > a for a, b in zip(times, times[1:]))
    p = Plates(path_m=[1e-4, 0.4e-4, 1.15e-4], hold_s=2e-3, velocity_m_s=1 / 60, ramp=ramp)
    _, dur, _ = p.travel_table()
    ends = np.cumsum(dur)
    T = float(_kw(model.keywords, "DYNAMIC")[0].data[0][1][1])
    assert T == pytest.approx(p.loading_time_s, rel=1e-9)
    for k, target in enumerate([1e-4, 0.4e-4, 1.15e-4]):  # the travel at the end of each move and hold
        for t_end in ends[2 * k:2 * k + 2]:
            assert (1 / 60) * _smooth_step_integral(pts, t_end) == pytest.approx(target, rel=2e-4)
