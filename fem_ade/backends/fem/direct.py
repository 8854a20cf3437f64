"""Direct solves of the Hessian on a 2D tensor space (the axisymmetric geometry): the mixed
(φ, μ)-form of the operator, a nested-dissection ordering, a sparse LU, and the low-rank
borders (constraints, pins, rank-one terms) by a Schur complement (docs/model.md §13).

Why mixed. The Hessian of E_h at a state (:meth:`fem_ade.backends.fem.step.MixedStep.
hessian_coefficients`) is

    H = κε K W⁻¹K + K diag(α) + diag(α) K + W diag(γ) + c₀ K   (+ Σ σᵢ bᵢbᵢᵀ),

whose κε K W⁻¹K couples every two nodes of neighbouring cells: at order 8 a row has ~130
entries, and a sparse LU of it fills badly (measured, the prolate at ε = 0.005, 66265 nodes,
one thread: 56 s and 2.4e8 entries with nested dissection, 25–37 s with SuperLU's own
orderings). With q = κε W⁻¹K v + α v as a second unknown it is the symmetric 2 × 2 block
operator of the stencil of K,

    [ W diag(γ − α²/κε) + c₀ K     K + diag(α) W/κε ] [v]   [b]
    [ K + diag(α) W/κε             −W/κε            ] [q] = [0],

whose Schur complement on v is H exactly (eliminate q). On a tensor mesh K = K_r ⊗ W_z +
W_r ⊗ K_z couples a node only along its grid lines within its cells, so a grid line on a cell
boundary separates the grid: :func:`nested_dissection` orders the nodes by such lines
(George 1973), both unknowns of a node together, and the permuted matrix is factored in that
order (:class:`Factorization`): by MKL's PARDISO as L D Lᵀ (:mod:`fem_ade.backends.fem.
pardiso`: 0.12 s of analysis, 0.40 s, 1.6e7 entries there) where MKL is installed, else by
SuperLU as L U without pivoting (a symmetric order keeps its fill: 1.05 s, 3.0e7 entries).

PARDISO's D and, without pivoting, SuperLU's U = D Lᵀ carry the inertia of the matrix
(Sylvester): the mixed matrix has the N negative directions of its −W/κε block and those of
H − σP; :attr:`HessianFactor.negative` counts the latter — the number of eigenvalues of
H v = λ P v below σ, with no eigen-solve.

Borders: :class:`Bordered` solves [[F + U S Uᵀ, C], [Cᵀ, 0]] for a factored F, a few dense
columns U (the rank-one terms, S = diag(σ)) and C (constraints, pins) by their Schur
complement — k + 1 solves with F once, then a small dense system per right side.
"""

from __future__ import annotations

import functools
import os

import numpy as np
import scipy.sparse as sp

#: the leaves of the nested dissection: boxes of at most this many cells per side are
#: ordered as they lie. Measured (the mixed P of the prolate at ε = 0.005, order 8, 66265
#: nodes, one thread): 1 cell: 0.93 s, 3.0e7 entries; 2: 1.72 s, 5.0e7; 4: 4.4 s, 9.0e7 (a
#: line inside a cell separates nothing: K couples a cell's nodes along its rows)
LEAF_CELLS = 1


@functools.lru_cache(maxsize=8)
def nested_dissection(shape: tuple[int, int], order: int) -> np.ndarray:
    """A nested-dissection order of the nodes of a 2D tensor grid (C order, ``shape`` nodes
    per axis, cells of ``order`` + 1 nodes per side): each box is split by the grid line at
    the cell boundary nearest its middle across its longer side, the two halves ordered
    first (recursively), the line last. Returns the permutation (new position → node),
    read-only (kept: a branch factors the same grid at every Newton step, 0.03 s each at
    66265 nodes)."""
    nr, nz = tuple(shape)
    p = int(order)
    index = np.arange(nr * nz).reshape(nr, nz)
    leaf = LEAF_CELLS * p + 1
    out: list[np.ndarray] = []
    stack = [(0, nr, 0, nz, False)]
    while stack:  # (an explicit stack: the tree is walked in the recursion's order)
        r0, r1, z0, z1, done = stack.pop()
        if done:  # the separator of this box, after both halves
            out.append(_separator(index, r0, r1, z0, z1, p))
            continue
        split = _split(r0, r1, z0, z1, p, leaf)
        if split is None:
            out.append(index[r0:r1, z0:z1].ravel())
            continue
        axis, s = split
        if axis == 0:
            halves = [(r0, s, z0, z1), (s + 1, r1, z0, z1)]
        else:
            halves = [(r0, r1, z0, s), (r0, r1, s + 1, z1)]
        stack.append((r0, r1, z0, z1, True))
        for box in reversed(halves):
            stack.append((*box, False))
    perm = np.concatenate(out)
    if perm.size != nr * nz:
        raise AssertionError("the nested dissection lost or repeated nodes")
    perm.flags.writeable = False
    return perm


