"""Every artifact of a tiny end-to-end run: each dataset has a ``units`` attribute (
docs/outputs.md) and each file the mode a plain open() gives (0666 & ~umask)."""

import os
import stat

import h5py
import pytest

from fiberpipe.config import load_config
from fiberpipe.pipeline import run_pipeline

TINY = """
name: tiny
input:
  phantom: {n_fibers: 2, shape: [40, 24, 24], radius_vox: 3, voxel_size: "0.0833 mm", seed: 1}
skeletonize: {enabled: true}   # skeleton.h5 too (the slices tracer alone does not write it)
mesh: {element_length: "0.5 mm"}
scene:
  effects: [gravity, contact, damping]
  damping: {alpha: "2000 1/s"}
solver: {end_time: "1e-4 s", output_frames: 2}
"""


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("tiny")
    (d / "tiny.yaml").write_text(TINY)
    old = os.umask(0o022)
    try:
        run_pipeline(load_config(d / "tiny.yaml"), d / "run")
    finally:
        os.umask(old)
    return d / "run"


def _units(path):
    out = {}

    def visit(name, obj):  # must return None, or visititems stops
        if isinstance(obj, h5py.Dataset):
            out[name] = obj.attrs.get("units")

    with h5py.File(path, "r") as f:
        f.visititems(visit)
        kind = f.attrs["kind"]
    return kind, out


def test_every_dataset_of_every_artifact_has_units(tiny_run):
    kinds = set()
    for path in sorted(tiny_run.rglob("*.h5")):
        kind, units = _units(path)
        kinds.add(kind)
        missing = [n for n, u in units.items() if u is None or u == "" or u == b""]
        assert not missing, f"{path.name} ({kind}): datasets without units: {missing}"
    assert {"mask", "skeleton", "fibers", "mesh", "simulation"} <= kinds


def test_units_of_the_non_si_datasets(tiny_run):
    assert _units(tiny_run / "skeleton.h5")[1] == {"skeleton": "1", "radius_vox": "voxel"}
    assert _units(tiny_run / "mask.h5")[1] == {"mask": "1"}
    mesh = _units(tiny_run / "mesh.h5")[1]
    assert mesh["mesh/elements"] == mesh["mesh/node_offsets"] == mesh["mesh/element_fiber"] == "index"
    assert _units(tiny_run / "fibers.h5")[1]["fibers/offsets"] == "index"
    assert _units(tiny_run / "phantom" / "truth.h5")[1]["fibers/offsets"] == "index"
    assert _units(tiny_run / "simulation.h5")[1]["history/contacts"] == "1"


def test_energy_residual_is_dimensionless(tiny_run):
    units = _units(tiny_run / "simulation.h5")[1]
    assert units["history/energy/residual"] == "1"  # a relative balance residual
    energies = {n: u for n, u in units.items() if n.startswith("history/energy/") and not n.endswith("/residual")}
    assert energies and set(energies.values()) == {"J"}
    assert units["mesh/node_offsets"] == "index"


def test_every_file_of_the_run_is_0644_under_umask_022(tiny_run):
    modes = {str(p.relative_to(tiny_run)): stat.S_IMODE(p.stat().st_mode) for p in tiny_run.rglob("*") if p.is_file()}
    assert {"phantom/volume.tif", "phantom/truth.h5", "simulation.pvd", "mesh.vtu", "post/summary.json"} <= set(modes)
    assert {k: oct(m) for k, m in modes.items() if m != 0o644} == {}
