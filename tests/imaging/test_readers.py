"""Format readers: each on a small file written by the library that owns the format; voxel size from
the header; one-line errors for a header that disagrees with the data and an unreadable chunk."""

from pathlib import Path

import numpy as np
import pytest

from fiberpipe.errors import InputError
from fiberpipe.imaging.io import load_volume
from fiberpipe.imaging.readers import READERS, reader_for

VS = (20e-6, 15e-6, 10e-6)  # dz, dy, dx: all different, so an axis swap shows


@pytest.fixture
def vol():
    rng = np.random.default_rng(1)
    v = rng.integers(0, 3000, size=(6, 7, 8)).astype(np.uint16)
    v[2:4, 3:5, 3:6] = 4000  # not constant, asymmetric
    return v


def _one_line_error(path, match, **kw):
    with pytest.raises(InputError, match=match) as e:
        load_volume(path, **kw)
    msg = str(e.value)
    assert "\n" not in msg and str(path) in msg
    return msg


def test_registry_picks_readers_by_suffix_and_folder(tmp_path):
    (tmp_path / "a.zarr").mkdir()
    (tmp_path / "slices").mkdir()
    (tmp_path / "store").mkdir()
    (tmp_path / "store" / "zarr.json").write_text("{}")
    cases = {"v.tif": "tiff", "v.TIFF": "tiff", "v.npy": "npy", "v.h5": "hdf5", "v.nxs": "hdf5", "v.mhd": "metaimage",
             "v.mha": "metaimage", "v.nii": "nifti", "v.nii.gz": "nifti", "v.raw": "raw", "v.dat": "raw",
             "a.zarr": "zarr", "store": "zarr", "slices": "tiff-folder"}
    for name, fmt in cases.items():
        assert reader_for(tmp_path / name).name == fmt, name
    assert {"tiff", "tiff-folder", "npy", "hdf5", "metaimage", "nifti", "zarr", "raw"} <= set(READERS)


# -- MetaImage (written by SimpleITK, the ITK library) ------------------------------------------


@pytest.mark.parametrize("name, compress", [("v.mhd", False), ("v.mha", False), ("v.mhd", True)])
def test_metaimage_written_by_simpleitk(tmp_path, vol, name, compress):
    sitk = pytest.importorskip("SimpleITK")
    img = sitk.GetImageFromArray(vol)  # numpy z y x -> ITK x y z
    img.SetSpacing([v * 1e3 for v in VS[::-1]])  # ITK spacing x y z, millimetres
    sitk.WriteImage(img, str(tmp_path / name), useCompression=compress)
    w, vs, src = load_volume(tmp_path / name)
    assert np.array_equal(w, vol) and w.dtype == vol.dtype
    assert np.allclose(vs, VS, rtol=1e-9) and src.startswith("metaimage:")


def test_metaimage_header_that_disagrees_with_the_data(tmp_path, vol):
    sitk = pytest.importorskip("SimpleITK")
    img = sitk.GetImageFromArray(vol)
    sitk.WriteImage(img, str(tmp_path / "v.mhd"))
    data = tmp_path / "v.raw"
    data.write_bytes(data.read_bytes()[:-10])  # truncated
    msg = _one_line_error(tmp_path / "v.mhd", "MetaImage header DimSize 8 7 6 of MET_USHORT needs 672 bytes",
                          voxel_size_m=1e-5)
    assert "662" in msg
    hdr = (tmp_path / "v.mhd").read_text()
    (tmp_path / "w.mhd").write_text(hdr.replace("ElementDataFile = v.raw", "ElementDataFile = missing.raw"))
    _one_line_error(tmp_path / "w.mhd", "data file missing.raw .*does not exist")


# -- NIfTI (nibabel) ----------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["v.nii", "v.nii.gz"])
def test_nifti_written_by_nibabel(tmp_path, vol, name):
    nib = pytest.importorskip("nibabel")
    dz, dy, dx = (v * 1e3 for v in VS)
    img = nib.Nifti1Image(vol.transpose(2, 1, 0), np.diag([dx, dy, dz, 1.0]))  # NIfTI i j k = x y z
    img.header.set_xyzt_units("mm")
    nib.save(img, str(tmp_path / name))
    w, vs, src = load_volume(tmp_path / name)
    assert np.array_equal(w, vol) and np.allclose(vs, VS, rtol=1e-6) and src.startswith("nifti:")
    img.header.set_xyzt_units("micron")
    nib.save(img, str(tmp_path / ("um_" + name)))
    _, vs, _ = load_volume(tmp_path / ("um_" + name))
    assert np.allclose(vs, np.array(VS) * 1e-3, rtol=1e-6)


