"""The FEM fields as a closed (non-periodic) mesh for ParaView output (a run's XDMF series).

A periodic mesh has no nodes on its upper faces; for pictures they are put back: the output
mesh has the periodic images closed, and ``index`` maps each output point to its DOF.
"""

from __future__ import annotations

import numpy as np

from .assemble import Operators, periodic_1d
from .mesh import PeriodicMesh


def _grid_cells(shape):
    """Cells (VTK order) of a structured grid of points of ``shape`` (C order)."""
    m = np.asarray(shape)
    idx = np.arange(int(np.prod(m))).reshape(tuple(m))
    if len(shape) == 2:
        c = idx[:-1, :-1]
        corners = [c, c + m[1], c + m[1] + 1, c + 1]
        return "quad", np.stack([q.ravel() for q in corners], axis=1)
    c = idx[:-1, :-1, :-1]
    di, dj = m[1] * m[2], m[2]
    corners = [c, c + di, c + di + dj, c + dj, c + 1, c + di + 1, c + di + dj + 1, c + dj + 1]
    return "hexahedron", np.stack([q.ravel() for q in corners], axis=1)


def closed_mesh(mesh: PeriodicMesh, ops: Operators):
    """(points (P, 3), [(cell type, connectivity)], index (P,) into the DOF vector)."""
    if ops.assembly == "kron":
        locs = [periodic_1d(np.asarray(a, float), ops.order)[2] for a in mesh.axes]
        closed = [np.append(x, a[-1]) for x, a in zip(locs, mesh.axes, strict=True)]
        grids = np.meshgrid(*closed, indexing="ij")
        points = np.stack([g.ravel() for g in grids], axis=1)
        idx1 = [np.append(np.arange(len(x)), 0) for x in locs]
        sizes = [len(x) for x in locs]
        I = np.meshgrid(*idx1, indexing="ij")
        index = np.ravel_multi_index(tuple(I), sizes).ravel()
        kind, cells = _grid_cells([len(c) for c in closed])
    else:
        from skfem.io.meshio import to_meshio

        sm = mesh.skfem_mesh()
        mio = to_meshio(sm._orig)
        points = mio.points
        kind, cells = mio.cells[0].type, mio.cells[0].data
        index = ops.basis.nodal_dofs[0][sm._ix]
    if points.shape[1] == 2:
        points = np.column_stack([points, np.zeros(len(points))])
    return points, [(kind, cells)], index


def uniform_grid_field(mesh: PeriodicMesh, ops: Operators, values: np.ndarray, m: int):
    """(field on the uniform periodic grid x_j = jL/m, shape (m,)*dim; the 1D coordinates x).

    Uniform tensor meshes with m = order·n: the DOF grid itself (a reshape). Other tensor
    meshes: multilinear interpolation of the nodal values; file meshes: linear interpolation
    of the nodal values over their periodically padded point cloud.
    """
    from scipy.interpolate import LinearNDInterpolator, RegularGridInterpolator

    L, dim = mesh.L, mesh.dim
    x = np.arange(m) * (L / m)
    if ops.assembly == "kron":
        locs = [periodic_1d(np.asarray(a, float), ops.order)[2] for a in mesh.axes]
        grid = values.reshape([len(v) for v in locs])
        if mesh.kind == "uniform" and all(len(v) == m for v in locs):
            return grid.copy(), x
        closed = [np.append(v, L) for v in locs]
        padded = np.pad(grid, [(0, 1)] * dim, mode="wrap")
        target = np.stack(np.meshgrid(*[x] * dim, indexing="ij"), axis=-1)
        return RegularGridInterpolator(closed, padded)(target), x
    pts, _, index = closed_mesh(mesh, ops)
    target = np.stack(np.meshgrid(*[x] * dim, indexing="ij"), axis=-1)
    interp = LinearNDInterpolator(pts[:, :dim], values[index])
    return interp(target), x
