"""The run's output estimated before it starts, against the free disk space."""

import pytest

from fiberpipe.errors import ConfigError
from fiberpipe.io.output_size import check_free_space, estimate_output_bytes


def test_estimate_is_an_upper_bound_of_the_raw_frames():
    # 24 frames of 4000 fibers × 51 nodes: positions alone are 24 × 204 000 × 3 × 8 B = 117.5 MB
    size = estimate_output_bytes(204000, 200000, 24)
    assert size.simulation_h5 >= 24 * 204000 * 3 * 8
    assert size.vtu_frames >= 24 * 204000 * 3 * 8
    assert estimate_output_bytes(204000, 200000, 48).total > size.total


def test_a_run_larger_than_the_free_space_is_refused_in_one_line_naming_the_outputs(tmp_path):
    with pytest.raises(ConfigError) as caught:
        check_free_space(tmp_path / "run", 204000, 200000, 24, where="yarn.yaml", free_bytes=10**8)
    message = str(caught.value)
    assert message.startswith("yarn.yaml: solver.output_frames = 24") and "\n" not in message
    assert "simulation.h5 /frames/positions" in message and "frames/*.vtu" in message
    assert check_free_space(tmp_path / "run", 204000, 200000, 24, free_bytes=10**10).total < 10**10


def test_fiberpipe_run_stops_before_the_first_step_when_the_output_would_not_fit(tmp_path, monkeypatch):
    import collections

    from _scenes import SMALL_SCENE, cli, write_cfg

    usage = collections.namedtuple("usage", "total used free")
    monkeypatch.setattr("fiberpipe.io.output_size.shutil.disk_usage", lambda path: usage(10**6, 10**6 - 1000, 1000))
    path = write_cfg(tmp_path / "small.yaml", SMALL_SCENE)
    result = cli("run", path, "--out", tmp_path / "run", "--to", "simulate")
    assert result.exit_code != 0
    errors = [line for line in result.output.splitlines() if line.lower().startswith("error")]
    assert len(errors) == 1 and "solver.output_frames = 6" in errors[0] and "frames/*.vtu" in errors[0], result.output
    assert not (tmp_path / "run" / "simulation.h5").exists()
