"""The study's reference and error measures against hand-computed values: the Richardson limit
(``reference.extrapolate``), the observed order, the rearrangement curve u_y(u_z) and its error."""

import csv
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import yaml

from fiberpipe.errors import ConfigError
from fiberpipe.studies.sweep import (
    _extrapolation_points,
    _rearrangement_error,
    load_study,
    observed_order,
    rearrangement_curve,
    richardson_extrapolate,
    run_study,
    study_points,
)

# ---------------------------------------------------------------- Richardson (reference.extrapolate)


def _limit(U):
    return 3e3 * U + 0.5


def _curve(h, p, U):
    """F_h(U) = F*(U) + C(U) h^p with F* = 3e3 U + 0.5 (N) and C(U) h^p = 0.2 (U / 1 mm)(h / 0.1 mm)^p:
    a p-th order sequence, linear in U for each h (so the linear interpolation onto the finest curve's
    U is exact), its discretisation error of the order of F* itself."""
    return _limit(U) + 0.2 * (U / 1e-3) * (h / 1e-4) ** p


@pytest.mark.parametrize("p", [1.0, 2.0, 1.5])
@pytest.mark.parametrize("h", [(2e-4, 3e-4), (1e-4, 2e-4), (3e-4, 4.5e-4)])
def test_richardson_recovers_the_limit_of_a_pth_order_sequence(h, p):
    U1 = np.linspace(0.0, 1e-3, 11)
    U2 = np.linspace(0.0, 1.2e-3, 7)  # the coarser run on another U grid, past the finest's range
    lim = richardson_extrapolate(list(h), [(U1, _curve(h[0], p, U1)), (U2, _curve(h[1], p, U2))], order=p)
    exact = _limit(U1)
    np.testing.assert_allclose(lim["F"], exact, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(lim["U"], U1)
    assert lim["order"] == p and lim["h"] == list(h)
    # the finest run itself is off by C h1^p: the extrapolation removes it
    assert np.max(np.abs(_curve(h[0], p, U1) - exact)) > 0.1


def test_richardson_with_the_wrong_order_is_off_by_the_known_amount():
    h1, h2, U = 2e-4, 4e-4, np.array([0.0, 5e-4, 1e-3])
    F1, F2 = _curve(h1, 2.0, U), _curve(h2, 2.0, U)
    lim = richardson_extrapolate([h1, h2], [(U, F1), (U, F2)], order=1.0)
    # p = 1 assumed: F1 + (F1 − F2)/(2 − 1) = F* + 2 C h1² − C h2² = F* − 2 C h1²
    np.testing.assert_allclose(lim["F"], _limit(U) - 2 * (_curve(h1, 2.0, U) - _limit(U)), rtol=1e-12, atol=1e-15)
    assert np.max(np.abs(lim["F"] - _limit(U))) == pytest.approx(2 * 0.2 * 4.0, rel=1e-12)  # C h1² = 0.8 N at 1 mm


@pytest.mark.parametrize("p", [0.8, 1.0, 2.0, 3.0])
@pytest.mark.parametrize("h", [(1e-4, 2e-4, 4e-4), (2e-4, 3e-4, 4.5e-4), (2e-4, 3e-4, 6e-4)])
def test_observed_order_recovers_p(h, p):
    U = np.linspace(0.0, 1.0, 5)
    f = [_curve(hi, p, U) for hi in h]
    assert observed_order(list(h), f) == pytest.approx(p, abs=1e-10)


def test_observed_order_is_clamped_and_degenerate_cases():
    U = np.linspace(0.1, 1.0, 5)
    h = [1e-4, 2e-4, 4e-4]
    assert observed_order(h, [_curve(x, 6.0, U) for x in h]) == 4.0  # clamped to [0.5, 4]
    assert observed_order(h, [_curve(x, 0.2, U) for x in h]) == 0.5
    assert observed_order(h, [U, U, U + 1.0]) == 2.0  # two equal solutions: the default


def test_richardson_auto_order_recovers_the_limit():
    h = [0.2e-3, 0.3e-3, 0.45e-3]
    U = np.linspace(0.0, 1e-3, 9)
    lim = richardson_extrapolate(h, [(U, _curve(x, 1.3, U)) for x in h], order="auto")
    assert lim["order"] == pytest.approx(1.3, abs=1e-10)
    np.testing.assert_allclose(lim["F"], _limit(U), rtol=1e-9, atol=1e-12)
    with pytest.raises(ValueError, match="needs 3"):
        richardson_extrapolate(h[:2], [(U, U), (U, U)], order="auto")
    with pytest.raises(ValueError, match="distinct"):
        richardson_extrapolate([1.0, 1.0], [(U, U), (U, U)], order=2)


CANTILEVER = """
name: c
input: {polylines: [[[0, 0, 0], ["6 mm", 0, 0]]]}
mesh: {element_length: "0.5 mm"}
fiber: {radius: "0.25 mm"}
scene:
  effects: [clamps, loads]
  clamps: [{fiber: 0, at: start}]
  loads: [{fiber: 0, at: end, force: [0, 0, "-1 mN"]}]
solver: {end_time: "0.1 ms"}
"""


def _spec(tmp_path, sweep, extra=""):
    (tmp_path / "base.yaml").write_text(CANTILEVER)
    (tmp_path / "s.yaml").write_text(f"base: base.yaml\nsweep: {sweep}\n{extra}")
    spec, ctx = load_study(tmp_path / "s.yaml")
    return spec, study_points(spec, ctx["base"], "s.yaml")


def test_extrapolation_picks_the_finest_values_in_si(tmp_path):
    spec, pts = _spec(tmp_path, '{mesh.element_length: ["0.6 mm", "0.0002 m", "0.3 mm"]}',
                      "reference: {extrapolate: {key: mesh.element_length, order: 2}}\nmeasures: [curve]\n")
    hs = _extrapolation_points(spec, pts, "s.yaml")
    assert [h for h, _ in hs] == pytest.approx([2e-4, 3e-4], rel=1e-12)
    assert [p["overrides"]["mesh.element_length"] for _, p in hs] == ["0.0002 m", "0.3 mm"]


@pytest.mark.parametrize("sweep, ref, measures, msg", [
    ('{mesh.element_length: ["0.3 mm", "0.2 mm"], solver.dt_safety: [0.5]}', "{key: mesh.element_length}", "[curve]", "sweep of that key only"),
    ('{mesh.element_length: ["0.3 mm", "0.0003 m"]}', "{key: mesh.element_length}", "[curve]", "at least 2 distinct"),
    ('{mesh.element_length: ["0.3 mm", "0.2 mm"]}', "{key: mesh.element_length, order: auto}", "[curve]", "at least 3 distinct"),
    ('{mesh.element_length: ["0.3 mm", "0.2 mm", "0.0002 m"]}', "{key: mesh.element_length}", "[curve]", "2 finest values"),
    ('{mesh.element_length: ["0.3 mm", "0.2 mm"]}', "{key: mesh.element_length}", "[curve, rearrangement]", "rearrangement measure needs a reference run"),
])
def test_bad_extrapolation_fails_before_running(tmp_path, sweep, ref, measures, msg):
    (tmp_path / "base.yaml").write_text(CANTILEVER)
    (tmp_path / "s.yaml").write_text(f"base: base.yaml\nsweep: {sweep}\nreference: {{extrapolate: {ref}}}\nmeasures: {measures}\n")
    with pytest.raises(ConfigError, match=msg):
        run_study(tmp_path / "s.yaml", tmp_path / "out", echo=lambda s: None)
    assert not (tmp_path / "out").exists()


# ---------------------------------------------------------------- rearrangement measure


def _three_beams(uz, uy2, uy3, nodes=4, r=0.25e-3):
    """Frames (K, 3·nodes, 3) of the 3-beam case: fiber 0 at y = 0 above, moved down by uz;
    fiber 1 at y = −r moved by −uy2 (outward), fiber 2 at y = +r moved by +uy3."""
    uz, uy2, uy3 = (np.asarray(a, float) for a in (uz, uy2, uy3))
    x = np.linspace(0.0, 3e-3, nodes)
    K = len(uz)
    X = np.zeros((K, 3 * nodes, 3))
    X[:, :, 0] = np.tile(x, 3)
    X[:, :nodes, 2] = np.sqrt(3.0) * r + r - uz[:, None]
    X[:, nodes:2 * nodes, 1] = -r - uy2[:, None]
    X[:, 2 * nodes:, 1] = r + uy3[:, None]
    X[:, nodes:, 2] = r
    # a little bending of fiber 0 (zero mean over its nodes) must not change u_z
    X[:, :nodes, 2] += 1e-6 * np.array([1.0, -1.0, -1.0, 1.0])[None, :] * np.linspace(0, 1, K)[:, None]
    return SimpleNamespace(frames_positions=X, mesh=SimpleNamespace(node_offsets=np.array([0, nodes, 2 * nodes, 3 * nodes])))


def test_rearrangement_curve_on_a_hand_made_case():
    uz = [0.0, 0.1e-3, 0.2e-3, 0.3e-3]
    uy2 = [0.0, 0.05e-3, 0.12e-3, 0.2e-3]
    uy3 = [0.0, 0.07e-3, 0.10e-3, 0.24e-3]
    z, y = rearrangement_curve(_three_beams(uz, uy2, uy3))
    np.testing.assert_allclose(z, uz, rtol=0, atol=1e-15)
    np.testing.assert_allclose(y, [0.0, 0.06e-3, 0.11e-3, 0.22e-3], rtol=0, atol=1e-15)
    # beams moving inward count negative
    _, y_in = rearrangement_curve(_three_beams(uz, [-a for a in uy2], [-a for a in uy3]))
    np.testing.assert_allclose(y_in, -y, rtol=0, atol=1e-15)


def test_rearrangement_error_against_hand_computed_values():
    # reference: u_y = 0.5 u_z up to 0.2 mm, then 0.1 mm + 1.0 (u_z − 0.2 mm), on 5 frames
    uz_r = np.array([0.0, 0.1, 0.2, 0.3, 0.4]) * 1e-3
    uy_r = np.array([0.0, 0.05, 0.1, 0.2, 0.3]) * 1e-3
    ref = _three_beams(uz_r, uy_r, uy_r)
    assert _rearrangement_error(ref, ref) == 0.0
    # run: frames at other u_z (interpolated on the reference), offsets +0.006 mm at 0.15 mm and
    # −0.012 mm at 0.35 mm; its frame at 0.5 mm is past the reference's range and does not count
    uz = np.array([0.0, 0.15, 0.25, 0.35, 0.5]) * 1e-3
    uy_on_ref = np.array([0.0, 0.075, 0.15, 0.25, 7.0]) * 1e-3
    uy = uy_on_ref + np.array([0.0, 0.006, 0.0, -0.012, 0.0]) * 1e-3
    run = _three_beams(uz, uy, uy)
    assert _rearrangement_error(ref, run) == pytest.approx(0.012 / 0.3, rel=1e-9)
    # asymmetric beams: only their mean counts (+0.004 and −0.004 mm → no error)
    run2 = _three_beams(uz_r, uy_r + 0.004e-3, uy_r - 0.004e-3)
    assert _rearrangement_error(ref, run2) == pytest.approx(0.0, abs=1e-12)


REARRANGEMENT = Path(__file__).resolve().parents[2] / "configs" / "verify" / "study-rearrangement.yaml"


def test_rearrangement_study_end_to_end(tmp_path):
    """The 3-beam case (configs/verify/study-rearrangement.yaml) shortened to u_z = 0.15 mm at
    1e4 mm/min; the sweep's point equal to the reference has error 0, the 10× faster one the error
    computed independently from the two runs' node positions."""
    from fiberpipe.post.history import load_simulation
    from fiberpipe.verification.contact_cases import _curve_error, kinematic_uy

    base = yaml.safe_load(REARRANGEMENT.read_text())
    base["scene"]["drives"][0]["displacement"] = [0, 0, "-0.15 mm"]
    base["scene"]["drives"][0]["velocity"] = "10000 mm/min"
    base["solver"]["output_frames"] = 31
    base["post"] = {"plots": False}
    (tmp_path / "base.yaml").write_text(yaml.safe_dump(base))
    (tmp_path / "s.yaml").write_text(
        "base: base.yaml\n"
        'sweep: {scene.drives.0.velocity: ["10000 mm/min", "100000 mm/min"]}\n'
        "measures: [rearrangement, positions]\n")
    out = run_study(tmp_path / "s.yaml", tmp_path / "out", echo=lambda s: None)
    rows = list(csv.DictReader((out / "study.csv").open()))
    assert [r["scene.drives.0.velocity"] for r in rows] == ["10000 mm/min", "100000 mm/min"]
    assert float(rows[0]["rearrangement_error"]) == 0.0 and float(rows[0]["position_error"]) == 0.0

    def curve(sim_path):  # u_z of beam 1, mean outward u_y of beams 2/3, by node masks
        s = load_simulation(sim_path)
        X, fib = np.asarray(s.frames_positions), np.repeat(np.arange(3), np.diff(s.mesh.node_offsets))
        uz = -(X[:, fib == 0, 2].mean(axis=1) - X[0, fib == 0, 2].mean())
        uy2 = -(X[:, fib == 1, 1].mean(axis=1) - X[0, fib == 1, 1].mean())
        uy3 = X[:, fib == 2, 1].mean(axis=1) - X[0, fib == 2, 1].mean()
        return uz, 0.5 * (uy2 + uy3)

    uz_r, uy_r = curve(out / "reference" / "simulation.h5")
    assert uz_r[-1] == pytest.approx(0.15e-3, rel=1e-6)
    # the slow run follows the rigid-section kinematics u_y = √(4r² − (√3 r − u_z)²) − r (within 0.5 %:
    # the plate's penalty onset seats beams 2/3 0.5 µm deeper, measured 0.31 %)
    assert np.max(np.abs(uy_r - kinematic_uy(uz_r))) / np.max(kinematic_uy(uz_r)) < 5e-3
    uz, uy = curve(out / "points" / rows[1]["id"] / "simulation.h5")
    expected = _curve_error(uz, uy, uz_r, uy_r)
    assert float(rows[1]["rearrangement_error"]) == pytest.approx(expected, rel=1e-7)  # the CSV keeps 9 digits
    assert expected > 1e-3  # the 10× faster loading departs
