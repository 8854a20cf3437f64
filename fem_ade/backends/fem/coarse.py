"""A coarse space of the membrane's shape modes for MINRES on the Newton system of a tensor
space without a direct solve (3D; docs/model.md §12); its functions on the Fourier–(r, z)
geometry (:func:`fourier_shape_functions`, for its GMRES: docs/model.md §13).

Why: Newton's preconditioner P, the bulk Hessian (:mod:`fem_ade.backends.fem.newton`), sees
a displacement of the interface as a bulk mode of eigenvalue ~4κ/ε³, where the Hessian gives
it the bending energy's: in units of P the shape modes' eigenvalues are ~1e-2 (3D, ε = 0.04,
32³) down to ~1e-5 (ε = 0.01), and MINRES spends its iterations on them — 331–389 per
Newton step on the tilted prolate at 64³ nodes, ε = 0.02 (studies/newton3d_bench.py). The cure is to
tell the preconditioner those modes' true curvature.

The coarse functions (:func:`shape_functions`). Moving the interface by a small vector field
δ moves φ by −δ·∇φ. Take δ's components from the Legendre polynomials of total degree ≤ d on
the interface's bounding box, each evaluated at the node's projection onto the surface
(x − s n, with s = √2 ε artanh φ the signed distance of the equilibrium profile and
n = ∇φ/|∇φ|), so that the function is constant across the interface as a displacement is:
z = p(x − s n) ∂ₐφ for each polynomial p and axis a, dim·C(d + dim, dim) functions (252 at
d = 6 in 3D). Measured, unsmoothed, on the tilted prolate at 32³, ε = 0.04 (first Newton
step, MINRES 118 iterations with P alone): piecewise-linear hats on an 8³ grid times ∂ₐφ without the
projection 81 iterations, with it 67; these polynomials at d = 6, 38. With |∇φ| in place of
the three ∂ₐφ (normal displacements only) 104 at 64³ against 55.

The preconditioner (:class:`CoarseSpace`). The functions Z (k × N) are projected onto the
constraints' tangent space, Z ← Z − (S⁻¹CᵀZᵀ)ᵀP⁻¹C with S = CᵀP⁻¹C (so that the bordered
system's preconditioner keeps S for its constraint block); smoothed, Z ← (I − P⁻¹H)Z, one
Richardson step with the bulk preconditioner (the prolongation smoothing of smoothed
aggregation: it damps the functions' bulk parts, where P⁻¹H ≈ 1, and keeps their shape-mode
parts, where P⁻¹H ≪ 1) and projected again; then the Ritz pairs of the Lagrangian's Hessian
H there, Z H Zᵀ y = θ Z P Zᵀ y (directions dependent to 1e-10 of the largest dropped), and
with V the P-orthonormal Ritz vectors of |θ| < ``cut``,

    M⁻¹ = P⁻¹ + Vᵀ diag(1/|θ| − 1) V,

P⁻¹ with each Ritz vector's eigenvalue 1/|θ| in place of 1: the two-level (additive coarse
correction) form of deflation by Ritz vectors, which equals V|Θ|⁻¹Vᵀ plus P⁻¹ on V's
P-orthogonal complement. It is symmetric positive definite for any V — a V made at another
state is still a preconditioner, only a weaker one, and MINRES converges to the same
solution — so one coarse space serves several Newton steps and continuation points;
:class:`~fem_ade.backends.fem.newton.NewtonSystem` makes a new one when a solve's iterations
have grown to :data:`REBUILD` times those of the first solve with it. Why the smoothing: a
Ritz vector is not an eigenvector, and what of it is bulk (its residual) the correction
amplifies by 1/|θ|; without it, a low degree made MINRES slower than P alone (the figures at
:data:`DEGREE`).

What it costs: per smoothing step, H and P⁻¹ on the stack; then one product with K on it and
Z H Zᵀ, Z P Zᵀ from Gram products (K is symmetric, so Zᵀ K W⁻¹ K Z = (KZ)ᵀ W⁻¹ (KZ) and
Zᵀ K diag(α) Z = (KZ)ᵀ diag(α) Z); two k × N arrays (0.35 GB each at 64³, d = 5); and a
product with V and Vᵀ per MINRES iteration, which at 32³ costs as much as P⁻¹ — the coarse
space halves the iterations there but not the time; the two break even at 48³ and it pays at
64³ (studies/newton3d_bench.py; :data:`fem_ade.backends.fem.newton.COARSE_FROM`).
"""

