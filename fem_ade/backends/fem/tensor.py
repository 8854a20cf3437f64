"""Spectral elements of order p on periodic tensor meshes: the space, its operators applied by
sum factorization, and interpolation (the spectral-element method: Deville, Fischer & Mund,
*High-Order Methods for Incompressible Fluid Flow*, 2002).

A tensor mesh is a product of 1D periodic meshes (uniform or graded). On each 1D mesh of n
cells, the Lagrange element of order p with nodes at the Gauss–Lobatto–Legendre (GLL) points
of every cell (:mod:`fem_ade.backends.fem.gll`) has N = p·n periodic nodes, a diagonal mass ``w``
(the
GLL weights) and a banded stiffness K₁ (bandwidth p, exact). With the same GLL rule on the
hexahedra (quadrilaterals), the d-dimensional mass is the outer product W = w₀ ⊗ w₁ ⊗ w₂ and

    K = K₁⁽⁰⁾ ⊗ W⁽¹⁾ ⊗ W⁽²⁾ + W⁽⁰⁾ ⊗ K₁⁽¹⁾ ⊗ W⁽²⁾ + W⁽⁰⁾ ⊗ W⁽¹⁾ ⊗ K₁⁽²⁾
      = W · Σₐ (Lₐ along axis a),     Lₐ = diag(wₐ)⁻¹ K₁⁽ᵃ⁾,

so K x costs three 1D banded products along the grid lines (sum factorization: no 3D matrix
is formed, memory O(nodes)), and μ = W⁻¹Kφ — the mixed form's −Δφ — is Σₐ Lₐφ, with no
division. p = 1 is the trapezoid rule (on a uniform mesh the 7-point Laplacian, 5-point in 2D).

DOFs are the tensor grid of the 1D nodes in C order (the last axis fastest).

Axes need not be periodic: a :class:`BoundedAxis` has natural (zero-flux) ends and p·n + 1
nodes, and with ``radial=True`` carries the measure 2πr dr of the axisymmetric geometry
(docs/model.md §11), with Gauss–Lobatto–Jacobi (0, 1) points in its cell at the axis r = 0.
The product structure, and so everything below, is the same for any mix of axes.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import scipy.sparse as sp

from fem_ade.backends.fem import gll


def _assemble(Ke: np.ndarray, dofs: np.ndarray, size: int) -> sp.csr_matrix:
    """Σ_e of the cell matrices ``Ke`` (n, p + 1, p + 1) on the nodes ``dofs`` (n, p + 1)."""
    k = dofs.shape[1]
    rows = np.repeat(dofs, k, axis=1).ravel()
    cols = np.tile(dofs, (1, k)).ravel()
    K = sp.csr_matrix((Ke.ravel(), (rows, cols)), shape=(size, size))
    K.sum_duplicates()
    K.sort_indices()
    return K


def _interpolation(B: np.ndarray, dofs: np.ndarray, size: int) -> sp.csr_matrix:
    """(P, N): the points' rows ``B`` (P, p + 1) of their cells' basis on the nodes ``dofs``
    (P, p + 1)."""
    rows = np.repeat(np.arange(len(B)), B.shape[1])
    M = sp.csr_matrix((B.ravel(), (rows, dofs.ravel())), shape=(len(B), size))
    M.sum_duplicates()
    return M


class Axis:
    """One periodic axis: cell vertices 0 = x₀ < … < xₙ = L, GLL nodes of order p per cell.

    Node e·p + j (j = 0..p − 1) is the j-th GLL point of cell e; node N ≡ node 0.
    """

    periodic = True
    radial = False

    def __init__(self, vertices, order: int):
        self.vertices = np.asarray(vertices, dtype=float)
        self.order = p = int(order)
        self.cells = n = len(self.vertices) - 1
        self.h = np.diff(self.vertices)
        self.length = float(self.vertices[-1] - self.vertices[0])
        self.size = p * n
        xi, w = gll.points_weights(p)
        nodes = self.vertices[:-1, None] + 0.5 * self.h[:, None] * (xi[None, :-1] + 1.0)
        self.nodes = nodes.ravel()
        weights = np.zeros(self.size)
        np.add.at(weights, self.element_dofs, 0.5 * self.h[:, None] * w[None, :])
        self.weights = weights

    @functools.cached_property
    def element_dofs(self) -> np.ndarray:
        """(n, p + 1): the nodes of each cell (the last one is the next cell's first)."""
        p = self.order
        return (p * np.arange(self.cells)[:, None] + np.arange(p + 1)[None, :]) % self.size

    @functools.cached_property
    def stiffness(self) -> sp.csr_matrix:
        """K₁ = Σ_e (2/h_e) Dᵀ diag(w) D, periodic (csr, N × N)."""
        Ke = (2.0 / self.h)[:, None, None] * gll.stiffness(self.order)[None]
        return _assemble(Ke, self.element_dofs, self.size)

    @functools.cached_property
    def laplacian(self) -> sp.csr_matrix:
        """L = diag(w)⁻¹ K₁: the 1D −d²/dx² of the mixed form (μ = Σₐ Lₐ φ)."""
        return sp.diags(1.0 / self.weights) @ self.stiffness

    @property
    def gaps(self) -> np.ndarray:
        """Distances between consecutive nodes (the last to the periodic image of the first)."""
        return np.diff(np.append(self.nodes, self.vertices[0] + self.length))

    def interpolation(self, y) -> sp.csr_matrix:
        """(len(y), N): the values at the points y (taken modulo the period) of the piecewise
        polynomial interpolant of nodal values — exact to the element's order."""
        p = self.order
        y = np.asarray(y, dtype=float) - self.vertices[0]
        y = np.mod(y, self.length)
        cell = np.clip(np.searchsorted(self.vertices - self.vertices[0], y, side="right") - 1,
                       0, self.cells - 1)
        xi = 2.0 * (y - (self.vertices[cell] - self.vertices[0])) / self.h[cell] - 1.0
        B = gll.interpolation_matrix(p, np.clip(xi, -1.0, 1.0))  # (len(y), p + 1)
        return _interpolation(B, self.element_dofs[cell], self.size)

    def lor(self) -> Axis:
        """The low-order refined axis: p = 1 on this axis' nodes (MFEM's LOR)."""
        return Axis(np.append(self.nodes, self.vertices[0] + self.length), 1)


class BoundedAxis:
    """One axis [x₀, xₙ] with natural (zero-flux) ends: cells x₀ < … < xₙ, GLL nodes of order
    p per cell, N = p·n + 1 nodes (node e·p + j is the j-th point of cell e).

    ``radial=True`` (x₀ = 0 is the axis of revolution, x = r): the 1D measure is 2πr dr, so
    that with a plain axis along z the 2D integrals are those of the 3D body of revolution
    (docs/model.md §11). Its weights and stiffness are

        cells e ≥ 1:  wⱼ = 2π (hₑ/2) ŵⱼ rⱼ,        Kₑ = 2π (2/hₑ) Dᵀ diag(ŵ r) D
        the cell at the axis:  wⱼ = 2π (h₀/2)² ρⱼ,   K₀ = 2π Dᵀ_J diag(ρ) D_J

    (ŵ the GLL weights; ρ, D_J the Gauss–Lobatto–Jacobi (0, 1) weights and derivative
    matrix, :func:`fem_ade.backends.fem.gll.jacobi_points_weights`, whose nodes the axis cell uses):
    r = h₀(1 + ξ)/2 there, so ∫ f r dr = (h₀/2)² ∫ f (1 + ξ) dξ, which GLJ integrates with a
    positive weight at r = 0 — the GLL rule applied to f·r gives the axis node the weight 0,
    a singular mass. Both stiffnesses are exact (degree 2p − 1 in ξ); the mass is the
    rule's, diagonal, as on the other axes.
    """

    periodic = False

    def __init__(self, vertices, order: int, radial: bool = False):
        self.vertices = np.asarray(vertices, dtype=float)
        self.order = p = int(order)
        self.radial = bool(radial)
        self.cells = n = len(self.vertices) - 1
        if n < 1 or np.any(np.diff(self.vertices) <= 0):
            raise ValueError("the cell vertices of an axis must increase")
        if self.radial and self.vertices[0] != 0.0:
            raise ValueError(f"a radial axis starts on the axis r = 0, got {self.vertices[0]}")
        self.h = np.diff(self.vertices)
        self.length = float(self.vertices[-1] - self.vertices[0])
        self.size = p * n + 1
        xi, w = gll.points_weights(p)
        nodes = self.vertices[:-1, None] + 0.5 * self.h[:, None] * (xi[None, :] + 1.0)
        if self.radial:
            xj, _ = gll.jacobi_points_weights(p)
            nodes[0] = 0.5 * self.h[0] * (xj + 1.0)
        self.nodes = np.append(nodes[:, :-1].ravel(), self.vertices[-1])
        weights = np.zeros(self.size)
        np.add.at(weights, self.element_dofs, self._cell_weights())
        self.weights = weights

    def cell_xi(self, e: int) -> np.ndarray:
        """The reference points of cell e: GLJ in the radial axis' first cell, else GLL."""
        if self.radial and e == 0:
            return gll.jacobi_points_weights(self.order)[0]
        return gll.points_weights(self.order)[0]

    def _cell_weights(self) -> np.ndarray:
        """(n, p + 1): each cell's quadrature weights of the axis' measure at its nodes."""
        _, w = gll.points_weights(self.order)
        cw = 0.5 * self.h[:, None] * w[None, :]
        if self.radial:
            cw = 2.0 * np.pi * cw * self.nodes[self.element_dofs]
            _, rho = gll.jacobi_points_weights(self.order)
            cw[0] = 2.0 * np.pi * (0.5 * self.h[0]) ** 2 * rho
        return cw

    @functools.cached_property
    def element_dofs(self) -> np.ndarray:
        """(n, p + 1): the nodes of each cell (the last one is the next cell's first)."""
        p = self.order
        return p * np.arange(self.cells)[:, None] + np.arange(p + 1)[None, :]

    @functools.cached_property
    def derivative(self) -> sp.csr_matrix:
        """d/dx at the nodes of the piecewise polynomial of nodal values: each cell's
        derivative (GLL, or GLJ in the radial axis' first cell), the mean of the two cells'
        at a shared node; csr, N × N (exact for polynomials of degree ≤ p)."""
        dofs = self.element_dofs
        rows, cols, vals = [], [], []
        for e in range(self.cells):
            D = gll.derivative_matrix_at(self.cell_xi(e)) * (2.0 / self.h[e])
            i, j = np.meshgrid(dofs[e], dofs[e], indexing="ij")
            rows.append(i.ravel())
            cols.append(j.ravel())
            vals.append(D.ravel())
        A = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(self.size, self.size))
        shared = np.bincount(dofs.ravel(), minlength=self.size)  # 1, or 2 between cells
        return sp.diags(1.0 / shared) @ A

    @functools.cached_property
    def stiffness(self) -> sp.csr_matrix:
        """K₁ = Σ_e ∫ ℓ′ᵢ ℓ′ⱼ (the axis' measure), exact (class docstring); csr, N × N."""
        p, dofs = self.order, self.element_dofs
        D = gll.derivative_matrix(p)
        _, w = gll.points_weights(p)
        if self.radial:
            r = self.nodes[dofs]  # (n, p + 1)
            Ke = 2.0 * np.pi * (2.0 / self.h)[:, None, None] * np.einsum(
                "ki,ek,kj->eij", D, w[None, :] * r, D)
            xj, rho = gll.jacobi_points_weights(p)
            DJ = gll.derivative_matrix_at(xj)
            Ke[0] = 2.0 * np.pi * DJ.T @ (rho[:, None] * DJ)
        else:
            Ke = (2.0 / self.h)[:, None, None] * gll.stiffness(p)[None]
        Ke = 0.5 * (Ke + np.transpose(Ke, (0, 2, 1)))
        return _assemble(Ke, dofs, self.size)

    @functools.cached_property
    def laplacian(self) -> sp.csr_matrix:
        """L = diag(w)⁻¹ K₁: the 1D part of −Δ in weak form (the radial one: −(1/r)(r u′)′)."""
        return sp.diags(1.0 / self.weights) @ self.stiffness

    @property
    def gaps(self) -> np.ndarray:
        """Distances between consecutive nodes."""
        return np.diff(self.nodes)

    def interpolation(self, y) -> sp.csr_matrix:
        """(len(y), N): the values at the points y (clipped to the axis) of the piecewise
        polynomial interpolant of nodal values — exact to the element's order."""
        p = self.order
        y = np.clip(np.asarray(y, dtype=float), self.vertices[0], self.vertices[-1])
        cell = np.clip(np.searchsorted(self.vertices, y, side="right") - 1, 0, self.cells - 1)
        xi = np.clip(2.0 * (y - self.vertices[cell]) / self.h[cell] - 1.0, -1.0, 1.0)
        B = np.empty((len(y), p + 1))
        first = cell == 0
        if self.radial and first.any():
            B[first] = gll.interpolation_matrix_at(self.cell_xi(0), xi[first])
            B[~first] = gll.interpolation_matrix(p, xi[~first])
        else:
            B[:] = gll.interpolation_matrix(p, xi)
        return _interpolation(B, self.element_dofs[cell], self.size)

    def lor(self) -> BoundedAxis:
        """The low-order refined axis: p = 1 on this axis' nodes."""
        return BoundedAxis(self.nodes, 1, radial=self.radial)


