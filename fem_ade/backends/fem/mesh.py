"""Periodic hexahedral (3D) and quadrilateral (2D) meshes of the box [0, L]^dim (model §1, §5).

Three kinds:

- ``uniform``: a tensor mesh with n equal cells per direction;
- ``graded``: a tensor mesh with smoothly varying, periodic spacing per axis;
- ``file``: any conforming hexahedral (quad in 2D) mesh read with meshio, whose opposite faces
  carry matching nodes; the periodicity is found by matching those nodes.

Tensor meshes keep their 1D node arrays (``axes``): their matrices are Kronecker sums of 1D
periodic matrices (:mod:`fem_ade.backends.fem.assemble`). Every mesh can also give the scikit-fem
periodic
mesh (``MeshHex1DG`` / ``MeshQuad1DG`` through ``MeshDG.periodic``), which is what file meshes use.
"""

from __future__ import annotations

import contextlib
import io
import logging
import math
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fem_ade.model.params import ModelError

#: a mesh needs at least this many cells per periodic direction
MIN_CELLS = 3


@dataclass
class PeriodicMesh:
    """A periodic mesh of [0, L]^dim: tensor axes (uniform/graded) or a scikit-fem mesh (file)."""

    kind: str
    dim: int
    L: float
    axes: tuple[np.ndarray, ...] | None = None  # per axis: nodes 0 = x0 < .. < xn = L
    source: str = ""
    _skfem: object = field(default=None, repr=False)
    #: the file's mesh before its opposite faces were identified (scikit-fem, non-periodic)
    original: object = field(default=None, repr=False)

    @property
    def is_tensor(self) -> bool:
        return self.axes is not None

    @property
    def cells_per_axis(self) -> tuple[int, ...]:
        if self.axes is None:
            return ()
        return tuple(len(a) - 1 for a in self.axes)

    @property
    def h_min(self) -> float:
        """Smallest cell edge (tensor) or smallest element extent (file)."""
        if self.axes is not None:
            return float(min(np.diff(a).min() for a in self.axes))
        m = self.original
        ext = np.ptp(m.p[:, m.t], axis=1)
        return float(ext.min())

    @property
    def h_max(self) -> float:
        if self.axes is not None:
            return float(max(np.diff(a).max() for a in self.axes))
        m = self.original
        return float(np.ptp(m.p[:, m.t], axis=1).max())

    def skfem_mesh(self):
        """The scikit-fem periodic mesh (MeshHex1DG in 3D, MeshQuad1DG in 2D)."""
        if self._skfem is None:
            self._skfem = _tensor_skfem(self.axes)
        return self._skfem

    def describe(self) -> dict:
        d = {"kind": self.kind, "dim": self.dim, "L": self.L}
        if self.axes is not None:
            d["cells"] = list(self.cells_per_axis)
        else:
            d["cells"] = int(self.skfem_mesh().t.shape[1])
            d["file"] = self.source
        d["h_min"] = self.h_min
        d["h_max"] = self.h_max
        return d


def _check_cells(n: int):
    if not isinstance(n, (int, np.integer)) or n < MIN_CELLS:
        raise ModelError(f"a periodic mesh needs at least {MIN_CELLS} cells per direction, got {n}")


def uniform(dim: int, n: int, L: float = 1.0) -> PeriodicMesh:
    """n equal cells per direction on [0, L]^dim."""
    _check_cells(n)
    x = np.linspace(0.0, L, n + 1)
    return PeriodicMesh("uniform", dim, float(L), axes=(x,) * dim)


def graded_axis(n: int, L: float, grading: float, shift: float = 0.0) -> np.ndarray:
    """Smooth periodic grading: x(s) = L (s − g sin(2π(s − shift)) / 2π), s = 0..1 in n steps.

    The spacing varies as 1 − g cos(2π(s − shift)), so the ratio of largest to smallest cell is
    (1 + g) / (1 − g); x(0) = 0 and x(1) = L are kept only for shift = 0, so the shift is
    applied as an offset that keeps both ends (the map minus its value at s = 0).
    """
    if not 0.0 <= grading < 1.0:
        raise ModelError(f"grading must be in [0, 1), got {grading}")
    s = np.linspace(0.0, 1.0, n + 1)
    g = grading / (2.0 * math.pi)
    x = s - g * (np.sin(2.0 * math.pi * (s - shift)) - math.sin(-2.0 * math.pi * shift))
    return L * x