from __future__ import annotations

import itertools
import math
import time

import numpy as np

#: the polynomials' total degree and the smoothing steps (:class:`CoarseSpace`); measured on the
#: first Newton step of studies/newton3d_bench.py's tilted prolate at 64³, ε = 0.02 (one thread;
#: 389 MINRES iterations with P alone, 13 s; ``cut`` 0.5): unsmoothed d = 4, 5, 6, 7: 94, 78, 55,
#: 49 iterations after 2.6, 4.7, 8.9, 16 s of set-up; one smoothing step, d = 4, 5, 6: 69, 52, 41
#: after 5.7, 9.6, 16 s (a solve 3.5, 3.0, 2.7 s). On the oblate of tests/test_switch.py with its
#: m = 2 mode (32³ nodes, order 8, ε = 0.04; 67 with P alone) unsmoothed d = 2, 4, 6: 113, 77, 59
#: — worse than P alone at low degree — and smoothed once 70, 46, 34 (d = 5: 36); twice 67, 39,
#: 30
DEGREE, SMOOTH = 5, 1
#: Ritz values below this (in units of P) are deflated; above it P is a fair model already
#: (measured, d = 5 smoothed once: 0.05, 0.1, 0.2, 0.5, 1 deflate 12, 24, 42, 98, 164 vectors
#: and take 53, 37, 32, 30, 30 iterations on the tilted prolate at 32³; at 64³ 0.2 and 0.5
#: take 53 and 52, a solve 2.8 and 3.0 s)
CUT = 0.2
#: a Ritz value's magnitude is floored here: a zero mode left in the space (none should
#: be: the constraints' gradients hold the rigid motions) must not make M singular
FLOOR = 1e-10
#: a solve taking this many times the iterations of the first solve with a coarse space
#: marks the space stale (the state has moved too far from where it was made)
REBUILD = 2.0
#: the polynomials' total degree of the Fourier–(r, z) geometry's coarse functions
#: (:func:`fourier_shape_functions`, used by :class:`fem_ade.backends.fem.fourier.KKTSolver`).
#: Measured on the triaxial branch's a = 1.0 point (studies/triaxial.py; n_θ = 8, 0.34M
#: unknowns, one thread; GMRES to 1e-8 with the θ-mean blocks alone: 256 iterations, 82 s):
#: d = 2, 3, 4, 6: 40, 33, 26, 28 iterations in 15, 14, 13, 18 s after 8.5, 14, 23, 45 s of
#: set-up; d = 4 with the θ-displacements p ∂_θφ/r sin(j m₀ θ) added: 24; without the
#: projection x − s n: 39. At a = 0.4: 123 → 21 iterations; at a = 0.05 (n_θ = 4): 23 → 8
FOURIER_DEGREE = 4
#: rows of the stack per product (bounds the temporaries: CHUNK × N doubles)
CHUNK = 32


def shape_functions(space, phi: np.ndarray, eps: float, degree: int = DEGREE) -> np.ndarray:
    """The coarse functions (k × N) of the interface of ``phi`` on a tensor ``space`` (module
    docstring): p(x − s n) ∂ₐφ for the Legendre polynomials p of total degree ≤ ``degree`` in
    the interface's bounding box and each axis a."""
    from fem_ade.backends.fem.modes import gradient

    grads = gradient(space, phi)
    Z = np.empty((math.comb(degree + space.dim, space.dim) * space.dim, phi.size))
    row = 0
    for p in _polynomials(space.doflocs, phi, np.array(grads), eps, degree):
        for g in grads:
            np.multiply(p, g, out=Z[row])
            row += 1
    return Z


