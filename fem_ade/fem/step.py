"""The time step of SPEC §4–§5 on a FEM space: the paper's scheme, the stabilized scheme and
exact constraints. The terms are the forms of :mod:`fem_ade.fem.forms`; the linear solve is
:class:`fem_ade.fem.solve.StepSolver`.

With μ eliminated by the lumped mass M_L (μ = M_L⁻¹Kφ, the lumped-mass −Δφ), one step of the
paper's scheme is

    S φⁿ⁺¹ = M_t φⁿ/Δt − ⟨Rⁿ, v⟩,     S = M_t/Δt − (2κ/ε)K + κε K M_L⁻¹ K,
    ⟨Rⁿ, v⟩ = κ⟨N(φⁿ), v⟩ + ⟨h(φⁿ), v⟩ + M₁(Vⁿ − α)(1, v) − (3√2/2)M₂(Aⁿ − β)⟨f(φⁿ), v⟩,

only the terms whose effect is on being evaluated. M_t is the mass of the time derivative and
of the explicit products: M_L by default (then S is SPD for every Δt < ε³/κ, like the spectral
symbol), or the consistent M (``mass="consistent"``, see :mod:`fem_ade.fem.solve`).

The stabilized scheme solves for δ = φⁿ⁺¹ − φⁿ

    [(1/Δt + s₀)M_t + (s₂ − 2κ/ε)K + κε K M_L⁻¹ K + Σᵢ σᵢ bᵢbᵢᵀ] δ = −∇E_h(φⁿ),

−∇E_h(φⁿ) = −⟨Rⁿ, v⟩ + (2κ/ε)Kφⁿ − κεKμⁿ (:meth:`MixedStep.descent`), (s₀, s₂) from
:func:`fem_ade.model.ratchet_stabilization`, and the rank-one Hessians σbbᵀ of the penalty
terms (:meth:`MixedStep.rank_one`): volume σ = 2M₁, b = ⟨δV/δφ, v⟩; area σ = 2M₂,
b = ⟨δA/δφ, v⟩; ADE σ = κ̄π/(A₀D²), b = ⟨δΔA/δφ, v⟩ — the exact gradients of the discrete
V, A, ΔA. They enter PCG matrix-free; the step matrix is rebuilt only when the ratcheted
(s₀, s₂) change, its AMG hierarchy only when the preconditioner's shift moves to another point
of its 5 % grid (:data:`fem_ade.fem.solve.SHIFT_GRID`).

Exact constraints (:mod:`fem_ade.constraints`): φⁿ⁺¹ = φⁿ + δ₀ + a z_V + b z_A, z = P⁻¹b (P the
scheme's step operator; two extra PCG solves, warm-started from the previous step's z), (a, b)
by :func:`fem_ade.constraints.solve_multipliers` at the step's targets (their ramp from the
initial V₀, A₀ to α, β); λ_V = −a, λ_A = −b.
"""

from __future__ import annotations

import math
import time

import numpy as np
import scipy.sparse as sp

from ..constraints import solve_multipliers
from ..model import ModelError, Params, ratchet_stabilization, stabilization_coefficients
from . import forms
from .solve import FourierGrid, StepSolver, _dot


def _norm(x) -> float:
    return math.sqrt(_dot(x, x))


def _woodbury(F, D, low):
    """x ↦ (D + Σᵢ σᵢ b̂ᵢ b̂ᵢᵀ)⁻¹ x in Fourier space (D diagonal; bᵢᵀx by Parseval)."""
    if not low:
        return lambda r: r / D
    z = [b / D for _, b in low]
    G = np.array([[F.dot(bi, zj) for zj in z] for _, bi in low])
    G += np.diag([1.0 / sig for sig, _ in low])

    def solve(r):
        y = r / D
        coef = np.linalg.solve(G, [F.dot(b, y) for _, b in low])
        return y - sum(ci * zi for ci, zi in zip(coef, z, strict=True))

    return solve


