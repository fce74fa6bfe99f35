"""Bad input through the CLI: a one-line error, non-zero exit, no traceback, earlier results kept.

Includes a property-based (hypothesis) fuzz over malformed configs and volumes.
"""

from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fiberpipe.cli import main

GOOD = {
    "name": "fuzz",
    "input": {"polylines": [[[0, 0, 0], ["3 mm", 0, 0]], [[0, "1 mm", 0], ["3 mm", "1 mm", 0]]]},
    "fiber": {"radius": "0.25 mm"},
    "mesh": {"element_length": "0.3 mm"},
}


def _invoke(args):
    return CliRunner().invoke(main, [str(a) for a in args])


def _assert_clean_failure(result):
    assert result.exit_code != 0, result.output
    assert "Traceback" not in result.output
    errors = [ln for ln in result.output.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1, result.output
    assert result.exception is None or isinstance(result.exception, SystemExit)


def _volume_config(tmp_path: Path, volume_name: str, **extra) -> Path:
    cfg = {"name": "vol", "input": {"volume": volume_name, "voxel_size": "15 um", **extra}}
    p = tmp_path / "vol.yaml"
    p.write_text(yaml.safe_dump(cfg))
    return p


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda d: np.save(d / "v.npy", np.zeros((0, 4, 4))), "empty"),
        (lambda d: np.save(d / "v.npy", np.full((8, 8, 8), np.nan)), "NaN"),
        (lambda d: np.save(d / "v.npy", np.zeros((16, 16))), "2D"),
        (lambda d: np.save(d / "v.npy", np.ones((16, 16, 16))), ""),
        (lambda d: (d / "v.npy").write_bytes(b"\x93NUMPY garbage"), ""),
    ],
)
def test_bad_volumes(tmp_path, make, message):
    make(tmp_path)
    r = _invoke(["run", _volume_config(tmp_path, "v.npy"), "--out", tmp_path / "run"])
    _assert_clean_failure(r)
    assert message.lower() in r.output.lower()


@pytest.mark.parametrize("content", [b"", b"II*\x00 truncated tiff", b"not a tiff at all"])
def test_bad_tiffs(tmp_path, content):
    (tmp_path / "v.tif").write_bytes(content)
    _assert_clean_failure(_invoke(["run", _volume_config(tmp_path, "v.tif"), "--out", tmp_path / "run"]))


def test_wrong_artifact_kind_is_refused(tmp_path):
    p = tmp_path / "good.yaml"
    p.write_text(yaml.safe_dump(GOOD))
    assert _invoke(["run", p, "--out", tmp_path / "run", "--to", "mesh"]).exit_code == 0
    cfg = dict(GOOD, input={"fibers": str(tmp_path / "run" / "mesh.h5")})
    q = tmp_path / "wrongkind.yaml"
    q.write_text(yaml.safe_dump(cfg))
    r = _invoke(["run", q, "--out", tmp_path / "run2"])
    _assert_clean_failure(r)
    assert "is a mesh artifact, but a fibers artifact is needed" in r.output


# -- fuzz -----------------------------------------------------------------------------------------

SECTIONS = ["name", "input", "segment", "trace", "mesh", "material", "fiber", "scene", "solver", "post", "bogus"]
KEYS = ["radius", "element_length", "youngs_modulus", "density", "effects", "mu", "alpha", "dt_safety", "law", "x", "polylines", "typo"]
VALUES = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-5, 5),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8),
    st.sampled_from(["0.3 mm", "-1 mm", "15 GPa", "3 kg", "1e5 1/s", "nan mm", "1/0", "mm", "[", "{a: 1}"]),
    st.lists(st.integers(-2, 2), max_size=3),
)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(section=st.sampled_from(SECTIONS), key=st.sampled_from(KEYS), value=VALUES)
def test_fuzzed_configs_fail_cleanly_or_run(tmp_path, section, key, value):
    cfg = yaml.safe_load(yaml.safe_dump(GOOD))
    if section in ("name",):
        cfg["name"] = value
    else:
        if not isinstance(cfg.get(section), dict):
            cfg[section] = {}
        cfg[section][key] = value
    p = tmp_path / "fuzz.yaml"
    p.write_text(yaml.safe_dump(cfg))
    out = tmp_path / "run"
    r = _invoke(["run", p, "--out", out, "--to", "mesh"])
    if r.exit_code == 0:
        assert (out / "mesh.h5").exists()
    else:
        _assert_clean_failure(r)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(shape=st.lists(st.integers(0, 12), min_size=1, max_size=4), fill=st.sampled_from([0.0, 1.0, np.nan, np.inf, "random"]))
