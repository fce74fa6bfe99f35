import meshio
import numpy as np

from fiberpipe.io.abaqus import write_abaqus_inp
from fiberpipe.io.vtk import mesh_vtu, write_pvd
from fiberpipe.model.mesh import mesh_polylines
from fiberpipe.polylines import Polylines


def _mesh():
    lines = [np.c_[np.full(5, i * 0.6e-3), np.zeros(5), np.linspace(0, 3e-3, 5)] for i in range(3)]
    return mesh_polylines(Polylines.from_list(lines, [0.25e-3, 0.2e-3, 0.3e-3]), 0.3e-3)


def test_abaqus_inp_reads_back_with_meshio(tmp_path):
    mesh = _mesh()
    p = write_abaqus_inp(tmp_path / "model.inp", mesh, youngs_modulus_pa=15e9, poisson_ratio=0.3, density_kg_m3=1380)
    back = meshio.read(p)
    np.testing.assert_allclose(back.points, mesh.nodes_m, rtol=1e-8)
    cells = np.concatenate([c.data for c in back.cells if c.type == "line"])
    np.testing.assert_array_equal(cells, mesh.elements())
    text = p.read_text()
    assert text.count("TYPE=B31,") == 3 and "SECTION=CIRC" in text and "*DENSITY" in text
    assert "2.000000000e-04" in text  # fiber 1 keeps its own radius


def test_vtu_has_radius_and_fiber_id_and_pvd_lists_frames(tmp_path):
    mesh = _mesh()
    mesh_vtu(tmp_path / "frame_0.vtu", mesh)
    back = meshio.read(tmp_path / "frame_0.vtu")
    assert set(back.point_data) >= {"radius"} and "fiber_id" in back.cell_data
    np.testing.assert_allclose(back.point_data["radius"][:11], 0.25e-3)
    write_pvd(tmp_path / "sim.pvd", [(0.0, "frame_0.vtu"), (1e-3, "frame_1.vtu")])
    text = (tmp_path / "sim.pvd").read_text()
    assert 'timestep="0.001"' in text and 'file="frame_1.vtu"' in text
