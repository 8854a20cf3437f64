"""The time step of the mixed scheme on a FEM space: the paper's scheme, the stabilized scheme
and exact constraints — written once; the linear solve is a strategy
(:mod:`fem_ade.backends.fem.solve`: fast diagonalization on tensor meshes, PCG elsewhere).

With μ eliminated by the diagonal GLL mass W (μ = W⁻¹Kφ, the discrete −Δφ), every step is

    φⁿ⁺¹ = φⁿ + Ŝ⁻¹ gⁿ,   gⁿ = −∇E_h(φⁿ) = −⟨Rⁿ, v⟩ + (2κ/ε)Kφⁿ − κεKμⁿ,
    Ŝ = (1/Δt + s₀)W + (s₂ − 2κ/ε)K + κε K W⁻¹ K + Σᵢ σᵢ bᵢbᵢᵀ,
    ⟨Rⁿ, v⟩ = κ⟨N(φⁿ), v⟩ + ⟨h(φⁿ), v⟩ + M₁(Vⁿ − α)(1, v) − (3√2/2)M₂(Aⁿ − β)⟨f(φⁿ), v⟩,

only the terms whose effect is on being evaluated (:mod:`fem_ade.backends.fem.forms`:
⟨Rⁿ, v⟩ = K a + W c from nodal products). The global terms (volume, area, ADE) are records
(:mod:`fem_ade.backends.fem.terms`): the step iterates over the active ones, and the
functionals it measures once per state are a dict by name (``{"V": …, "A": …, "dA": …}``).
The paper's scheme is s₀ = s₂ = 0 and no σ terms — then this is its
(φⁿ⁺¹ − φⁿ)/Δt + κ(εΔ² + (2/ε)Δ)φⁿ⁺¹ = −Rⁿ, rearranged. The stabilized scheme takes (s₀, s₂)
from :func:`fem_ade.model.params.ratchet_stabilization` and the rank-one Hessians σbbᵀ of the
global terms (:meth:`MixedStep.rank_one`): volume σ = 2M₁, b = ⟨δV/δφ, v⟩; area σ = 2M₂,
b = ⟨δA/δφ, v⟩; ADE σ = κ̄π/(A₀D²), b = ⟨δΔA/δφ, v⟩ — the exact gradients of the discrete V,
A, ΔA.

Exact constraints (:mod:`fem_ade.model.constraints`): φⁿ⁺¹ = φⁿ + Ŝ⁻¹gⁿ + a z_V + b z_A,
z = Ŝ⁻¹b (solved with gⁿ: one batched solve; warm-started from the previous step's z when the
solve is iterative), (a, b) by :func:`fem_ade.model.constraints.solve_multipliers` at the step's
targets (their ramp from the initial V₀, A₀ to α, β); λ_V = −a, λ_A = −b.
"""

from __future__ import annotations

import math
import time

import numpy as np

from fem_ade.backends.fem import forms
from fem_ade.backends.fem.solve import EXACT, Eigenbasis, StepMatrix, global_dot, make_solver, norm
from fem_ade.backends.fem.terms import AREA, GLOBAL_TERMS, VOLUME, active_terms
from fem_ade.model.constraints import solve_multipliers
from fem_ade.model.params import (
    ModelError,
    Params,
    ratchet_stabilization,
    stabilization_coefficients,
)


