import numpy as np

from fiberpipe.imaging.accuracy import format_accuracy, trace_accuracy
from fiberpipe.polylines import Polylines

VS = 1e-5


def _lines(offsets_vox):
    z = np.arange(50.0)
    fibers = [np.column_stack([np.full_like(z, x), np.full_like(z, y), z]) * VS for x, y in offsets_vox]
    return Polylines.from_list(fibers, 5 * VS)


def test_identity_and_shift():
    t = _lines([(10, 10), (30, 10), (10, 30)])
    a = trace_accuracy(t, t, voxel_size_m=VS)
    assert a["recall"] == 1 and a["precision"] == 1 and a["mean_error_vox"] < 1e-6 and a["coverage"] > 0.99
    s = _lines([(10.5, 10), (30.5, 10), (10.5, 30)])
    a = trace_accuracy(s, t, voxel_size_m=VS)
    assert abs(a["mean_error_vox"] - 0.5) < 0.02 and a["n_matched"] == 3


def test_missing_extra_merged_split():
    t = _lines([(10, 10), (20, 10), (40, 40)])
    # one line midway between the touching pair (merged), one spurious, none for (40, 40)
    merged = _lines([(15, 10), (70, 70)])
    a = trace_accuracy(merged, t, voxel_size_m=VS)
    assert a["n_merged"] == 1 and a["recall"] < 0.5 and a["precision"] <= 0.5
    # fiber (40, 40) traced in two pieces
    z1, z2 = np.arange(0, 25.0), np.arange(26, 50.0)
    pieces = [np.column_stack([np.full_like(z, 40), np.full_like(z, 40), z]) * VS for z in (z1, z2)]
    a = trace_accuracy(Polylines.from_list(pieces, 5 * VS), t, voxel_size_m=VS)
    assert a["n_split"] == 1 and a["n_matched"] == 1
    table = format_accuracy([a], ["pieces"])
    assert table.startswith("| case |") and "pieces" in table
