"""ParaView output: an XDMF time series of point fields on a mesh, written with meshio.

:class:`XdmfSeries` writes the mesh once and then one set of point fields per call of
:meth:`XdmfSeries.write`; open ``NAME.xdmf`` in ParaView (reader "XDMF Reader") and step
through time. For the spectral grid, :meth:`XdmfSeries.from_grid` builds a uniform grid of
hexahedra over the whole periodic box with the periodic images closed: n + 1 points per
direction, the last layer a copy of the first, so that a contour of φ has no seam at the box
faces; :meth:`write` accepts a grid field of shape (n, n, n) and adds that layer itself.
A finite-element backend passes its own ``points`` and ``cells`` (e.g. ``[("hexahedron",
conn)]``, VTK node order) and point fields of length ``len(points)``.

Data format: ``"HDF"`` (a compact ``NAME.h5`` next to the ``.xdmf``) needs h5py, which is
not among fem_ade's dependencies; ``"XML"`` stores the values as text inside the ``.xdmf``
(portable, larger: about 5 MB per 64³ field). ``"auto"`` (the default) uses HDF when h5py
is importable, else XML. (meshio 5.3 writes the .h5, and the .bin files of its third format
"Binary", in the current directory rather than next to the .xdmf; the HDF file is put next
to the .xdmf here, and "Binary" is not offered.)

The XML file is written when the series is closed: use it as a context manager or call
:meth:`close` (a series left open at a crash has its HDF data but no readable .xdmf).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import meshio
import numpy as np

FORMATS = ("auto", "HDF", "XML")


def periodic_grid(n: int | tuple[int, int, int], L: float | tuple[float, float, float],
                  origin=(0.0, 0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """(points, hexahedra) of the closed periodic grid: (n+1)³ points spanning [0, L]³.

    Point (i, j, k) has index (i·(n₁+1) + j)·(n₂+1) + k and coordinates origin + (i, j, k)·h,
    i.e. the C order of an (n₀+1, n₁+1, n₂+1) array. Cells use VTK's hexahedron node order.
    """
    ns = np.broadcast_to(np.asarray(n, dtype=np.int64), (3,))
    Ls = np.broadcast_to(np.asarray(L, dtype=float), (3,))
    axes = [origin[a] + np.linspace(0.0, Ls[a], ns[a] + 1) for a in range(3)]
    X = np.meshgrid(*axes, indexing="ij")
    points = np.stack([x.ravel() for x in X], axis=1)
    m = ns + 1
    idx = np.arange(int(np.prod(m))).reshape(tuple(m))
    c = idx[:-1, :-1, :-1]
    di, dj, dk = m[1] * m[2], m[2], 1
    corners = [c, c + di, c + di + dj, c + dj,
               c + dk, c + di + dk, c + di + dj + dk, c + dj + dk]
    cells = np.stack([q.ravel() for q in corners], axis=1)
    return points, cells


def grid_mesh(n: int, L: float, dim: int = 3, origin=(0.0, 0.0, 0.0)):
    """(points (P, 3), [(cell type, cells)]) of the closed periodic n^dim grid: hexahedra in
    3D (:func:`periodic_grid`), quadrilaterals in the plane z = 0 in 2D."""
    if dim == 2:
        points, hexes = periodic_grid((n, n, 1), (L, L, 0.0), origin)
        return points[::2], [("quad", hexes[:, :4] // 2)]  # the layer z = 0 of each (i, j)
    points, cells = periodic_grid(n, L, origin)
    return points, [("hexahedron", cells)]


def closed_grid_values(a: np.ndarray) -> np.ndarray:
    """A periodic grid field (n,)*dim at the points of :func:`grid_mesh` (the last layer of
    each direction a copy of the first), flattened in C order."""
    a = np.asarray(a, dtype=float)
    return np.pad(a, [(0, 1)] * a.ndim, mode="wrap").ravel()


class XdmfSeries:
    """An XDMF time series of point fields on a fixed mesh (meshio ``TimeSeriesWriter``).

    Usage::

        with XdmfSeries.from_grid("out/fields.xdmf", n=64, L=1.0) as series:
            series.write(0.0, {"phi": phi0})       # phi0: (64, 64, 64) grid field
            series.write(1e-6, {"phi": phi1})

        XdmfSeries("out/fields.xdmf", points, [("hexahedron", conn)])  # any mesh

    ``data_format``: "auto", "HDF" or "XML" (module docstring).
    """

    def __init__(self, path: str | Path, points: np.ndarray, cells, *,
                 data_format: str = "auto", grid_shape: tuple[int, ...] | None = None):
        if data_format not in FORMATS:
            raise ValueError(f"unknown XDMF data format {data_format!r}; use one of {FORMATS}")
        if data_format == "auto":
            data_format = "HDF" if importlib.util.find_spec("h5py") is not None else "XML"
        self.path = Path(path)
        self.data_format = data_format
        self.points = np.asarray(points, dtype=float)
        if isinstance(cells, np.ndarray):
            cells = [("hexahedron", cells)]
        self.cells = [(str(kind), np.asarray(conn, dtype=np.int64)) for kind, conn in cells]
        self.grid_shape = grid_shape
        self.times: list[float] = []
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._writer = meshio.xdmf.TimeSeriesWriter(self.path, data_format=data_format)
        if data_format == "HDF":
            # meshio 5.3 opens NAME.h5 in the current directory, while the .xdmf refers to it
            # next to itself: open it next to the .xdmf instead of calling __enter__
            import h5py

            self._writer.h5_filename = str(self.path.with_suffix(".h5"))
            self._writer.h5_file = h5py.File(self._writer.h5_filename, "w")
        self._writer.write_points_cells(self.points, self.cells)
        self._open = True

    @classmethod
    def from_grid(cls, path: str | Path, n: int, L: float, *, data_format: str = "auto",
                  origin=(0.0, 0.0, 0.0), dim: int = 3) -> XdmfSeries:
        """A series on the periodic n^dim grid of period L, periodic images closed
        (:func:`grid_mesh`); :meth:`write` then takes (n,)*dim fields."""
        points, cells = grid_mesh(n, L, dim, origin)
        return cls(path, points, cells, data_format=data_format, grid_shape=(n,) * dim)

    def _point_values(self, name: str, values) -> np.ndarray:
        a = np.asarray(values, dtype=float)
        d = 0 if self.grid_shape is None else len(self.grid_shape)
        if d and a.shape[:d] == tuple(self.grid_shape):
            a = np.pad(a, [(0, 1)] * d + [(0, 0)] * (a.ndim - d), mode="wrap")
            a = a.reshape((-1,) + a.shape[d:])
        if a.shape[0] != len(self.points):
            raise ValueError(f"field {name!r} has {a.shape[0]} values for {len(self.points)} "
                             f"points (shape {np.shape(values)})")
        return a

    def write(self, t: float, point_data: dict) -> None:
        """Append the fields ``point_data`` (name → values) at time ``t``."""
        if not self._open:
            raise RuntimeError(f"{self.path} is closed")
        data = {k: self._point_values(k, v) for k, v in point_data.items()}
        self._writer.write_data(float(t), point_data=data)
        self.times.append(float(t))

    def close(self) -> None:
        """Write the .xdmf file (and close the .h5). Idempotent."""
        if self._open:
            self._open = False
            self._writer.__exit__(None, None, None)

    def __enter__(self) -> XdmfSeries:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def read_series(path: str | Path) -> tuple[np.ndarray, list, list[tuple[float, dict]]]:
    """Read an XDMF time series back: (points, cells, [(t, point_data), ...])."""
    with meshio.xdmf.TimeSeriesReader(path) as reader:
        points, cells = reader.read_points_cells()
        steps = []
        for k in range(reader.num_steps):
            t, point_data, _ = reader.read_data(k)
            steps.append((float(t), point_data))
    return points, cells, steps