#: 1D operators of axes with more nodes than this are applied as sparse matrices (measured,
#: axisymmetric p = 4: at 257 × 449 nodes the dense products take 9× the sparse ones' time)
DENSE_LIMIT = 128


def along(A, X: np.ndarray, axis: int) -> np.ndarray:
    """A (dense, or sparse) applied along ``axis`` of X: one BLAS-3 product, no transposes.

    Dense 1D operators are used even where they are banded: at 64 nodes per axis one product
    along the middle axis takes 0.8 ms dense against 2.9 ms as a scipy sparse product after
    a transpose (measured, 3D, p = 4)."""
    if sp.issparse(A):
        if axis == X.ndim - 1:  # the last axis: X (pre, N) Aᵀ = (A Xᵀ)ᵀ
            pre = X.reshape(-1, X.shape[-1])
            return np.asarray((A @ pre.T).T).reshape(X.shape[:-1] + (A.shape[0],))
        Xm = np.moveaxis(X, axis, 0)
        Y = A @ Xm.reshape(Xm.shape[0], -1)
        return np.moveaxis(np.asarray(Y).reshape((A.shape[0],) + Xm.shape[1:]), 0, axis)
    pre = math.prod(X.shape[:axis])
    post = math.prod(X.shape[axis + 1:])
    N = X.shape[axis]
    out_shape = X.shape[:axis] + (A.shape[0],) + X.shape[axis + 1:]
    if post == 1:
        return (X.reshape(pre, N) @ A.T).reshape(out_shape)
    if pre == 1:
        return (A @ X.reshape(N, post)).reshape(out_shape)
    return np.matmul(A, X.reshape(pre, N, post)).reshape(out_shape)