def graded(dim: int, n: int, L: float = 1.0, grading: float = 0.3,
           centre: float | None = None) -> PeriodicMesh:
    """A tensor mesh with n cells per direction, refined smoothly: finest at x = centre·L on
    every axis, or (``centre`` None) at a different phase per axis (0, 0.13, 0.26 of L: a
    mesh with no symmetry, for testing)."""
    _check_cells(n)
    shifts = [0.13 * k for k in range(dim)] if centre is None else [centre] * dim
    axes = tuple(graded_axis(n, L, grading, shift=shift) for shift in shifts)
    return PeriodicMesh("graded", dim, float(L), axes=axes)


@contextmanager
def _quiet_skfem():
    """scikit-fem logs a warning when it copies arrays to C order; that is not news here."""
    logger = logging.getLogger("skfem")
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        yield
    finally:
        logger.setLevel(level)


# ---------------------------------------------------------------------------------------------
# scikit-fem periodic meshes
# ---------------------------------------------------------------------------------------------
def _dg_class(dim: int):
    from skfem import MeshHex1DG, MeshQuad1DG

    return {2: MeshQuad1DG, 3: MeshHex1DG}[dim]


def _tensor_skfem(axes):
    """Periodic skfem mesh of a tensor grid (node matching is exact: same coordinates)."""
    from skfem import MeshHex1, MeshQuad1

    dim = len(axes)
    base = (MeshQuad1 if dim == 2 else MeshHex1).init_tensor(*axes)
    return periodify(base, [float(a[-1] - a[0]) for a in axes], [float(a[0]) for a in axes])


def periodify(mesh, lengths, origin, rtol: float = 1e-6):
    """Identify the nodes of opposite faces of a box mesh (``MeshDG.periodic``).

    Every node on a face x_d = origin_d + L_d is replaced by the node at x_d = origin_d with the
    same other coordinates (corner and edge nodes map to the one node with all coordinates at
    the origin faces). The tolerance is ``rtol`` times the smallest edge. A node without a
    partner raises :class:`ModelError`.
    """
    p = mesh.p
    dim = p.shape[0]
    t = mesh.t
    edges = np.linalg.norm(p[:, t] - p[:, np.roll(t, 1, axis=0)], axis=0)
    tol = rtol * float(edges[edges > 0].min())
    origin = np.asarray(origin, float)[:, None]
    lengths = np.asarray(lengths, float)[:, None]
    wrapped = p.copy()
    on_max = np.abs(p - (origin + lengths)) <= tol
    wrapped[on_max] = np.broadcast_to(origin, p.shape)[on_max]
    moved = np.flatnonzero(on_max.any(axis=0))
    # look nodes up by their coordinates rounded to the tolerance grid
    keys = np.round((p - origin) / tol).astype(np.int64)
    lookup = {tuple(k): i for i, k in enumerate(keys.T)}
    wkeys = np.round((wrapped[:, moved] - origin) / tol).astype(np.int64)
    partner = np.array([lookup.get(tuple(k), -1) for k in wkeys.T], dtype=np.int64)
    if (partner < 0).any():
        bad = p[:, moved[np.flatnonzero(partner < 0)[0]]]
        raise ModelError(
            "mesh is not periodic: the node at "
            f"({', '.join(f'{c:.6g}' for c in bad)}) has no matching node on the opposite face"
        )
    # nodes on the low faces must all be matched too (same count per face)
    on_min = np.abs(p - origin) <= tol
    for d in range(dim):
        if on_min[d].sum() != on_max[d].sum():
            raise ModelError(
                f"mesh is not periodic: {on_min[d].sum()} nodes on the face x{d} = min but "
                f"{on_max[d].sum()} on x{d} = max"
            )
    cls = _dg_class(dim)
    try:
        with _quiet_skfem():
            return cls.periodic(mesh, moved.astype(np.int32), partner.astype(np.int32))
    except ValueError as err:
        raise ModelError(f"cannot make the mesh periodic: {err}") from None


