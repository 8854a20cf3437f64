"""Axisymmetric closed membranes: the sharp-interface model the phase field stands for.

A surface of revolution about the z axis is given by its meridian, the curve (r(s), z(s)) in a
half plane, parameterised by arc length s ∈ [0, S] and its tangent angle ψ(s):

    r′ = cos ψ,   z′ = −sin ψ,   k₁ = ψ′ (along the meridian),   k₂ = sin ψ / r (around the axis)

so that the mean curvature is 2H = k₁ + k₂ (a sphere of radius R: 2H = 2/R), the area
A = 2π∫ r ds, the enclosed volume V = π∫ r² sin ψ ds, and the total mean curvature
M = ∮ 2H dA = 2π∫ (k₁ + k₂) r ds.

Energies, in units of the bending energy of a sphere (8πκ for (κ/2)∮(2H)² dA), with the area
fixed at 4π (R₀ = √(A/4π) = 1; every result is scale-free):

    w = (1/16π) ∮ (2H − c)² dA                              bending, c the spontaneous 2H
    e = w + q (m − m₀)²,   m = M / 8π,   q = 3π κ̄ / (2√2 κ)   with area-difference elasticity

m is the reduced area difference: the two leaflets, a distance D apart, differ in area by
ΔA = D·M, and m = ΔA / (8πDR₀) is 1 for a sphere. The factor q is the phase-field model's:
its bending energy is 2√2/3 times Helfrich's, its ADE term κ̄π/(2A₀D²)(ΔA − ΔA₀)² is not
(the phase-field model of this project: c = √2·C·R₀, m₀ = ΔA₀/(8πDR₀)).

Two families of meridians, each a sine or Fourier series of ψ whose every member is a closed
smooth surface by construction, evaluated on Chebyshev (spheroidal) or uniform (torus) nodes
with spectrally accurate quadrature, and minimised with the area, the volume and the closure
as equality constraints (a trust-region SQP, then polished by Newton on the Lagrange
conditions):

* spheroidal topology, t = s/S ∈ [0, 1] from the top pole to the bottom one:
  ψ(t) = πt + Σₖ aₖ sin(kπt) — both poles smooth (ψ odd about each end); up-down symmetric
  shapes (prolate, oblate) use even k only; closure r(S) = 0;
* a torus, t ∈ [0, 1) once around the tube from its outer equator, up-down symmetric:
  ψ(t) = π/2 + 2πt + Σₖ bₖ sin(2πkt), r(0) = r₀ > 0; closure z(S) = 0 (r closes by symmetry).

Nothing here is imported from fem_ade: this is a second reference, independent of the
phase-field code it checks.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize
from threadpoolctl import threadpool_limits

#: the phase-field model's ADE factor in units of a sphere's bending energy, per κ̄/κ
Q_ADE = 3.0 * math.pi / (2.0 * math.sqrt(2.0))

BRANCHES = ("sphere", "prolate", "oblate", "stomatocyte", "pear", "torus")


class BranchError(ValueError):
    """The branch does not exist at these parameters (or the minimiser could not stay on it)."""


# ---------------------------------------------------------------------------------------
# quadrature and integration on [0, 1]
# ---------------------------------------------------------------------------------------
def chebyshev_nodes(m: int) -> np.ndarray:
    """The m + 1 Chebyshev–Lobatto points of [0, 1], from 0 to 1."""
    return 0.5 * (1.0 - np.cos(np.pi * np.arange(m + 1) / m))


def chebyshev_integration(m: int) -> np.ndarray:
    """Q with (Q f)ᵢ = ∫₀^{tᵢ} p(t) dt, p the degree-m interpolant of f at the nodes."""
    from numpy.polynomial import chebyshev as C

    t = chebyshev_nodes(m)
    x = 2.0 * t - 1.0
    vander = C.chebvander(x, m)
    inverse = np.linalg.inv(vander)  # values -> coefficients
    out = np.zeros((m + 1, m + 1))
    for j in range(m + 1):
        coef = np.zeros(m + 1)
        coef[j] = 1.0
        integral = C.chebint(coef, lbnd=-1.0) * 0.5  # dt = dx / 2
        out[:, j] = C.chebval(x, integral)
    return out @ inverse


def periodic_integration(m: int) -> tuple[np.ndarray, np.ndarray]:
    """(nodes, Q) on m uniform points of [0, 1): (Q f)ᵢ = ∫₀^{tᵢ} (f − mean f) + tᵢ mean f,
    exact for trigonometric polynomials of degree < m/2."""
    t = np.arange(m) / m
    k = np.fft.fftfreq(m, d=1.0 / m)
    # ∫ e^{2πikt} = (e^{2πikt} − 1) / (2πik) for k ≠ 0; t for k = 0
    F = np.fft.fft(np.eye(m), axis=0) / m  # f -> coefficients
    E = np.exp(2j * np.pi * np.outer(t, k))
    with np.errstate(divide="ignore", invalid="ignore"):
        G = np.where(k == 0, t[:, None], (E - 1.0) / (2j * np.pi * k))
    return t, np.real(G @ F)


# ---------------------------------------------------------------------------------------
# a meridian and its integrals
# ---------------------------------------------------------------------------------------
@dataclass
class Geometry:
    """A surface of revolution on its nodes: t, ψ, ψ′ (in t), r, z, k₁, k₂, and the totals."""

    t: np.ndarray
    psi: np.ndarray
    r: np.ndarray
    z: np.ndarray
    k1: np.ndarray
    k2: np.ndarray
    S: float
    area: float
    volume: float
    mean_curvature: float  # M = ∮ 2H dA
    bending: float  # ∮ (2H − c)² dA
    closure: float  # r(S) (spheroidal) or z(S) (torus): zero on a closed meridian

    @property
    def reduced_volume(self) -> float:
        R0 = math.sqrt(self.area / (4.0 * math.pi))
        return self.volume / (4.0 * math.pi / 3.0 * R0**3)

    @property
    def reduced_area_difference(self) -> float:
        R0 = math.sqrt(self.area / (4.0 * math.pi))
        return self.mean_curvature / (8.0 * math.pi * R0)

    @property
    def w(self) -> float:
        return self.bending / (16.0 * math.pi)


class Spheroidal:
    """ψ(t) = πt + Σₖ aₖ sin(kπt) on [0, 1], k ∈ ``modes``, on m + 1 Chebyshev nodes."""

    topology = "spheroidal"
    #: the unknowns after the coefficients: the meridian's length S
    extra = 1

    def __init__(self, modes, m: int):
        self.modes = np.asarray(modes, dtype=int)
        self.m = m
        #: with even k only the meridian is symmetric about the equator and closes by itself
        self.needs_closure = bool(np.any(self.modes % 2))
        self.t = chebyshev_nodes(m)
        self.Q = chebyshev_integration(m)
        self.weights = self.Q[-1].copy()
        arg = np.pi * np.outer(self.t, self.modes)
        # the unknowns are uₖ = k·aₖ: the bending energy's Hessian is then about uniform
        self.sin = np.sin(arg) / self.modes
        self.dcos = np.pi * np.cos(arg)

    def at(self, x: np.ndarray, c: float = 0.0) -> Geometry:
        """The geometry of the unknowns x = (coefficients, S)."""
        return self.geometry(x[:-1], x[-1], c)

    def geometry(self, coef: np.ndarray, S: float, c: float = 0.0) -> Geometry:
        """One meridian, or a batch: ``coef`` (k, B) and ``S`` (B,) give B of them (the
        columns; the totals are then arrays of B)."""
        t, weights = (self.t, self.weights) if coef.ndim == 1 else (self.t[:, None],
                                                                     self.weights[:, None])
        psi = np.pi * t + self.sin @ coef
        dpsi = np.pi + self.dcos @ coef
        r = S * (self.Q @ np.cos(psi))
        z = -S * (self.Q @ np.sin(psi))
        k1 = dpsi / S
        k2 = np.empty_like(k1)
        inner = slice(1, -1)
        k2[inner] = np.sin(psi[inner]) / r[inner]
        k2[0], k2[-1] = k1[0], k1[-1]  # at a pole sin ψ / r → ψ′
        w = weights * S
        area = 2.0 * np.pi * np.sum(w * r, axis=0)
        volume = np.pi * np.sum(w * r * r * np.sin(psi), axis=0)
        two_h = k1 + k2
        return Geometry(self.t, psi, r, z, k1, k2, S, area, volume,
                        2.0 * np.pi * np.sum(w * two_h * r, axis=0),
                        2.0 * np.pi * np.sum(w * (two_h - c) ** 2 * r, axis=0), r[-1])


class Toroidal:
    """ψ(t) = π/2 + 2πt + Σₖ bₖ sin(2πkt) on m uniform nodes of [0, 1), r(0) = r₀."""

    topology = "torus"
    #: the unknowns after the coefficients: S and r₀
    extra = 2

    def __init__(self, modes, m: int):
        self.modes = np.asarray(modes, dtype=int)
        self.m = m
        self.needs_closure = True  # z; r closes by the up-down symmetry
        self.t, self.Q = periodic_integration(m)
        self.weights = np.full(m, 1.0 / m)
        arg = 2.0 * np.pi * np.outer(self.t, self.modes)
        self.sin = np.sin(arg) / self.modes  # unknowns k·bₖ, as for Spheroidal
        self.dcos = 2.0 * np.pi * np.cos(arg)

    def at(self, x: np.ndarray, c: float = 0.0) -> Geometry:
        """The geometry of the unknowns x = (coefficients, S, r₀)."""
        return self.geometry(x[:-2], x[-2], x[-1], c)

    def geometry(self, coef: np.ndarray, S: float, r0: float, c: float = 0.0) -> Geometry:
        """One meridian, or a batch (as :meth:`Spheroidal.geometry`)."""
        t, weights = (self.t, self.weights) if coef.ndim == 1 else (self.t[:, None],
                                                                     self.weights[:, None])
        psi = 0.5 * np.pi + 2.0 * np.pi * t + self.sin @ coef
        dpsi = 2.0 * np.pi + self.dcos @ coef
        cos, sin = np.cos(psi), np.sin(psi)
        r = r0 + S * (self.Q @ cos)
        z = -S * (self.Q @ sin)
        k1 = dpsi / S
        k2 = sin / r
        w = weights * S
        two_h = k1 + k2
        return Geometry(self.t, psi, r, z, k1, k2, S, 2.0 * np.pi * np.sum(w * r, axis=0),
                        np.pi * np.sum(w * r * r * sin, axis=0),
                        2.0 * np.pi * np.sum(w * two_h * r, axis=0),
                        2.0 * np.pi * np.sum(w * (two_h - c) ** 2 * r, axis=0),
                        S * np.sum(weights * sin, axis=0))


# ---------------------------------------------------------------------------------------
# the minimisation
# ---------------------------------------------------------------------------------------
@dataclass
class Problem:
    """What is minimised: ``v`` the reduced volume (None: free, the torus's Willmore
    problem), ``m0`` the reduced relaxed area difference and ``kbar`` κ̄/κ (ADE off when
    kbar is 0), ``c`` the spontaneous 2H in units of 1/R₀."""

    v: float | None
    m0: float = 0.0
    kbar: float = 0.0
    c: float = 0.0

    def energy(self, g: Geometry) -> float:
        e = g.bending / (16.0 * math.pi)
        if self.kbar:
            e += self.kbar * Q_ADE * (g.mean_curvature / (8.0 * math.pi) - self.m0) ** 2
        return e


@dataclass
class Result:
    """A minimised membrane: its branch, reduced volume and area difference, energies, the
    meridian (r, z at the nodes, R₀ = 1) and how the minimisation went."""

    branch: str
    problem: Problem
    geometry: Geometry = field(repr=False)
    x: np.ndarray = field(repr=False)
    converged: bool
    message: str
    residual: float  # the largest of the constraints' and the Lagrange conditions' misfit
    #: the meridian family x belongs to (a start for a continuation: branches.solve's start)
    family: object = field(default=None, repr=False, compare=False)

    @property
    def v(self) -> float:
        return self.geometry.reduced_volume

    @property
    def da(self) -> float:
        return self.geometry.reduced_area_difference

    @property
    def w(self) -> float:
        return self.geometry.w

    @property
    def e(self) -> float:
        return self.problem.energy(self.geometry)

    def to_json(self, points: int = 201) -> dict:
        g = self.geometry
        idx = np.unique(np.round(np.linspace(0, len(g.t) - 1, min(points, len(g.t)))).astype(int))
        return {"branch": self.branch, "v": self.v, "w": self.w, "e": self.e, "da": self.da,
                "v_target": self.problem.v, "da0": self.problem.m0, "kbar": self.problem.kbar,
                "c": self.problem.c, "converged": self.converged, "message": self.message,
                "residual": self.residual, "meridian_length": g.S,
                "r": g.r[idx].tolist(), "z": (g.z[idx] - 0.5 * (g.z.max() + g.z.min())).tolist()}


class _Objective:
    """x ↦ energy and constraints of one family: x = (coefficients, S[, r₀]).

    The geometry of the last few x (real, or a gradient's batch of complex steps) is kept:
    the optimiser asks for the energy and the constraints, and their gradients, at the same
    points, and the geometry is most of the cost (the same values, computed once)."""

    KEEP = 4  # geometries kept: an iterate's and its batch of steps, and the one before

    def __init__(self, family, problem: Problem):
        self.family, self.problem = family, problem
        self._kept: dict = {}

    def geometry(self, x) -> Geometry:
        x = np.asarray(x)
        key = (x.dtype.str, x.tobytes())
        g = self._kept.get(key)
        if g is None:
            g = self.family.at(x, self.problem.c)
            if self._kept and len(self._kept) >= self.KEEP:
                del self._kept[next(iter(self._kept))]  # the oldest
            if self.KEEP:
                self._kept[key] = g
        return g

    def energy(self, x) -> float:
        return self.problem.energy(self.geometry(x))

    def constraints(self, x) -> np.ndarray:
        g = self.geometry(x)
        out = [g.area / (4.0 * math.pi) - 1.0]
        if self.family.needs_closure:
            out.append(g.closure)
        if self.problem.v is not None:
            out.append(g.volume / (4.0 * math.pi / 3.0) - self.problem.v)
        return np.array(out)


def _gradient(f, x) -> np.ndarray:
    """∂f/∂x by complex steps (exact to round-off: every operation here is analytic)."""
    h = 1e-30
    n = len(x)
    steps = np.repeat(x.astype(complex)[:, None], n, axis=1)  # column i: x + ih eᵢ
    steps[np.arange(n), np.arange(n)] += 1j * h
    return np.imag(f(steps)) / h  # f of all n steps at once (the families take batches)


def minimise(family, problem: Problem, x0: np.ndarray, *, maxiter: int = 3000):
    """Minimise ``problem`` over ``family`` from ``x0``: a trust-region SQP (scipy's
    ``trust-constr``, which keeps its steps where the model holds — a plain SQP's first
    step can turn a meridian inside out) with exact gradients and BFGS Hessians, then
    Newton on the Lagrange conditions. Returns (x, converged, message, residual)."""
    with threadpool_limits(1):  # ≤ 100 unknowns: BLAS threads only contend (8× slower
        return _minimise(family, problem, x0, maxiter)  # beside another job)


def _minimise(family, problem, x0, maxiter):
    obj = _Objective(family, problem)
    cons = optimize.NonlinearConstraint(lambda x: np.real(obj.constraints(x)), 0.0, 0.0,
                                        jac=lambda x: _gradient(obj.constraints, x),
                                        hess=optimize.BFGS())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # BFGS on a linear constraint
        res = optimize.minimize(lambda x: float(np.real(obj.energy(x))), x0,
                                jac=lambda x: _gradient(obj.energy, x), hess=optimize.BFGS(),
                                constraints=[cons], method="trust-constr",
                                options={"maxiter": maxiter, "gtol": 1e-12, "xtol": 1e-14})
    x, residual = _polish(obj, res.x)
    ok = bool(np.isfinite(residual) and residual < 1e-8)
    return x, ok, str(res.message), residual


def _polish(obj: _Objective, x: np.ndarray, steps: int = 8):
    """Newton on ∇E + Jᵀλ = 0, c(x) = 0 with a finite-difference Hessian of the Lagrangian;
    returns the better of the start and each iterate (by the misfit)."""
    n = len(x)

    def lagrange_parts(x):
        J = _gradient(obj.constraints, x)
        gE = _gradient(obj.energy, x)
        lam = np.linalg.lstsq(J.T, -gE, rcond=None)[0]
        return J, gE, lam

    def misfit(x):
        J, gE, lam = lagrange_parts(x)
        return max(np.abs(gE + J.T @ lam).max(), np.abs(np.real(obj.constraints(x))).max())

    best, best_r = x, misfit(x)
    for _ in range(steps):
        J, gE, lam = lagrange_parts(x)

        def grad_L(y, lam=lam):
            return _gradient(obj.energy, y) + _gradient(obj.constraints, y).T @ lam

        H = np.empty((n, n))
        for i in range(n):  # central differences of the exact gradient
            e = np.zeros(n)
            e[i] = 1e-6
            H[:, i] = (grad_L(x + e) - grad_L(x - e)) / 2e-6
        H = 0.5 * (H + H.T)
        k = J.shape[0]
        K = np.block([[H, J.T], [J, np.zeros((k, k))]])
        rhs = -np.concatenate([gE + J.T @ lam, np.real(obj.constraints(x))])
        try:
            step = np.linalg.lstsq(K, rhs, rcond=1e-13)[0][:n]
        except np.linalg.LinAlgError:
            break
        x = x + step
        r = misfit(x)
        if not np.isfinite(r):
            break
        if r < best_r:
            best, best_r = x, r
        if r < 1e-10:
            break
    return best, best_r