def fourier_shape_functions(space, phi: np.ndarray, eps: float,
                            degree: int = FOURIER_DEGREE) -> np.ndarray:
    """The coarse functions (k × N) of the interface of ``phi`` on a Fourier–(r, z) ``space``
    (:class:`fem_ade.backends.fem.fourier.FourierSpace`): p(x − s n) ∂ₐφ cos(j m₀ θ) for the
    Legendre polynomials p of total degree ≤ ``degree`` in the (r, z) bounding box of the
    interface's every angle, a ∈ {r, z} and j < n_θ — a displacement of the interface in
    (r, z) that varies along θ as a cosine; x − s n and ∂ₐφ are each angle's (its (r, z)
    slice's)."""
    from fem_ade.backends.fem.modes import gradient

    S = space.slices(phi)
    grads = np.array([gradient(space.rz, s) for s in S]).transpose(1, 0, 2)  # (2, n_θ, N_rz)
    X = np.broadcast_to(space.rz.doflocs[:, None, :], grads.shape)
    cosines = np.cos(np.outer(space.m, space.theta))[:, :, None]  # (j, angle, 1)
    Z = np.empty((math.comb(degree + 2, 2) * len(cosines) * 2, phi.size))
    rows = iter(Z)
    for p in _polynomials(X, S, grads, eps, degree):
        for c in cosines:
            for g in grads:
                next(rows)[:] = space.from_slices(p * g * c)
    return Z


def _polynomials(X: np.ndarray, phi: np.ndarray, grads: np.ndarray, eps: float,
                 degree: int):
    """The Legendre polynomials of total degree ≤ ``degree`` in the bounding box of the
    interface (|φ| < 0.9), each at the nodes' projections x − s n onto it (``X`` the nodes'
    coordinates and ``grads`` ∇φ, axis first), in the order of :func:`shape_functions`."""
    from numpy.polynomial import legendre

    dim = len(X)
    norm = np.sqrt(sum(g * g for g in grads))
    s = math.sqrt(2.0) * eps * np.arctanh(np.clip(phi, -1.0 + 1e-6, 1.0 - 1e-6))
    X = X - s / np.maximum(norm, 1e-300) * grads
    band = np.abs(phi) < 0.9
    if not np.any(band):
        raise ValueError("the field has no interface (|phi| >= 0.9 everywhere)")
    lo = np.array([x[band].min() for x in X])
    hi = np.array([x[band].max() for x in X])
    half = np.maximum((hi - lo) / 2.0, 1e-12)
    shape = (dim,) + (1,) * (X.ndim - 1)
    U = np.clip((X - ((lo + hi) / 2.0).reshape(shape)) / half.reshape(shape), -1.0, 1.0)
    eye = np.eye(degree + 1)
    P1 = [[legendre.legval(U[a], eye[q]) for q in range(degree + 1)] for a in range(dim)]
    for q in itertools.product(range(degree + 1), repeat=dim):
        if sum(q) <= degree:
            p = P1[0][q[0]].copy()
            for a in range(1, dim):
                p *= P1[a][q[a]]
            yield p


def independent_basis(G: np.ndarray) -> np.ndarray:
    """B with Bᵀ G B = I spanning the functions whose Gram matrix is ``G`` (k × k), the
    directions of G's eigenvalues below 1e-10 of its largest dropped (dependent functions)."""
    g, Q = np.linalg.eigh(G)
    keep = g > 1e-10 * g.max()
    return Q[:, keep] / np.sqrt(g[keep])


def hessian(space, ke: float, co: dict, z: np.ndarray) -> np.ndarray:
    """H z for a stack z (k × N), H = κε K W⁻¹K + K diag(α) + diag(α) K + W diag(γ) + c₀ K +
    Σ σᵢ bᵢbᵢᵀ from its coefficients ``co`` (:meth:`fem_ade.backends.fem.step.MixedStep.
    hessian_coefficients`; equal to ``hessian_vector`` + ``constraint_hessian_vector``
    row by row), ``ke`` = κε."""
    w = space.weights
    kz = w * space.laplacian(z)
    hz = (ke * w * space.laplacian(kz / w) + w * space.laplacian(co["alpha"] * z)
          + co["alpha"] * kz + w * co["gamma"] * z + co["c0"] * kz)
    for s, b in co["rank_one"]:
        hz += s * np.outer(z @ b, b)
    return hz


