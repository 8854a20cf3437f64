"""The linear solve of one step (SPEC §5), behind a small interface.

With μ eliminated by the lumped mass M_L (``m`` = M·1: positive for Q1 and for tensor Q2, where
it is the Gauss–Lobatto/Simpson rule), the step matrix is

    S = M_t/Δt − (2κ/ε)K + κε K M_L⁻¹ K,

applied as three sparse products (never formed). M_t is the mass of the time derivative: M_L
by default, or the consistent M (SPEC §5 literally). With M_t = M_L, S is SPD exactly when
Δt < ε³/κ, as the spectral symbol; with M_t = M it becomes indefinite well below that (3D Q1,
n = 16: at 10× the paper's Δt), because M's smallest eigenvalues are M_L's / 27.

S is solved by preconditioned CG with the Bosch–Kay–Stoll–Wathen-type preconditioner
P = (1/Δt)(M_t + sK) M_L⁻¹ (M_t + sK), s = √(Δtκε), P⁻¹ = Δt (M_t + sK)⁻¹ M_L (M_t + sK)⁻¹,
where each (M_t + sK)⁻¹ is approximated by

- ``amg``: one pyamg smoothed-aggregation V-cycle (iteration count flat in h and Δt);
- ``chebyshev``: a fixed Chebyshev polynomial of D⁻¹(M_t + sK) (degree 2 while M_t + sK is
  strongly mass-dominated, as at the paper's Δt, else 4: :data:`CHEBYSHEV_LOW_DEGREE_LIMIT`);
- ``jacobi``: the same with degree 1 (a scaled diagonal; cheapest, weakest);
- ``auto``: ``fft`` where it applies, else ``chebyshev`` on meshes of uniform cells while
  M_t + sK is mass-dominated, else ``amg`` (the measured winners, ``studies/bench.py``: on a
  graded 64³ mesh Chebyshev needs 23 PCG iterations at the paper's Δt where AMG needs 8);
- ``fft``: uniform Q1 tensor meshes only: there M, K and M_L are circulant (Kronecker products
  of 1D circulants), so S is diagonalised by the discrete Fourier transform. The backend then
  takes the step directly in Fourier space, without PCG (:meth:`fem_ade.fem.step.MixedStep.
  fourier_step`); :func:`fft_step_inverse` is the same S⁻¹ as a preconditioner.

pyamg's coarse levels are converted to CSR (it keeps them as BSR with 1×1 blocks, whose
Gauss–Seidel is its slow generic one), and S is applied with two sparse products when M_t is
lumped, S x = (m/τ)x + K(c x + κε M_L⁻¹Kx).

The stabilized scheme (SPEC §10) solves with S = (1/Δt + s₀)M_t + (s₂ − 2κ/ε)K + κε K M_L⁻¹ K
plus a rank ≤ 3 term Σ σᵢbᵢbᵢᵀ (the penalties' Hessians), applied matrix-free inside PCG; the
preconditioner is the same P for the diagonal part with the effective step τ = 1/(1/Δt + s₀)
in place of Δt and s from :func:`preconditioner_shift` (√(τκε) in every case measured).
Measured (discocyte, Q1 32³, amg, 500 steps): 4.2 / 3.6 / 3.4 PCG its per step on average
(max 6, 6, 5) at 1× / 10× / 100× the paper's Δt; ≈ 0.04 s per step (2 cores, shared).

Interface: ``StepSolver(M_t, K, m, dt=, kappa=, eps=, kind=, rtol=, s0=0, s2=0)`` and
``solve(b, x0, ref=None, scale=None, low_rank=()) -> (x, its)``; the stopping test is relative
to the residual of ``ref`` (the previous state), so the tolerance scales with the change per
step. A PETSc version only has to provide the same two calls.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import LinearOperator

from ..model import ModelError
from ..registry import FEM_SOLVERS as SOLVERS

#: ``auto`` takes ``chebyshev`` while s·max(K_ii/m_i) ≤ this (M_L + sK mass-dominated enough
#: that D⁻¹(M_L + sK) has condition ≤ 1 + 2·this by Gershgorin), else ``amg``
AUTO_CHEBYSHEV_LIMIT = 20.0
#: ``chebyshev`` takes degree 2 while s·max(K_ii/m_i) ≤ this (the paper's Δt: measured at 64³,
#: discocyte, 5 PCG its and 9× the spectral step against 8 its and 19× at degree 4), else 4
CHEBYSHEV_LOW_DEGREE_LIMIT = 2.0
#: PCG stops at rtol·‖b − Sφⁿ‖. Measured (discocyte 32³, 50 steps, against the exact fft
#: solve): |ΔE| = 3e-8 at 1e-6 and 2e-6 at 1e-5, against a discretisation error |ΔE| ≈ 3.
DEFAULT_RTOL = 1e-6
#: keyword arguments of pyamg.smoothed_aggregation_solver for the ``amg`` solver
AMG_OPTIONS: dict = {}
#: the stabilized scheme's preconditioner shift s is rounded to a power of this, so that the
#: AMG hierarchy of M_t + sK (≈ 1 s to build at 32³) is reused while the ratcheted (s₀, s₂)
#: move by small amounts (they do, every few steps, with ΔA drifting): the step operator is
#: always the exact one, only P is off by ≤ 2.5 % in s (no measurable change in iterations).
#: A function of (s₀, s₂) alone, so a resumed run rebuilds the same P (bit-identical runs).
SHIFT_GRID = 1.05


#: the sum of a partial sum over the MPI ranks (None: one process); set by
#: :mod:`fem_ade.fem.petsc` when the DOFs are distributed, so that every functional and
#: every dot product of the step is global
_ALLREDUCE = None


def _dot(a, b) -> float:
    """a·b without BLAS: ``np.dot`` of long vectors goes to a threaded BLAS, whose threads
    wait for a time slice on a loaded machine (measured on 2 busy cores: 7 ms per dot of 32³
    values, ten times the step's cost); einsum's own loop takes 20 µs, always. Distributed
    DOFs: this rank's part, summed over the ranks."""
    value = float(np.einsum("i,i->", a, b))
    return value if _ALLREDUCE is None else _ALLREDUCE(value)


def pcg(A, b, x0, M, atol, maxiter=500):
    """Preconditioned CG (the textbook recurrence, as scipy's ``cg``) stopping at ‖r‖ ≤ atol;
    ``A``, ``M`` are callables. Returns (x, its); on breakdown or maxiter, the last iterate."""
    x = np.array(x0, dtype=float, copy=True)
    r = b - A(x)
    if math.sqrt(_dot(r, r)) <= atol:
        return x, 0
    z = M(r)
    p = z.copy()
    rz = _dot(r, z)
    its = 0
    while its < maxiter:
        q = A(p)
        pq = _dot(p, q)
        if not (pq > 0.0 and math.isfinite(pq)):
            break
        alpha = rz / pq
        x += alpha * p
        r -= alpha * q
        its += 1
        if math.sqrt(_dot(r, r)) <= atol:
            break
        z = M(r)
        rz_new = _dot(r, z)
        p *= rz_new / rz
        p += z
        rz = rz_new
    return x, its


def amg_vcycle(ml):
    """One V-cycle from zero, ``ml.aspreconditioner(cycle="V")`` without its two residual
    norms and the extra fine-level product it spends on them (the same result)."""
    cycle = getattr(ml, "_MultilevelSolver__solve", None)
    if cycle is None or len(ml.levels) < 2:
        return ml.aspreconditioner(cycle="V").matvec

    def apply(b):
        b = np.asarray(b, dtype=float).ravel()
        x = np.zeros_like(b)
        cycle(0, x, b, "V")
        return x

    return apply


def chebyshev_inverse(A: sp.csr_matrix, degree: int, lower_ratio: float = 30.0):
    """A fixed polynomial p(D⁻¹A)D⁻¹ ≈ A⁻¹ (Chebyshev iteration from zero, ``degree`` steps).

    The spectrum of D⁻¹A is taken in [λmin, λmax]: λmax from a few power iterations (×1.05),
    λmin from Gershgorin's discs when they stay positive (for M_L + sK they do: λmin ≥
    1/(1 + s·max K_ii/m_i)), else λmax/``lower_ratio``. The residual polynomial is a scaled
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


class FourierGrid:
    """A uniform periodic Q1 grid (``shape`` nodes, spacings ``spacing``, DOFs in C order):
    there M, K and M_L are circulant — Kronecker products of 1D circulants — so the Fourier
    transform diagonalises them. Their symbols on the rfftn half-spectrum, at θ = 2πj/n:
    1D mass h(4 + 2cos θ)/6, stiffness (2 − 2cos θ)/h, lumped mass h; in d dimensions
    M̂ = Π m, K̂ = Σ_a k_a Π_{b≠a} m_b, M̂_L = Π h (a number, ``ml``)."""

    def __init__(self, shape, spacing):
        from scipy import fft

        from ..backend import fft_workers

        self.fft, self.workers = fft, fft_workers()
        self.shape, dim = tuple(shape), len(shape)
        self.axes = tuple(range(dim))
        ms, ks = [], []
        for a, (n, h) in enumerate(zip(shape, spacing, strict=True)):
            theta = 2.0 * np.pi * (fft.rfftfreq(n) if a == dim - 1 else fft.fftfreq(n))
            view = [1] * dim
            view[a] = -1
            ms.append((h * (4.0 + 2.0 * np.cos(theta)) / 6.0).reshape(view))
            ks.append(((2.0 - 2.0 * np.cos(theta)) / h).reshape(view))
        self.Mh = ms[0]
        for m in ms[1:]:
            self.Mh = self.Mh * m
        self.Kh = 0.0
        for a in range(dim):
            term = ks[a]
            for b in range(dim):
                if b != a:
                    term = term * ms[b]
            self.Kh = self.Kh + term
        self.ml = float(np.prod(spacing))
        self.size = int(np.prod(shape))
        n_last = shape[-1]
        w = np.full(n_last // 2 + 1, 2.0)  # Parseval weights of the half-spectrum
        w[0] = 1.0
        if n_last % 2 == 0:
            w[-1] = 1.0
        self.parseval = w / self.size

    def fwd(self, u):
        return self.fft.rfftn(np.reshape(u, self.shape), axes=self.axes, workers=self.workers)

    def hermitian(self, uh):
        """Remove (in place) the part of a half-spectrum that ``irfftn`` cannot see: in the
        planes k_last = 0 and n/2 a real field has û(−k) = conj(û(k)). Round-off breaks this,
        and a step whose operator grows some modes (the paper's scheme where
        κ(εk⁴ − (2/ε)k²) < 0, momentum) grows the broken part unseen until it reaches the field
        (measured: the discocyte diverged at step 9681 without this). As the spectral
        reference does (``SpectralBackend._hermitian``)."""
        axes = tuple(range(len(self.shape) - 1))
        n = self.shape[-1]
        for iz in (0, n // 2) if n % 2 == 0 else (0,):
            plane = uh[..., iz]
            mirror = np.conj(np.roll(np.flip(plane, axis=axes), 1, axis=axes))
            uh[..., iz] = 0.5 * (plane + mirror)
        return uh

    def inv(self, uh):
        return self.fft.irfftn(uh, s=self.shape, axes=self.axes, workers=self.workers).ravel()

    def dot(self, ah, bh) -> float:
        """Σ_j a_j b_j of two real fields from their half-spectra (Parseval)."""
        return float(np.sum(self.parseval * (np.conj(ah) * bh).real))

    def symbol(self, *, mass_factor, c, ke, lumped=True):
        """(M_L or M)·mass_factor + c K + ke K M_L⁻¹ K: S of the step, diagonal here."""
        return ((self.ml if lumped else self.Mh) * mass_factor + c * self.Kh
                + ke * self.Kh * self.Kh / self.ml)


def fft_step_inverse(grid, *, dt, kappa, eps, s0=0.0, s2=0.0):
    """S⁻¹ for uniform periodic Q1: ``grid`` = (n per axis, h per axis, lumped time mass);
    Ŝ = (1/Δt + s₀)M̂_t + (s₂ − 2κ/ε)K̂ + κε K̂²/M̂_L (:class:`FourierGrid`), positive when
    Δt < ε³/κ or s₂ ≥ 2κ/ε."""
    shape, hs, lumped = grid
    F = FourierGrid(shape, hs)
    inv = 1.0 / F.symbol(mass_factor=1.0 / dt + s0, c=s2 - 2.0 * kappa / eps,
                         ke=kappa * eps, lumped=lumped)

    def apply(r):
        return F.inv(F.fwd(r) * inv)

    return apply


def preconditioner_shift(tau, c, ke):
    """The s of P = (1/τ)(M_t + sK)M_L⁻¹(M_t + sK) for S = M_t/τ + cK + κε K M_L⁻¹K.

    On an eigenvector of M_L⁻¹K (eigenvalue y) P⁻¹S is (1 + cτy + κετy²)/(1 + sy)². With
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


class StepSolver:
    """Solve S x = b (the Schur complement of SPEC §5) by PCG; assembled once per (Δt, s₀, s₂).

    S = (1/Δt + s₀)M_t + (s₂ − 2κ/ε)K + κε K M_L⁻¹ K: s₀ = s₂ = 0 is the paper's scheme, else
    the stabilized one (its diagonal part; the low-rank terms are given to :meth:`solve`).
    """

    def __init__(self, M, K, m, *, dt, kappa, eps, kind="amg", rtol=None, degree=None,
                 grid=None, s0=0.0, s2=0.0, cache=None, lumped=False):
        if kind not in SOLVERS:
            raise ModelError(f"unknown FEM solver {kind!r}; valid: {', '.join(SOLVERS)}")
        self.tau = dt if s0 == 0.0 else 1.0 / (1.0 / dt + s0)  # the effective time step
        self.c = s2 - 2.0 * kappa / eps
        stabilized = s0 != 0.0 or s2 != 0.0
        if stabilized:  # s on a grid of ratio SHIFT_GRID: P depends on (s₀, s₂) by steps
            s_opt = preconditioner_shift(self.tau, self.c, kappa * eps)
            self.s = SHIFT_GRID ** round(math.log(s_opt) / math.log(SHIFT_GRID))
        else:
            self.s = math.sqrt(dt * kappa * eps)
        # how far M_t + sK is from its mass: s·max(K_ii/m_i) (Gershgorin: cond(D⁻¹B) ≤ 1 + 2x)
        stiffness = self.s * float(np.max(K.diagonal() / np.asarray(M.diagonal()).ravel()))
        if kind == "auto":  # Chebyshev only on a uniform mesh of vertices: graded, file and
            # Q2 meshes (lumped weights varying by more than 1.5) need AMG's flat counts
            uniform = float(np.max(m) / np.min(m)) <= 1.5
            kind = ("fft" if grid is not None else "chebyshev"
                    if uniform and stiffness <= AUTO_CHEBYSHEV_LIMIT else "amg")
        if degree is None:
            degree = 2 if stiffness <= CHEBYSHEV_LOW_DEGREE_LIMIT else 4
        self.degree = 1 if kind == "jacobi" else degree
        self.kind = kind
        self.rtol = DEFAULT_RTOL if rtol is None else float(rtol)
        self.K = K
        self.minv = 1.0 / m
        self.m = m
        self.ke = kappa * eps
        # with M_t = M_L (diagonal), S x = (m/τ)x + K(c x + κε M_L⁻¹ K x): two sparse products
        self.lumped = lumped
        self.A0 = None if lumped else (M / self.tau + self.c * K).tocsr()
        n = M.shape[0]
        self.n = n
        self.dt = dt
        B = (M + self.s * K).tocsr()
        # pyamg and the Chebyshev bounds draw random start vectors: seed them (and leave the
        # caller's random state alone), so that a rebuilt solver is bit for bit the same one
        # (a resumed run repeats the uninterrupted one exactly)
        rng_state = np.random.get_state()
        np.random.seed(12345)
        key = (kind, self.s)
        try:
            if kind == "fft":
                if grid is None:
                    raise ModelError("solver 'fft' needs a uniform tensor mesh with Q1 elements")
                self.levels = 0
                self.B_inv = None
                self.fft_inverse = fft_step_inverse(grid, dt=dt, kappa=kappa, eps=eps,
                                                    s0=s0, s2=s2)
            elif cache is not None and key in cache:
                self.levels, self.B_inv = cache[key]
            elif kind == "amg":
                import pyamg

                ml = pyamg.smoothed_aggregation_solver(B, symmetry="hermitian", max_coarse=500,
                                                       **AMG_OPTIONS)
                for level in ml.levels:  # pyamg keeps coarse levels as BSR with 1×1 blocks,
                    level.A = level.A.tocsr()  # whose Gauss–Seidel is the slow generic one
                    for name in ("P", "R"):
                        if hasattr(level, name):
                            setattr(level, name, getattr(level, name).tocsr())
                self.levels = len(ml.levels)
                self.B_inv = amg_vcycle(ml)
            else:
                self.levels = 1
                self.B_inv = chebyshev_inverse(B, self.degree)
            if cache is not None and kind != "fft" and key not in cache:
                if len(cache) >= 4:
                    cache.pop(next(iter(cache)))
                cache[key] = (self.levels, self.B_inv)
        finally:
            np.random.set_state(rng_state)
        self.S = LinearOperator((n, n), matvec=self.apply, dtype=float)
        self.P = LinearOperator((n, n), matvec=self.precondition, dtype=float)

    def apply(self, x):
        """S x = (M_t/τ + cK) x + κε K (M_L⁻¹ K x)."""
        x = np.asarray(x).ravel()
        Kx = self.K @ x
        if self.lumped:
            return (self.m / self.tau) * x + self.K @ (self.c * x + self.ke * (self.minv * Kx))
        return self.A0 @ x + self.ke * (self.K @ (self.minv * Kx))

    def precondition(self, r):
        """P⁻¹ r = τ (M_t + sK)⁻¹ M_L (M_t + sK)⁻¹ r (inverses approximate), or S⁻¹ r (fft)."""
        if self.kind == "fft":
            return self.fft_inverse(np.asarray(r).ravel())
        y = self.B_inv(np.asarray(r).ravel())
        return self.tau * self.B_inv(self.m * y)

    def operator(self, low_rank=()):
        """S + Σ σᵢ bᵢbᵢᵀ as a LinearOperator (``low_rank``: pairs (σ, b)), matrix-free."""
        if not low_rank:
            return self.S
        def matvec(x):  # no dense BLAS products (see _dot)
            x = np.asarray(x).ravel()
            y = self.apply(x)
            for sig, b in low_rank:
                y += (sig * _dot(b, x)) * b
            return y

        return LinearOperator((self.n, self.n), matvec=matvec, dtype=float)

    def solve(self, b, x0, ref=None, scale=None, low_rank=()):
        """Return (x, its): ‖b − Ŝx‖ ≤ rtol·‖b − Ŝ·ref‖ (ref defaults to x0), Ŝ = S + Σσbbᵀ.

        ``scale`` = ‖b − Ŝ·ref‖ may be given by a caller who has it cheaper. PCG keeps the
        preconditioner of the diagonal part S: a rank-k perturbation costs at most k extra
        iterations in exact arithmetic.
        """
        op = self.operator(low_rank)
        ref = x0 if ref is None else ref
        if scale is None:
            r = b - op.matvec(ref)
            scale = math.sqrt(_dot(r, r))
        if scale == 0.0:
            return np.array(ref, copy=True), 0
        # not converged or broken down (NaN input): return what there is; the loop's
        # guards judge the state (max |φ|, finiteness), the history shows the its.
        return pcg(op.matvec, np.asarray(b, dtype=float), x0, self.precondition,
                   self.rtol * scale, maxiter=500)