def _split(r0, r1, z0, z1, p, leaf):
    """(axis, index) of the separating grid line of a box, or None for a leaf."""
    for axis, (a, b) in sorted(((0, (r0, r1)), (1, (z0, z1))), key=lambda t: t[1][0] - t[1][1]):
        if b - a <= leaf:
            continue
        middle = 0.5 * (a + b - 1)
        lines = [s for s in range(a + 1, b - 1) if s % p == 0]
        if lines:
            return axis, min(lines, key=lambda s: abs(s - middle))
    return None


def _separator(index, r0, r1, z0, z1, p):
    split = _split(r0, r1, z0, z1, p, LEAF_CELLS * p + 1)
    axis, s = split
    return index[s, z0:z1].ravel() if axis == 0 else index[r0:r1, s].ravel()


def mixed_matrix(K: sp.spmatrix, w: np.ndarray, ke: float, alpha, gamma, c0: float,
                 sigma: float = 0.0, P: tuple[float, float] | None = None) -> sp.csc_matrix:
    """The mixed form of H − σP (module docstring) as a (2N, 2N) sparse matrix, unknowns
    (v, q) in blocks; ``P`` = (a, c) of the bulk preconditioner P = aW + cK + κε KW⁻¹K (its
    κε KW⁻¹K shares H's, so H − σP keeps the form with κε → (1 − σ)κε)."""
    w = np.asarray(w, dtype=float)
    alpha = np.broadcast_to(np.asarray(alpha, dtype=float), w.shape)
    gamma = np.broadcast_to(np.asarray(gamma, dtype=float), w.shape)
    if sigma:
        a, c = P
        ke_s = (1.0 - sigma) * ke
        gamma = gamma - sigma * a
        c0 = c0 - sigma * c
    else:
        ke_s = ke
    if ke_s <= 0:
        raise ValueError(f"shift {sigma} leaves no fourth-order term (1 - sigma <= 0)")
    W = sp.diags(w)
    top = W @ sp.diags(gamma - alpha * alpha / ke_s) + c0 * K
    off = K + sp.diags(alpha * w / ke_s)
    return sp.bmat([[top, off], [off, -W / ke_s]], format="csc")


#: the sparse code of the factorizations: ``FEM_ADE_SPARSE`` = ``superlu`` (scipy's), ``pardiso``
#: (MKL's, :mod:`fem_ade.backends.fem.pardiso`: 0.52 s with its analysis where SuperLU takes
#: 1.05 s, measured there) or ``auto`` (the default: PARDISO where MKL's runtime library is
#: installed, else SuperLU)
SPARSE_ENV, SPARSE_CODES = "FEM_ADE_SPARSE", ("auto", "superlu", "pardiso")


def sparse_code() -> str:
    """The sparse code the factorizations use now (:data:`SPARSE_ENV`); ModelError for an
    unknown one or for ``pardiso`` without MKL."""
    from fem_ade.backends.fem import pardiso
    from fem_ade.model.params import ModelError

    code = os.environ.get(SPARSE_ENV, "auto").strip().lower() or "auto"
    if code not in SPARSE_CODES:
        raise ModelError(f"{SPARSE_ENV} must be one of {', '.join(SPARSE_CODES)}, got {code!r}")
    if code == "auto":
        return "pardiso" if pardiso.available() else "superlu"
    if code == "pardiso" and not pardiso.available():
        raise ModelError(f"{SPARSE_ENV}=pardiso needs MKL's runtime library: pip install mkl "
                         "(or the project's 'fast' extra)")
    return code