class CoarseSpace:
    """The coarse correction of the Newton system's preconditioner at ``lin`` (module
    docstring): ``apply(x)`` = Vᵀ diag(1/|θ| − 1) V x; ``theta`` the Ritz values (all,
    ascending), ``size`` the functions, ``rank`` the independent ones, ``deflated`` the
    vectors kept, ``seconds`` the wall time it took; ``solves`` and ``first`` the solves
    made with it, the iterations of the first and of the last."""

    def __init__(self, sys_, lin, degree: int = DEGREE, cut: float = CUT,
                 smooth: int = SMOOTH):
        t0 = time.perf_counter()
        space, w = sys_.space, sys_.w
        Z = shape_functions(space, lin.phi, sys_.params.eps, degree)
        self.size = Z.shape[0]
        C = np.array(lin.C)
        PC, S = sys_.constraint_block(lin.C)
        PC = np.array(PC)
        Z -= np.linalg.solve(S, C @ Z.T).T @ PC
        a, c, ke = sys_.bulk()
        co = sys_.step.hessian_coefficients(lin.phi, lin.mu, lin.Kphi, lin.lam[0], lin.lam[1])
        for _ in range(smooth):
            for i in range(0, len(Z), CHUNK):
                z = Z[i:i + CHUNK]
                Z[i:i + CHUNK] = z - sys_.P_inverse(hessian(space, ke, co, z))
            Z -= np.linalg.solve(S, C @ Z.T).T @ PC
        KZ = np.empty_like(Z)
        for i in range(0, len(Z), CHUNK):
            KZ[i:i + CHUNK] = w * space.laplacian(Z[i:i + CHUNK])
        G, A = self._grams(Z, KZ, w, (a, c, ke), co)
        del KZ
        B = independent_basis(G)
        theta, Y = np.linalg.eigh(B.T @ A @ B)
        self.theta, self.rank = theta, B.shape[1]
        chosen = np.abs(theta) < cut
        self.V = (B @ Y[:, chosen]).T @ Z
        self.d = 1.0 / np.maximum(np.abs(theta[chosen]), FLOOR) - 1.0
        self.deflated = int(chosen.sum())
        self.seconds = time.perf_counter() - t0
        self.solves, self.first, self.last = 0, None, 0

    @staticmethod
    def _grams(Z, KZ, w, bulk, co):
        """Z P Zᵀ and Z H Zᵀ (H: :meth:`fem_ade.backends.fem.step.MixedStep.
        hessian_coefficients`) from Gram products of Z and KZ."""
        a, c, ke = bulk
        k = len(Z)
        ZZ, ZK, KK, KAZ, ZGZ = (np.zeros((k, k)) for _ in range(5))
        wg = w * co["gamma"]
        for i in range(0, k, CHUNK):
            z, kz = Z[i:i + CHUNK], KZ[i:i + CHUNK]
            ZZ[i:i + CHUNK] = (z * w) @ Z.T
            ZK[i:i + CHUNK] = z @ KZ.T
            KK[i:i + CHUNK] = (kz / w) @ KZ.T
            KAZ[i:i + CHUNK] = (kz * co["alpha"]) @ Z.T
            ZGZ[i:i + CHUNK] = (z * wg) @ Z.T
        G = a * ZZ + c * ZK + ke * KK
        A = ke * KK + KAZ + KAZ.T + ZGZ + co["c0"] * ZK
        for s, b in co["rank_one"]:
            zb = Z @ b
            A += s * np.outer(zb, zb)
        return (G + G.T) / 2.0, (A + A.T) / 2.0

    def apply(self, x: np.ndarray) -> np.ndarray:
        return self.V.T @ (self.d * (self.V @ x))

    def record(self, iterations: int) -> None:
        """Count a solve made with this space."""
        self.solves, self.last = self.solves + 1, int(iterations)
        if self.first is None:
            self.first = max(self.last, 1)

    @property
    def stale(self) -> bool:
        """True once a solve has taken :data:`REBUILD` times the first one's iterations."""
        return self.first is not None and self.last > REBUILD * self.first

    def describe(self) -> dict:
        return {"functions": self.size, "rank": self.rank, "deflated": self.deflated,
                "lowest_ritz": [float(t) for t in self.theta[:4]],
                "seconds": round(self.seconds, 2)}
