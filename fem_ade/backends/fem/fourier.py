"""The Fourier–(r, z) geometry: a field with the mirror symmetries of an m₀-fold shape about
the z axis, φ(r, z, θ) = Σⱼ aⱼ(r, z) cos(j m₀ θ), j = 0 … n_θ − 1, on the axisymmetric
geometry's spectral elements in (r, z) and n_θ collocation angles in θ (docs/model.md §13).

Why. The azimuthal blocks (:mod:`fem_ade.backends.fem.modes`) say where an axisymmetric state
loses stability in mode m; the branch born there is non-axisymmetric. Near its birth it is a
few cosines away from the axisymmetric state, and a 3D box spends most of its nodes on what
the (r, z) mesh already resolves. Here the cost is n_θ (r, z) problems (the Fourier–spectral-
element idea of cylindrical flow codes: Semtex, Nek5000's Fourier option).

The discrete space. The nodes are the (r, z) mesh's axis nodes (one value each, the same for
every θ) and its other nodes at the angles θ_k = (k + ½)π/(m₀ n_θ), k < n_θ — the midpoints
of the fundamental sector 0 ≤ θ ≤ π/m₀, whose even reflections are the shape's mirror planes
(θ = 0 and θ = π/m₀). With the (r, z) weights w (which carry 2πr) and its stiffness K_rz,

    W = diag(w_axis, w_off/n_θ, …),
    xᵀKx = (1/n_θ) Σ_k s_kᵀ K_rz s_k + Σ_off (M ⊗ K_θ),   s_k = (axis values, values at θ_k),

with M = M_{1/r²} the Gram matrix of ∫ψχ/r² 2πr (:func:`fem_ade.backends.fem.modes.
radial_inverse_square`, exact on fields that vanish on the axis) and K_θ = (1/n_θ) Qᵀ diag(
(j m₀)²) Q, Q the orthonormal DCT-II along θ: (1/n_θ) Σ_k x_k² and xᵀK_θx are the θ-means of
u² and (∂_θu)² exactly for u = Σⱼ bⱼcos(j m₀ θ), j < n_θ. Every other term of E_h is a nodal
product with the weights W (:mod:`fem_ade.backends.fem.forms`), so the scheme's own energy,
gradient and Hessian (:class:`fem_ade.backends.fem.step.MixedStep`) apply unchanged: nodal
products in θ are collocation (the cosines' products alias above j = n_θ).

In the modes (the DCT of the off-axis values) W and K are block-diagonal: mode 0 is the
axisymmetric space (axis values with the θ-mean of the others) and mode j ≥ 1 is the azimuthal
block m = j m₀ off the axis, K_m = K_rz + m²M, both scaled by 1/n_θ. A field with one mode,
ψ(r, z) cos mθ, has the energy, gradient and Hessian of the (r, z) block m (tests).

Newton's method (:class:`FourierNewtonSystem`) solves the bordered system by GMRES,
preconditioned by the modes' blocks at the θ-mean of the Hessian's coefficients — exact for
an axisymmetric state, whose Hessian is block-diagonal — each factored by the sparse LU of
the axisymmetric geometry (:mod:`fem_ade.backends.fem.direct`), the constraints and the
rank-one terms as borders of the whole — after a coarse step on the membrane's shape modes
(:class:`Galerkin`): the θ-mean blocks smear an interface that moves with θ and miss the
displacements of it that cost only bending, which GMRES would find one by one (256
iterations at the triaxial branch's a = 1.0, 26 with the coarse step:
:func:`fem_ade.backends.fem.coarse.fourier_shape_functions`). No rigid motion keeps both
mirror planes but the translation along z, which is pinned as on the axisymmetric geometry.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy import fft

from fem_ade.backends.fem.newton import NewtonSystem
from fem_ade.model.params import ModelError

#: GMRES of the bordered Newton system: its restart length and its most iterations; a
#: solve that stops short of its tolerance (stagnation near a bifurcation, where a mode's
#: block is nearly singular: seen at 345 iterations) is used if its residual is below
#: INEXACT. The restart is long because, without the coarse step, the θ-mean blocks miss
#: more of the Hessian as the shape leaves the axis and a restart throws away what GMRES
#: learnt: at the triaxial branch's a = 0.7 predictor (n_θ = 8, 0.34M unknowns) GMRES(60)
#: took 508 iterations (150 s), GMRES(600) 176 (53 s); 300 vectors are 0.8 GB there. With
#: the coarse step a solve there takes 20–40 iterations
RESTART, MAX_ITERATIONS, INEXACT = 300, 900, 1e-5
#: the coarse step (:class:`Galerkin`) is kept for the next Newton step while φ has moved
#: less than this at every node since it was made
REUSE = 0.05


class FourierSpace:
    """The Fourier–(r, z) space of an (r, z) tensor space ``rz`` (module docstring): ``m0``
    the shape's fold (its mirror planes θ = 0 and θ = π/m₀), ``n_theta`` angles. A field is
    a vector [axis values; off-axis values at θ₀; … at θ_{n_θ−1}]."""

    def __init__(self, rz, m0: int, n_theta: int):
        from fem_ade.backends.fem.modes import radial_inverse_square

        if not (isinstance(m0, (int, np.integer)) and m0 >= 1):
            raise ModelError(f"the fold m0 is an integer >= 1, got {m0!r}")
        if not (isinstance(n_theta, (int, np.integer)) and n_theta >= 1):
            raise ModelError(f"n_theta is an integer >= 1, got {n_theta!r}")
        self.rz, self.m0, self.n_theta = rz, int(m0), int(n_theta)
        r, z = rz.doflocs
        self.axis = np.flatnonzero(r == 0.0)
        self.off = np.flatnonzero(r > 0.0)
        self.na, self.no = self.axis.size, self.off.size
        self.theta = (np.arange(n_theta) + 0.5) * math.pi / (m0 * n_theta)
        self.m = m0 * np.arange(n_theta)  # the azimuthal mode of each cosine
        self.K_rz = rz.assembled_stiffness()
        self.M = sp.csr_matrix(radial_inverse_square(rz))[self.off][:, self.off].tocsr()
        w = rz.weights
        self.weights = np.concatenate([w[self.axis], np.tile(w[self.off] / n_theta, n_theta)])
        self.n_dofs = self.weights.size
        self.K = _Stiffness(self)
        theta = np.concatenate([np.zeros(self.na), np.repeat(self.theta, self.no)])
        self.doflocs = np.stack([np.concatenate([r[self.axis], np.tile(r[self.off], n_theta)]),
                                 np.concatenate([z[self.axis], np.tile(z[self.off], n_theta)]),
                                 theta])
        self.order = rz.order

    # -- fields --------------------------------------------------------------------------
    def slices(self, x: np.ndarray) -> np.ndarray:
        """The (r, z) fields at each angle, (n_θ, N_rz)."""
        S = np.empty((self.n_theta, self.rz.n_dofs))
        S[:, self.axis] = x[:self.na]
        S[:, self.off] = x[self.na:].reshape(self.n_theta, self.no)
        return S

    def from_slices(self, S: np.ndarray) -> np.ndarray:
        """The field whose slices are ``S`` (the axis values: their mean over θ)."""
        S = np.asarray(S, dtype=float)
        return np.concatenate([S[:, self.axis].mean(axis=0), S[:, self.off].ravel()])

    def from_modes(self, modes: dict) -> np.ndarray:
        """The field Σⱼ aⱼ(r, z) cos(j m₀ θ) of {j: aⱼ on the (r, z) nodes} (a₀ on the axis
        nodes; the others' axis values are dropped: ψ = O(r^m) there)."""
        S = np.zeros((self.n_theta, self.rz.n_dofs))
        for j, a in modes.items():
            if not 0 <= j < self.n_theta:
                raise ModelError(f"mode j = {j} is not one of 0 … {self.n_theta - 1}")
            S += np.cos(self.m[j] * self.theta)[:, None] * np.asarray(a, dtype=float)[None]
        x = self.from_slices(S)
        a0 = np.asarray(modes.get(0, np.zeros(self.rz.n_dofs)), dtype=float)
        x[:self.na] = a0[self.axis]
        return x

    def modes(self, x: np.ndarray) -> np.ndarray:
        """The cosine coefficients aⱼ(r, z), (n_θ, N_rz): the inverse of :meth:`from_modes`
        (a₀ holds the axis values; aⱼ, j ≥ 1, is 0 there)."""
        X = fft.dct(x[self.na:].reshape(self.n_theta, self.no), type=2, norm="ortho", axis=0)
        X *= math.sqrt(2.0 / self.n_theta)
        X[0] /= math.sqrt(2.0)
        A = np.zeros((self.n_theta, self.rz.n_dofs))
        A[:, self.off] = X
        A[0, self.axis] = x[:self.na]
        return A

    def laplacian(self, x: np.ndarray) -> np.ndarray:
        """μ = W⁻¹Kx."""
        return (self.K @ x) / self.weights

    def k_theta(self, X: np.ndarray) -> np.ndarray:
        """K_θ along the first axis of X (n_θ, …)."""
        Y = fft.dct(X, type=2, norm="ortho", axis=0)
        Y *= (self.m.astype(float) ** 2).reshape((-1,) + (1,) * (X.ndim - 1))
        return fft.idct(Y, type=2, norm="ortho", axis=0) / self.n_theta

    def describe(self) -> dict:
        return {"geometry": "fourier", "m0": self.m0, "n_theta": self.n_theta,
                "rz_nodes": self.rz.n_dofs, "dofs": self.n_dofs, "order": self.order}


class _Stiffness:
    """K of a :class:`FourierSpace`, matrix-free (``K @ x``)."""

    def __init__(self, space: FourierSpace):
        self.space = space
        self.shape = (space.n_dofs, space.n_dofs)

    def __matmul__(self, x):
        s = self.space
        x = np.asarray(x, dtype=float)
        KS = (s.K_rz @ s.slices(x).T).T / s.n_theta  # (n_θ, N_rz)
        X = x[s.na:].reshape(s.n_theta, s.no)
        off = KS[:, s.off] + (s.M @ s.k_theta(X).T).T
        return np.concatenate([KS[:, s.axis].sum(axis=0), off.ravel()])


@dataclass
class FourierState:
    """What Newton's method and the scheme's step need of a backend, on a
    :class:`FourierSpace`: the space, the step (its params), the field φ, the scene."""

    space: FourierSpace
    stepper: object
    phi: np.ndarray
    scene: object
    exact: bool = True
    geometry: str = "fourier"

    @property
    def params(self):
        return self.stepper.params

    def _set(self, phi, phi_prev=None) -> None:
        self.phi = np.asarray(phi, dtype=float)

    @classmethod
    def of(cls, be, m0: int, n_theta: int, modes: dict | None = None) -> FourierState:
        """The Fourier–(r, z) state of an axisymmetric backend ``be`` (its mesh, order and
        parameters): φ = be.phi + Σⱼ aⱼ cos(j m₀ θ) for ``modes`` {j: aⱼ}, j ≥ 1."""
        from fem_ade.backends.fem.step import MixedStep

        if getattr(be, "geometry", "") != "axisymmetric":
            raise ModelError("the Fourier-(r, z) geometry extends an axisymmetric state")
        space = FourierSpace(be.space, m0, n_theta)
        step = MixedStep(space, be.stepper.params, scheme="stabilized", exact=True)
        phi = space.from_modes({0: be.phi, **(modes or {})})
        return cls(space, step, phi, be.scene)

    def set_parameter(self, name: str, value: float) -> None:
        """The parameter ``name`` (v, da0, …: :func:`fem_ade.scenes.vesicle.set_parameter`)
        at ``value``."""
        from fem_ade.scenes.vesicle import set_parameter

        self.stepper.params = set_parameter(self.stepper.params, name, float(value))


class FourierNewtonSystem(NewtonSystem):
    """The bordered Newton system on a :class:`FourierSpace` (module docstring): the
    translation along z pinned, extra ``pins`` (linear functionals' gradients, e.g. a mode's
    amplitude) held where the start has them; solved by GMRES with the modes' blocks."""

    def __init__(self, be: FourierState, linear: str = "auto", pins=(),
                 coarse_degree: int | None = None):
        self.be, self.space, self.step = be, be.space, be.stepper
        self.coarse_degree = coarse_degree
        self.galerkin = None  # the coarse step in use (:class:`Galerkin`)
        self.w = self.space.weights
        self.translations = [*self._translations(),
                             *[np.asarray(p, dtype=float) for p in pins]]
        self.direct, self.uses_coarse, self.coarse, self._K = True, False, None, None
        self._P = None
        self.gmres_iterations: list[int] = []

    # P⁻¹ by the modes' blocks (factored once)
    def P_inverse(self, x: np.ndarray) -> np.ndarray:
        if self._P is None:
            a, c, ke = self.bulk()
            ones = np.ones(self.space.rz.n_dofs)
            self._P = ModeBlocks(self.space, ke, 0.0 * ones, a * ones, c)
        x = np.asarray(x)
        if x.ndim == 2:
            return np.stack([self._P.solve(v) for v in x])
        return self._P.solve(x)

    def restore_directions(self, phi, Kphi) -> list[np.ndarray]:
        """P⁻¹∇V, P⁻¹∇A less their parts along P⁻¹ of the pins, so that restoring V and A
        moves no pinned functional (the amplitude a branch is followed in)."""
        d = super().restore_directions(phi, Kphi)
        T = np.column_stack(self.translations)
        D = np.column_stack([self.P_inverse(t) for t in self.translations])
        G = T.T @ D
        return [x - D @ np.linalg.solve(G, T.T @ x) for x in d]

    def factor(self, lin, sigma: float = 0.0, C=None):
        """The bordered system at ``lin`` as a GMRES solver (:class:`KKTSolver`)."""
        if sigma or C is not None:
            raise ModelError("the Fourier-(r, z) Newton system solves at sigma = 0 only")
        if lin.bordered is None:
            kept = self.galerkin
            if kept is not None and np.abs(lin.phi - kept.phi).max() > REUSE:
                kept = self.galerkin = None  # gone before the next is made (GBs at n_θ = 16)
            lin.bordered = KKTSolver(self, lin, degree=self.coarse_degree, coarse=kept)
            self.galerkin = lin.bordered.coarse
        return lin.bordered


class ModeBlocks:
    """The block-diagonal operator of the modes, factored: mode 0 the (r, z) H with the θ-mean
    coefficients (α, γ on the (r, z) nodes), mode j ≥ 1 its block m = j m₀ off the axis
    (less σP where ``sigma``, P = (a, c) the bulk's); ``solve`` applies its inverse to a
    field (module docstring)."""

    def __init__(self, space: FourierSpace, ke: float, alpha, gamma, c0: float,
                 sigma: float = 0.0, P: tuple[float, float] | None = None):
        from fem_ade.backends.fem.direct import HessianFactor, node_order

        self.space = space
        rz, off = space.rz, space.off
        shape = rz.shape
        co0 = {"alpha": alpha, "gamma": gamma, "c0": c0}
        self.factors = [HessianFactor(space.K_rz, rz.weights, ke, co0,
                                      node_order(shape, rz.order), sigma=sigma, P=P)]
        co = {"alpha": np.asarray(alpha)[off], "gamma": np.asarray(gamma)[off], "c0": c0}
        nodes = node_order(shape, rz.order, off)
        Koo = sp.csr_matrix(space.K_rz)[off][:, off].tocsr()
        for m in space.m[1:]:
            self.factors.append(HessianFactor(Koo + float(m * m) * space.M, rz.weights[off],
                                              ke, co, nodes, sigma=sigma, P=P))
        self.negative = [f.negative for f in self.factors]

    def solve(self, b: np.ndarray) -> np.ndarray:
        """The blocks' inverse on a field (the DCT along θ, n_θ (r, z) solves, back)."""
        s = self.space
        nt, sq = s.n_theta, math.sqrt(s.n_theta)
        B = fft.dct(b[s.na:].reshape(nt, s.no), type=2, norm="ortho", axis=0)
        b0 = np.empty(s.rz.n_dofs)  # mode 0 in (r, z) coordinates: D⁻¹ on the right side
        b0[s.axis], b0[s.off] = b[:s.na], B[0] * sq
        x0 = self.factors[0].solve(b0)
        X = np.empty_like(B)
        X[0] = x0[s.off] * sq
        for j in range(1, nt):
            X[j] = nt * self.factors[j].solve(B[j])
        return np.concatenate([x0[s.axis], fft.idct(X, type=2, norm="ortho", axis=0).ravel()])


class KKTSolver:
    """[[H_L − σP, C], [Cᵀ, 0]] at a linearization, by GMRES preconditioned by the same system
    with the modes' blocks for H_L (:class:`ModeBlocks`, its borders by
    :class:`fem_ade.backends.fem.direct.Bordered`) after the coarse step of :class:`Galerkin`
    on the shape functions of ``degree`` (default :data:`fem_ade.backends.fem.coarse.
    FOURIER_DEGREE`; 0: none); ``solve(b, c)`` → (x, multipliers)."""

    def __init__(self, sys_: FourierNewtonSystem, lin, rtol: float = 1e-8,
                 sigma: float = 0.0, degree: int | None = None, coarse=None):
        from fem_ade.backends.fem.coarse import FOURIER_DEGREE, fourier_shape_functions
        from fem_ade.backends.fem.direct import Bordered

        degree = FOURIER_DEGREE if degree is None else degree
        t0 = time.perf_counter()
        # the linearization's fields, not the object that keeps this solver (no cycle: the
        # n_θ factorizations are freed as soon as the Newton iterate moves on; measured, with
        # the cycle: 13.9 GB held after five solves at n_θ = 8)
        self.lin = _Fields(lin.phi, lin.mu, lin.Kphi, lin.lam)
        self.sys, self.rtol, self.sigma = sys_, rtol, sigma
        step, space = sys_.step, sys_.space
        co = step.hessian_coefficients(lin.phi, lin.mu, lin.Kphi, lin.lam[0], lin.lam[1])
        mean = [theta_mean(space, np.broadcast_to(co[k], lin.phi.shape)) for k in ("alpha",
                                                                                  "gamma")]
        a, c, ke = sys_.bulk()
        self.blocks = ModeBlocks(space, ke, mean[0], mean[1], co["c0"], sigma, (a, c))
        self.rank_one = co["rank_one"]
        self.C = lin.C
        blocks = self.blocks  # no reference back to self: the factors go when self does

        def blocks_solve(B):
            B = np.asarray(B)
            if B.ndim == 2:
                return np.column_stack([blocks.solve(B[:, j]) for j in range(B.shape[1])])
            return blocks.solve(B)

        self.prec = Bordered(blocks_solve, [b for _, b in self.rank_one],
                             [s for s, _ in self.rank_one], self.C)
        self.coarse = coarse
        if degree and coarse is None:
            Z = fourier_shape_functions(space, lin.phi, step.params.eps, degree)
            self.coarse = Galerkin(Z, self.apply, self.C, lin.phi)
        self.setup_s = time.perf_counter() - t0
        self.iterations: list[int] = []

    def apply(self, x: np.ndarray) -> np.ndarray:
        from fem_ade.backends.fem.newton import kkt_apply

        sigma, P = self.sigma, self.sys.P
        return kkt_apply(self.sys.step, self.lin, self.C, x,
                         (lambda v: sigma * P(v)) if sigma else None)

    def solve(self, b: np.ndarray, c: np.ndarray | None = None):
        from scipy.sparse.linalg import LinearOperator, gmres

        b = np.asarray(b, dtype=float)
        if b.ndim == 2:
            cols = [self.solve(b[:, j], None if c is None else c[:, j])
                    for j in range(b.shape[1])]
            return np.column_stack([x for x, _ in cols]), np.column_stack([y for _, y in cols])
        N, k = b.size, len(self.C)
        rhs = np.concatenate([b, np.zeros(k) if c is None else c])
        A = LinearOperator((N + k, N + k), matvec=self.apply, dtype=float)

        def prec(r):
            if self.coarse is None:
                return np.concatenate(self.prec.solve(r[:N], r[N:]))
            x1, Hx1 = self.coarse.step(r[:N])
            x, y = self.prec.solve(r[:N] - Hx1, r[N:] - np.array([c @ x1 for c in self.C]))
            return np.concatenate([x + x1, y])

        M = LinearOperator((N + k, N + k), matvec=prec, dtype=float)
        count = [0]
        x, info = gmres(A, rhs, M=M, rtol=self.rtol, atol=0.0, restart=RESTART,
                        maxiter=MAX_ITERATIONS // RESTART + 1,
                        callback=lambda _: count.__setitem__(0, count[0] + 1),
                        callback_type="pr_norm")
        self.iterations.append(count[0])
        self.sys.gmres_iterations.append(count[0])
        if info != 0:  # an inexact step is still a Newton step (the line search checks it)
            reached = float(np.linalg.norm(self.apply(x) - rhs) / np.linalg.norm(rhs))
            if not reached <= INEXACT:
                raise ArithmeticError(f"GMRES reached {reached:.1e} in {count[0]} iterations "
                                      "on the Fourier-(r, z) Newton system")
        return x[:N], x[N:]


class Galerkin:
    """The coarse step of the two-level preconditioner of :class:`KKTSolver`: for the top of
    a residual r, x₁ = Zᵀ(Z H Zᵀ)⁺ Z r and H x₁, the functions Z (k × N) first projected onto
    the constraints' null space (Cᵀx₁ = 0: the step leaves the constraint rows' residual as
    it is). The preconditioner is then x₁ + B(r − A x₁), B the bordered blocks' (the
    coarse-then-fine form of a two-level method; GMRES needs no symmetry of it). ``apply``
    is the bordered system's product (the top rows of A [z; 0] are H z, shifted where A is).

    :class:`FourierNewtonSystem` keeps one for the Newton steps after the one it was made at
    while φ stays within :data:`REUSE` of its φ (node by node): made at another state it is
    still a fixed linear map, so GMRES converges to the same solution, only in more
    iterations (the constraint rows' part of A x₁, C x₁, is then taken at the current
    state). Its set-up (H on each of its 240 functions at n_θ = 8) costs about two GMRES
    solves (29 s against 11 s a solve at the triaxial branch's a = 1.0), but one made
    far away is worth little: the a = 0.7 point's at a = 1.0 took 169 iterations (26 with
    its own)."""

    def __init__(self, Z: np.ndarray, apply, C: list, phi: np.ndarray):
        from fem_ade.backends.fem.coarse import independent_basis

        self.phi = phi
        C = np.array(C)
        Z -= (Z @ C.T) @ np.linalg.solve(C @ C.T, C)  # in place: Z is 2.6 GB at n_θ = 16
        k, N = len(C), Z.shape[1]
        self.Z, self.HZ = Z, np.empty_like(Z)
        for z, hz in zip(Z, self.HZ, strict=True):
            hz[:] = apply(np.concatenate([z, np.zeros(k)]))[:N]
        B = independent_basis(Z @ Z.T)  # an orthonormal basis of Z's span (Z may be deficient)
        E = B.T @ (Z @ self.HZ.T) @ B
        t, Y = np.linalg.eigh((E + E.T) / 2.0)
        inv = np.zeros_like(t)
        big = np.abs(t) > 1e-12 * np.abs(t).max()
        inv[big] = 1.0 / t[big]
        self.E_inverse = (B @ Y) @ (inv[:, None] * (B @ Y).T)

    def step(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        y = self.E_inverse @ (self.Z @ r)
        return self.Z.T @ y, self.HZ.T @ y


@dataclass
class _Fields:
    phi: np.ndarray
    mu: np.ndarray
    Kphi: np.ndarray
    lam: np.ndarray


def theta_mean(space: FourierSpace, x: np.ndarray) -> np.ndarray:
    """The θ-mean of a nodal field on the (r, z) nodes."""
    out = np.empty(space.rz.n_dofs)
    out[space.axis] = x[:space.na]
    out[space.off] = x[space.na:].reshape(space.n_theta, space.no).mean(axis=0)
    return out


def lowest(state: FourierState, k: int = 3, sigma: float = -1e-5,
           tol: float = 1e-8) -> np.ndarray:
    """The ``k`` eigenvalues of H v = λ P v nearest ``sigma`` on the constrained space (V, A
    held, P-orthogonal to the translation along z as the blocks are; no amplitude pin) of a
    steady ``state``: its stability among the fields of its space (the shape's mirror
    symmetries), by shift-invert Lanczos (ARPACK) with the bordered H − σP solved by GMRES
    (:class:`KKTSolver`)."""
    from scipy.sparse.linalg import LinearOperator, eigsh

    from fem_ade.backends.fem.newton import lagrangian_hessian_vector, linearize

    sys_ = FourierNewtonSystem(state)
    t = translation(state.space, state.phi)  # the blocks' zero mode of m = 0: P·∂_zφ
    sys_.translations = [sys_.P(t) / math.sqrt(float(t @ sys_.P(t)))]
    lin = linearize(sys_, state.phi)
    solver = KKTSolver(sys_, lin, rtol=tol * 1e-2, sigma=sigma)
    n = lin.phi.size

    def H(x):
        return lagrangian_hessian_vector(sys_.step, lin, x)

    ops = [LinearOperator((n, n), matvec=f, dtype=float) for f in
           (H, sys_.P, lambda x: solver.solve(np.ravel(x))[0])]
    v0 = solver.solve(sys_.P(np.random.default_rng(1).standard_normal(n)))[0]
    found = eigsh(ops[0], k=k, M=ops[1], sigma=sigma, which="LM", OPinv=ops[2], v0=v0,
                  tol=tol, ncv=max(2 * k + 2, 8), return_eigenvectors=False)
    return np.sort(np.asarray(found))


def translation(space: FourierSpace, phi: np.ndarray) -> np.ndarray:
    """∂_zφ on a Fourier space (each angle's (r, z) field differentiated along z)."""
    from fem_ade.backends.fem.tensor import along

    rz = space.rz
    S = space.slices(phi).reshape((space.n_theta,) + tuple(rz.shape))
    dz = along(rz.axes[1].derivative, S, 2).reshape(space.n_theta, -1)
    return space.from_slices(dz)
