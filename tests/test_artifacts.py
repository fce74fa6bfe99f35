import h5py
import numpy as np
import pytest

from fiberpipe.artifacts import read_artifact, read_fibers, read_mesh, write_artifact, write_fibers, write_mesh
from fiberpipe.errors import ArtifactError
from fiberpipe.model.mesh import mesh_polylines
from fiberpipe.polylines import Polylines


def _fibers():
    rng = np.random.default_rng(0)
    return Polylines.from_list([np.cumsum(rng.random((6, 3)), axis=0) * 1e-3 for _ in range(3)], 0.25e-3)


def test_fibers_layout_and_root_attributes(tmp_path):
    p = write_fibers(tmp_path / "fibers.h5", _fibers(), config_sha256="abc", inputs={"mask": "123"})
    with h5py.File(p) as f:
        assert f["fibers/points"].shape == (18, 3) and f["fibers/points"].dtype == np.float64
        assert f["fibers/offsets"].dtype == np.int64 and list(f["fibers/offsets"][()]) == [0, 6, 12, 18]
        assert f["fibers/radius"].attrs["units"] == "m"
        for key in ("kind", "schema_version", "fiberpipe_version", "created_utc", "config_sha256", "inputs"):
            assert key in f.attrs
    back = read_fibers(p)
    np.testing.assert_array_equal(back.points_m, _fibers().points_m)


def test_reader_refuses_wrong_kind_version_and_garbage(tmp_path):
    p = write_fibers(tmp_path / "fibers.h5", _fibers())
    with pytest.raises(ArtifactError, match="is a fibers artifact, but a mesh"):
        read_mesh(p)
    with h5py.File(p, "a") as f:
        f.attrs["schema_version"] = 99
    with pytest.raises(ArtifactError, match="schema version 99"):
        read_fibers(p)
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"not hdf5 at all")
    with pytest.raises(ArtifactError, match="not a readable HDF5"):
        read_fibers(junk)
    with pytest.raises(ArtifactError, match="not found"):
        read_fibers(tmp_path / "missing.h5")


def test_write_is_atomic(tmp_path, monkeypatch):
    target = write_fibers(tmp_path / "fibers.h5", _fibers())
    before = target.read_bytes()

    class Boom(Exception):
        pass

    def bad(*a, **k):
        raise Boom

    monkeypatch.setattr(np, "asarray", bad)
    with pytest.raises(Boom):
        write_artifact(target, "fibers", {"fibers/points": [1, 2]})
    monkeypatch.undo()
    assert target.read_bytes() == before  # the earlier artifact is untouched
    assert [x.name for x in tmp_path.iterdir()] == ["fibers.h5"]  # no temporary file left behind


def test_mesh_round_trip(tmp_path):
    mesh = mesh_polylines(_fibers(), 0.3e-3)
    p = write_mesh(tmp_path / "mesh.h5", mesh, material={"youngs_modulus_pa": 15e9})
    back = read_mesh(p)
    np.testing.assert_array_equal(back.nodes_m, mesh.nodes_m)
    art = read_artifact(p, "mesh")
    np.testing.assert_array_equal(art["mesh/elements"], mesh.elements())


def test_written_files_get_the_umask_mode_not_0600(tmp_path):
    """A plain open() under umask 022 gives 0644; the atomic writers must do the same (not mkstemp's 0600)."""
    import os
    import stat

    from fiberpipe.artifacts import write_text_atomic

    old = os.umask(0o022)
    try:
        fib = write_fibers(tmp_path / "fibers.h5", _fibers())
        txt = tmp_path / "summary.json"
        write_text_atomic(txt, "{}")
        os.umask(0o027)
        group = write_fibers(tmp_path / "group.h5", _fibers())
    finally:
        os.umask(old)
    assert stat.S_IMODE(fib.stat().st_mode) == 0o644
    assert stat.S_IMODE(txt.stat().st_mode) == 0o644
    assert stat.S_IMODE(group.stat().st_mode) == 0o640


def test_input_hash_covers_folders_and_metaimage_data_and_reads_each_input_once(tmp_path, monkeypatch):
    import hashlib
    import os

    import fiberpipe.artifacts as A

    # a single file: its plain sha256
    raw = tmp_path / "v.raw"
    raw.write_bytes(b"\x01\x02" * 64)
    assert A.input_sha256(raw) == hashlib.sha256(raw.read_bytes()).hexdigest()
    assert A.input_sha256(tmp_path / "absent.tif") is None
    # a folder (TIFF stack, Zarr store): a change in any file, or a renamed file, changes the hash
    stack = tmp_path / "stack"
    (stack / "sub").mkdir(parents=True)
    (stack / "s000.tif").write_bytes(b"a" * 10)
    (stack / "sub" / "0.0.0").write_bytes(b"b" * 10)
    h0 = A.input_sha256(stack)
    (stack / "sub" / "0.0.0").write_bytes(b"c" * 10)
    os.utime(stack / "sub" / "0.0.0", ns=(1, 1))
    h1 = A.input_sha256(stack)
    (stack / "s000.tif").rename(stack / "s001.tif")
    h2 = A.input_sha256(stack)
    assert len({h0, h1, h2}) == 3
    # a MetaImage header with a separate data file: the data file's bytes count
    mhd = tmp_path / "v.mhd"
    mhd.write_text("NDims = 3\nDimSize = 4 4 4\nElementType = MET_USHORT\nElementDataFile = v.raw\n")
    m0 = A.input_sha256(mhd)
    raw.write_bytes(b"\x03\x02" * 64)
    os.utime(raw, ns=(2, 2))
    assert A.input_sha256(mhd) != m0
    # asked again unchanged (the cache key, then the provenance record): the bytes are read once
    reads = []
    real = A._update_with_file
    monkeypatch.setattr(A, "_update_with_file", lambda h, p, *a: (reads.append(p), real(h, p, *a)))
    A._INPUT_HASHES.clear()
    first = A.input_sha256(stack)
    assert A.input_sha256(stack) == first and len(reads) == 2  # the folder's two files, once


def test_compressed_frames_are_chunked_per_frame_and_read_back_identically(tmp_path):
    from fiberpipe.artifacts import chunk_shape

    rng = np.random.default_rng(0)
    frames = rng.normal(size=(5, 40000, 3)) * 1e-3  # 5 frames of 40 000 nodes (0.96 MB a frame)
    history = np.cumsum(rng.normal(size=(3000, 2)), axis=0)
    small = np.arange(10.0)
    path = write_artifact(tmp_path / "s.h5", "simulation", {"frames/positions": frames, "history/plate_force": history,
                                                            "frames/time": small}, compression="gzip", chunks="rows")
    with h5py.File(path, "r") as f:
        assert f["frames/positions"].compression == "gzip" and f["frames/positions"].chunks == (1, 40000, 3)
        assert f["history/plate_force"].compression == "gzip"
        assert f["frames/time"].compression is None  # small arrays stay contiguous
    art = read_artifact(path, "simulation")
    assert np.array_equal(art["frames/positions"], frames) and np.array_equal(art["history/plate_force"], history)
    # a 4000-fiber frame (204 000 nodes, 4.9 MB) is cut into chunks of at most 1 MiB, one frame each
    chunks = chunk_shape((24, 204000, 3), 8)
    assert chunks[0] == 1 and chunks[2] == 3 and chunks[1] * 3 * 8 <= 1 << 20 and chunks[1] * 3 * 8 > 1 << 19
    assert chunk_shape((2000,), 8) == (2000,)