class TensorSpace:
    """The order-p spectral-element space on a periodic tensor mesh (``axes``: the vertices of
    each axis). Provides what the step needs: the nodal weights W (the diagonal mass), K as a
    matrix-free operator (``K @ x``), μ = W⁻¹Kφ, the DOF coordinates, and interpolation."""

    assembly = "tensor"
    basis = None

    def __init__(self, axes, order: int):
        """``axes``: per axis, the cell vertices of a periodic :class:`Axis` of ``order``, or
        an axis object (:class:`Axis`, :class:`BoundedAxis`) of that order."""
        self.order = int(order)
        self.axes = [a if isinstance(a, (Axis, BoundedAxis)) else Axis(a, order) for a in axes]
        if any(a.order != self.order for a in self.axes):
            raise ValueError("the axes of a tensor space must have its order")
        self.dim = len(self.axes)
        self.shape = tuple(a.size for a in self.axes)
        self.n_dofs = int(np.prod(self.shape))
        self.weights = functools.reduce(np.multiply.outer, [a.weights for a in self.axes]).ravel()
        self.K = StiffnessOperator(self)

    @functools.cached_property
    def doflocs(self) -> np.ndarray:
        """(dim, N) coordinates of the DOFs (C order)."""
        grids = np.meshgrid(*[a.nodes for a in self.axes], indexing="ij")
        return np.stack([g.ravel() for g in grids])

    @property
    def node_axes(self) -> list[np.ndarray]:
        return [a.nodes for a in self.axes]

    @property
    def h_max(self) -> float:
        """The largest distance between neighbouring nodes along an axis."""
        return float(max(a.gaps.max() for a in self.axes))

    @property
    def circulant(self) -> bool:
        """True when every 1D operator is circulant — p = 1 on a uniform mesh (for p = 2 the
        nodes are equally spaced too, but their weights alternate): then the real FFT
        diagonalizes them."""
        return self.order == 1 and all(
            a.periodic and np.allclose(a.gaps, a.gaps[0], rtol=1e-12, atol=0)
            for a in self.axes)

    @functools.cached_property
    def _dense_laplacians(self) -> list:
        """The 1D Lₐ as dense arrays up to :data:`DENSE_LIMIT` nodes (one BLAS product along
        the axis is faster than a sparse one there), sparse beyond (banded: O(pN) per line
        against O(N²))."""
        return [np.ascontiguousarray(a.laplacian.toarray()) if a.size <= DENSE_LIMIT
                else a.laplacian.tocsr() for a in self.axes]

    def laplacian(self, x: np.ndarray) -> np.ndarray:
        """μ = W⁻¹Kx = Σₐ Lₐ x (sum factorization; x may be a stack (k, N))."""
        x = np.asarray(x)
        stack = x.ndim == 2
        X = np.reshape(x, ((x.shape[0],) if stack else ()) + self.shape)
        off = 1 if stack else 0
        Ls = self._dense_laplacians
        out = along(Ls[0], X, off)
        for a in range(1, self.dim):
            out += along(Ls[a], X, a + off)
        return out.reshape(x.shape)

    def preconditioner_stiffness(self) -> sp.csr_matrix:
        """K̃ for AMG: K itself for p = 1, the low-order refined K for p > 1 (assembled)."""
        return self.lor().assembled_stiffness()

    def assembled_stiffness(self) -> sp.csr_matrix:
        """K as a sparse matrix (the AMG path): Σₐ ⊗ (K₁ on axis a, diag(w) elsewhere)."""
        K = None
        for a in range(self.dim):
            mats = [self.axes[b].stiffness if b == a else sp.diags(self.axes[b].weights)
                    for b in range(self.dim)]
            term = functools.reduce(lambda x, y: sp.kron(x, y, format="csr"), mats)
            K = term if K is None else K + term
        K = K.tocsr()
        K.sort_indices()
        return K

    def lor(self) -> TensorSpace:
        """The low-order refined space: p = 1 on the same nodes (spectrally equivalent to this
        one; its M + sK is what AMG preconditions for p > 1)."""
        if self.order == 1:
            return self
        return TensorSpace([a.lor() for a in self.axes], 1)

    def interpolate_to(self, points_per_axis) -> np.ndarray:
        """(values) → the interpolant on the tensor grid of the given 1D points, as a function
        of a nodal vector: returns a callable."""
        mats = [a.interpolation(y) for a, y in zip(self.axes, points_per_axis, strict=True)]

        def apply(x):
            X = np.reshape(x, self.shape)
            for a, B in enumerate(mats):
                X = along(B, X, a)
            return X

        return apply

    def describe(self) -> dict:
        return {"order": self.order, "nodes_per_axis": list(self.shape),
                "node_gap_max": self.h_max,
                "node_gap_min": float(min(a.gaps.min() for a in self.axes))}


class StiffnessOperator:
    """K of a :class:`TensorSpace`, matrix-free: ``K @ x`` = W·Σₐ Lₐx; ``diagonal()``."""

    def __init__(self, space: TensorSpace):
        self.space = space
        self.shape = (space.n_dofs, space.n_dofs)

    def __matmul__(self, x):
        return self.space.weights * self.space.laplacian(x)

    def dot(self, x):
        return self @ x

    def diagonal(self) -> np.ndarray:
        s = self.space
        parts = [a.stiffness.diagonal() / a.weights for a in s.axes]
        total = parts[0].reshape((-1,) + (1,) * (s.dim - 1))
        for a in range(1, s.dim):
            shape = [1] * s.dim
            shape[a] = -1
            total = total + parts[a].reshape(shape)
        return s.weights * np.broadcast_to(total, s.shape).ravel()