def test_fuzzed_volumes_fail_cleanly_or_run(tmp_path, shape, fill):
    arr = np.random.default_rng(0).random(shape) if fill == "random" else np.full(shape, fill)
    np.save(tmp_path / "v.npy", arr)
    r = _invoke(["run", _volume_config(tmp_path, "v.npy"), "--out", tmp_path / "run", "--to", "trace"])
    if r.exit_code != 0:
        _assert_clean_failure(r)


@pytest.mark.parametrize("command", [
    ["study", "s.yaml", "--workers", "0"],
    ["study", "s.yaml", "--workers", "-3"],
    ["fit", "c.yaml", "--target", "t.csv", "--param", "scene.friction.mu=0.1:0.4", "--workers", "0"],
    ["specimen", "c.yaml", "--seed", "-1"],
    ["phantom", "--out", "ph", "--seed", "-1"],
])
def test_workers_below_one_and_negative_seeds_are_refused(tmp_path, command):
    """--workers 0 or below, or a negative --seed, is a usage error naming the option before
    anything runs (not replaced by the study's own value, not a run with -3 workers, not numpy's
    'expected non-negative integer')."""
    for name in ("s.yaml", "c.yaml", "t.csv"):
        (tmp_path / name).write_text("x")
    result = CliRunner().invoke(main, [str(tmp_path / c) if c in ("s.yaml", "c.yaml", "t.csv", "ph") else c
                                       for c in command])
    option = command[-2]
    assert result.exit_code == 2 and option in result.output and "Traceback" not in result.output


@pytest.mark.parametrize("key, stage", [("input.truth", "trace"), ("post.reference_fibers", "post"),
                                        ("input.fibers", "mesh")])
def test_a_corrupt_fibers_input_is_refused_before_any_stage_runs(tmp_path, key, stage):
    """A fibers artifact the config names (ground truth, reference, input) with a NaN position is
    refused with its key before the first stage writes (a failed trace rewrote fibers.h5 before)."""
    from fiberpipe.artifacts import write_fibers
    from fiberpipe.config import validate_config
    from fiberpipe.errors import InputError
    from fiberpipe.pipeline import check_user_inputs
    from fiberpipe.polylines import Polylines

    bad = tmp_path / "bad.h5"
    write_fibers(bad, Polylines(np.array([[0, 0, 0], [1e-3, np.nan, 0.0]]), np.array([0, 2]), np.array([2.5e-4])))
    section, name = key.split(".")
    given = {} if key == "input.fibers" else GOOD.get(section, {})  # input.fibers replaces the polylines
    cfg = validate_config({**GOOD, section: {**given, name: str(bad)}}, where="t.yaml")
    with pytest.raises(InputError, match=rf"^{key}: .*bad.h5: fiber 0 has non-finite coordinates$"):
        check_user_inputs(cfg, [stage])


@pytest.mark.parametrize("args, message", [
    (["run"], "error: Missing argument 'CONFIG'. (see fiberpipe run --help)"),
    (["bogus"], "error: No such command 'bogus'. (see fiberpipe --help)"),
    (["run", "x.yaml", "--colour"], "error: No such option '--colour'. Did you mean '--out'?"),
])
def test_usage_errors_are_one_line(args, message):
    """A bad option, a missing argument or an unknown command: one line like every other error
    (click printed three: usage, hint, error)."""
    result = CliRunner().invoke(main, args, prog_name="fiberpipe")
    assert result.exit_code == 2 and result.output.strip().startswith(message), result.output
    assert len(result.output.strip().splitlines()) == 1, result.output


def test_export_checks_its_folders_before_the_stages_run(tmp_path):
    """export abaqus: a deck path under a file, or a --run folder under one, fails before the stages
    run (it ran them, then failed with FileExistsError), naming the option."""
    p = tmp_path / "good.yaml"
    p.write_text(yaml.safe_dump(GOOD))
    (tmp_path / "afile").write_text("x")
    r = _invoke(["export", "abaqus", p, "--run", tmp_path / "run", "--out", tmp_path / "afile" / "x.inp"])
    _assert_clean_failure(r)
    assert "choose another --out" in r.output and not (tmp_path / "run").exists()
    r = _invoke(["export", "abaqus", p, "--run", tmp_path / "afile" / "run", "--out", tmp_path / "x.inp"])
    _assert_clean_failure(r)
    assert "choose another --run" in r.output
