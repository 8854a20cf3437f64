"""ParaView output: a crash-consistent XDMF time series of point fields on a mesh.

:class:`XdmfSeries` writes the mesh once and one set of point fields per call of
:meth:`XdmfSeries.write`; open ``NAME.xdmf`` in ParaView (reader "XDMF Reader") and step
through time. For the spectral grid, :meth:`XdmfSeries.from_grid` builds a uniform grid of
hexahedra over the whole periodic box with the periodic images closed: n + 1 points per
direction, the last layer a copy of the first, so that a contour of φ has no seam at the box
faces; :meth:`write` accepts a grid field of shape (n, n, n) and adds that layer itself.
A finite-element backend passes its own ``points`` and ``cells`` (e.g. ``[("hexahedron",
conn)]``, VTK node order) and point fields of length ``len(points)``.

Files (HDF5 through h5py; XDMF 3 as meshio writes it, which meshio's reader and ParaView
read): the mesh in ``NAME.h5``, the fields of each saved step in ``NAME-KKKKKKKK.h5`` (K its
step number, with the time and step as attributes), and the index ``NAME.xdmf``. Every file is
written under a temporary name and renamed, and the index is rewritten after every step, so
at any moment — a SIGKILL included — ``NAME.xdmf`` lists whole files only and nothing saved
before is lost. ``resume_from=K`` reopens a series: the step files that are intact and not
after step K are kept (a damaged one, or one a killed run wrote after its last checkpoint,
is removed), the index is rebuilt from them, and new steps are appended.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from xml.sax.saxutils import escape

import numpy as np

#: the XDMF names of the cell types a series takes (meshio's names → XDMF's)
XDMF_CELLS = {"hexahedron": ("Hexahedron", 8), "quad": ("Quadrilateral", 4)}


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
    """A crash-consistent XDMF time series of point fields on a fixed mesh (module docstring).

    Usage::

        with XdmfSeries.from_grid("out/fields.xdmf", n=64, L=1.0) as series:
            series.write(0.0, {"phi": phi0})       # phi0: (64, 64, 64) grid field
            series.write(1e-6, {"phi": phi1})

        XdmfSeries("out/fields.xdmf", points, [("hexahedron", conn)])  # any mesh
    """

    def __init__(self, path: str | Path, points: np.ndarray, cells, *,
                 grid_shape: tuple[int, ...] | None = None, resume_from: int | None = None,
                 keep=None):
        import h5py

        self._h5py = h5py
        self.path = Path(path)
        self.points = np.asarray(points, dtype=float)
        if isinstance(cells, np.ndarray):
            cells = [("hexahedron", cells)]
        self.cells = [(str(kind), np.asarray(conn, dtype=np.int64)) for kind, conn in cells]
        for kind, _ in self.cells:
            if kind not in XDMF_CELLS:
                raise ValueError(f"unknown cell type {kind!r}; valid: {', '.join(XDMF_CELLS)}")
        self.grid_shape = grid_shape
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.mesh_file = self.path.with_suffix(".h5")
        #: (step, t, file name, {field: (shape)}) of every step in the index
        self.entries: list[tuple[int, float, str, dict]] = []
        if resume_from is not None:
            self.entries = self._intact_steps(resume_from, keep)
        if not self._mesh_intact():
            self._atomic_h5(self.mesh_file, {"points": self.points,
                                             **{f"cells{i}": c for i, (_, c) in
                                                enumerate(self.cells)}}, {})
        self._write_index()
        self._open = True

    @property
    def times(self) -> list[float]:
        return [t for _, t, _, _ in self.entries]

    @classmethod
    def from_grid(cls, path: str | Path, n: int, L: float, *, origin=(0.0, 0.0, 0.0),
                  dim: int = 3, resume_from: int | None = None, keep=None) -> XdmfSeries:
        """A series on the periodic n^dim grid of period L, periodic images closed
        (:func:`grid_mesh`); :meth:`write` then takes (n,)*dim fields."""
        points, cells = grid_mesh(n, L, dim, origin)
        return cls(path, points, cells, grid_shape=(n,) * dim, resume_from=resume_from,
                   keep=keep)

    # -- files ------------------------------------------------------------------------------
    def _step_file(self, step: int) -> Path:
        return self.path.with_name(f"{self.path.stem}-{step:08d}.h5")

    def _atomic_h5(self, path: Path, arrays: dict, attrs: dict) -> None:
        """One HDF5 file, whole or not at all. HDF5 reports a write the file system refuses
        (no space, a file-size limit) as OSError and then, closing the file, RuntimeError:
        both become the OSError of a failed write (the run's WriteFailed, exit 3)."""
        import errno as errno_

        tmp = path.with_name(path.stem + ".tmp.h5")
        try:
            with self._h5py.File(tmp, "w") as f:
                for name, value in arrays.items():
                    f.create_dataset(name, data=value)
                for name, value in attrs.items():
                    f.attrs[name] = value
        except (OSError, RuntimeError) as err:
            tmp.unlink(missing_ok=True)
            text = str(err)
            code = next((c for c in (errno_.EFBIG, errno_.ENOSPC, errno_.EDQUOT, errno_.EIO)
                         if f"errno = {c}," in text), getattr(err, "errno", None))
            reason = os.strerror(code) if code else " ".join(text.split())[:120]
            raise OSError(code or errno_.EIO, reason, str(tmp)) from None
        os.replace(tmp, path)

    def _mesh_intact(self) -> bool:
        try:
            with self._h5py.File(self.mesh_file, "r") as f:
                same = np.array_equal(f["points"][()], self.points) and all(
                    np.array_equal(f[f"cells{i}"][()], c) for i, (_, c) in enumerate(self.cells))
            return bool(same)
        except (OSError, KeyError, ValueError):
            return False

    def _intact_steps(self, last: int, keep=None) -> list:
        """The step files of this series that open, hold their fields, are not after
        ``last`` and pass ``keep(step)`` (default: all); the others (damaged, written after
        the checkpoint, or not wanted) are removed."""
        pattern = re.compile(rf"^{re.escape(self.path.stem)}-(\d{{8}})\.h5$")
        for leftover in self.path.parent.glob(f"{self.path.stem}*.tmp*"):  # cut-short writes
            leftover.unlink()
        kept = []
        for f in sorted(self.path.parent.iterdir()):
            m = pattern.match(f.name)
            if not m:
                continue
            step = int(m.group(1))
            entry = None
            if step <= last and (keep is None or keep(step)):
                try:
                    with self._h5py.File(f, "r") as h:
                        fields = {k: h[k].shape for k in h.keys()}
                        entry = (step, float(h.attrs["t"]), f.name, fields)
                except (OSError, KeyError, ValueError):
                    entry = None
            if entry is None or not entry[3] or any(
                    shape[0] != len(self.points) for shape in entry[3].values()):
                f.unlink()
                continue
            kept.append(entry)
        return kept

    def _write_index(self) -> None:
        """NAME.xdmf from the entries, atomically."""
        P = len(self.points)
        mesh = self.mesh_file.name
        lines = ['<?xml version="1.0"?>',
                 '<Xdmf Version="3.0" xmlns:xi="http://www.w3.org/2001/XInclude">',
                 "  <Domain>",
                 '    <Grid Name="mesh" GridType="Uniform">',
                 f'      <Geometry GeometryType="XYZ"><DataItem DataType="Float" '
                 f'Dimensions="{P} 3" Format="HDF" Precision="8">{escape(mesh)}:/points'
                 "</DataItem></Geometry>"]
        for i, (kind, conn) in enumerate(self.cells):
            name, per = XDMF_CELLS[kind]
            lines.append(f'      <Topology TopologyType="{name}" NumberOfElements="'
                         f'{len(conn)}"><DataItem DataType="Int" Dimensions="{len(conn)} '
                         f'{per}" Format="HDF" Precision="8">{escape(mesh)}:/cells{i}'
                         "</DataItem></Topology>")
        lines += ["    </Grid>",
                  '    <Grid Name="TimeSeries" GridType="Collection" '
                  'CollectionType="Temporal">']
        ptr = ('xpointer(//Grid[@Name=&quot;mesh&quot;]/*[self::Topology or '
               'self::Geometry])')
        for step, t, file, fields in self.entries:
            lines += [f'      <Grid Name="step {step}">', f'        <xi:include xpointer="{ptr}"/>',
                      f'        <Time Value="{t!r}"/>']
            for name, shape in fields.items():
                kind = "Scalar" if len(shape) == 1 else "Vector"
                dims = " ".join(str(d) for d in shape)
                lines.append(f'        <Attribute Name="{escape(name)}" AttributeType="{kind}" '
                             f'Center="Node"><DataItem DataType="Float" Dimensions="{dims}" '
                             f'Format="HDF" Precision="8">{escape(file)}:/{escape(name)}'
                             "</DataItem></Attribute>")
            lines.append("      </Grid>")
        lines += ["    </Grid>", "  </Domain>", "</Xdmf>", ""]
        tmp = self.path.with_name(self.path.name + ".tmp")
        tmp.write_text("\n".join(lines))
        os.replace(tmp, self.path)

    # -- the series ----------------------------------------------------------------------------
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

    def write(self, t: float, point_data: dict, step: int | None = None) -> None:
        """Add the fields ``point_data`` (name → values) at time ``t`` as step ``step``
        (default: one after the last): its file, then the index."""
        if not self._open:
            raise RuntimeError(f"{self.path} is closed")
        data = {k: self._point_values(k, v) for k, v in point_data.items()}
        if step is None:
            step = self.entries[-1][0] + 1 if self.entries else 0
        step = int(step)
        file = self._step_file(step)
        self._atomic_h5(file, data, {"t": float(t), "step": step})
        self.entries = [e for e in self.entries if e[0] != step]
        self.entries.append((step, float(t), file.name, {k: v.shape for k, v in data.items()}))
        self.entries.sort(key=lambda e: e[0])
        self._write_index()

    def close(self) -> None:
        """Nothing is left to write (the index is current after every step). Idempotent."""
        self._open = False

    def __enter__(self) -> XdmfSeries:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def read_series(path: str | Path) -> tuple[np.ndarray, list, list[tuple[float, dict]]]:
    """Read an XDMF time series back with meshio: (points, cells, [(t, point_data), ...])."""
    import meshio

    with meshio.xdmf.TimeSeriesReader(path) as reader:
        points, cells = reader.read_points_cells()
        steps = []
        for k in range(reader.num_steps):
            t, point_data, _ = reader.read_data(k)
            steps.append((float(t), point_data))
    return points, cells, steps
