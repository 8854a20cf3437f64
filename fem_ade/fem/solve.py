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
- ``chebyshev``: a fixed Chebyshev polynomial of D⁻¹(M_t + sK) (degree 4; cheap while M_t + sK
  is mass-dominated, i.e. at the paper's Δt);
- ``jacobi``: the same with degree 1 (a scaled diagonal; cheapest, weakest);
- ``auto``: ``fft`` where it applies, else ``chebyshev`` while M_t + sK is mass-dominated,
  else ``amg`` (the measured winners, ``studies/bench_fem.py``);
- ``fft``: uniform Q1 tensor meshes only: there M, K and M_L are circulant (Kronecker products
  of 1D circulants), so S is diagonalised by the discrete Fourier transform and P = S exactly
  (one PCG iteration; a fast direct solver, kept inside PCG so the residual is still checked).

Interface: ``StepSolver(M_t, K, m, dt=, kappa=, eps=, kind=, rtol=)`` and
``solve(b, x0, ref=None) -> (x, its)``; the stopping test is relative to the residual of ``ref``
(the previous state), so the tolerance scales with the change per step. A PETSc version only
has to provide the same two calls.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import LinearOperator, cg

from ..model import ModelError

SOLVERS = ("amg", "chebyshev", "jacobi", "fft", "auto")
#: ``auto`` takes ``chebyshev`` while s·max(K_ii/m_i) ≤ this (M_L + sK mass-dominated enough
#: that D⁻¹(M_L + sK) has condition ≤ 1 + 2·this by Gershgorin), else ``amg``
AUTO_CHEBYSHEV_LIMIT = 20.0
#: PCG stops at rtol·‖b − Sφⁿ‖. Measured (discocyte 32³, 50 steps, against the exact fft
#: solve): |ΔE| = 3e-8 at 1e-6 and 2e-6 at 1e-5, against a discretisation error |ΔE| ≈ 3.
DEFAULT_RTOL = 1e-6
#: keyword arguments of pyamg.smoothed_aggregation_solver for the ``amg`` solver
AMG_OPTIONS: dict = {}


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


def fft_step_inverse(grid, *, dt, kappa, eps):
    """S⁻¹ for uniform periodic Q1: ``grid`` = (n per axis, h per axis, lumped time mass).

    1D symbols at θ = 2πj/n: mass h(4 + 2cos θ)/6, stiffness (2 − 2cos θ)/h, lumped mass h;
    in d dimensions M̂ = Π m, K̂ = Σ_a k_a Π_{b≠a} m_b, M̂_L = Π h, and
    Ŝ = M̂/Δt − (2κ/ε)K̂ + κε K̂²/M̂_L (positive when Δt < ε³/κ).
    """
    from scipy import fft

    shape, hs, lumped = grid
    dim = len(shape)
    ms, ks = [], []
    for a, (n, h) in enumerate(zip(shape, hs, strict=True)):
        theta = 2.0 * np.pi * (fft.rfftfreq(n) if a == dim - 1 else fft.fftfreq(n))
        view = [1] * dim
        view[a] = -1
        ms.append((h * (4.0 + 2.0 * np.cos(theta)) / 6.0).reshape(view))
        ks.append(((2.0 - 2.0 * np.cos(theta)) / h).reshape(view))
    Mh = ms[0]
    for m in ms[1:]:
        Mh = Mh * m
    Kh = 0.0
    for a in range(dim):
        term = ks[a]
        for b in range(dim):
            if b != a:
                term = term * ms[b]
        Kh = Kh + term
    ML = float(np.prod(hs))
    symbol = (ML if lumped else Mh) / dt - (2.0 * kappa / eps) * Kh + kappa * eps * Kh * Kh / ML
    inv = 1.0 / symbol
    axes = tuple(range(dim))

    def apply(r):
        rh = fft.rfftn(r.reshape(shape), axes=axes, workers=-1)
        return fft.irfftn(rh * inv, s=shape, axes=axes, workers=-1).ravel()

    return apply


class StepSolver:
    """Solve S φ = b (the Schur complement of SPEC §5) by PCG; assembled once per run."""

    def __init__(self, M, K, m, *, dt, kappa, eps, kind="amg", rtol=None, degree=4,
                 grid=None):
        if kind not in SOLVERS:
            raise ModelError(f"unknown FEM solver {kind!r}; valid: {', '.join(SOLVERS)}")
        self.s = math.sqrt(dt * kappa * eps)
        if kind == "auto":
            stiffness = float(np.max(K.diagonal() / np.asarray(M.diagonal()).ravel()))
            kind = ("fft" if grid is not None else
                    "chebyshev" if self.s * stiffness <= AUTO_CHEBYSHEV_LIMIT else "amg")
        self.kind = kind
        self.rtol = DEFAULT_RTOL if rtol is None else float(rtol)
        self.K = K
        self.minv = 1.0 / m
        self.m = m
        self.ke = kappa * eps
        self.A0 = (M / dt - (2.0 * kappa / eps) * K).tocsr()
        n = M.shape[0]
        self.S = LinearOperator((n, n), matvec=self.apply, dtype=float)
        self.dt = dt
        B = (M + self.s * K).tocsr()
        if kind == "fft":
            if grid is None:
                raise ModelError("solver 'fft' needs a uniform tensor mesh with Q1 elements")
            self.levels = 0
            self.B_inv = None
            self.fft_inverse = fft_step_inverse(grid, dt=dt, kappa=kappa, eps=eps)
        elif kind == "amg":
            import pyamg

            ml = pyamg.smoothed_aggregation_solver(B, symmetry="hermitian", max_coarse=500,
                                                   **AMG_OPTIONS)
            self.levels = len(ml.levels)
            cycle = ml.aspreconditioner(cycle="V")
            self.B_inv = cycle.matvec
        else:
            self.levels = 1
            self.B_inv = chebyshev_inverse(B, 1 if kind == "jacobi" else degree)
        self.P = LinearOperator((n, n), matvec=self.precondition, dtype=float)

    def apply(self, x):
        """S x = (M_t/Δt − (2κ/ε)K) x + κε K (M_L⁻¹ K x)."""
        x = np.asarray(x).ravel()
        return self.A0 @ x + self.ke * (self.K @ (self.minv * (self.K @ x)))

    def precondition(self, r):
        """P⁻¹ r = Δt (M_t + sK)⁻¹ M_L (M_t + sK)⁻¹ r (inverses approximate), or S⁻¹ r (fft)."""
        if self.kind == "fft":
            return self.fft_inverse(np.asarray(r).ravel())
        y = self.B_inv(np.asarray(r).ravel())
        return self.dt * self.B_inv(self.m * y)

    def solve(self, b, x0, ref=None, scale=None):
        """Return (x, its): ‖b − Sx‖ ≤ rtol·‖b − S·ref‖ (ref defaults to x0).

        ``scale`` = ‖b − S·ref‖ may be given by a caller who has it cheaper.
        """
        ref = x0 if ref is None else ref
        if scale is None:
            scale = np.linalg.norm(b - self.apply(ref))
        if scale == 0.0:
            return np.array(ref, copy=True), 0
        its = [0]

        def count(_):
            its[0] += 1

        x, _info = cg(self.S, b, x0=x0, rtol=0.0, atol=self.rtol * scale, M=self.P,
                     maxiter=500, callback=count)
        # not converged (info > 0) or broken down (NaN input): return what there is; the
        # driver's guards judge the state (max |φ|, finiteness), the history shows the its.
        return x, its[0]
