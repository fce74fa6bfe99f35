"""Simulated (here: bent) fibers rendered as CT, traced again: error below one voxel."""

import numpy as np

from fiberpipe.model.specimen import cassette_specimen
from fiberpipe.polylines import Polylines
from fiberpipe.post.closed_loop import closed_loop_error


def test_rendered_frame_traces_back_within_a_voxel():
    fibers, info = cassette_specimen(n_fibers=10, columns=5, length_m=6e-3, points_per_fiber=41, seed=3)
    # a deformed "frame": bend every fiber in y by up to 0.2 mm, as compaction does
    pts = fibers.points_m.copy()
    z = pts[:, 2]
    pts[:, 1] += 0.2e-3 * np.sin(np.pi * z / 6e-3) ** 2
    frame = Polylines(pts, fibers.offsets, fibers.radius_m)
    res = closed_loop_error(frame, 62.5e-6, seed=1)
    assert res["n_traced"] == 10
    assert res["mean_error_vox"] < 1.0
