"""The CLI end to end on small inputs: outputs, caching, and one-line errors on bad input."""

import json

import numpy as np
import pytest
from click.testing import CliRunner

from fiberpipe.cli import main

TIP = """
name: tip
input:
  polylines:
    - [[0, 0, 0], ["15 mm", 0, 0]]
    - [[0, "1 mm", 0], ["15 mm", "1 mm", 0]]
fiber: {radius: "0.25 mm"}
mesh: {element_length: "0.3 mm"}
"""


def _run(*args):
    result = CliRunner().invoke(main, list(args))
    return result


def test_run_writes_mesh_artifacts_and_skips_when_unchanged(tmp_path, write_yaml):
    cfg = write_yaml(TIP)
    out = tmp_path / "run"
    r = _run("run", str(cfg), "--out", str(out))
    assert r.exit_code == 0, r.output
    for name in ("fibers.h5", "mesh.h5", "mesh.vtu", "model.inp", "run.log", "summary.json"):
        assert (out / name).exists(), name
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stages"]["mesh"]["elements"] == 100
    mtime = (out / "mesh.h5").stat().st_mtime_ns
    r = _run("run", str(cfg), "--out", str(out))
    assert "up to date" in r.output
    assert (out / "mesh.h5").stat().st_mtime_ns == mtime
    # a changed mesh setting reruns the mesh stage only
    cfg.write_text(TIP.replace("0.3 mm", "0.5 mm"))
    r = _run("run", str(cfg), "--out", str(out))
    assert "input        up to date" in r.output and "mesh         done" in r.output
    assert json.loads((out / "summary.json").read_text())["stages"]["mesh"]["elements"] == 60


def test_inspect_prints_kind_and_checks(tmp_path, write_yaml):
    out = tmp_path / "run"
    _run("run", str(write_yaml(TIP)), "--out", str(out))
    r = _run("inspect", str(out / "mesh.h5"), "--check")
    assert r.exit_code == 0
    assert "kind: mesh" in r.output and "/mesh/nodes: float64 (102, 3) [m]" in r.output and "check: ok" in r.output


@pytest.mark.parametrize(
    "text, message",
    [
        (TIP + "scene: {effect: [gravity]}\n", "unknown key 'scene.effect' (did you mean 'effects'?)"),
        (TIP + "material: {density: '3 m'}\n", "'material.density'"),
        ("name: [unclosed\n", "not valid YAML"),
        (TIP.replace("0.25 mm", "-0.25 mm"), "fiber.radius must be positive"),
        ("name: x\ninput: {volume: missing.tif, voxel_size: '15 um'}\n", "missing.tif"),
    ],
)
def test_bad_input_is_one_line_and_keeps_earlier_results(tmp_path, write_yaml, text, message):
    out = tmp_path / "run"
    assert _run("run", str(write_yaml(TIP, "good.yaml")), "--out", str(out)).exit_code == 0
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file() and p.name != "run.log"}
    r = _run("run", str(write_yaml(text, "bad.yaml")), "--out", str(out))
    assert r.exit_code != 0
    assert message in r.output
    assert "Traceback" not in r.output
    assert len([ln for ln in r.output.splitlines() if ln.startswith("error:")]) == 1
    after = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file() and p.name != "run.log"}
    assert after == before


def test_missing_config_file(tmp_path):
    r = _run("run", str(tmp_path / "nope.yaml"))
    assert r.exit_code != 0 and "config file not found" in r.output


def test_changed_stage_code_reruns_that_stage_and_what_follows(tmp_path, write_yaml, monkeypatch):
    """A fix of the mesh code (its sources' digest changes) reruns mesh but keeps the fibers: the
    stage key includes the sha256 of the sources each stage runs."""
    import fiberpipe.pipeline as P

    cfg = write_yaml(TIP)
    out = tmp_path / "run"
    assert _run("run", str(cfg), "--out", str(out)).exit_code == 0
    real = P.code_sha256

    def patched(paths):
        return real(paths) + ("-fixed" if "model" in paths else "")

    monkeypatch.setattr(P, "code_sha256", patched)
    r = _run("run", str(cfg), "--out", str(out))
    assert r.exit_code == 0, r.output
    assert "input        up to date" in r.output and "mesh         done" in r.output


def test_every_stage_hashes_existing_sources():
    from pathlib import Path

    import fiberpipe.pipeline as P

    root = Path(P.__file__).resolve().parent
    for name, stage in P.STAGES.items():
        assert stage.code, name
        for rel in stage.code:
            assert (root / rel).exists(), (name, rel)


@pytest.mark.parametrize("points, offsets, message", [
    ([[0, 0, 0], [1e-3, np.nan, 0]], [0, 2], "fiber 0 has non-finite coordinates"),
    ([[0, 0], [1e-3, 0]], [0, 2], r"fibers/points must be an \(N, 3\) array of positions, got shape \(2, 2\)"),
    ([[0, 0, 0], [1e-3, 0, 0]], [0, 3], "inconsistent fibers layout"),
])
def test_a_corrupt_fibers_artifact_fails_its_reader_and_the_check(tmp_path, points, offsets, message):
    """What a run refuses, `inspect --check` refuses too (it read such files as 'check: ok'), with
    the file named; the reader names the fiber with a non-finite position."""
    import re

    from fiberpipe.artifacts import read_fibers, write_artifact
    from fiberpipe.errors import ArtifactError

    path = tmp_path / "fibers.h5"
    write_artifact(path, "fibers", {"fibers/points": np.asarray(points, float), "fibers/offsets": np.asarray(offsets),
                                    "fibers/radius": np.array([2.5e-4])})
    with pytest.raises(ArtifactError, match=message):
        read_fibers(path)
    r = _run("inspect", str(path), "--check")
    assert r.exit_code == 1 and "check: FAILED" in r.output and re.search("layout: .*" + message, r.output)
