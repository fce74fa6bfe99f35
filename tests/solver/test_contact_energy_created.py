"""The energy a contact law creates at high loads (docs/contact.md §11), on the quickstart bundle.

Slow (two runs of ≈ 60 s): the quickstart's 14 traced fibres compacted by 2.2 mm without friction,
so that ALLPW − ALLFD is the normal contact's own balance. With hertz_oriented's default ℓ_blend
(1 mm) the point law on long crossings makes the bundle rattle at ≈ 10–100 N per contact and
creates ≈ 40× the plate work (measured 0.195 J against 0.0047 J); with ℓ_blend = 0.15 mm (half an
element) the contact stays conservative (−0.0011 J). The post stage's bound must see both.
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


def _created_over_work(mesh_path, blend_length):
    contact = {"law": "hertz_oriented"} if blend_length is None else {"law": "hertz_oriented", "blend_length": blend_length}
    cfg = load_config(REPO / "configs" / "quickstart.yaml",
                      {"scene.effects": ["gravity", "damping", "contact", "plates", "walls"], "scene.contact": contact,
                       "solver.output_frames": 2})
    model, effects, settings = build_simulation(read_mesh(mesh_path), cfg)
    res = simulate(model, effects, settings)
    energy = {k.split("/", 1)[1]: v for k, v in res.history.items() if k.startswith("energy/")}
    return float(contact_energy_created(energy).max()) / float(abs(energy["external"]).max())


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="known defect: with the default blend_length (1 mm) the point law on "
                   "long crossings creates ≈ 40× the plate work (measured 0.195 J against 0.0047 J; docs/contact.md)")
def test_default_hertz_oriented_creates_no_energy_on_long_crossings(quickstart_mesh):
    """A conservative contact creates no energy: the bound stays below 1 % of the external work."""
    assert _created_over_work(quickstart_mesh, None) < 1e-2


@pytest.mark.slow
def test_blend_length_of_half_an_element_creates_no_energy(quickstart_mesh):
    assert _created_over_work(quickstart_mesh, "0.15 mm") < 1e-2  # measured 0 (ALLPW − ALLFD < 0)
