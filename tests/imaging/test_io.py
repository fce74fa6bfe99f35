"""load_volume / save_volume_tif: round trips and every bad input (InputError with the path)."""

import numpy as np
import pytest
import tifffile

from fiberpipe.errors import InputError
from fiberpipe.imaging.io import load_volume, save_volume_tif

VS = (20e-6, 15e-6, 15e-6)


@pytest.fixture
def vol():
    rng = np.random.default_rng(0)
    return rng.integers(0, 60000, size=(6, 7, 8)).astype(np.uint16)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
def test_tif_round_trip_with_metadata(tmp_path, vol, dtype):
    v = vol.astype(dtype)
    save_volume_tif(tmp_path / "v.tif", v, VS)
    w, vs, src = load_volume(tmp_path / "v.tif")
    assert w.dtype == dtype and np.array_equal(w, v)
    assert np.allclose(vs, VS, rtol=1e-6) and src.startswith("tiff:")


def test_config_voxel_size_overrides_metadata(tmp_path, vol):
    save_volume_tif(tmp_path / "v.tif", vol, VS)
    _, vs, _ = load_volume(tmp_path / "v.tif", voxel_size_m=1e-6)
    assert np.allclose(vs, 1e-6)


def test_folder_of_slices_natural_order(tmp_path, vol):
    for k in range(vol.shape[0]):  # names whose plain sort order is wrong (s10 < s2)
        tifffile.imwrite(tmp_path / f"s{k * 5}.tif", vol[k])
    w, vs, src = load_volume(tmp_path, voxel_size_m=VS)
    assert np.array_equal(w, vol) and src.startswith("tiff-folder:")


def test_npy_h5_raw(tmp_path, vol):
    import h5py

    np.save(tmp_path / "v.npy", vol)
    w, vs, _ = load_volume(tmp_path / "v.npy", voxel_size_m=1e-5)
    assert np.array_equal(w, vol) and np.allclose(vs, 1e-5)
    with h5py.File(tmp_path / "v.h5", "w") as f:
        d = f.create_dataset("ct/volume", data=vol)
        d.attrs["element_size_um"] = [20.0, 15.0, 15.0]
        f.create_dataset("other", data=np.zeros(3))
    w, vs, src = load_volume(tmp_path / "v.h5")
    assert np.array_equal(w, vol) and np.allclose(vs, VS) and src.endswith("ct/volume")
    with h5py.File(tmp_path / "w.h5", "w") as f:
        f.create_dataset("a", data=vol).attrs["voxel_size_m"] = 1e-5
        f.create_dataset("b", data=vol)
    with pytest.raises(InputError, match="several 3D datasets"):
        load_volume(tmp_path / "w.h5")
    w, vs, _ = load_volume(tmp_path / "w.h5", dataset="a")
    assert np.allclose(vs, 1e-5)
    vol.tofile(tmp_path / "v.raw")
    w, _, _ = load_volume(tmp_path / "v.raw", shape=vol.shape, dtype="uint16", voxel_size_m=1e-5)
    assert np.array_equal(w, vol)
    with pytest.raises(InputError, match="bytes"):
        load_volume(tmp_path / "v.raw", shape=(6, 7, 9), dtype="uint16", voxel_size_m=1e-5)
    with pytest.raises(InputError, match="shape"):
        load_volume(tmp_path / "v.raw", voxel_size_m=1e-5)


def _err(path, match, **kw):
    with pytest.raises(InputError, match=match) as e:
        load_volume(path, **kw)
    assert str(path) in str(e.value)  # the message names the file
    assert "\n" not in str(e.value)


