"""The VTK files of a run opened by VTK's own XML readers (the ``vtk`` package, which ParaView is
built on): ``mesh.vtu`` and the simulation frames (``vtkXMLUnstructuredGridReader``) and the ``.pvd``
series (``vtkXMLDataParser``), with their point data: radius, fiber_id, contact force."""

import numpy as np
import pytest

from fiberpipe.io.vtk import mesh_vtu
from fiberpipe.model.mesh import mesh_polylines
from fiberpipe.polylines import Polylines
from fiberpipe.stages.simulate import write_frames_vtk

vtk = pytest.importorskip("vtk")
from vtk.util.numpy_support import vtk_to_numpy  # noqa: E402


def _mesh():
    lines = [np.c_[np.full(5, i * 0.6e-3), np.zeros(5), np.linspace(0, 3e-3, 5)] for i in range(3)]
    return mesh_polylines(Polylines.from_list(lines, [0.25e-3, 0.2e-3, 0.3e-3]), 0.3e-3)


def _read_vtu(path):
    reader = vtk.vtkXMLUnstructuredGridReader()
    reader.SetFileName(str(path))
    reader.Update()
    assert reader.GetErrorCode() == 0
    return reader.GetOutput()


def _point_array(grid, name):
    arr = grid.GetPointData().GetArray(name)
    assert arr is not None, f"no point data {name!r}"
    return vtk_to_numpy(arr)


def test_mesh_vtu_opens_in_vtk_with_radius_and_fiber_id(tmp_path):
    mesh = _mesh()
    grid = _read_vtu(mesh_vtu(tmp_path / "mesh.vtu", mesh))
    assert grid.GetNumberOfPoints() == mesh.n_nodes and grid.GetNumberOfCells() == mesh.n_elements
    np.testing.assert_allclose(vtk_to_numpy(grid.GetPoints().GetData()), mesh.nodes_m)
    assert all(grid.GetCellType(i) == vtk.VTK_LINE for i in range(grid.GetNumberOfCells()))
    np.testing.assert_allclose(_point_array(grid, "radius"), np.repeat(mesh.radius_m, np.diff(mesh.node_offsets)))
    np.testing.assert_array_equal(_point_array(grid, "fiber_id"), mesh.node_fiber())


def test_frames_and_their_pvd_series_open_in_vtk_with_the_contact_force(tmp_path):
    mesh = _mesh()
    times = np.array([0.0, 1e-4, 2e-4])
    rng = np.random.default_rng(0)
    positions = mesh.nodes_m[None] + 1e-5 * rng.normal(size=(3, mesh.n_nodes, 3))
    force = rng.normal(size=(3, mesh.n_nodes, 3))
    pvd = write_frames_vtk(tmp_path, mesh, times, positions, contact_force=force)
    # the .pvd series through VTK's XML parser (VTK 9.7 has no PVD reader of its own: ParaView's
    # vtkPVDReader reads the same VTKFile type="Collection" elements), each frame through its VTU reader
    parser = vtk.vtkXMLDataParser()
    parser.SetFileName(str(pvd))
    assert parser.Parse() == 1
    root = parser.GetRootElement()
    assert root.GetName() == "VTKFile" and root.GetAttribute("type") == "Collection"
    collection = root.GetNestedElement(0)
    datasets = [collection.GetNestedElement(i) for i in range(collection.GetNumberOfNestedElements())]
    assert [float(d.GetAttribute("timestep")) for d in datasets] == pytest.approx(times)
    for k, d in enumerate(datasets):
        grid = _read_vtu(tmp_path / d.GetAttribute("file"))
        np.testing.assert_allclose(vtk_to_numpy(grid.GetPoints().GetData()), positions[k])
        np.testing.assert_allclose(_point_array(grid, "contact_force"), force[k])
        np.testing.assert_allclose(_point_array(grid, "contact_force_magnitude"), np.linalg.norm(force[k], axis=1))
        np.testing.assert_allclose(_point_array(grid, "displacement"), positions[k] - mesh.nodes_m)
        np.testing.assert_allclose(_point_array(grid, "radius"), np.repeat(mesh.radius_m, np.diff(mesh.node_offsets)))
        np.testing.assert_array_equal(_point_array(grid, "fiber_id"), mesh.node_fiber())
