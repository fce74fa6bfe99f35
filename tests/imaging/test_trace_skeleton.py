import numpy as np

from fiberpipe.imaging.accuracy import trace_accuracy
from fiberpipe.imaging.phantom import make_phantom, render_polylines
from fiberpipe.imaging.segment import segment
from fiberpipe.imaging.skeleton import skeletonize
from fiberpipe.imaging.trace import trace
from fiberpipe.polylines import Polylines

VS = 1e-5


def _line(p0, d, length, n=200):
    t = np.linspace(-length / 2, length / 2, n)[:, None]
    return (np.asarray(p0, float) + t * np.asarray(d, float)) * VS


def test_two_fibers_crossing_at_60_degrees():
    # two straight fibers in the x-z plane crossing at 60 degrees, offset 6 voxels in y
    # (they touch at the crossing), r = 3 voxels
    a = np.deg2rad(30)
    f1 = _line((40, 20, 40), (np.sin(a), 0, np.cos(a)), 76)
    f2 = _line((40, 26, 40), (-np.sin(a), 0, np.cos(a)), 76)
    truth = Polylines.from_list([f1, f2], 3 * VS)
    vol = render_polylines(truth, (80, 46, 80), VS, blur_sigma_vox=1.0, contrast_to_noise=6.0, seed=0)
    mask, _ = segment(vol)
    skel, rad = skeletonize(mask)
    traced = trace(mask, voxel_size_m=VS, method="skeleton", skeleton=skel, radius_vox=rad)
    acc = trace_accuracy(traced, truth, voxel_size_m=VS)
    assert traced.n_fibers == 2, traced.meta
    assert acc["n_matched"] == 2 and acc["mean_error_vox"] < 1.0, acc
    assert acc["coverage"] > 0.8


def test_skeleton_tracer_on_separated_phantom():
    vol, truth = make_phantom(n_fibers=10, shape=(100, 80, 80), touching_fraction=0, min_gap_vox=3,
                              contrast_to_noise=6, seed=4)
    vs = truth.meta["voxel_size_m"]
    traced = trace(segment(vol)[0], voxel_size_m=vs, method="skeleton")
    acc = trace_accuracy(traced, truth, voxel_size_m=vs)
    assert acc["recall"] >= 0.9 and acc["mean_error_vox"] < 1.0, acc