def test_nifti_without_a_unit_has_no_voxel_size_and_a_truncated_one_fails(tmp_path, vol):
    nib = pytest.importorskip("nibabel")
    nib.save(nib.Nifti1Image(vol.transpose(2, 1, 0), np.eye(4)), str(tmp_path / "v.nii"))
    _one_line_error(tmp_path / "v.nii", "no voxel size")
    w, vs, _ = load_volume(tmp_path / "v.nii", voxel_size_m=1e-5)
    assert np.array_equal(w, vol)
    p = tmp_path / "v.nii"
    p.write_bytes(p.read_bytes()[:-100])
    _one_line_error(p, r"NIfTI header dim \[8, 7, 6\] of uint16 needs 672 bytes", voxel_size_m=1e-5)


# -- Zarr (zarr) --------------------------------------------------------------------------------


def test_zarr_array_and_ome_zarr_group(tmp_path, vol):
    zarr = pytest.importorskip("zarr")
    a = zarr.open_array(str(tmp_path / "a.zarr"), mode="w", shape=vol.shape, chunks=(2, 4, 4), dtype=vol.dtype)
    a[...] = vol
    a.attrs["voxel_size_m"] = list(VS)
    w, vs, src = load_volume(tmp_path / "a.zarr")
    assert np.array_equal(w, vol) and np.allclose(vs, VS) and src.startswith("zarr:")
    g = zarr.open_group(str(tmp_path / "ome.zarr"), mode="w")
    g.create_array("0", shape=vol.shape, chunks=(3, 7, 8), dtype=vol.dtype)[...] = vol
    g.create_array("1", shape=(3, 4, 4), chunks=(3, 4, 4), dtype=vol.dtype)[...] = vol[::2, ::2, ::2]
    g.attrs["multiscales"] = [{
        "version": "0.4",
        "axes": [{"name": n, "type": "space", "unit": "micrometer"} for n in "zyx"],
        "datasets": [{"path": "0", "coordinateTransformations": [{"type": "scale", "scale": [v * 1e6 for v in VS]}]},
                     {"path": "1", "coordinateTransformations": [{"type": "scale", "scale": [v * 2e6 for v in VS]}]}],
    }]
    w, vs, src = load_volume(tmp_path / "ome.zarr")
    assert np.array_equal(w, vol) and np.allclose(vs, VS) and src.endswith(":0")


def test_zarr_unreadable_chunk_is_named(tmp_path, vol):
    zarr = pytest.importorskip("zarr")
    a = zarr.open_array(str(tmp_path / "a.zarr"), mode="w", shape=vol.shape, chunks=(2, 7, 8), dtype=vol.dtype)
    a[...] = vol
    chunk_files = sorted(p for p in (tmp_path / "a.zarr").rglob("*") if p.is_file() and not p.name.startswith((".", "zarr")))
    assert len(chunk_files) == 3
    chunk_files[1].write_bytes(b"not a compressed chunk at all")
    _one_line_error(tmp_path / "a.zarr", r"unreadable chunk \(1, 0, 0\)", voxel_size_m=1e-5)


# -- HDF5 / NeXus -------------------------------------------------------------------------------


def test_nexus_default_signal_and_axes_give_the_volume_and_voxel_size(tmp_path, vol):
    nx = pytest.importorskip("nexusformat.nexus")
    dz, dy, dx = (v * 1e6 for v in VS)
    z = nx.NXfield(np.arange(vol.shape[0]) * dz, name="z", units="um")
    y = nx.NXfield(np.arange(vol.shape[1]) * dy, name="y", units="um")
    x = nx.NXfield(np.arange(vol.shape[2]) * dx, name="x", units="um")
    data = nx.NXdata(nx.NXfield(vol, name="data"), [z, y, x])
    entry = nx.NXentry(data=data, dark=nx.NXfield(np.zeros((2, 7, 8), np.uint16)))  # a second 3D dataset
    root = nx.NXroot(entry=entry)
    root.save(str(tmp_path / "scan.nxs"), mode="w")
    w, vs, src = load_volume(tmp_path / "scan.nxs")
    assert np.array_equal(w, vol) and np.allclose(vs, VS, rtol=1e-9) and src.endswith("entry/data/data")


def test_hdf5_unreadable_chunk_is_named(tmp_path, vol):
    import h5py

    p = tmp_path / "v.h5"
    with h5py.File(p, "w") as f:
        d = f.create_dataset("ct", data=vol, chunks=(2, 7, 8), compression="gzip")
        info = d.id.get_chunk_info(1)
    raw = bytearray(p.read_bytes())
    raw[info.byte_offset : info.byte_offset + info.size] = b"\x00" * info.size
    p.write_bytes(bytes(raw))
    _one_line_error(p, r"unreadable chunk \(1, 0, 0\) of dataset 'ct'", voxel_size_m=1e-5)