def from_file(path: str | Path, dim: int = 3, L: float | None = None) -> PeriodicMesh:
    """Read a hexahedral (quad in 2D) box mesh with meshio and identify its opposite faces.

    Raises :class:`ModelError` (one line) when the file is missing or unreadable, holds other
    cells, has fewer than 3 cells per direction, does not fill the box [0, L]^dim, or when its
    opposite faces do not carry matching nodes.
    """
    import meshio
    from skfem.io.meshio import from_meshio

    path = Path(path)
    if not path.is_file():
        raise ModelError(f"mesh file not found: {path}")
    said = io.StringIO()
    try:  # meshio prints its own complaints and may exit: keep them, report one line
        with contextlib.redirect_stderr(said), contextlib.redirect_stdout(said):
            mio = meshio.read(path)
    except (Exception, SystemExit) as err:  # meshio raises many kinds
        why = " ".join(said.getvalue().split()) or str(err) or type(err).__name__
        raise ModelError(f"cannot read mesh file {path}: {why}") from None
    want = "hexahedron" if dim == 3 else "quad"
    kinds = {c.type for c in mio.cells}
    if kinds != {want}:
        raise ModelError(
            f"mesh {path.name} must contain only '{want}' cells for a {dim}D scene, "
            f"found {sorted(kinds)}"
        )
    points = np.asarray(mio.points)[:, :dim]
    cells = np.vstack([c.data for c in mio.cells])
    if cells.size == 0 or cells.min() < 0 or cells.max() >= len(points):
        raise ModelError(f"mesh {path.name}: a cell refers to a point it does not have "
                         f"(indices {cells.min()}..{cells.max()}, {len(points)} points)")
    if len(np.unique(np.sort(cells, axis=1), axis=0)) != len(cells):
        raise ModelError(f"mesh {path.name} lists a cell twice (a duplicated cell counts its "
                         "volume twice)")
    mio = meshio.Mesh(points, [(want, cells)])
    try:
        with _quiet_skfem():
            mesh = from_meshio(mio)
    except (ValueError, IndexError) as err:
        raise ModelError(f"cannot use mesh {path.name}: {err}") from None
    lo, hi = mesh.p.min(axis=1), mesh.p.max(axis=1)
    if not np.allclose(lo, 0.0, atol=1e-9 * max(float(np.max(hi - lo)), 1e-300)):
        raise ModelError(f"mesh {path.name} starts at {np.round(lo, 6).tolist()}: the periodic "
                         "box is [0, L]^dim (shift the mesh)")
    ext = hi - lo
    if L is not None and not np.allclose(ext, L, rtol=1e-6, atol=0):
        raise ModelError(
            f"mesh {path.name} spans {np.round(ext, 6).tolist()}, but the scene's periodic box "
            f"has side L = {L}"
        )
    cell_ext = np.ptp(mesh.p[:, mesh.t], axis=1).max(axis=1)
    ncell = ext / cell_ext
    if (ncell < MIN_CELLS - 1e-9).any():
        raise ModelError(
            f"mesh {path.name} has fewer than {MIN_CELLS} cells across some direction "
            f"(about {np.round(ncell, 2).tolist()})"
        )
    periodic = periodify(mesh, ext, lo)
    return PeriodicMesh("file", dim, float(ext[0]), source=str(path), _skfem=periodic,
                        original=mesh)


#: the grading of ``graded`` without ``:g``
DEFAULT_GRADING = 0.3


def parse_option(mesh) -> tuple[str, object]:
    """The ``mesh`` option as (kind, value): ("uniform", None), ("graded", (g, centre)),
    ("file", path) or ("given", PeriodicMesh). ``graded[:g][@c]``: grading g in [0, 1)
    (default 0.3), finest at c·L on every axis (c in [0, 1); default: a different phase per
    axis). Raises ModelError for a malformed grading."""
    if isinstance(mesh, PeriodicMesh):
        return "given", mesh
    if mesh is None or mesh == "uniform":
        return "uniform", None
    if isinstance(mesh, str) and (mesh == "graded" or mesh.startswith(("graded:", "graded@"))):
        body, _, where = mesh[len("graded"):].partition("@")
        text = body[1:] if body.startswith(":") else body
        try:
            g = float(text) if text else DEFAULT_GRADING
            centre = float(where) if where else None
        except ValueError:
            raise ModelError(f"--mesh graded[:g][@c] needs numbers g in (0, 1) and c in "
                             f"[0, 1), got {mesh!r}") from None
        if not 0.0 < g < 1.0:
            raise ModelError(f"--mesh graded:g needs 0 < g < 1 (g = 0 is the uniform mesh), "
                             f"got {g}")
        if centre is not None and not 0.0 <= centre < 1.0:
            raise ModelError(f"--mesh graded@c needs 0 <= c < 1 (a fraction of L), got {centre}")
        return "graded", (g, centre)
    return "file", Path(mesh)


def make(dim: int, n: int, L: float, mesh=None) -> PeriodicMesh:
    """The mesh a backend runs on: ``None``/"uniform", "graded[:g]", a path, or a PeriodicMesh."""
    kind, value = parse_option(mesh)
    if kind == "given":
        if value.dim != dim:
            raise ModelError(f"mesh is {value.dim}D but the scene is {dim}D")
        return value
    if kind == "uniform":
        return uniform(dim, n, L)
    if kind == "graded":
        return graded(dim, n, L, *value)
    return from_file(value, dim, L)
