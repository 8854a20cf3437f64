"""The stability of an axisymmetric steady state in each azimuthal mode m (docs/model.md §13).

A perturbation ψ(r, z) cos mθ of an axisymmetric φ(r, z) decouples by m: every term of E_h
is an integral of nodal products and of ∇(·)·∇(·) and Δ(·), and on ψ cos mθ the Laplacian is
Δ_m = ∂²_r + (1/r)∂_r − m²/r² + ∂²_z, |∇(ψ cos mθ)|² averages to ½(|∇ψ|² + m²ψ²/r²). So the
Hessian of E_h in mode m is the axisymmetric one (:meth:`fem_ade.backends.fem.step.MixedStep.
hessian_coefficients`) with K replaced by

    K_m = K + m² M_{1/r²},     M_{1/r²} = diag(w_r / r²) ⊗ W_z   (weak form: ∫ m²ψχ/r² 2πr),

the same θ-factor (π for m ≥ 1, 2π for m = 0) on every term, and for m ≥ 1:

* no rank-one terms and no first-order constraints: V, A, ΔA are θ-averages, whose first
  variation along cos mθ vanishes (their multipliers' second-order terms stay);
* ψ = O(r^m) at the axis: ψ = 0 on r = 0 (the axis nodes removed). Then ψ = r q with q a
  polynomial of degree p − 1 in the axis cell, ψχ/r² = q_ψ q_χ has degree 2p − 2, and the
  cell's Gauss–Lobatto–Jacobi (0, 1) rule (exact to 2p − 1 with the weight r) integrates
  ∫ψχ/r² 2πr dr exactly with the diagonal weights w_j/r_j²; other cells use their GLL rule on
  a smooth 1/r.

K_m is still K_r,m ⊗ W_z + W_r ⊗ K_z with K_r,m = K_r + m² diag(w_r/r²), so the bulk
preconditioner P_m = (4κ/ε³)W + (4κ/ε)K_m + κε K_m W⁻¹K_m is assembled like P.

Zero modes: rigid motions cost no energy in the continuous problem, and the mesh pins them
with a small energy of either sign, so each block's eigenproblem is taken P-orthogonal to
them (as the m = 0 block was to the translation along z): m = 0 the translation along z,
t = ∂_zφ; m = 1 the translation across the axis, t = ∂_rφ (δφ = −∂_xφ = −∂_rφ cos θ) and the
tilt, a rotation about a horizontal axis, t = z∂_rφ − r∂_zφ (zero for a sphere, whose tilt
moves nothing: a direction of negligible size is left out).

The eigenvalues of H_m v = λ P_m v on the constrained space, by shift-invert Lanczos
(ARPACK) with the sparse LU of the bordered H_m − σP_m (:mod:`fem_ade.backends.fem.direct`), and the
count below σ from the same LU's inertia (Sylvester), with no eigen-solve.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from fem_ade.backends.fem.tensor import along
from fem_ade.model.params import ModelError

#: a zero mode whose P-norm, beyond the modes before it, is below this fraction of the
#: first one's is left out (the tilt of a sphere: nothing moves; measured: 2e-3 of the
#: translation on the sphere at ε = 0.02, 0.3 on the prolate at v = 0.8)
NEGLIGIBLE_MODE = 1e-2


@dataclass
class ModeBlock:
    """Mode m of an axisymmetric state: the free nodes (all for m = 0; off the axis for
    m ≥ 1), K_m on them (sparse), the weights, the Hessian's coefficients, the borders
    (rank-one terms and constraints, m = 0) and the zero modes (as P_m t)."""

    m: int
    free: np.ndarray
    K: sp.csr_matrix
    w: np.ndarray
    coefficients: dict
    rank_one: list
    constraints: list
    bulk: tuple[float, float, float]

    @property
    def size(self) -> int:
        return self.w.size

    def P(self, x: np.ndarray) -> np.ndarray:
        """P_m x = aW x + cK_m x + κε K_m W⁻¹K_m x."""
        a, c, ke = self.bulk
        Kx = self.K @ x
        if x.ndim == 2:
            return a * self.w[:, None] * x + c * Kx + ke * (self.K @ (Kx / self.w[:, None]))
        return a * self.w * x + c * Kx + ke * (self.K @ (Kx / self.w))

    def H(self, x: np.ndarray) -> np.ndarray:
        """H_m x = κε K_m W⁻¹K_m x + K_m(αx) + αK_m x + Wγx + c₀K_m x + Σσ b(bᵀx)."""
        co, ke = self.coefficients, self.bulk[2]
        alpha, gamma = co["alpha"], co["gamma"]
        Kx = self.K @ x
        out = ke * (self.K @ (Kx / self.w)) + self.K @ (alpha * x) + alpha * Kx \
            + self.w * gamma * x + co["c0"] * Kx
        for s, b in self.rank_one:
            out = out + s * float(b @ x) * b
        return out


def radial_inverse_square(space) -> sp.csr_matrix:
    """M_{1/r²} = M_r ⊗ diag(w_z), the Gram matrix of ∫ ψχ/r² 2πr dr dz on fields that vanish
    on the axis, by the axis cell's Gauss–Lobatto–Jacobi rule (exact there) and the other
    cells' GLL rule: M_r = diag(w_j/r_j²) off the axis plus, from the rule's node on the axis,
    where ψχ/r² is ψ′(0)χ′(0), the rank-one w₀ d dᵀ (d: the derivative at r = 0 of each of
    the axis cell's basis functions). Without it a mode m = 1 field, ψ′(0) ≠ 0, loses that
    term: −Δ₁ of a Bessel mode J₁(kr)cos(πz) then errs by 3 at the first node (measured), by
    1e-10 with it. Rows and columns of the axis nodes are zero (those nodes are dropped)."""
    from fem_ade.backends.fem import gll

    ar, az = space.axes
    r = ar.nodes
    diag = np.zeros_like(r)
    off = r > 0
    diag[off] = ar.weights[off] / r[off] ** 2
    Mr = sp.diags(diag).tolil()
    xj, rho = gll.jacobi_points_weights(ar.order)
    h0 = ar.h[0]
    d = gll.derivative_matrix_at(xj)[0] * (2.0 / h0)  # d/dr at r = 0 of the axis cell's basis
    w0 = 2.0 * np.pi * (0.5 * h0) ** 2 * rho[0]
    cell = ar.element_dofs[0]
    d[cell == 0] = 0.0  # (the axis node itself is dropped)
    Mr[np.ix_(cell, cell)] = Mr[np.ix_(cell, cell)].toarray() + w0 * np.outer(d, d)
    return sp.kron(Mr.tocsr(), sp.diags(az.weights), format="csr")


def zero_modes(space, phi: np.ndarray, m: int) -> list[np.ndarray]:
    """The rigid motions of mode m as fields (module docstring): m = 0 ∂_zφ; m = 1 ∂_rφ and
    z∂_rφ − r∂_zφ; none for m ≥ 2."""
    from fem_ade.backends.fem.tensor import along

    ar, az = space.axes
    Phi = phi.reshape(space.shape)
    if m == 0:
        return [along(az.derivative, Phi, 1).ravel()]
    if m == 1:
        r, z = space.doflocs
        w = space.weights
        inside = w * (phi + 1.0)
        zc = float(np.sum(inside * z) / np.sum(inside))  # the rotation's centre: the centroid
        dr = along(ar.derivative, Phi, 0).ravel()
        dz = along(az.derivative, Phi, 1).ravel()
        return [dr, (z - zc) * dr - r * dz]
    return []


def mode_block(sys_, lin, m: int) -> ModeBlock:
    """Mode ``m`` of the linearization ``lin`` of a Newton system on the axisymmetric
    geometry (module docstring)."""
    space = sys_.space
    if getattr(sys_.be, "geometry", "cartesian") != "axisymmetric":
        raise ModelError("azimuthal modes are those of an axisymmetric state (--geometry "
                         "axisymmetric)")
    if not (isinstance(m, (int, np.integer)) and m >= 0):
        raise ModelError(f"an azimuthal mode is an integer m >= 0, got {m!r}")
    co = sys_.step.hessian_coefficients(lin.phi, lin.mu, lin.Kphi, lin.lam[0], lin.lam[1])
    K = sys_.K_assembled
    if m:
        K = K + (m * m) * radial_inverse_square(space)
        r = space.doflocs[0]
        free = np.flatnonzero(r > 0)
    else:
        free = np.arange(space.n_dofs)
    K = sp.csr_matrix(K)[free][:, free].tocsr()
    w = sys_.w[free]
    alpha = np.broadcast_to(co["alpha"], sys_.w.shape)[free]
    gamma = np.broadcast_to(co["gamma"], sys_.w.shape)[free]
    coefficients = {"alpha": alpha, "gamma": gamma, "c0": co["c0"]}
    rank_one = [(s, b[free]) for s, b in co["rank_one"]] if m == 0 else []
    block = ModeBlock(m, free, K, w, coefficients, rank_one, [], sys_.bulk())
    constraints = [c[free] for c in lin.C[:2]] if m == 0 else []
    block.constraints = constraints + [block.P(t) for t in _independent(block, [
        t[free] for t in zero_modes(space, lin.phi, m)])]
    return block


def _independent(block: ModeBlock, modes: list[np.ndarray]) -> list[np.ndarray]:
    """The zero modes made P-orthogonal (Gram–Schmidt), each left out whose part beyond the
    ones before is below :data:`NEGLIGIBLE_MODE` of the first's P-norm: a sphere's tilt is
    the translation plus round-off, and that round-off, projected out, took the l = 2 mode
    of block 1 with it (measured)."""
    kept, first = [], None
    for t in modes:
        for u in kept:
            t = t - (u @ block.P(t)) * u
        size = float(np.sqrt(max(t @ block.P(t), 0.0)))
        first = size if first is None else first
        if first and size > NEGLIGIBLE_MODE * first:
            kept.append(t / size)
    return kept


@dataclass
class ModeResult:
    """The k lowest eigenvalues of mode m (ascending) and the count below the shift."""

    m: int
    eigenvalues: np.ndarray
    unstable: int
    size: int


def block_factor(sys_, block: ModeBlock, sigma: float):
    """The bordered H_m − σP_m of a block, factored: (HessianFactor, Bordered)."""
    from fem_ade.backends.fem.direct import Bordered, HessianFactor, node_order

    a, c, ke = block.bulk
    space = sys_.space
    nodes = node_order(space.shape, space.order, None if block.m == 0 else block.free)
    F = HessianFactor(block.K, block.w, ke, block.coefficients, nodes, sigma=sigma, P=(a, c))
    B = Bordered(F.solve, [b for _, b in block.rank_one], [s for s, _ in block.rank_one],
                 block.constraints)
    return F, B


#: ARPACK's tolerance on the shift-inverted eigenvalues, and its Lanczos basis: at least
#: this many vectors, 2k + 2 beyond. Measured (the prolate at ε = 0.005, 66265 nodes): the
#: lowest of m = 0 in 9 solves with 8 vectors, 21 with scipy's default 20; the four lowest in
#: 14 against 21 (m = 5, whose lowest pair is 1e-8 apart: 21 and 30)
TOL, MIN_NCV = 1e-9, 8


#: where a shift is tried first when the caller knows an eigenvalue near the block's lowest
#: (``near``: the previous branch point's): at this fraction of it. Shift-invert Lanczos
#: converges in fewer solves the nearer the shift is to the lowest eigenvalue; measured (the
#: prolate at ε = 0.005, k = 1, blocks m = 3 … 8): 136 solves with the shift at σ, 116 at the
#: lowest of block m − 1, 76 at 0.9 of the block's own lowest, 72 at 0.95. Along the committed
#: branches with modes (the prolate at ε = 0.01, 66 steps; the oblate at ε = 0.005) a block's
#: lowest moved down by at most 3 % from one point to the next for m ≥ 2 (m = 0: 4.4 %; m = 1,
#: whose lowest is near 0: 27 %, where the inertia finds an eigenvalue below the shift tried
#: and the shift goes back to σ: one factorization more).
NEAR = 0.9


def lowest(sys_, lin, m: int, k: int = 4, sigma: float = -1e-6,
           tol: float = TOL, near: float | None = None) -> ModeResult:
    """The ``k`` lowest eigenvalues of H_m v = λ P_m v on the constrained space of mode
    ``m`` (module docstring) and the count below ``sigma`` (the unstable directions), by
    shift-invert Lanczos: the k nearest above a shift below which the inertia counts none.
    That shift is :data:`NEAR` · ``near`` where that is above ``sigma`` and the inertia counts
    none below it (``near``: an eigenvalue expected near the lowest, e.g. the previous branch
    point's); else ``sigma`` itself for a state with none below it; else it is moved down —
    past the nearest eigenvalue below (found by the same LU), then by doubling — until the
    inertia counts none below it."""
    block = mode_block(sys_, lin, m)
    B, shift, below = _clear_shift(sys_, block, sigma, tol, near)
    dim = block.size - len(block.constraints)
    k = min(k, dim - 2)
    values = _lanczos(block, B, shift, k, "LA", tol) if k > 0 else np.zeros(0)
    return ModeResult(m, np.sort(values), below, dim)


def lowest_mode(sys_, lin, m: int, sigma: float = -1e-6,
                tol: float = TOL) -> tuple[float, np.ndarray]:
    """(λ, ψ): the lowest eigenvalue of block ``m`` and its eigenvector on all the space's
    nodes (0 on the axis for m ≥ 1: ψ = O(r^m)), P_m-orthogonal to the block's zero modes and
    scaled to max |ψ| = 1 with its largest value positive — the shape ψ(r, z) cos mθ of the
    block's softest perturbation (what a branch switches along)."""
    block = mode_block(sys_, lin, m)
    B, shift, _ = _clear_shift(sys_, block, sigma, tol)
    values, vectors = _lanczos(block, B, shift, 1, "LA", tol, vectors=True)
    psi = np.zeros(sys_.space.n_dofs)
    psi[block.free] = vectors[:, 0]
    psi /= psi[np.argmax(np.abs(psi))]
    return float(values[0]), psi


def _clear_shift(sys_, block: ModeBlock, sigma: float, tol: float,
                 near: float | None = None):
    """(the bordered factor at a shift with no eigenvalue below it, that shift, the count
    below ``sigma``): :data:`NEAR` · ``near`` or ``sigma`` itself where none is below it (see
    :func:`lowest`)."""
    from fem_ade.backends.fem.direct import count_below

    if near is not None and NEAR * near > sigma:
        F, B = block_factor(sys_, block, NEAR * near)
        if count_below(F, B) == 0:  # none below it, so none below σ either
            return B, NEAR * near, 0
    F, B = block_factor(sys_, block, sigma)
    below = count_below(F, B)
    shift = sigma
    if below:
        nearest = _lanczos(block, B, sigma, 1, "SA", tol)[0]  # the nearest below σ
        step = max(2.0 * (sigma - nearest), 1e-6)
        while True:
            shift = sigma - step
            F, B = block_factor(sys_, block, shift)
            if count_below(F, B) == 0:
                break
            step *= 4.0
    return B, shift, below


def _lanczos(block: ModeBlock, B, shift: float, k: int, which: str, tol: float,
             vectors: bool = False):
    """ARPACK's shift-invert Lanczos on H v = λ P v with the bordered (H − shift·P)⁻¹ ``B``:
    the k eigenvalues nearest above the shift (``which="LA"``) or below it (``"SA"``);
    ``vectors``: (eigenvalues, eigenvectors as columns)."""
    from scipy.sparse.linalg import LinearOperator, eigsh

    n = block.size
    H = LinearOperator((n, n), matvec=block.H, dtype=float)
    P = LinearOperator((n, n), matvec=block.P, dtype=float)
    OPinv = LinearOperator((n, n), matvec=lambda x: B.solve(np.ravel(x))[0], dtype=float)
    rng = np.random.default_rng(1)
    v0 = B.solve(block.P(rng.standard_normal(n)))[0]  # in the constrained space
    ncv = min(n - len(block.constraints) - 1, max(2 * k + 2, MIN_NCV))
    found = eigsh(H, k=k, M=P, sigma=shift, which=which, OPinv=OPinv, v0=v0, tol=tol,
                  ncv=ncv, return_eigenvectors=vectors)
    return found if vectors else np.asarray(found)


# ---------------------------------------------------------------------------------------------
# the rigid motions of a 3D state
# ---------------------------------------------------------------------------------------------
def rigid_motions(be, phi: np.ndarray) -> list[np.ndarray]:
    """The rigid motions of a 3D state as fields on its nodes: the translations ∂ₐφ and the
    rotations about the centroid (x − c) × ∇φ, by the spectral elements' derivative."""
    space = be.space
    grads = gradient(space, phi)
    X = space.doflocs
    inside = space.weights * (phi + 1.0)
    c = [float(np.sum(inside * x) / np.sum(inside)) for x in X]
    d = [X[a] - c[a] for a in range(3)]
    rotations = [d[1] * grads[2] - d[2] * grads[1], d[2] * grads[0] - d[0] * grads[2],
                 d[0] * grads[1] - d[1] * grads[0]]
    return grads + rotations


def gradient(space, phi: np.ndarray) -> list[np.ndarray]:
    """∇φ at the nodes of a tensor space, one array per axis (the spectral elements'
    derivative, the mean of the two cells' at a shared node)."""
    Phi = np.reshape(phi, space.shape)
    return [along(_derivative(ax), Phi, a).ravel() for a, ax in enumerate(space.axes)]


def _derivative(axis):
    """d/dx at the nodes of a periodic axis (the mean of the two cells' at a shared node)."""
    from fem_ade.backends.fem import gll

    if not getattr(axis, "periodic", False):
        return axis.derivative
    p, dofs = axis.order, axis.element_dofs
    D = gll.derivative_matrix(p)
    rows, cols, vals = [], [], []
    for e in range(axis.cells):
        i, j = np.meshgrid(dofs[e], dofs[e], indexing="ij")
        rows.append(i.ravel())
        cols.append(j.ravel())
        vals.append((D * (2.0 / axis.h[e])).ravel())
    A = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(axis.size, axis.size))
    shared = np.bincount(dofs.ravel(), minlength=axis.size)
    return sp.diags(1.0 / shared) @ A


def p_orthogonal(P, modes: list[np.ndarray], negligible: float = 1e-2) -> list[np.ndarray]:
    """P·t for each mode t made P-orthogonal to the ones before, a mode whose part beyond
    them is below ``negligible`` of the largest's P-norm left out (a rotation about a
    state's axis of symmetry): the rigid motions of a 3D state as constraints' gradients,
    normalized (uᵀPu = 1), for its stability and Newton's pins. (:func:`_independent` is
    the blocks' own, scaled by the first mode's norm: the two keep the results they made.)"""
    norms = [math.sqrt(max(float(t @ P(t)), 0.0)) for t in modes]
    scale = max(norms, default=0.0)
    kept = []
    for t in modes:
        for u in kept:
            t = t - float(u @ P(t)) * u
        size = math.sqrt(max(float(t @ P(t)), 0.0))
        if scale and size > negligible * scale:
            kept.append(t / size)
    return [P(u) for u in kept]
