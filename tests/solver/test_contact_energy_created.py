"""The energy the contact creates at high loads, on the quickstart bundle (docs/contact.md, "Created
energy").

Slow (one run of ≈ 60 s): the quickstart's 14 traced fibers compacted by 2.2 mm without friction.
The default contact (ℓ_blend = 0.05 mm) stays conservative: the post stage's bound on the created
energy stays small.
"""

from pathlib import Path

import pytest

from fiberpipe.artifacts import read_mesh
from fiberpipe.config import load_config
from fiberpipe.post.energies import contact_energy_created
from fiberpipe.solver import simulate
from fiberpipe.solver.build import build_simulation

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def quickstart_mesh(tmp_path_factory):
    from fiberpipe.cli import main
    from click.testing import CliRunner

    out = tmp_path_factory.mktemp("qs")
    r = CliRunner().invoke(main, ["run", str(REPO / "configs" / "quickstart.yaml"), "--out", str(out), "--to", "mesh"])
    assert r.exit_code == 0, r.output
    return out / "mesh.h5"


def _created_over_work(mesh_path, blend_length, **contact_keys):
    contact = {"law": "hertz_oriented", **contact_keys}
    if blend_length is not None:
        contact["blend_length"] = blend_length
    cfg = load_config(REPO / "configs" / "quickstart.yaml",
                      {"scene.effects": ["gravity", "damping", "contact", "plates", "walls"], "scene.contact": contact,
                       "solver.output_frames": 2})
    model, effects, settings = build_simulation(read_mesh(mesh_path), cfg)
    res = simulate(model, effects, settings)
    energy = {k.split("/", 1)[1]: v for k, v in res.history.items() if k.startswith("energy/")}
    return float(contact_energy_created(energy).max()) / float(abs(energy["external"]).max())


@pytest.mark.slow
def test_default_contact_creates_no_energy(quickstart_mesh):
    """The default contact (ℓ_blend = 0.05 mm): the bound stays below 0.5 % of the external work."""
    assert _created_over_work(quickstart_mesh, None) < 5e-3
