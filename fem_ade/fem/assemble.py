"""The constant matrices of SPEC §5 — mass M and stiffness K — assembled once per run.

Tensor meshes (uniform, graded): M and K are Kronecker products / sums of 1D periodic Q1 or Q2
matrices, M = M₀⊗M₁⊗M₂ and K = K₀⊗M₁⊗M₂ + M₀⊗K₁⊗M₂ + M₀⊗M₁⊗K₂. For box cells this is the
exact Galerkin matrix (a tensor-product basis on a tensor-product cell), tested against
scikit-fem assembly in ``tests/test_fem_laplacian.py``. DOFs are then ordered lexicographically
(C order over the axes). Other meshes are assembled by scikit-fem (:mod:`fem_ade.fem.forms`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from . import forms
from .mesh import PeriodicMesh

#: 1D reference element matrices on [0, 1] (vertex, [midpoint,] vertex)
_MASS_1D = {
    1: np.array([[2.0, 1.0], [1.0, 2.0]]) / 6.0,
    2: np.array([[4.0, 2.0, -1.0], [2.0, 16.0, 2.0], [-1.0, 2.0, 4.0]]) / 30.0,
}
_STIFF_1D = {
    1: np.array([[1.0, -1.0], [-1.0, 1.0]]),
    2: np.array([[7.0, -8.0, 1.0], [-8.0, 16.0, -8.0], [1.0, -8.0, 7.0]]) / 3.0,
}


@dataclass
class Operators:
    """M, K, the nodal quadrature weights w = M·1 and the DOF coordinates (dim, N)."""

    M: sp.csr_matrix
    K: sp.csr_matrix
    weights: np.ndarray
    doflocs: np.ndarray
    order: int
    assembly: str  # "kron" or "skfem"
    basis: object = None  # the scikit-fem basis (skfem assembly only)

    @property
    def n_dofs(self) -> int:
        return self.M.shape[0]


def periodic_1d(x: np.ndarray, order: int):
    """1D periodic mass, stiffness and DOF coordinates on nodes x₀ < … < xₙ (xₙ ≡ x₀).

    Q1: DOF j is node j (j < n). Q2: DOF 2j is node j, DOF 2e+1 the midpoint of cell e.
    """
    n = len(x) - 1
    h = np.diff(x)
    ndof = order * n
    loc = np.arange(order + 1)
    dofs = (order * np.arange(n)[:, None] + loc[None, :]) % ndof  # (n, order+1)
    rows = np.repeat(dofs, order + 1, axis=1).ravel()
    cols = np.tile(dofs, (1, order + 1)).ravel()
    Me = h[:, None, None] * _MASS_1D[order][None]
    Ke = (1.0 / h)[:, None, None] * _STIFF_1D[order][None]
    M = sp.csr_matrix((Me.ravel(), (rows, cols)), shape=(ndof, ndof))
    K = sp.csr_matrix((Ke.ravel(), (rows, cols)), shape=(ndof, ndof))
    if order == 1:
        locs = x[:-1].copy()
    else:
        locs = np.empty(ndof)
        locs[0::2] = x[:-1]
        locs[1::2] = 0.5 * (x[:-1] + x[1:])
    return M, K, locs


def tensor_points(locs) -> np.ndarray:
    """(dim, N) coordinates of the tensor grid of the 1D node locations ``locs``, in C order:
    the DOF order of the Kronecker assembly."""
    grids = np.meshgrid(*locs, indexing="ij")
    return np.stack([g.ravel() for g in grids])


def kron_operators(axes, order: int) -> Operators:
    """Kronecker assembly on a tensor mesh (exact for box cells)."""
    ones = [periodic_1d(np.asarray(a, float), order) for a in axes]
    Ms = [o[0] for o in ones]
    Ks = [o[1] for o in ones]

    def kron_all(mats):
        out = mats[0]
        for m in mats[1:]:
            out = sp.kron(out, m, format="csr")
        return out

    M = kron_all(Ms)
    K = None
    for d in range(len(axes)):
        term = kron_all([Ks[k] if k == d else Ms[k] for k in range(len(axes))])
        K = term if K is None else K + term
    doflocs = tensor_points([o[2] for o in ones])
    M = M.tocsr()
    K = K.tocsr()
    M.sort_indices()
    K.sort_indices()
    weights = np.asarray(M.sum(axis=1)).ravel()
    return Operators(M, K, weights, doflocs, order, "kron")


def element(dim: int, order: int):
    """The scikit-fem Lagrange element: Q1/Q2 on quads (2D) or hexahedra (3D)."""
    from skfem import ElementHex1, ElementHex2, ElementQuad1, ElementQuad2

    return {(2, 1): ElementQuad1, (2, 2): ElementQuad2,
            (3, 1): ElementHex1, (3, 2): ElementHex2}[(dim, order)]()


def skfem_operators(mesh: PeriodicMesh, order: int) -> Operators:
    """scikit-fem assembly of ``forms.mass`` and ``forms.laplace`` on the periodic mesh."""
    from skfem import Basis

    basis = Basis(mesh.skfem_mesh(), element(mesh.dim, order))
    M = forms.mass.assemble(basis).tocsr()
    K = forms.laplace.assemble(basis).tocsr()
    weights = np.asarray(M.sum(axis=1)).ravel()
    return Operators(M, K, weights, np.asarray(basis.doflocs), order, "skfem", basis)


def operators(mesh: PeriodicMesh, order: int, assembly: str = "auto") -> Operators:
    """Kronecker assembly for tensor meshes, scikit-fem otherwise (or as ``assembly`` says)."""
    if order not in (1, 2):
        raise ValueError(f"order must be 1 or 2, got {order}")
    if assembly == "auto":
        assembly = "kron" if mesh.is_tensor else "skfem"
    if assembly == "kron":
        if not mesh.is_tensor:
            raise ValueError("Kronecker assembly needs a tensor mesh")
        return kron_operators(mesh.axes, order)
    return skfem_operators(mesh, order)