def test_bad_inputs(tmp_path, vol):
    _err(tmp_path / "missing.tif", "not found")
    (tmp_path / "text.tif").write_text("this is not an image")
    _err(tmp_path / "text.tif", "not a TIFF or truncated")
    save_volume_tif(tmp_path / "full.tif", vol, VS)
    data = (tmp_path / "full.tif").read_bytes()
    (tmp_path / "cut.tif").write_bytes(data[: len(data) // 2])
    _err(tmp_path / "cut.tif", "not a TIFF or truncated|truncated")
    tifffile.imwrite(tmp_path / "flat.tif", vol[0])
    _err(tmp_path / "flat.tif", "2D image", voxel_size_m=1e-5)
    np.save(tmp_path / "empty.npy", np.zeros((0, 4, 4), np.uint8))
    _err(tmp_path / "empty.npy", "empty", voxel_size_m=1e-5)
    np.save(tmp_path / "nan.npy", np.full((3, 4, 4), np.nan, np.float32))
    _err(tmp_path / "nan.npy", "all NaN", voxel_size_m=1e-5)
    some = vol.astype(np.float32)
    some[2, 3, 4] = np.nan
    np.save(tmp_path / "somenan.npy", some)
    _err(tmp_path / "somenan.npy", "1 NaN", voxel_size_m=1e-5)
    np.save(tmp_path / "const.npy", np.full((3, 4, 4), 7, np.uint8))
    _err(tmp_path / "const.npy", "constant", voxel_size_m=1e-5)
    (tmp_path / "bad.npy").write_bytes(b"garbage")
    _err(tmp_path / "bad.npy", "npy", voxel_size_m=1e-5)
    (tmp_path / "bad.h5").write_bytes(b"garbage")
    _err(tmp_path / "bad.h5", "HDF5")
    (tmp_path / "emptydir").mkdir()
    _err(tmp_path / "emptydir", "no .tif")


def test_no_voxel_size(tmp_path, vol):
    np.save(tmp_path / "v.npy", vol)
    _err(tmp_path / "v.npy", "no voxel size")
    # a 72 dpi (inch) resolution is an image-writer default, not a voxel size
    tifffile.imwrite(tmp_path / "dpi.tif", vol, resolution=(72, 72), resolutionunit="INCH")
    _err(tmp_path / "dpi.tif", "no voxel size")
    # an ImageJ file without a unit
    tifffile.imwrite(tmp_path / "ij.tif", vol, imagej=True)
    _err(tmp_path / "ij.tif", "no voxel size")
    # OME metadata is read
    tifffile.imwrite(tmp_path / "v.ome.tif", vol,
                     metadata={"axes": "ZYX", "PhysicalSizeX": 15.0, "PhysicalSizeY": 15.0,
                               "PhysicalSizeZ": 20.0})
    _, vs, _ = load_volume(tmp_path / "v.ome.tif")
    assert np.allclose(vs, VS)


@pytest.mark.parametrize("shape, axis", [((1, 64, 64), "z"), ((2, 64, 64), "z"), ((16, 2, 16), "y"), ((16, 16, 1), "x")])
def test_too_thin_volume_is_refused_at_load(tmp_path, shape, axis):
    """One slice passed segment and skeletonize and then failed in trace (np.gradient needs >= 2
    samples per axis); it is refused when loaded, naming the axis."""
    v = np.random.default_rng(1).integers(0, 255, size=shape).astype(np.uint8)
    np.save(tmp_path / "thin.npy", v)
    _err(tmp_path / "thin.npy", rf"too thin: {min(shape)} voxels? along {axis} .*at least 3 voxels along each axis",
         voxel_size_m=1e-5)
    ok = np.random.default_rng(1).integers(0, 255, size=(3, 3, 3)).astype(np.uint8)
    np.save(tmp_path / "ok.npy", ok)
    assert load_volume(tmp_path / "ok.npy", voxel_size_m=1e-5)[0].shape == (3, 3, 3)


def test_constant_volume_message_shows_a_plain_number(tmp_path):
    np.save(tmp_path / "zero.npy", np.zeros((3, 4, 4), np.uint8))
    with pytest.raises(InputError) as e:
        load_volume(tmp_path / "zero.npy", voxel_size_m=1e-5)
    assert "all voxels 0)" in str(e.value) and "np." not in str(e.value)
    np.save(tmp_path / "half.npy", np.full((3, 4, 4), 0.5, np.float32))
    _err(tmp_path / "half.npy", r"all voxels 0\.5\)", voxel_size_m=1e-5)


def test_garbage_npy_is_not_a_readable_npy_volume(tmp_path):
    (tmp_path / "bad.npy").write_bytes(b"garbage")
    _err(tmp_path / "bad.npy", "is not a readable .npy volume", voxel_size_m=1e-5)
    np.save(tmp_path / "obj.npy", np.array([{"a": 1}], dtype=object), allow_pickle=True)
    with pytest.raises(InputError) as e:
        load_volume(tmp_path / "obj.npy", voxel_size_m=1e-5)
    assert "is not a readable .npy volume" in str(e.value) and "allow_pickle" not in str(e.value)


def test_fiberpipe_artifact_given_as_a_volume_is_named(tmp_path):
    from fiberpipe.artifacts import write_fibers, write_mesh, write_volume
    from fiberpipe.model.mesh import mesh_polylines
    from fiberpipe.polylines import Polylines

    fibers = Polylines.from_list([np.array([[0, 0, 0], [1e-3, 0, 0]]), np.array([[0, 1e-3, 0], [1e-3, 1e-3, 0]])], 1e-4)
    write_mesh(tmp_path / "mesh.h5", mesh_polylines(fibers, 0.3e-3))
    _err(tmp_path / "mesh.h5", "is a fiberpipe mesh artifact, not a volume")
    write_fibers(tmp_path / "fibers.h5", fibers)
    _err(tmp_path / "fibers.h5", "is a fiberpipe fibers artifact, not a volume.*input.fibers")
    sk = np.zeros((4, 5, 6), bool)
    sk[1, 2, :] = True
    write_volume(tmp_path / "skeleton.h5", "skeleton", sk, 1e-5, extra={"radius_vox": sk.astype(np.float32)})
    _err(tmp_path / "skeleton.h5", "is a fiberpipe skeleton artifact, not a volume")
    # a mask artifact is an image: read as one
    write_volume(tmp_path / "mask.h5", "mask", sk, 1e-5)
    vol, vs, _ = load_volume(tmp_path / "mask.h5")
    assert vol.shape == (4, 5, 6) and np.allclose(vs, 1e-5)
    # a plain HDF5 file without a 3D dataset keeps its own message
    import h5py

    with h5py.File(tmp_path / "plain.h5", "w") as f:
        f["a"] = np.zeros((3, 3))
    _err(tmp_path / "plain.h5", "no 3D dataset; give the dataset name")
