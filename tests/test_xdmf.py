"""XDMF time series for ParaView (fem_ade.store.xdmf), read back with meshio."""

import os

import meshio
import numpy as np
import pytest

from fem_ade.store.xdmf import XdmfSeries, periodic_grid, read_series


def _field(n, k):
    x = np.arange(n) / n
    X = np.meshgrid(x, x, x, indexing="ij")
    return np.sin(2 * np.pi * X[0]) * np.cos(2 * np.pi * X[2]) + k


def test_grid_series_reads_back(tmp_path, monkeypatch):
    os.mkdir(tmp_path / "elsewhere")
    monkeypatch.chdir(tmp_path / "elsewhere")  # nothing goes to the current directory
    n, L, times = 8, 2.0, [0.0, 1e-6, 3e-6]
    path = tmp_path / "out" / "fields.xdmf"
    with XdmfSeries.from_grid(path, n, L) as series:
        for k, t in enumerate(times):
            series.write(t, {"phi": _field(n, k), "mu": -_field(n, k)})
    assert path.is_file()
    assert os.listdir(tmp_path / "elsewhere") == []

    with meshio.xdmf.TimeSeriesReader(path) as reader:
        points, cells = reader.read_points_cells()
        assert reader.num_steps == len(times)
        steps = [reader.read_data(k) for k in range(reader.num_steps)]
    assert points.shape == ((n + 1) ** 3, 3)
    assert np.allclose(points.min(axis=0), 0.0) and np.allclose(points.max(axis=0), L)
    assert cells[0].type == "hexahedron" and cells[0].data.shape == (n**3, 8)
    for k, (t, point_data, _) in enumerate(steps):
        assert t == pytest.approx(times[k])
        assert sorted(point_data) == ["mu", "phi"]
        phi = point_data["phi"].reshape(n + 1, n + 1, n + 1)
        assert np.allclose(phi[:n, :n, :n], _field(n, k))
        # periodic images closed: the last layer is a copy of the first, in each direction
        assert np.array_equal(phi[n], phi[0])
        assert np.array_equal(phi[:, n], phi[:, 0])
        assert np.array_equal(phi[:, :, n], phi[:, :, 0])


def test_hexahedra_are_valid():
    import pyvista as pv

    points, cells = periodic_grid(4, 1.0)
    grid = pv.from_meshio(meshio.Mesh(points, [("hexahedron", cells)]))
    vols = grid.compute_cell_sizes()["Volume"]
    assert np.allclose(vols, 1.0 / 64) and grid.volume == pytest.approx(1.0)


def test_general_mesh_and_field_checks(tmp_path):
    points, cells = periodic_grid(2, 1.0)
    path = tmp_path / "mesh.xdmf"
    series = XdmfSeries(path, points, [("hexahedron", cells)])
    series.write(0.5, {"u": np.arange(len(points), dtype=float)})
    with pytest.raises(ValueError, match="values for"):
        series.write(1.0, {"u": np.zeros(3)})
    series.close()
    series.close()  # idempotent
    with pytest.raises(RuntimeError):
        series.write(2.0, {"u": np.zeros(len(points))})
    _, _, steps = read_series(path)
    assert [t for t, _ in steps] == [0.5]
    assert np.array_equal(steps[0][1]["u"], np.arange(len(points)))
    with pytest.raises(ValueError, match="cell type"):
        XdmfSeries(tmp_path / "x.xdmf", points, [("tetra", cells[:, :4])])


def test_series_survives_damage_and_resumes(tmp_path):
    """Every saved step is its own file, written under a temporary name and renamed, and the
    index is rewritten after each: a damaged step file (a killed write), a step written after
    the checkpoint and a leftover temporary file are dropped on resume, the rest is kept."""
    n, path = 4, tmp_path / "phi.xdmf"
    series = XdmfSeries.from_grid(path, n, 1.0)
    for k in range(4):
        series.write(0.1 * k, {"phi": np.full((n, n, n), float(k))}, step=10 * k)
    # no close(): as after a SIGKILL; the index already lists the four steps
    assert [t for t, _ in read_series(path)[2]] == pytest.approx([0.0, 0.1, 0.2, 0.3])
    (tmp_path / "phi-00000010.h5").write_bytes(b"a write cut short")
    (tmp_path / "phi-00000040.tmp.h5").write_bytes(b"")
    again = XdmfSeries.from_grid(path, n, 1.0, resume_from=20)
    assert again.times == pytest.approx([0.0, 0.2])
    assert not (tmp_path / "phi-00000030.h5").exists()
    assert not list(tmp_path.glob("*.tmp*"))
    again.write(0.25, {"phi": np.full((n, n, n), 9.0)}, step=25)
    _, _, steps = read_series(path)
    assert [t for t, _ in steps] == pytest.approx([0.0, 0.2, 0.25])
    assert steps[-1][1]["phi"].max() == 9.0


@pytest.mark.parametrize("backend", ["spectral", "fem"])
def test_2d_runs_write_a_series(cli, tmp_path, backend):
    """2D scenes get a series of quadrilaterals (the grid closed periodically, or the mesh)."""
    out = tmp_path / "E"
    r = cli(["ellipse-2d", "--backend", backend, "--n", "24", "--steps", "4", "--out", out,
             "--quiet"])
    assert r.returncode == 0, r.stderr
    points, cells, steps = read_series(out / "phi.xdmf")
    assert len(steps) == 2 and np.all(points[:, 2] == 0)
    if backend == "spectral":
        assert len(points) == 25**2