class MixedStep:
    """The scheme on one FEM space (``ops``: M, K, nodal weights w, scikit-fem basis).

    State it owns and :meth:`state` returns: the ratcheted (s₀, s₂) of the stabilized scheme
    and the warm starts z of the constraint solves. The field (φ, μ, Kφ, φⁿ⁻¹) is the caller's.
    """

    def __init__(self, ops, params: Params, *, scheme: str, exact: bool, mass: str = "lumped",
                 products: str = "nodal", solver: str = "amg", rtol: float | None = None,
                 fft_grid=None, solver_class=StepSolver):
        if mass not in ("lumped", "consistent"):
            raise ModelError(f"mass must be 'lumped' or 'consistent', got {mass!r}")
        if products not in ("nodal", "quadrature"):
            raise ModelError(f"products must be 'nodal' or 'quadrature', got {products!r}")
        self.params = params
        self.scheme, self.exact = scheme, exact
        self.K, self.w, self.basis = ops.K, ops.weights, ops.basis
        if (self.w <= 0).any():
            raise ModelError("the lumped mass has non-positive entries on this mesh/element")
        self.mass, self.products = mass, products
        self.Mt = sp.diags(self.w).tocsr() if mass == "lumped" else ops.M
        # (cells, spacing) of a uniform Q1 grid (the ``fft`` solver), with M_t's kind
        self.fft_grid = None if fft_grid is None else (*fft_grid, mass == "lumped")
        if solver in ("fft", "auto") and fft_grid is not None:
            solver = "fft"  # uniform Q1: the direct Fourier path (no PCG)
        elif solver == "fft":
            raise ModelError("solver 'fft' needs a uniform tensor mesh with Q1 elements")
        self.fourier = FourierGrid(*fft_grid) if solver == "fft" else None
        self.solver_opts = {"kind": solver, "rtol": rtol}
        self.solver_class = solver_class  # StepSolver, or fem_ade.fem.petsc.PetscStepSolver
        self.stab: tuple[float, float] | None = None
        self.z: tuple[np.ndarray, np.ndarray] | None = None
        self._solvers: dict[tuple, StepSolver] = {}
        self._preconditioners: dict = {}  # B⁻¹ of M_t + sK by (kind, s), shared (stabilized)
        self.dt = math.nan
        self.solver: StepSolver | None = None
        self.ramp = None  # the exact constraints' targets (fem_ade.constraints.TargetRamp)

    # -- linear algebra ---------------------------------------------------------------------
    def weak(self, a, c) -> np.ndarray:
        """K a + M_t c: a functional from nodal products (:mod:`fem_ade.fem.forms`)."""
        return self.K @ a + self.Mt @ c

    def solver_for(self, dt: float, stab) -> StepSolver:
        """The StepSolver of (Δt, stab) (stab None: the paper's scheme), cached by value."""
        key = (dt, stab)
        if key not in self._solvers:
            p = self.params
            if len(self._solvers) >= 4:  # adaptive Δt, ratchet: keep the few most recent
                self._solvers.pop(next(iter(self._solvers)))
            s0, s2 = (0.0, 0.0) if stab is None else stab
            self._solvers[key] = self.solver_class(
                self.Mt, self.K, self.w, dt=dt, kappa=p.kappa, eps=p.eps, grid=self.fft_grid,
                s0=s0, s2=s2, cache=None if stab is None else self._preconditioners,
                lumped=self.mass == "lumped", **self.solver_opts)
        return self._solvers[key]

    def set_dt(self, dt: float, phi, mu, Kphi) -> None:
        """Δt changes the step matrix and its preconditioner (the stabilized scheme's, before
        its first step, at φ⁰'s (s₀, s₂))."""
        self.dt = float(dt)
        if self.fourier is not None:
            return  # the direct path builds its symbols per step: they are cheap
        stab = None
        if self.scheme == "stabilized":
            stab = self.stab or stabilization_coefficients(self.params,
                                                           *self.values(phi, mu, Kphi))
        self.solver = self.solver_for(self.dt, stab)

    # -- functionals ------------------------------------------------------------------------
    def values(self, phi, mu, Kphi):
        """(A, ΔA, V) at φ, None where the effect (area, ade, volume) is off."""
        p = self.params
        A = forms.area(phi, Kphi, self.w, p.eps) if p.on("area") else None
        dA = (forms.area_difference(phi, Kphi, self.w, p.D, p.eps) if p.on("ade") else None)
        V = forms.volume(phi, self.w, p.localized_volume) if p.on("volume") else None
        return A, dA, V

    def diagnostics(self, phi, mu, Kphi) -> dict:
        """E, W, G, V, A, ΔA (and T1, T2) of SPEC §6 (off terms report 0)."""
        p, w = self.params, self.w
        dA = forms.area_difference(phi, Kphi, w, p.D, p.eps) if p.on("ade") else None
        return p.energy(forms.bending(phi, mu, w, p.kappa, p.eps, p.C_eff),
                        forms.volume(phi, w, p.localized_volume),
                        forms.area(phi, Kphi, w, p.eps), dA)

    def volume_gradient(self, u) -> np.ndarray:
        """⟨δV/δφ, v⟩ at u: ½M_t·1, or M_t s′(u) for the localized V."""
        c = forms.volume_gradient(u, self.params.localized_volume)
        return self.Mt @ (c * np.ones_like(u))

    def area_gradient(self, u, Ku) -> np.ndarray:
        """⟨δA/δφ, v⟩ at u (with M_t = M_L the exact gradient of the discrete A)."""
        s, c = forms.area_gradient(u, self.params.eps)
        return s * Ku + self.Mt @ c

    # -- the explicit side ------------------------------------------------------------------
    def explicit_rhs(self, phi, mu, Kphi):
        """(⟨Rⁿ, v⟩ as a DOF vector, (A, ΔA, V)) (SPEC §4–§5); only the terms whose effect is
        on."""
        if self.products == "quadrature":
            values = self.values(phi, mu, Kphi)
            return self._explicit_rhs_quadrature(phi, mu, *values), values
        a, c, values = self.explicit_parts(phi, mu, Kphi)
        return self.weak(a, c), values

    def explicit_parts(self, phi, mu, Kphi):
        """(a, c, (A, ΔA, V)) with ⟨Rⁿ, v⟩ = K a + M_t c: the nodal products of every term."""
        p = self.params
        A, dA, V = self.values(phi, mu, Kphi)
        a, c = forms.bending_explicit(phi, mu, kappa=p.kappa, eps=p.eps, C=p.C_eff)
        if dA is not None:
            a2, c2 = forms.area_difference_gradient(phi, mu, p.eps, p.ade_force_coefficient(dA))
            a += a2
            c += c2
        if A is not None:
            s, c2 = forms.area_gradient(phi, p.eps, p.area_force_scale(A))
            a += s * phi
            c += c2
        if V is not None:  # slope × ⟨δV/δφ, v⟩ = slope × M_t(½ or s′(φ))
            c += p.volume_slope(V) * forms.volume_gradient(phi, p.localized_volume)
        return a, c, (A, dA, V)

    def _explicit_rhs_quadrature(self, phi, mu, A, dA, V) -> np.ndarray:
        p, basis = self.params, self.basis
        fields = {"phi": basis.interpolate(phi), "mu": basis.interpolate(mu), "eps": p.eps}
        r = forms.bending_explicit_form.assemble(basis, kappa=p.kappa, C=p.C_eff, **fields)
        if dA is not None:
            r += forms.area_difference_gradient_form.assemble(
                basis, coef=p.ade_force_coefficient(dA), **fields)
        if A is not None:
            r += forms.area_gradient_form.assemble(basis, coef=p.area_force_scale(A), **fields)
        if V is not None:
            r += p.volume_slope(V) * (self.Mt @ (forms.volume_gradient(phi, p.localized_volume)
                                                 * np.ones_like(phi)))
        return r

    def descent(self, Kphi, mu, rhs) -> np.ndarray:
        """−∇E_h(φⁿ) as a functional: −⟨Rⁿ, v⟩ − (−(2κ/ε)K + κεKM_L⁻¹K)φⁿ; it is also
        b − Sφⁿ of the paper's step, whose size sets the PCG tolerance."""
        p = self.params
        return (2.0 * p.kappa / p.eps) * Kphi - p.kappa * p.eps * (self.K @ mu) - rhs

    def rank_one(self, phi, mu, Kphi, A, dA, V):
        """[(σ, b)]: the rank-one Hessians of the penalty terms (volume, area, ADE)."""
        p = self.params
        out = []
        if V is not None and p.volume_curvature > 0:
            out.append((p.volume_curvature, self.volume_gradient(phi)))
        if A is not None and p.area_curvature > 0:
            out.append((p.area_curvature, self.area_gradient(phi, Kphi)))
        if dA is not None and p.ade_modulus > 0:
            out.append((p.ade_modulus,
                        self.weak(*forms.area_difference_gradient(phi, mu, p.eps, -0.75 * p.D))))
        return out

    # -- the steps --------------------------------------------------------------------------
    def step(self, phi, mu, Kphi, phi_prev):
        """One step from φⁿ (φⁿ⁻¹ for the warm start): (φⁿ⁺¹, extra history columns).

        ``krylov_its`` and ``solve_s`` count all the step's PCG solves (three when exact).
        """
        rhs, (A, dA, V) = self.explicit_rhs(phi, mu, Kphi)
        g = self.descent(Kphi, mu, rhs)
        if self.scheme == "paper" and not self.exact:
            b = self.Mt @ (phi / self.dt) - rhs
            x0 = phi if phi_prev is None else 2.0 * phi - phi_prev
            t0 = time.perf_counter()
            phi_new, its = self.solver.solve(b, x0, ref=phi, scale=_norm(g))
            return phi_new, {"krylov_its": int(its), "solve_s": time.perf_counter() - t0}
        low_rank = ()
        if self.scheme == "stabilized":
            self.stab = ratchet_stabilization(self.stab,
                                              stabilization_coefficients(self.params, A, dA, V))
            self.solver = self.solver_for(self.dt, self.stab)
            low_rank = self.rank_one(phi, mu, Kphi, A, dA, V)
        x0 = np.zeros_like(phi) if phi_prev is None else phi - phi_prev
        t0 = time.perf_counter()
        delta, its = self.solver.solve(g, x0, ref=np.zeros_like(g), scale=_norm(g),
                                       low_rank=low_rank)
        base, extra = phi + delta, {}
        if self.exact:
            base, lam_V, lam_A, its_z = self._constrained_update(phi, Kphi, base, low_rank)
            its += its_z
            extra = {"lambda_V": lam_V, "lambda_A": lam_A, "ramp": self.ramp.fraction}
        return base, {"krylov_its": int(its), "solve_s": time.perf_counter() - t0, **extra}

    def _constrained_update(self, phi, Kphi, base, low_rank):
        """φⁿ⁺¹ = base + a z_V + b z_A with V, A at this step's targets (α, β once the ramp is
        done): (φⁿ⁺¹, λ_V, λ_A, PCG its)."""
        bs = [self.volume_gradient(phi), self.area_gradient(phi, Kphi)]
        zs, its = [], 0
        for i, b in enumerate(bs):
            x0 = np.zeros_like(b) if self.z is None else self.z[i]
            z, k = self.solver.solve(b, x0, ref=np.zeros_like(b), scale=_norm(b),
                                     low_rank=low_rank)
            zs.append(z)
            its += k
        self.z = (zs[0], zs[1])
        Kb, Kz = self.K @ base, [self.K @ z for z in zs]
        JV = [_dot(bs[0], z) for z in zs]
        a, b = self._multipliers(base, Kb, zs, Kz, JV)
        return base + a * zs[0] + b * zs[1], -a, -b, its

    def _multipliers(self, base, Kbase, zs, Kz, JV):
        """(a, b) such that u = base + a z_V + b z_A has V, A at this step's targets (the
        ramp's): Newton on the 2×2 system, whose volume row is JV = (δV/δφ)·z when V is
        linear (the paper's functional) and is re-measured at u when it is localized."""
        p, w = self.params, self.w

        def measure(a, b):
            u = base + a * zs[0] + b * zs[1]
            Ku = Kbase + a * Kz[0] + b * Kz[1]
            gA = self.area_gradient(u, Ku)
            gV = [_dot(self.volume_gradient(u), z) for z in zs] if p.localized_volume else JV
            J = np.array([gV, [_dot(gA, z) for z in zs]])
            return forms.volume(u, w, p.localized_volume), forms.area(u, Ku, w, p.eps), J

        a, b, _ = self.ramp.solve(lambda targets: solve_multipliers(measure, *targets))
        return a, b

    # -- the direct path of uniform Q1 meshes: the same steps in Fourier space -------------------
    def fourier_step(self, phi_hat, phi, mu, Kphi):
        """One step of the scheme from φ̂ⁿ (and its φ, μ, Kφ): (φ̂ⁿ⁺¹, extra columns).

        On a uniform periodic Q1 mesh M_L, M, K are diagonal in Fourier space
        (:class:`fem_ade.fem.solve.FourierGrid`): the step's S⁻¹ is a division, the rank-one
        Hessians of the stabilized scheme and the constraint directions enter by Woodbury, so
        a step costs about as many transforms as the spectral reference's (four for the
        paper's scheme) and no PCG. The system solved is the same as :meth:`step`'s.
        """
        F, p = self.fourier, self.params
        t0 = time.perf_counter()
        a, c, (A, dA, V) = self.explicit_parts(phi, mu, Kphi)
        mt = F.ml if self.mass == "lumped" else F.Mh
        lumped = self.mass == "lumped"
        R = F.Kh * F.fwd(a) + mt * F.fwd(c)
        ke, two = p.kappa * p.eps, 2.0 * p.kappa / p.eps
        if self.scheme == "paper" and not self.exact:
            S = F.symbol(mass_factor=1.0 / self.dt, c=-two, ke=ke, lumped=lumped)
            return (mt * phi_hat / self.dt - R) / S, {"krylov_its": 0,
                                                      "solve_s": time.perf_counter() - t0}
        g = (two * F.Kh - ke * F.Kh * F.Kh / F.ml) * phi_hat - R  # −∇E_h(φⁿ)
        low = []
        if self.scheme == "stabilized":
            self.stab = ratchet_stabilization(self.stab,
                                              stabilization_coefficients(p, A, dA, V))
            s0, s2 = self.stab
            D = F.symbol(mass_factor=1.0 / self.dt + s0, c=s2 - two, ke=ke, lumped=lumped)
            low = self._rank_one_hat(phi_hat, phi, mu, A, dA, V, mt)
        else:
            D = F.symbol(mass_factor=1.0 / self.dt, c=-two, ke=ke, lumped=lumped)
        solve = _woodbury(F, D, low)
        new = phi_hat + solve(g)
        extra = {}
        if self.exact:
            new, lam_V, lam_A = self._fourier_constrained(phi, phi_hat, new, solve, low, mt)
            extra = {"lambda_V": lam_V, "lambda_A": lam_A, "ramp": self.ramp.fraction}
        return new, {"krylov_its": 0, "solve_s": time.perf_counter() - t0, **extra}

    def _volume_hat(self, phi, mt):
        """⟨δV/δφ, v⟩ in Fourier space: ½M̂_t at k = 0 only, or M̂_t·(s′(φ))^ (localized)."""
        F = self.fourier
        c = forms.volume_gradient(phi, self.params.localized_volume)
        if np.isscalar(c):
            out = np.zeros(F.Kh.shape, dtype=complex)
            out.flat[0] = c * F.size * (mt if np.isscalar(mt) else mt.flat[0])
            return out
        return mt * F.fwd(c)

    def _area_hat(self, phi_hat, phi, mt):
        """⟨δA/δφ, v⟩ in Fourier space: s K̂φ̂ + M̂_t ĉ (:func:`forms.area_gradient`)."""
        s, c = forms.area_gradient(phi, self.params.eps)
        return s * self.fourier.Kh * phi_hat + mt * self.fourier.fwd(c)

    def _rank_one_hat(self, phi_hat, phi, mu, A, dA, V, mt):
        """:meth:`rank_one` in Fourier space: [(σ, b̂)]."""
        p, F = self.params, self.fourier
        out = []
        if V is not None and p.volume_curvature > 0:
            out.append((p.volume_curvature, self._volume_hat(phi, mt)))
        if A is not None and p.area_curvature > 0:
            out.append((p.area_curvature, self._area_hat(phi_hat, phi, mt)))
        if dA is not None and p.ade_modulus > 0:
            a, c = forms.area_difference_gradient(phi, mu, p.eps, -0.75 * p.D)
            out.append((p.ade_modulus, F.Kh * F.fwd(a) + mt * F.fwd(c)))
        return out

    def _fourier_constrained(self, phi, phi_hat, base_h, solve, low, mt):
        """:meth:`_constrained_update` in Fourier space: (φ̂ⁿ⁺¹, λ_V, λ_A)."""
        F, p = self.fourier, self.params
        bV = self._volume_hat(phi, mt)
        bA = next((b for sig, b in low if sig == p.area_curvature and p.on("area")), None)
        bA = self._area_hat(phi_hat, phi, mt) if bA is None else bA
        zh = [solve(bV), solve(bA)]
        base, Kbase = F.inv(base_h), F.inv(F.Kh * base_h)
        zs = [F.inv(z) for z in zh]
        Kz = [F.inv(F.Kh * z) for z in zh]
        JV = [F.dot(bV, z) for z in zh]
        a, b = self._multipliers(base, Kbase, zs, Kz, JV)
        return base_h + a * zh[0] + b * zh[1], -a, -b

    # -- state ------------------------------------------------------------------------------
    def state(self) -> dict:
        s = {}
        if self.stab is not None:
            s["stab"] = np.array(self.stab)
        if self.z is not None:  # the warm starts of the constraint solves
            s["z_V"], s["z_A"] = self.z[0].copy(), self.z[1].copy()
        return s

    def set_state(self, state: dict) -> None:
        self.stab = (tuple(float(v) for v in state["stab"]) if "stab" in state else None)
        self.z = ((np.array(state["z_V"], dtype=float).ravel(),
                   np.array(state["z_A"], dtype=float).ravel()) if "z_V" in state else None)