class SuperLU:
    """A sparse LU of a matrix already in its symmetric fill-reducing order, without
    pivoting (``permc_spec="NATURAL"``): ``solve``, ``negative`` (the negative pivots: U =
    D Lᵀ), ``fill``."""

    def __init__(self, A: sp.spmatrix):
        from scipy.sparse.linalg import splu

        n = A.shape[0]
        self.lu = splu(sp.csc_matrix(A), permc_spec="NATURAL", diag_pivot_thresh=0.0,
                       options={"SymmetricMode": True})
        if not (np.array_equal(self.lu.perm_r, np.arange(n))
                and np.array_equal(self.lu.perm_c, np.arange(n))):
            raise ArithmeticError("the factorization pivoted: its inertia is not the pivots'")

    @functools.cached_property
    def negative(self) -> int:
        d = self.lu.U.diagonal()  # (U as a matrix: a copy of the factor, made on demand)
        if not np.all(np.isfinite(d)) or np.any(d == 0.0):
            raise ArithmeticError("a zero pivot: the matrix is singular in this order")
        return int(np.count_nonzero(d < 0))

    @property
    def fill(self) -> int:
        return int(self.lu.nnz)

    def solve(self, b: np.ndarray) -> np.ndarray:
        return self.lu.solve(np.ascontiguousarray(b))


class Factorization:
    """A symmetric matrix factored in a symmetric fill-reducing order ``perm`` by the sparse
    code :func:`sparse_code` chooses (``code`` to choose it here): PARDISO's L D Lᵀ, or
    SuperLU's L U without pivoting — SuperLU too where PARDISO had to perturb a pivot.
    ``solve(b)``; ``negative``: the count of negative eigenvalues (the inertia, module
    docstring); ``code``: the code that factored it."""

    def __init__(self, A: sp.spmatrix, perm: np.ndarray, code: str | None = None):
        from fem_ade.backends.fem import pardiso

        self.perm = np.asarray(perm)
        self.n = A.shape[0]
        Ap = sp.csc_matrix(A)[self.perm][:, self.perm]
        self.code = code or sparse_code()
        if self.code not in ("pardiso", "superlu"):
            raise ValueError(f"a sparse code is 'pardiso' or 'superlu', got {self.code!r}")
        if self.code == "pardiso":
            try:
                self.lu = pardiso.LDL(Ap)
            except pardiso.Perturbed:
                self.code = "superlu"
        if self.code == "superlu":
            self.lu = SuperLU(Ap)

    @property
    def negative(self) -> int:
        """The count of negative eigenvalues (Sylvester)."""
        return self.lu.negative

    @property
    def fill(self) -> int:
        """The entries of the factors."""
        return self.lu.fill

    def solve(self, b: np.ndarray) -> np.ndarray:
        """A⁻¹b for b of shape (n,) or (n, k)."""
        b = np.asarray(b, dtype=float)
        x = np.empty_like(b)
        x[self.perm] = self.lu.solve(b[self.perm])
        return x


def mixed_order(perm_nodes: np.ndarray) -> np.ndarray:
    """The order of the mixed unknowns (v, q) from a node order: both of a node together."""
    N = perm_nodes.size
    return np.column_stack([perm_nodes, perm_nodes + N]).ravel()


def node_order(shape: tuple[int, int], order: int, free: np.ndarray | None = None):
    """The nested-dissection order of a grid's nodes, or of its ``free`` ones (a Dirichlet
    line removed: the axis, for m ≥ 1) numbered 0 … len(free) − 1."""
    nodes = nested_dissection(tuple(shape), int(order))
    if free is None:
        return nodes
    n = shape[0] * shape[1]
    position = -np.ones(n, dtype=int)
    position[free] = np.arange(len(free))
    kept = position[nodes]
    return kept[kept >= 0]


