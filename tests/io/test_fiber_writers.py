"""Traced fibers in the formats other programs read, each read back by a parser written here from
the format's published description (not by the writer's code): open_iA's FCP fiber CSV
(``iACsvConfig::getFCPFiberFormat``: five skipped lines, 14 comma-separated columns in µm) and the
Avizo/Amira SpatialGraph (AmiraMesh ASCII: ``define`` counts, ``@k`` data declarations and
sections)."""

import re

import numpy as np
import pytest
from click.testing import CliRunner

from fiberpipe.artifacts import write_fibers
from fiberpipe.cli import main
from fiberpipe.io.avizo import write_avizo_spatialgraph
from fiberpipe.io.fiberscout import fiber_angles_deg, write_fiberscout_csv
from fiberpipe.polylines import Polylines


def _fibers():
    """A straight fiber along z, a straight one at 30 deg from z in the x-z plane, a circular arc."""
    t = np.linspace(0, 1, 11)[:, None]
    straight = np.array([10e-6, 20e-6, 0.0]) + t * np.array([0, 0, 500e-6])
    tilted = np.array([100e-6, 0, 0]) + t * 400e-6 * np.array([np.sin(np.radians(30)), 0, np.cos(np.radians(30))])
    a = np.linspace(0, np.pi / 2, 31)
    arc = np.column_stack([200e-6 + 300e-6 * np.cos(a), np.full(31, 50e-6), 300e-6 * np.sin(a)])
    return Polylines.from_list([straight, tilted, arc], np.array([3e-6, 4e-6, 5e-6]))


def _read_fcp(path):
    """open_iA's FCP fiber CSV: skip 5 lines (the 2nd is not 'Voids'), then 14 columns per row."""
    lines = path.read_text(encoding="utf-8").splitlines()
    assert lines[1] != "Voids"
    rows = [line.split(",") for line in lines[5:] if line.strip()]
    assert all(len(r) == 14 for r in rows)
    return np.array([[float(v) for v in r] for r in rows])


def test_the_fiberscout_csv_reads_back_as_open_ia_reads_it(tmp_path):
    fibers = _fibers()
    table = _read_fcp(write_fiberscout_csv(tmp_path / "fibers.csv", fibers))
    assert table[:, 0].tolist() == [1, 2, 3]
    np.testing.assert_allclose(table[:, 1:4], [[10, 20, 0], [100, 0, 0], [500, 50, 0]], atol=1e-5)  # start, µm
    np.testing.assert_allclose(table[0, 4:7], [10, 20, 500], atol=1e-5)
    np.testing.assert_allclose(table[:, 7], [500, 400, 300 * np.sqrt(2)], rtol=1e-6)  # straight length
    np.testing.assert_allclose(table[:2, 8], [500, 400], rtol=1e-6)  # curved = straight for straight fibers
    assert abs(table[2, 8] - 300 * np.pi / 2) < 0.1  # the arc's length, to its 31-point chord sum (0.07 µm short)
    np.testing.assert_allclose(table[:, 9], [6, 8, 10])  # diameter
    np.testing.assert_allclose(table[:, 11], np.pi / 4 * table[:, 9] ** 2 * table[:, 8], rtol=1e-6)  # volume
    assert table[:, 13].tolist() == [0, 0, 1]  # only the arc is curved
    # phi, theta as open_iA computes them from the start and end points
    phi, theta = fiber_angles_deg(table[:, 1:4], table[:, 4:7])
    np.testing.assert_allclose(theta[:2], [0, 30], atol=1e-6)
    np.testing.assert_allclose(phi[1], 0, atol=1e-6)
    np.testing.assert_allclose([theta[2], phi[2]], [45, 180], atol=1e-6)


def _read_amira(path):
    """AmiraMesh ASCII: 'define NAME n' sets a location's count; 'LOC { type[k] NAME } @i' declares
    data section @i; after the header, '@i' starts that section's count x k values."""
    text = path.read_text(encoding="utf-8")
    assert text.startswith("# AmiraMesh 3D ASCII 2.0")
    header, data = text.split("# Data section follows", 1)
    counts = {m[0]: int(m[1]) for m in re.findall(r"define\s+(\w+)\s+(\d+)", header)}
    decl = {}
    for loc, typ, k, name, at in re.findall(r"(\w+)\s*\{\s*(float|int)(?:\[(\d+)\])?\s+(\w+)\s*\}\s*@(\d+)", header):
        decl[at] = (name, loc, int(k or 1), float if typ == "float" else int)
    out = {}
    parts = re.split(r"^@(\d+)\s*$", data, flags=re.M)
    for at, body in zip(parts[1::2], parts[2::2]):
        name, loc, k, typ = decl[at]
        values = np.array([typ(v) for v in body.split()])
        out[name] = values.reshape(counts[loc], k) if k > 1 else values
        assert len(values) == counts[loc] * k
    return out, header


def test_the_avizo_spatialgraph_reads_back_as_amiramesh(tmp_path):
    fibers = _fibers()
    graph, header = _read_amira(write_avizo_spatialgraph(tmp_path / "fibers.am", fibers))
    assert 'ContentType "HxSpatialGraph"' in header
    assert graph["EdgeConnectivity"].tolist() == [[0, 1], [2, 3], [4, 5]]
    assert graph["NumEdgePoints"].tolist() == [11, 11, 31]
    points = graph["EdgePointCoordinates"]
    offsets = np.concatenate([[0], np.cumsum(graph["NumEdgePoints"])])
    for i in range(3):
        line = points[offsets[i]:offsets[i + 1]]
        np.testing.assert_allclose(line, fibers.fiber(i) * 1e6, atol=1e-5)
        # an edge's first and last points are its vertices
        a, b = graph["EdgeConnectivity"][i]
        np.testing.assert_allclose(graph["VertexCoordinates"][[a, b]], line[[0, -1]], atol=1e-5)
    np.testing.assert_allclose(graph["Thickness"], np.repeat([3, 4, 5], [11, 11, 31]))


@pytest.mark.parametrize("fmt, suffix", [("fiberscout", ".csv"), ("avizo", ".am")])
def test_fiberpipe_export_writes_each_format(tmp_path, fmt, suffix):
    write_fibers(tmp_path / "fibers.h5", _fibers())
    result = CliRunner().invoke(main, ["export", fmt, str(tmp_path / "fibers.h5")])
    assert result.exit_code == 0, result.output
    assert (tmp_path / f"fibers{suffix}").exists()
    out = tmp_path / "elsewhere" / f"x{suffix}"
    out.parent.mkdir()
    assert CliRunner().invoke(main, ["export", fmt, str(tmp_path / "fibers.h5"), "--out", str(out)]).exit_code == 0
    assert out.exists()


def test_exporting_a_missing_file_is_one_line(tmp_path):
    result = CliRunner().invoke(main, ["export", "avizo", str(tmp_path / "none.h5")])
    assert result.exit_code != 0 and "none.h5" in result.output and len(result.output.strip().splitlines()) == 1
