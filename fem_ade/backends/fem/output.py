"""The FEM fields as a closed (non-periodic) mesh for ParaView output (a run's XDMF series).

A periodic mesh has no nodes on its upper faces; for pictures they are put back: the output
mesh has the periodic images closed, and ``index`` maps each output point to its DOF.
"""

from __future__ import annotations

import numpy as np

from fem_ade.backends.fem.mesh import PeriodicMesh


def grid_cells(shape):
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


def closed_mesh(mesh: PeriodicMesh, space):
    """(points (P, 3), [(cell type, connectivity)], index (P,) into the DOF vector)."""
    if space.axes is not None:
        locs = space.node_axes
        closed = [np.append(x, a[-1]) for x, a in zip(locs, mesh.axes, strict=True)]
        grids = np.meshgrid(*closed, indexing="ij")
        points = np.stack([g.ravel() for g in grids], axis=1)
        idx1 = [np.append(np.arange(len(x)), 0) for x in locs]
        sizes = [len(x) for x in locs]
        I = np.meshgrid(*idx1, indexing="ij")
        index = np.ravel_multi_index(tuple(I), sizes).ravel()
        kind, cells = grid_cells([len(c) for c in closed])
    else:
        from skfem.io.meshio import to_meshio

        mio = to_meshio(mesh.original)  # the file's own vertices and cells
        points = mio.points
        kind, cells = mio.cells[0].type, mio.cells[0].data
        index = _vertex_dofs(mesh, space, points)
    if points.shape[1] == 2:
        points = np.column_stack([points, np.zeros(len(points))])
    return points, [(kind, cells)], index


def _vertex_dofs(mesh: PeriodicMesh, space, points: np.ndarray) -> np.ndarray:
    """The DOF of the periodic space at each vertex of the file's mesh: matched by coordinates
    modulo the box (the periodic images of a face share their DOF)."""
    dim = mesh.dim
    dofs = space.basis.nodal_dofs[0]
    where = np.asarray(space.basis.doflocs)[:, dofs]
    lo = mesh.original.p.min(axis=1)
    tol = 1e-6 * mesh.h_min

    def keys(x):
        wrapped = np.mod(x - lo[:, None], mesh.L)
        wrapped[np.isclose(wrapped, mesh.L, atol=tol, rtol=0.0)] = 0.0
        return [tuple(k) for k in np.round(wrapped / tol).astype(np.int64).T]

    lookup = dict(zip(keys(where), dofs, strict=True))
    return np.array([lookup[k] for k in keys(np.asarray(points)[:, :dim].T)])


def uniform_grid_field(mesh: PeriodicMesh, space, values: np.ndarray, m: int):
    """(field on the uniform periodic grid x_j = jL/m, shape (m,)*dim; the 1D coordinates x).

    Tensor meshes: the element's own interpolant (exact to its order: sum-factorized 1D
    Lagrange interpolation), the nodes themselves when they are that grid (p = 1, uniform,
    m = n); file meshes: linear interpolation of the nodal values over their periodically
    padded point cloud.
    """
    from scipy.interpolate import LinearNDInterpolator

    L, dim = mesh.L, mesh.dim
    x = np.arange(m) * (L / m)
    if space.axes is not None:
        if space.circulant and all(n == m for n in space.shape) and \
                all(abs(a.nodes[0]) < 1e-14 * L for a in space.axes):
            return np.reshape(values, space.shape).copy(), x
        return space.interpolate_to([x] * dim)(values), x
    pts, _, index = closed_mesh(mesh, space)
    target = np.stack(np.meshgrid(*[x] * dim, indexing="ij"), axis=-1)
    interp = LinearNDInterpolator(pts[:, :dim], values[index])
    return interp(target), x
