"""The linear solve of one step: one interface, two strategies.

With the GLL mass W diagonal (:mod:`fem_ade.backends.fem.gll`), μ eliminated as μ = W⁻¹Kφ, every
scheme's step operator is

    S = a W + c K + κε K W⁻¹ K,      a = 1/Δt + s₀,   c = s₂ − 2κ/ε        (:class:`StepMatrix`)

(s₀ = s₂ = 0: the paper's scheme; else the stabilized one), plus, in the stabilized scheme, a
rank ≤ 3 term Σ σᵢbᵢbᵢᵀ (the penalties' Hessians). S is SPD exactly when Δt < ε³/κ or
s₂ ≥ 2κ/ε, as the spectral symbol. A solver answers one question (:meth:`solve`): given
right sides r₁ … r_k (the step's descent direction and the exact constraints' directions),
return Ŝ⁻¹rⱼ, Ŝ = S + Σσbbᵀ.

* :class:`DiagonalizedSolver` (``fdm``; tensor meshes, any order, uniform or graded): **fast
  diagonalization** (Lynch, Rice & Thomas 1964; Deville, Fischer & Mund §4.3.3). On a tensor
  mesh W = ⊗ wₐ and K = Σₐ K₁⁽ᵃ⁾ ⊗ (⊗_{b≠a} w_b), so with the 1D generalized eigenbases
  K₁⁽ᵃ⁾Vₐ = diag(wₐ)VₐΛₐ, VₐᵀWₐVₐ = I, and V = ⊗Vₐ:

      VᵀWV = I,   VᵀKV = Λ = Λ₀ ⊕ Λ₁ ⊕ Λ₂,   VᵀKW⁻¹KV = Λ²,   S⁻¹ = V (a + cΛ + κεΛ²)⁻¹ Vᵀ

  — exact, with no iteration: d dense 1D transforms forward, a diagonal scaling, d back
  (BLAS-3 products along the grid lines; the real FFT where the 1D matrices are circulant,
  p = 1 on a uniform mesh). The rank-one terms enter by Woodbury, all right sides of a step
  in one batched transform.
* :class:`KrylovSolver` (``amg``, ``chebyshev``, ``jacobi``; every mesh): preconditioned CG
  on the matrix-free Ŝ with the Bosch–Kay–Stoll–Wathen-type preconditioner
  P = (1/τ)(W + sK̃)W⁻¹(W + sK̃), s = √(τκε), τ = 1/a, each (W + sK̃)⁻¹ approximated by one
  pyamg smoothed-aggregation V-cycle (``amg``), a Chebyshev polynomial (``chebyshev``) or a
  scaled diagonal (``jacobi``). K̃ is K for p = 1 and for file meshes; for p > 1 on tensor
  meshes each (W + sK)⁻¹ is :data:`INNER_ITERATIONS` PCG iterations on the high-order
  W + sK preconditioned by W + sK̃, K̃ the **low-order refined** stiffness — p = 1 on the GLL
  nodes, spectrally equivalent to K (Orszag 1980; Canuto 1994; MFEM's LOR solvers) and as
  sparse as a Q1 matrix — and the outer CG is the flexible one, so the iteration counts stay
  flat in h and p. The stopping test is relative to the size of the step's residual at the
  previous state (``scales``), so the tolerance follows the change.

``auto`` is ``fdm`` on tensor meshes, else ``chebyshev`` on meshes of near-uniform cells while
W + sK is mass-dominated, else ``amg``. ``fft`` is ``fdm`` restricted to the meshes where it
uses the FFT (p = 1, uniform).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from fem_ade.backends.fem.tensor import along
from fem_ade.model.params import ModelError
from fem_ade.registry import FEM_SOLVERS as SOLVERS

#: ``auto`` takes ``chebyshev`` (file meshes) while s·max(K_ii/w_i) ≤ this (W + sK mass-
#: dominated enough that D⁻¹(W + sK) has condition ≤ 1 + 2·this by Gershgorin), else ``amg``
AUTO_CHEBYSHEV_LIMIT = 20.0
#: ``chebyshev`` takes degree 2 while s·max(K_ii/w_i) ≤ this, else 4
CHEBYSHEV_LOW_DEGREE_LIMIT = 2.0
#: PCG stops at rtol·‖b − Sφⁿ‖. Measured (discocyte 32³, 50 steps, against the exact
#: solve): |ΔE| = 3e-8 at 1e-6 and 2e-6 at 1e-5, against a discretisation error |ΔE| ≈ 3.
DEFAULT_RTOL = 1e-6
#: keyword arguments of pyamg.smoothed_aggregation_solver for the ``amg`` solver
AMG_OPTIONS: dict = {}
#: the stabilized scheme's preconditioner shift s is rounded to a power of this, so that the
#: AMG hierarchy of W + sK̃ is reused while the ratcheted (s₀, s₂) move by small amounts: the
#: step operator is always the exact one, only P is off by ≤ 2.5 % in s. A function of
#: (s₀, s₂) alone, so a resumed run rebuilds the same P (bit-identical runs).
SHIFT_GRID = 1.05
#: the solvers that solve exactly (no tolerance, no iteration)
EXACT = ("fdm", "fft")
#: for p > 1 each (W + sK)⁻¹ of the preconditioner is this many PCG iterations on the
#: high-order W + sK, preconditioned by the low-order refined one (its V-cycle, Chebyshev
#: polynomial or diagonal). Measured (discocyte, paper Δt, outer its per step): one V-cycle
#: on the LOR matrix alone gives 26, 31, 34 at 64³, 96³, 128³ nodes (p = 4) — K̃W⁻¹K̃ is not
#: spectrally equivalent to KW⁻¹K, though K̃ is to K — while 3 inner iterations give 9, 9
#: at 64³ and 96³ for p = 4 and 8, in 0.6× the time
INNER_ITERATIONS = 3

#: the sum of a partial sum over the MPI ranks (None: one process); set by
#: :mod:`fem_ade.backends.fem.petsc` when the DOFs are distributed, so that every functional and
#: every dot product of the step is global
_ALLREDUCE = None


def global_dot(a, b) -> float:
    """a·b without BLAS: ``np.dot`` of long vectors goes to a threaded BLAS, whose threads
    wait for a time slice on a loaded machine (measured on 2 busy cores: 7 ms per dot of 32³
    values, ten times the step's cost); einsum's own loop takes 20 µs, always. Distributed
    DOFs: this rank's part, summed over the ranks. Every inner product of the FEM backend's
    forms, step, Newton and continuation goes through it."""
    value = float(np.einsum("i,i->", a, b))
    return value if _ALLREDUCE is None else _ALLREDUCE(value)


def norm(x) -> float:
    return math.sqrt(global_dot(x, x))


@dataclass(frozen=True)
class StepMatrix:
    """S = a W + c K + κε K W⁻¹ K, the operator of every scheme's step (module docstring)."""

    a: float
    c: float
    ke: float

    @classmethod
    def of(cls, *, dt: float, kappa: float, eps: float, s0: float = 0.0,
           s2: float = 0.0) -> StepMatrix:
        return cls(1.0 / dt + s0, s2 - 2.0 * kappa / eps, kappa * eps)

    @property
    def tau(self) -> float:
        """The effective time step 1/a."""
        return 1.0 / self.a

    def symbol(self, lam):
        """a + cλ + κελ²: S on an eigenvector of W⁻¹K with eigenvalue λ."""
        return self.a + self.c * lam + self.ke * lam * lam

    def shift(self, stabilized: bool) -> float:
        """The preconditioner's s (:func:`preconditioner_shift`; on the grid of
        :data:`SHIFT_GRID` for the stabilized scheme)."""
        if not stabilized:
            return math.sqrt(self.tau * self.ke)
        s_opt = preconditioner_shift(self.tau, self.c, self.ke)
        return SHIFT_GRID ** round(math.log(s_opt) / math.log(SHIFT_GRID))


def pcg(A, b, x0, M, atol, maxiter=500):
    """Flexible preconditioned CG stopping at ‖r‖ ≤ atol; ``A``, ``M`` are callables. Returns
    (x, its); on breakdown or maxiter, the last iterate.

    β is the Polak–Ribière one, rₖ₊₁·(zₖ₊₁ − zₖ)/rₖ·zₖ (Notay 2000): the same iterates as the
    textbook recurrence for a linear SPD preconditioner, and robust when the preconditioner
    is a few inner iterations (the high-order ``amg`` path)."""
    x = np.array(x0, dtype=float, copy=True)
    r = b - A(x)
    if norm(r) <= atol:
        return x, 0
    z = M(r)
    p = z.copy()
    rz = global_dot(r, z)
    its = 0
    while its < maxiter:
        q = A(p)
        pq = global_dot(p, q)
        if not (pq > 0.0 and math.isfinite(pq)):
            break
        alpha = rz / pq
        x += alpha * p
        r -= alpha * q
        its += 1
        if norm(r) <= atol:
            break
        z_old = z
        z = M(r)
        rz_new = global_dot(r, z)
        beta = (rz_new - global_dot(r, z_old)) / rz
        p *= beta
        p += z
        rz = rz_new
    return x, its


def chebyshev_inverse(A: sp.csr_matrix, degree: int, lower_ratio: float = 30.0):
    """A fixed polynomial p(D⁻¹A)D⁻¹ ≈ A⁻¹ (Chebyshev iteration from zero, ``degree`` steps).

    The spectrum of D⁻¹A is taken in [λmin, λmax]: λmax from a few power iterations (×1.05),
    λmin from Gershgorin's discs when they stay positive (for W + sK they do: λmin ≥
    1/(1 + s·max K_ii/w_i)), else λmax/``lower_ratio``. The residual polynomial is a scaled
    Chebyshev polynomial, so p > 0 on (0, λmax] and the operator is SPD for any SPD A.
    """
    from pyamg.util.linalg import approximate_spectral_radius

    diag = A.diagonal()
    dinv = 1.0 / diag
    DA = sp.diags(dinv) @ A
    lmax = 1.05 * approximate_spectral_radius(DA, maxiter=30, symmetric=False)
    gershgorin = float(np.min(2.0 - np.asarray(abs(A).sum(axis=1)).ravel() * dinv))
    lmin = max(gershgorin, lmax / lower_ratio)
    theta, delta = 0.5 * (lmax + lmin), 0.5 * (lmax - lmin)

    def apply(r):
        r = np.asarray(r).ravel()
        # Chebyshev iteration for A x = r, x0 = 0 (Saad, Alg. 12.1)
        sigma = theta / delta
        rho = 1.0 / sigma
        d = dinv * r / theta
        x = d.copy()
        res = r.copy()
        for _ in range(degree - 1):
            res = res - A @ d
            rho_new = 1.0 / (2.0 * sigma - rho)
            d = rho_new * rho * d + 2.0 * rho_new / delta * (dinv * res)
            x += d
            rho = rho_new
        return x

    return apply


def preconditioner_shift(tau, c, ke):
    """The s of P = (1/τ)(W + sK)W⁻¹(W + sK) for S = W/τ + cK + κε K W⁻¹K.

    On an eigenvector of W⁻¹K (eigenvalue y) P⁻¹S is (1 + cτy + κετy²)/(1 + sy)². With
    s = √(κετ) (which matches the y² term; the paper's scheme, c = −2κ/ε < 0) the ratio lies in
    [min(1, (2 + β)/4), max(1, (2 + β)/4)], β = cτ/√(κετ). For the stabilized scheme (c > 0)
    β may exceed 2; then s is raised to the value that minimises the ratio's spread over y
    (a scalar search, measured cheap and decisive: see ``tests/test_fem_schemes.py``).
    """
    s_star = math.sqrt(ke * tau)
    beta = c * tau / s_star
    if beta <= 2.0:
        return s_star
    t = np.logspace(-4, 4, 801)
    num = 1.0 + beta * t + t * t

    def spread(sig):
        r = num / (1.0 + sig * t) ** 2
        return r.max() / r.min()

    sigmas = np.linspace(1.0, 0.5 * beta, 200)
    best = min(sigmas, key=spread)
    return float(best) * s_star


def woodbury(solve_stack, rhs: list, low_rank) -> list:
    """Ŝ⁻¹rⱼ for Ŝ = S + Σσᵢbᵢbᵢᵀ from S⁻¹ applied once to the stack [r…, b…]
    (``solve_stack``: list → list): y − Z G⁻¹Bᵀy, Z = S⁻¹B, G = diag(1/σ) + BᵀZ."""
    if not low_rank:
        return solve_stack(rhs)
    bs = [b for _, b in low_rank]
    out = solve_stack(list(rhs) + bs)
    ys, zs = out[: len(rhs)], out[len(rhs):]
    G = np.array([[global_dot(b, z) for z in zs] for b in bs])
    G += np.diag([1.0 / sig for sig, _ in low_rank])
    result = []
    for y in ys:
        coef = np.linalg.solve(G, [global_dot(b, y) for b in bs])
        for ci, zi in zip(coef, zs, strict=True):
            y = y - ci * zi
        result.append(y)
    return result


# ---------------------------------------------------------------------------------------------
# fast diagonalization (tensor meshes)
# ---------------------------------------------------------------------------------------------
class Eigenbasis:
    """The eigenbasis V of W⁻¹K on a tensor space (module docstring): ``lam`` (Λ on the
    transformed grid), ``forward`` (Vᵀ, on a stack of functionals), ``backward`` (V).

    When the 1D matrices are circulant (p = 1, uniform mesh) V can be the real Fourier
    transform (then Vᵀ is rfftn and V irfftn up to the scale ``scale`` = W, a number;
    ``fourier`` None: wherever it can); otherwise V is built from the dense 1D generalized
    eigenproblems K₁v = λ diag(w) v (``scipy.linalg.eigh``), once per mesh.
    """

    def __init__(self, space, fourier: bool | None = None):
        self.shape = tuple(space.shape)
        self.dim = len(self.shape)
        self.fourier = space.circulant if fourier is None else fourier
        if self.fourier and not space.circulant:
            raise ModelError("the FFT diagonalizes circulant 1D operators only (order 1 on a "
                             "uniform mesh)")
        if self.fourier:
            from scipy import fft

            from fem_ade.backends.threads import fft_workers

            self.fft, self.workers = fft, fft_workers()
            lams = []
            for a, ax in enumerate(space.axes):
                n, h = ax.size, float(ax.gaps[0])
                theta = 2.0 * np.pi * (fft.rfftfreq(n) if a == self.dim - 1 else fft.fftfreq(n))
                lams.append((2.0 - 2.0 * np.cos(theta)) / h**2)
            self.scale = float(space.weights[0])
        else:
            import scipy.linalg as sl

            lams, self.V, self.VT = [], [], []
            for ax in space.axes:
                lam, vec = sl.eigh(ax.stiffness.toarray(), np.diag(ax.weights))
                lams.append(np.maximum(lam, 0.0))  # the constants: 0 (to round-off)
                self.V.append(np.ascontiguousarray(vec))
                self.VT.append(np.ascontiguousarray(vec.T))
            self.scale = 1.0
        lam = 0.0
        for a, la in enumerate(lams):
            view = [1] * self.dim
            view[a] = -1
            lam = lam + la.reshape(view)
        self.lam = lam

    def inverse(self, S: StepMatrix) -> np.ndarray:
        """1/(Ŝ·scale) on the transformed grid."""
        return 1.0 / (S.symbol(self.lam) * self.scale)

    def apply(self, stack: np.ndarray, inv_symbol: np.ndarray) -> np.ndarray:
        """V diag(inv_symbol) Vᵀ on a stack (k, N) of vectors, one batched transform."""
        k = stack.shape[0]
        X = stack.reshape((k,) + self.shape)
        axes = tuple(range(1, self.dim + 1))
        if self.fourier:
            Xh = self.fft.rfftn(X, axes=axes, workers=self.workers)
            Xh *= inv_symbol
            return self.fft.irfftn(Xh, s=self.shape, axes=axes,
                                   workers=self.workers).reshape(k, -1)
        for a in range(self.dim):
            X = along(self.VT[a], X, a + 1)
        X = X * inv_symbol
        for a in range(self.dim):
            X = along(self.V[a], X, a + 1)
        return X.reshape(k, -1)


class DiagonalizedSolver:
    """Ŝ⁻¹ exactly by fast diagonalization (module docstring): no iteration, ``its`` = 0."""

    levels = 0
    rtol = None

    def __init__(self, basis: Eigenbasis, S: StepMatrix):
        self.basis, self.S = basis, S
        self.kind = "fft" if basis.fourier else "fdm"
        self.inv_symbol = basis.inverse(S)

    def _solve_stack(self, vectors: list) -> list:
        out = self.basis.apply(np.stack(vectors), self.inv_symbol)
        return list(out)

    def solve(self, rhs: list, x0=None, scales=None, low_rank=()):
        """([Ŝ⁻¹r for r in rhs], 0)."""
        return woodbury(self._solve_stack, rhs, low_rank), 0


# ---------------------------------------------------------------------------------------------
# preconditioned CG (every mesh)
# ---------------------------------------------------------------------------------------------
def amg_vcycle(B: sp.csr_matrix):
    """One pyamg smoothed-aggregation V-cycle for B (public API: ``aspreconditioner``)."""
    import pyamg

    ml = pyamg.smoothed_aggregation_solver(B, symmetry="hermitian", max_coarse=500,
                                           **AMG_OPTIONS)
    for level in ml.levels:  # pyamg keeps coarse levels as BSR with 1×1 blocks, whose
        level.A = level.A.tocsr()  # Gauss–Seidel is the slow generic one
        for name in ("P", "R"):
            if hasattr(level, name):
                setattr(level, name, getattr(level, name).tocsr())
    return len(ml.levels), ml.aspreconditioner(cycle="V").matvec


class KrylovSolver:
    """Ŝ⁻¹ by PCG (module docstring). ``space`` gives W (``weights``), K (``K @ x``) and K̃
    (``preconditioner_stiffness()``); ``cache`` shares the preconditioners of W + sK̃ by
    (kind, s) across the solvers of one run (the stabilized scheme's ratchet)."""

    def __init__(self, space, S: StepMatrix, *, kind: str = "amg", rtol: float | None = None,
                 stabilized: bool = False, cache: dict | None = None, degree=None):
        self.space, self.S = space, S
        self.m = space.weights
        self.minv = 1.0 / self.m
        self.K = space.K
        self.rtol = DEFAULT_RTOL if rtol is None else float(rtol)
        self.s = S.shift(stabilized)
        Kt = space.preconditioner_stiffness()
        stiffness = self.s * float(np.max(Kt.diagonal() / self.m))
        if kind == "auto":
            uniform = float(np.max(self.m) / np.min(self.m)) <= 1.5
            kind = "chebyshev" if uniform and stiffness <= AUTO_CHEBYSHEV_LIMIT else "amg"
        if degree is None:
            degree = 2 if stiffness <= CHEBYSHEV_LOW_DEGREE_LIMIT else 4
        self.kind = kind
        self.degree = 1 if kind == "jacobi" else degree
        key = (kind, self.s)
        # pyamg and the Chebyshev bounds draw random start vectors: seed them (and leave the
        # caller's random state alone), so that a rebuilt solver is bit for bit the same one
        rng_state = np.random.get_state()
        np.random.seed(12345)
        try:
            if cache is not None and key in cache:
                self.levels, self.B_inv = cache[key]
            else:
                B = (sp.diags(self.m) + self.s * Kt).tocsr()
                if kind == "amg":
                    self.levels, self.B_inv = amg_vcycle(B)
                else:
                    self.levels, self.B_inv = 1, chebyshev_inverse(B, self.degree)
                if cache is not None:
                    if len(cache) >= 4:
                        cache.pop(next(iter(cache)))
                    cache[key] = (self.levels, self.B_inv)
        finally:
            np.random.set_state(rng_state)
        self.inner = INNER_ITERATIONS if getattr(space, "order", 1) > 1 and \
            getattr(space, "axes", None) is not None else 1
        if self.inner > 1:  # LOR: a few PCG iterations on the high-order W + sK
            lor_inv = self.B_inv

            def high_order(v):
                return self.m * v + self.s * (self.K @ v)

            def inner(r):
                return pcg(high_order, r, np.zeros_like(r), lor_inv, 0.0,
                           maxiter=self.inner)[0]

            self.B_inv = inner

    def apply(self, x, low_rank=()):
        """Ŝx = a W x + K(c x + κε W⁻¹K x) + Σσb(b·x)."""
        S = self.S
        y = (S.a * self.m) * x + self.K @ (S.c * x + S.ke * (self.minv * (self.K @ x)))
        for sig, b in low_rank:
            y += (sig * global_dot(b, x)) * b
        return y

    def precondition(self, r):
        """P⁻¹r = τ (W + sK̃)⁻¹ W (W + sK̃)⁻¹ r (inverses approximate)."""
        y = self.B_inv(np.asarray(r).ravel())
        return self.S.tau * self.B_inv(self.m * y)

    def solve(self, rhs: list, x0=None, scales=None, low_rank=()):
        """([x with ‖r − Ŝx‖ ≤ rtol·scale], total PCG iterations). ``x0``: warm starts;
        ``scales``: ‖r − Ŝ·(previous state)‖ per right side (default ‖r‖)."""
        xs, total = [], 0
        for j, r in enumerate(rhs):
            start = np.zeros_like(r) if x0 is None or x0[j] is None else x0[j]
            scale = norm(r) if scales is None or scales[j] is None else scales[j]
            if scale == 0.0:
                xs.append(np.zeros_like(r))
                continue
            # not converged or broken down (NaN input): return what there is; the loop's
            # guards judge the state (max |φ|, finiteness), the history shows the its.
            x, its = pcg(lambda v: self.apply(v, low_rank), np.asarray(r, dtype=float), start,
                         self.precondition, self.rtol * scale, maxiter=500)
            xs.append(x)
            total += its
        return xs, total


def make_solver(kind: str, space, S: StepMatrix, *, rtol=None, stabilized=False, cache=None,
                eigenbasis=None):
    """The solver ``kind`` (:data:`fem_ade.registry.FEM_SOLVERS`) of S on ``space``;
    ``eigenbasis``: the space's :class:`Eigenbasis` (built once per run by the caller)."""
    if kind not in SOLVERS:
        raise ModelError(f"unknown FEM solver {kind!r}; valid: {', '.join(SOLVERS)}")
    if kind == "auto":
        kind = "fdm" if eigenbasis is not None else "auto"
    if kind in EXACT:
        if eigenbasis is None:
            raise ModelError(f"solver {kind!r} needs a tensor mesh (uniform or graded)")
        if kind == "fft" and not eigenbasis.fourier:
            raise ModelError("solver 'fft' needs equally spaced nodes (order 1 on a uniform "
                             "mesh); 'fdm' solves every tensor mesh exactly")
        return DiagonalizedSolver(eigenbasis, S)
    return KrylovSolver(space, S, kind=kind, rtol=rtol, stabilized=stabilized, cache=cache)
