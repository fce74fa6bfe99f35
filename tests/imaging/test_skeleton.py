import numpy as np

from fiberpipe.imaging.skeleton import skeletonize


def _cylinder(shape, r, centre):
    z, y, x = np.indices(shape)
    return (y - centre[0]) ** 2 + (x - centre[1]) ** 2 <= r * r


def test_cylinder_skeleton_on_axis_and_radius():
    mask = _cylinder((60, 31, 31), 6.0, (15, 15))
    skel, rad = skeletonize(mask)
    assert skel.dtype == bool and rad.dtype == np.float32 and rad.shape == mask.shape
    zz, yy, xx = np.nonzero(skel)
    mid = (zz > 8) & (zz < 52)
    assert np.all(np.abs(yy[mid] - 15) <= 1) and np.all(np.abs(xx[mid] - 15) <= 1)
    assert np.all(rad[~skel] == 0)
    assert abs(np.median(rad[skel][mid]) - 6.0) <= 1.0


def test_slab_edt_equals_full_edt():
    # long volume: the EDT is computed in slabs with a halo; it must equal the full EDT
    from scipy import ndimage as ndi

    from fiberpipe.imaging.skeleton import _edt_on

    rng = np.random.default_rng(0)
    mask = ndi.binary_dilation(rng.random((300, 20, 20)) > 0.97, iterations=2)
    where = rng.random(mask.shape) > 0.5
    out = _edt_on(mask, where, chunk=50, halo=10)
    full = ndi.distance_transform_edt(mask)
    assert np.allclose(out[where], full[where]) and np.all(out[~where] == 0)


def test_touching_parallel_fibers_merge_into_one_line():
    # the documented limit: two tangent cylinders thin to a single line between them
    mask = _cylinder((60, 31, 51), 8.0, (15, 17)) | _cylinder((60, 31, 51), 8.0, (15, 33))
    skel, _ = skeletonize(mask)
    from scipy import ndimage as ndi

    _, n = ndi.label(skel, structure=np.ones((3, 3, 3)))
    assert n == 1
    xx = np.nonzero(skel)[2]
    assert np.median(xx) == 25  # on the contact plane, not on either axis
