"""The FEM space of a run: the spectral-element space of order p on a tensor mesh
(:class:`fem_ade.backends.fem.tensor.TensorSpace`, matrix-free), or scikit-fem's Lagrange space of
order
1 or 2 on a hexahedral (quadrilateral) mesh file, assembled.

Both integrate with the GLL rule on the element's own nodes, so both have the diagonal mass W
(the GLL weights) and the same weak form: ``K @ x``, ``weights``, ``laplacian(x)`` = W⁻¹Kx,
``doflocs``, ``n_dofs``, ``order``, and ``preconditioner_stiffness()`` (the sparse K̃ that AMG
works on: the low-order refined stiffness of a tensor space, a file mesh's own K).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from fem_ade.backends.fem import forms, gll
from fem_ade.backends.fem.mesh import PeriodicMesh
from fem_ade.backends.fem.tensor import TensorSpace
from fem_ade.model.params import ModelError

#: the orders of scikit-fem's Lagrange hexahedra (quads) whose nodes are GLL points
FILE_MESH_ORDERS = (1, 2)


def gll_quadrature(dim: int, order: int) -> tuple[np.ndarray, np.ndarray]:
    """The tensor GLL rule of ``order`` on scikit-fem's reference cell [0, 1]^dim:
    (points (dim, q), weights (q,))."""
    xi, w = gll.points_weights(order)
    x, w = 0.5 * (xi + 1.0), 0.5 * w
    grids = np.meshgrid(*[x] * dim, indexing="ij")
    weights = np.prod(np.meshgrid(*[w] * dim, indexing="ij"), axis=0)
    return np.stack([g.ravel() for g in grids]), weights.ravel()


def element(dim: int, order: int):
    """The scikit-fem Lagrange element: Q1/Q2 on quads (2D) or hexahedra (3D)."""
    from skfem import ElementHex1, ElementHex2, ElementQuad1, ElementQuad2

    return {(2, 1): ElementQuad1, (2, 2): ElementQuad2,
            (3, 1): ElementHex1, (3, 2): ElementHex2}[(dim, order)]()


class AssembledSpace:
    """Q1/Q2 on a periodic mesh file, assembled by scikit-fem with the GLL rule: its mass is
    diagonal (the nodes are the quadrature points), its K a sparse matrix."""

    assembly = "skfem"
    axes = None

    def __init__(self, mesh: PeriodicMesh, order: int):
        from skfem import Basis

        if order not in FILE_MESH_ORDERS:
            raise ModelError(f"a mesh file takes order 1 or 2 (scikit-fem's Lagrange "
                             f"hexahedra); order {order} needs a tensor mesh (uniform or graded)")
        self.order = order
        self.dim = mesh.dim
        self.basis = Basis(mesh.skfem_mesh(), element(mesh.dim, order),
                           quadrature=gll_quadrature(mesh.dim, order))
        M = forms.mass.assemble(self.basis).tocsr()
        self.weights = M.diagonal().copy()
        off = abs(M - sp.diags(self.weights)).max()
        if off > 1e-12 * self.weights.max():
            raise ModelError("the GLL mass of this mesh is not diagonal (the element's nodes "
                             "are not its quadrature points)")
        self.K = forms.laplace.assemble(self.basis).tocsr()
        self.K.sort_indices()
        self.doflocs = np.asarray(self.basis.doflocs)
        self.n_dofs = self.K.shape[0]

    def laplacian(self, x):
        """μ = W⁻¹Kx."""
        return (self.K @ x) / self.weights

    def preconditioner_stiffness(self) -> sp.csr_matrix:
        return self.K

    def describe(self) -> dict:
        return {"order": self.order, "n_dofs": int(self.n_dofs)}


def space(mesh: PeriodicMesh, order: int):
    """The space of a run: :class:`TensorSpace` on tensor meshes, :class:`AssembledSpace` on a
    mesh file."""
    if mesh.is_tensor:
        return TensorSpace(mesh.axes, order)
    return AssembledSpace(mesh, order)


def tensor_points(locs) -> np.ndarray:
    """(dim, N) coordinates of the tensor grid of the 1D node locations ``locs``, in C order."""
    grids = np.meshgrid(*locs, indexing="ij")
    return np.stack([g.ravel() for g in grids])