class HessianFactor:
    """H − σP in mixed form (module docstring), factored: ``solve(b)`` = (H − σP)⁻¹ b on
    the primal unknowns; ``negative``: the eigenvalues of H v = λ P v below σ (the inertia of
    the mixed matrix less its N negative directions of −W/κε). ``K``, ``w`` and the
    coefficients on the nodes ordered by ``nodes`` (:func:`node_order`)."""

    def __init__(self, K, w, ke: float, coefficients: dict, nodes: np.ndarray,
                 sigma: float = 0.0, P: tuple[float, float] | None = None):
        w = np.asarray(w, dtype=float)
        self.N = w.size
        A = mixed_matrix(K, w, ke, coefficients["alpha"], coefficients["gamma"],
                         coefficients["c0"], sigma, P)
        self.factor = Factorization(A, mixed_order(nodes))

    @property
    def negative(self) -> int:
        """The eigenvalues of H v = λ P v below σ: the mixed matrix's negative pivots less
        the N of its −W/κε block."""
        return self.factor.negative - self.N

    @property
    def fill(self) -> int:
        return self.factor.fill

    def solve(self, b: np.ndarray) -> np.ndarray:
        """(H − σP)⁻¹ b (the mixed system with [b; 0], its v part); b (N,) or (N, k)."""
        b = np.asarray(b, dtype=float)
        rhs = np.concatenate([b, np.zeros_like(b)], axis=0)
        return self.factor.solve(rhs)[:self.N]


class Bordered:
    """[[F + U diag(s) Uᵀ, C], [Cᵀ, 0]] x = [b; c] for a factored F (``solve``), dense
    columns U with weights s (rank-one terms) and C (constraints), by the Schur complement:
    ``inertia`` of the border (positive, negative) beside F's, for Haynsworth's additivity
    (the inertia of the whole is F's plus that of −(the border's Schur complement))."""

    def __init__(self, solve, U: list, s: list, C: list):
        self.solve_F = solve
        self.U = np.column_stack(U) if len(U) else None
        self.C = np.column_stack(C) if len(C) else None
        self.s = np.asarray(s, dtype=float)
        cols = [x for x in (self.U, self.C) if x is not None]
        if not cols:
            self.B, self.G, self.Z = None, None, None
            self.border_negative = 0
            return
        self.B = np.column_stack(cols)  # all border columns
        k_u = 0 if self.U is None else self.U.shape[1]
        self.k_u, self.k = k_u, self.B.shape[1]
        self.Z = self.solve_F(self.B)  # F⁻¹ B
        # the border's block: [[-diag(1/s), 0], [0, 0]] for (U, C) unknowns y_U = s Uᵀx
        D = np.zeros((self.k, self.k))
        if k_u:
            D[:k_u, :k_u] = -np.diag(1.0 / self.s)
        self.G = D - self.B.T @ self.Z  # the Schur complement of F in the bordered matrix
        ev = np.linalg.eigvalsh(0.5 * (self.G + self.G.T))
        self.border_negative = int(np.count_nonzero(ev < 0))

    def solve(self, b: np.ndarray, c: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(x, the constraints' multipliers) of the bordered system; b (N,) or (N, k)."""
        x0 = self.solve_F(b)
        if self.B is None:
            return x0, np.zeros(0)
        rhs = -(self.B.T @ x0)
        if c is not None:
            rhs[self.k_u:] += c
        y = np.linalg.solve(self.G, rhs)
        x = x0 - self.Z @ y  # F x + B y = b
        return x, y[self.k_u:]


def count_below(factor: HessianFactor, bordered: Bordered) -> int:
    """Eigenvalues of the constrained pencil below the shift. With y = s Uᵀx the bordered
    matrix is [[F, U, C], [Uᵀ, −diag(1/s), 0], [Cᵀ, 0, 0]]: its inertia is F's plus that of
    its Schur complement G (Haynsworth); less the −1/s block's (one negative per s > 0) it is
    that of [[F + UsUᵀ, C], [Cᵀ, 0]], and less (n_c, n_c) — one positive and one negative per
    constraint — that of F + UsUᵀ on {Cᵀx = 0}."""
    if bordered.B is None:
        return factor.negative
    n_c = bordered.k - bordered.k_u
    return (factor.negative + bordered.border_negative - int(np.count_nonzero(bordered.s > 0))
            - n_c)


def relative_residual(apply, x, b) -> float:
    r = apply(x) - b
    return float(np.linalg.norm(r) / max(np.linalg.norm(b), 1e-300))