class MixedStep:
    """The scheme on one FEM space (``space``: nodal weights W, K as ``K @ x``, and for tensor
    meshes the 1D axes the fast diagonalization needs).

    State it owns and :meth:`state` returns: the ratcheted (s₀, s₂) of the stabilized scheme
    and the warm starts z of the constraint solves. The field (φ, μ, Kφ, φⁿ⁻¹) is the caller's.
    """

    def __init__(self, space, params: Params, *, scheme: str, exact: bool, solver: str = "auto",
                 rtol: float | None = None, solver_factory=make_solver):
        self.params = params
        self.terms = active_terms(params)  # the global terms whose effect is on
        self.scheme, self.exact = scheme, exact
        self.space = space
        self.K, self.w = space.K, space.weights
        if (self.w <= 0).any():
            raise ModelError("the GLL mass has non-positive entries on this mesh/element")
        tensor = getattr(space, "axes", None) is not None  # whole 1D axes in this process
        if solver in EXACT and not tensor:
            raise ModelError(f"solver {solver!r} needs a tensor mesh (uniform or graded)")
        # the eigenbasis of the exact solves: once per run (it does not depend on Δt)
        self.eigenbasis = None
        if tensor and solver in ("auto", *EXACT):  # fdm: the dense eigenbasis even where the
            self.eigenbasis = Eigenbasis(space, None if solver != "fdm" else False)  # FFT fits
        self.solver_kind, self.rtol = solver, rtol
        self.solver_factory = solver_factory
        self.stab: tuple[float, float] | None = None
        self.z: tuple[np.ndarray, np.ndarray] | None = None
        self._solvers: dict[tuple, object] = {}
        self._preconditioners: dict = {}  # (W + sK̃)⁻¹ by (kind, s), shared (stabilized)
        self.dt = math.nan
        self.solver = None
        self.ramp = None  # the exact constraints' targets (fem_ade.model.constraints.TargetRamp)

    # -- linear algebra ---------------------------------------------------------------------
    def weak(self, a, c) -> np.ndarray:
        """K a + W c: a functional from nodal products (:mod:`fem_ade.backends.fem.forms`)."""
        return self.K @ a + self.w * c

    def solver_for(self, dt: float, stab):
        """The solver of (Δt, stab) (stab None: the paper's scheme), cached by value."""
        key = (dt, stab)
        if key not in self._solvers:
            p = self.params
            if len(self._solvers) >= 4:  # adaptive Δt, ratchet: keep the few most recent
                self._solvers.pop(next(iter(self._solvers)))
            s0, s2 = (0.0, 0.0) if stab is None else stab
            S = StepMatrix.of(dt=dt, kappa=p.kappa, eps=p.eps, s0=s0, s2=s2)
            self._solvers[key] = self.solver_factory(
                self.solver_kind, self.space, S, rtol=self.rtol, stabilized=stab is not None,
                cache=None if stab is None else self._preconditioners,
                eigenbasis=self.eigenbasis)
        return self._solvers[key]

    def set_dt(self, dt: float, phi, mu, Kphi) -> None:
        """Δt changes the step matrix and its solver (the stabilized scheme's, before its
        first step, at φ⁰'s (s₀, s₂))."""
        self.dt = float(dt)
        stab = None
        if self.scheme == "stabilized":
            stab = self.stab or stabilization_coefficients(self.params,
                                                           self.values(phi, mu, Kphi))
        self.solver = self.solver_for(self.dt, stab)

    # -- functionals ------------------------------------------------------------------------
    def values(self, phi, mu, Kphi) -> dict:
        """The active terms' functionals at φ by name ({"V": …, "A": …, "dA": …}; an effect
        that is off has no entry)."""
        p, w = self.params, self.w
        return {t.functional: t.measure(p, w, phi, Kphi) for t in self.terms}

    def diagnostics(self, phi, mu, Kphi) -> dict:
        """E, W, G, V, A, ΔA (and T1, T2); off terms report 0 (``Params.energy``). The
        penalties' V and A are measured even when off; ΔA only when ADE is on."""
        p, w = self.params, self.w
        functionals = {t.functional: t.measure(p, w, phi, Kphi) for t in GLOBAL_TERMS
                       if t.model.penalty or p.on(t.effect)}
        return p.energy(forms.bending(phi, mu, w, p.kappa, p.eps, p.C_eff), functionals)

    def volume_gradient(self, u) -> np.ndarray:
        """⟨δV/δφ, v⟩ at u: ½W·1, or W s′(u) for the localized V."""
        return VOLUME.gradient(self.params, self.K, self.w, u, None, None)

    def area_gradient(self, u, Ku) -> np.ndarray:
        """⟨δA/δφ, v⟩ at u (the exact gradient of the discrete A)."""
        return AREA.gradient(self.params, self.K, self.w, u, None, Ku)

    # -- derivatives (Newton's method: fem_ade.backends.fem.newton)
    # ------------------------------------
    def gradient(self, phi, mu, Kphi) -> np.ndarray:
        """∇E_h(φ): the exact gradient of the discrete energy (minus :meth:`descent`)."""
        a, c, _ = self.explicit_parts(phi, mu, Kphi)
        return -self.descent(phi, mu, a, c)

    def hessian_vector(self, phi, mu, Kphi, v) -> np.ndarray:
        """∇²E_h(φ) v, exactly: the derivative of :meth:`gradient` along v. Every term's
        linearization (:mod:`fem_ade.backends.fem.forms`), the ADE term's rank-one part
        G″·(∇ΔA·v)∇ΔA included; the penalties' terms where their effects are on."""
        p = self.params
        mu_v = self.space.laplacian(v)
        values = self.values(phi, mu, Kphi)
        a, c = self.hessian_parts(phi, mu, v, mu_v, values)
        Hv = self.K @ (a - (2.0 * p.kappa / p.eps) * v + (p.kappa * p.eps) * mu_v) \
            + self.w * c
        for sigma, b in self.rank_one(phi, mu, Kphi):
            Hv = Hv + sigma * global_dot(b, v) * b  # the functionals' slopes
        return Hv

    def hessian_parts(self, phi, mu, v, mu_v, values):
        """(a′, c′): the nodal products of the linearized explicit terms along (v, μ_v) —
        ∇²E_h v = K(a′ − (2κ/ε)v + κε μ_v) + W c′ + the rank-one terms — at φ whose
        :meth:`values` are ``values``. Pointwise and linear in (v, μ_v), so evaluated at
        v = 1, μ_v = 0 and at v = 0, μ_v = 1 they are the coefficients of
        :meth:`hessian_coefficients`. The terms are summed in :meth:`explicit_parts`' order."""
        p = self.params
        a, c = forms.bending_explicit_linear(phi, mu, v, mu_v, kappa=p.kappa, eps=p.eps,
                                             C=p.C_eff)
        for term in reversed(self.terms):
            a2, c2 = term.force_linear(p, phi, mu, v, mu_v, values[term.functional])
            if a2 is not None:
                a = a + a2
            if c2 is not None:
                c = c + c2
        return a, c

    def hessian_coefficients(self, phi, mu, Kphi, lam_V: float = 0.0,
                             lam_A: float = 0.0) -> dict:
        """The Hessian of the Lagrangian E_h + λ_V V_h + λ_A A_h at φ as coefficients, for
        assembling it (:mod:`fem_ade.backends.fem.direct`):

            H = κε K W⁻¹K + K diag(α) + diag(α) K + W diag(γ) + c₀ K + Σ σᵢ bᵢbᵢᵀ,

        ``alpha`` (α: a′'s coefficient of v, which equals c′'s of μ_v — the symmetry of the
        Hessian, checked here), ``gamma`` (γ: c′'s coefficient of v), ``c0`` (−2κ/ε and the
        area terms' constant multiples of K) and ``rank_one`` [(σ, b)]."""
        p = self.params
        ones, zeros = np.ones_like(phi), np.zeros_like(phi)
        values = self.values(phi, mu, Kphi)
        a1, c1 = self.hessian_parts(phi, mu, ones, zeros, values)
        a2, c2 = self.hessian_parts(phi, mu, zeros, ones, values)
        a1, c1, a2, c2 = (np.broadcast_to(x, phi.shape).astype(float) for x in (a1, c1, a2, c2))
        # a′ = s v + α v (s: the constant multiple of v, the area terms'), c′ = γ v + α μ_v
        s = a1 - c2
        if np.any(a2 != 0.0) or np.ptp(s) > 1e-12 * max(1.0, float(np.max(np.abs(a1)))):
            raise ArithmeticError("the Hessian's parts are not of the assumed form")
        c0 = float(np.mean(s)) - 2.0 * p.kappa / p.eps
        gamma = c1 + lam_V * forms.volume_gradient_linear(phi, ones, p.localized_volume)
        if lam_A:
            sa, ca = forms.area_gradient_linear(phi, ones, p.eps)
            c0 += lam_A * sa
            gamma = gamma + lam_A * ca
        return {"alpha": c2, "gamma": gamma, "c0": c0,
                "rank_one": self.rank_one(phi, mu, Kphi)}

    def constraint_hessian_vector(self, phi, Kphi, v, lam_V, lam_A) -> np.ndarray:
        """(λ_V ∇²V_h + λ_A ∇²A_h) v: the exact constraints' part of the Lagrangian's
        Hessian."""
        p = self.params
        out = lam_V * self.w * forms.volume_gradient_linear(phi, v, p.localized_volume)
        s, c = forms.area_gradient_linear(phi, v, p.eps)
        return out + lam_A * (s * (self.K @ v) + self.w * c)

    # -- the explicit side ------------------------------------------------------------------
    def explicit_parts(self, phi, mu, Kphi):
        """(a, c, values) with ⟨Rⁿ, v⟩ = K a + W c: the nodal products of every term, and the
        functionals measured (:meth:`values`).

        The global terms are added last to first (ADE, area, volume): the order of the sum
        the scheme has always had, which the floating-point sums (and the histories, bit for
        bit) depend on."""
        p = self.params
        values = self.values(phi, mu, Kphi)
        a, c = forms.bending_explicit(phi, mu, kappa=p.kappa, eps=p.eps, C=p.C_eff)
        for term in reversed(self.terms):
            a2, c2 = term.force(p, phi, mu, values[term.functional])
            if a2 is not None:
                a += a2
            if c2 is not None:
                c += c2
        return a, c, values

    def explicit_rhs(self, phi, mu, Kphi):
        """(⟨Rⁿ, v⟩ as a DOF vector, the functionals by name); only the terms whose effect
        is on."""
        a, c, values = self.explicit_parts(phi, mu, Kphi)
        return self.weak(a, c), values

    def descent(self, phi, mu, a, c) -> np.ndarray:
        """gⁿ = −∇E_h(φⁿ) = K((2κ/ε)φ − κεμ − a) − W c for ⟨Rⁿ, v⟩ = K a + W c (one product
        with K); it is also the residual b − Sφⁿ of the paper's step."""
        p = self.params
        return self.K @ ((2.0 * p.kappa / p.eps) * phi - (p.kappa * p.eps) * mu - a) - self.w * c

    def rank_one(self, phi, mu, Kphi):
        """[(σ, b)]: the rank-one Hessians σ = T″(Q), b = ⟨δQ/δφ, v⟩ of the active global
        terms (volume, area, ADE: the model's order) whose σ is positive."""
        p = self.params
        out = []
        for term in self.terms:
            sigma = term.curvature(p)
            if sigma > 0:
                out.append((sigma, term.gradient(p, self.K, self.w, phi, mu, Kphi)))
        return out

    # -- the step ---------------------------------------------------------------------------
    def step(self, phi, mu, Kphi, phi_prev):
        """One step from φⁿ (φⁿ⁻¹ for the warm start): (φⁿ⁺¹, extra history columns).

        ``krylov_its`` counts the PCG iterations of all the step's solves (0: exact solve).
        """
        a, c, values = self.explicit_parts(phi, mu, Kphi)
        g = self.descent(phi, mu, a, c)
        low_rank = ()
        if self.scheme == "stabilized":
            self.stab = ratchet_stabilization(self.stab,
                                              stabilization_coefficients(self.params, values))
            self.solver = self.solver_for(self.dt, self.stab)
            low_rank = self.rank_one(phi, mu, Kphi)
        rhs = [g]
        x0 = [None if phi_prev is None else phi - phi_prev]
        scales = [norm(g)]
        if self.exact:
            bs = [self.volume_gradient(phi), self.area_gradient(phi, Kphi)]
            rhs += bs
            x0 += [None, None] if self.z is None else list(self.z)
            scales += [norm(b) for b in bs]
        t0 = time.perf_counter()
        xs, its = self.solver.solve(rhs, x0, scales, low_rank=low_rank)
        base, extra = phi + xs[0], {}
        if self.exact:
            self.z = (xs[1], xs[2])
            base, lam_V, lam_A = self._constrained_update(base, bs, xs[1:])
            extra = {"lambda_V": lam_V, "lambda_A": lam_A, "ramp": self.ramp.fraction}
        return base, {"krylov_its": int(its), "solve_s": time.perf_counter() - t0, **extra}

    def _constrained_update(self, base, bs, zs):
        """φⁿ⁺¹ = base + a z_V + b z_A with V, A at this step's targets (α, β once the ramp is
        done): (φⁿ⁺¹, λ_V, λ_A)."""
        Kb, Kz = self.K @ base, [self.K @ z for z in zs]
        JV = [global_dot(bs[0], z) for z in zs]
        a, b = self._multipliers(base, Kb, zs, Kz, JV)
        return base + a * zs[0] + b * zs[1], -a, -b

    def _multipliers(self, base, Kbase, zs, Kz, JV):
        """(a, b) such that u = base + a z_V + b z_A has V, A at this step's targets (the
        ramp's): Newton on the 2×2 system, whose volume row is JV = (δV/δφ)·z when V is
        linear (the paper's functional) and is re-measured at u when it is localized."""
        p, w = self.params, self.w

        def measure(a, b):
            u = base + a * zs[0] + b * zs[1]
            Ku = Kbase + a * Kz[0] + b * Kz[1]
            gA = self.area_gradient(u, Ku)
            gV = [global_dot(self.volume_gradient(u), z) for z in zs] if p.localized_volume else JV
            J = np.array([gV, [global_dot(gA, z) for z in zs]])
            return VOLUME.measure(p, w, u, Ku), AREA.measure(p, w, u, Ku), J

        a, b, _ = self.ramp.solve(lambda targets: solve_multipliers(measure, *targets))
        return a, b

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
