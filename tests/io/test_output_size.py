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
