"""The finite-element backend: the mixed (φ, μ) semi-implicit step of SPEC §4–§5.

One step: find φⁿ⁺¹ (and μⁿ⁺¹ = M_L⁻¹Kφⁿ⁺¹, the lumped-mass −Δφ) with

    (M_t/Δt − (2κ/ε)K + κε K M_L⁻¹ K) φⁿ⁺¹ = M_t φⁿ/Δt − ⟨Rⁿ, v⟩,
    ⟨Rⁿ, v⟩ = κ⟨N(φⁿ), v⟩ + ⟨h(φⁿ), v⟩ + M₁(Vⁿ − α)(1, v) − (3√2/2)M₂(Aⁿ − β)⟨f(φⁿ), v⟩,

the terms of ⟨Rⁿ, v⟩ being those of :mod:`fem_ade.fem.forms` (the paper's scheme, SPEC §4; the
stabilized scheme and exact constraints, which solve for δ = φⁿ⁺¹ − φⁿ, are described in
:class:`FEMBackend`). Default (``products="nodal"``,
``mass="lumped"``): nonlinear products are interpolated at the nodes and every mass product is
the nodal quadrature M_L = diag(M·1), so ⟨Rⁿ, v⟩ = K a + M_L c (one sparse product) and the step
matrix is SPD for every Δt < ε³/κ, like the spectral symbol (with the consistent M in the time
derivative, ``mass="consistent"``, it is not: see :mod:`fem_ade.fem.solve`). Observed rates
against the spectral reference: 2 (Q1) and 4 (Q2) in E, V, A. A term whose effect is off is
never evaluated. M and K are assembled once (:mod:`fem_ade.fem.assemble`); the solve is
:class:`fem_ade.fem.solve.StepSolver`.
"""

from __future__ import annotations

import math
import time

import numpy as np
import scipy.sparse as sp

from ..constraints import check as check_constraints
from ..constraints import project, solve_multipliers
from ..model import AREA_FACTOR, ModelError, ratchet_stabilization, stabilization_coefficients
from ..scenes import Scene
from . import diagnostics, forms, output
from . import mesh as fmesh
from .assemble import operators
from .solve import StepSolver, _dot

SCHEMES = ("paper", "stabilized")


def _norm(x) -> float:
    return math.sqrt(_dot(x, x))


class FEMBackend:
    """Periodic Q1/Q2 finite elements on hexahedra (quads in 2D); the Backend protocol.

    Options beyond the protocol's (scene, n, dt, ic, perturb, seed, scheme, constraints):

    - ``order``: 1 or 2 (Q1, Q2);
    - ``mesh``: None/"uniform" (n cells per side), "graded[:g]" (smooth periodic grading,
      largest/smallest cell (1 + g)/(1 − g), g = 0.3), a mesh file path (meshio; opposite
      faces must carry matching nodes) or a :class:`fem_ade.fem.mesh.PeriodicMesh`;
    - ``solver``: "amg" | "chebyshev" | "jacobi" | "fft" | "auto" (:mod:`fem_ade.fem.solve`);
    - ``rtol``: PCG tolerance relative to ‖b − Sφⁿ‖ (default 1e-6);
    - ``products``: "nodal" (default) or "quadrature" (scikit-fem LinearForms);
    - ``mass``: "lumped" (default) or "consistent" mass in the time derivative and products;
    - ``assembly``: "auto" (Kronecker for tensor meshes), "kron" or "skfem".

    ``scheme="stabilized"``: the large-step scheme of the spectral reference (SPEC §10,
    :func:`spectral_ref.solver.SpectralBackend._step_solver`) in weak form: δ = φⁿ⁺¹ − φⁿ solves

        [(1/Δt + s₀)M_t + (s₂ − 2κ/ε)K + κε K M_L⁻¹ K + Σᵢ σᵢ bᵢbᵢᵀ] δ = −∇E_h(φⁿ),

    −∇E_h(φⁿ) = −⟨Rⁿ, v⟩ + (2κ/ε)Kφⁿ − κεKμⁿ, (s₀, s₂) from
    :func:`fem_ade.model.ratchet_stabilization` (kept in :meth:`state`), and the rank-one
    Hessians of the penalties: volume σ = 2M₁, b = ½M_L·1; area σ = 2M₂, b = ⟨δA/δφ, v⟩; ADE
    σ = κ̄π/(A₀D²), b = ⟨δΔA/δφ, v⟩ (nodal products, the exact gradients of the discrete A, ΔA).
    The low-rank terms enter PCG matrix-free; the step matrix is rebuilt only when the
    ratcheted (s₀, s₂) change, its AMG hierarchy only when the preconditioner's shift moves to
    another point of its 5 % grid (:data:`fem_ade.fem.solve.SHIFT_GRID`).

    ``constraints="exact"``: V = α and A = β by multipliers inside the step, as the spectral
    reference (:mod:`fem_ade.constraints`): φⁿ⁺¹ = φⁿ + δ₀ + a z_V + b z_A, z = P⁻¹b (P the
    scheme's step operator; two extra PCG solves, warm-started from the previous step's z),
    (a, b) by :func:`fem_ade.constraints.solve_multipliers`; λ_V = −a, λ_A = −b. The initial
    condition is projected once by :func:`fem_ade.constraints.project`.
    """

    name = "fem"
    extra_columns = ("krylov_its", "solve_s")

    def __init__(self, scene: Scene, *, n: int, dt: float, ic: str = "consistent",
                 perturb: float = 0.0, seed: int = 0, scheme: str = "paper",
                 constraints: str = "penalty", order: int = 1, mesh=None,
                 solver: str = "amg", rtol: float | None = None, products: str = "nodal",
                 mass: str = "lumped", assembly: str = "auto"):
        t0 = time.perf_counter()
        if order not in (1, 2):
            raise ModelError(f"FEM order must be 1 or 2, got {order}")
        if scheme not in SCHEMES:
            raise ModelError(f"unknown scheme {scheme!r}; valid: {', '.join(SCHEMES)}")
        if mass not in ("lumped", "consistent"):
            raise ModelError(f"mass must be 'lumped' or 'consistent', got {mass!r}")
        if products not in ("nodal", "quadrature"):
            raise ModelError(f"products must be 'nodal' or 'quadrature', got {products!r}")
        self.scene = scene
        self.scheme = scheme
        self.stab: tuple[float, float] | None = None  # (s₀, s₂) of the stabilized scheme
        self._z: tuple[np.ndarray, np.ndarray] | None = None  # P⁻¹b_V, P⁻¹b_A (exact)
        self.n = n
        self.params = p = scene.params.validate()
        self.dt = float(dt)
        self.order = order
        self.products = products
        self.mesh = fmesh.make(scene.dim, n, p.L, mesh)
        self.ops = operators(self.mesh, order, "skfem" if products == "quadrature" else assembly)
        self.M, self.K, self.w = self.ops.M, self.ops.K, self.ops.weights
        if (self.w <= 0).any():
            raise ModelError("the lumped mass has non-positive entries on this mesh/element")
        self.mass = mass
        # the mass of the time derivative and of the explicit products: M_L (default) or M
        self.Mt = sp.diags(self.w).tocsr() if mass == "lumped" else self.M
        t1 = time.perf_counter()
        phi = np.asarray(scene.initial_phi(self.ops.doflocs, ic=ic, perturb=perturb, seed=seed),
                         dtype=float)
        self.exact = check_constraints(constraints) == "exact"
        if self.exact:  # V = α, A = β: the initial condition is projected once
            self.extra_columns = FEMBackend.extra_columns + ("lambda_V", "lambda_A")
            phi = self._project(phi)[0]
        self._set(phi, None)
        t2 = time.perf_counter()
        self._solver_opts = {"kind": solver, "rtol": rtol}
        self._solvers: dict[tuple, StepSolver] = {}
        self._preconditioners: dict = {}  # B⁻¹ of M_t + sK by (kind, s), shared (stabilized)
        self.set_dt(self.dt)
        t3 = time.perf_counter()
        self._out = None
        self._setup = {"assembly_s": t1 - t0, "solver_setup_s": t3 - t2,
                       "setup_s": time.perf_counter() - t0}

    def set_dt(self, dt: float) -> None:
        """Change Δt: the step matrix and its preconditioner depend on it (kept per Δt, and
        for the stabilized scheme per (s₀, s₂); before its first step, at φ⁰'s (s₀, s₂))."""
        self.dt = float(dt)
        stab = None
        if self.scheme == "stabilized":
            stab = self.stab if self.stab is not None else self._required_stab()
        self.solver = self._solver_for(stab)

    def _solver_for(self, stab) -> StepSolver:
        """The StepSolver of (Δt, stab) (stab None: the paper's scheme), cached by value."""
        key = (self.dt, stab)
        if key not in self._solvers:
            p = self.params
            if len(self._solvers) >= 4:  # adaptive Δt, ratchet: keep the few most recent
                self._solvers.pop(next(iter(self._solvers)))
            s0, s2 = (0.0, 0.0) if stab is None else stab
            self._solvers[key] = StepSolver(self.Mt, self.K, self.w, dt=self.dt, kappa=p.kappa,
                                            eps=p.eps, grid=self._fft_grid(), s0=s0, s2=s2,
                                            cache=None if stab is None else self._preconditioners,
                                            **self._solver_opts)
        return self._solvers[key]

    def _values(self):
        """(A, ΔA) at φⁿ, None where the effect (area, ade) is off."""
        p, phi = self.params, self.phi
        A = diagnostics.area(phi, self.Kphi, self.w, p.eps) if p.on("area") else None
        dA = (diagnostics.area_difference(phi, self.Kphi, self.w, p) if p.on("ade")
              else None)
        return A, dA

    def _required_stab(self):
        return stabilization_coefficients(self.params, *self._values())

    def _fft_grid(self):
        """(shape, spacing) when the DOFs form a uniform Q1 grid (the ``fft`` solver), else None."""
        if self.ops.assembly != "kron" or self.order != 1 or self.mesh.kind != "uniform":
            return None
        return (tuple(self.mesh.cells_per_axis),
                tuple(float(a[1] - a[0]) for a in self.mesh.axes), self.mass == "lumped")

    # -- state -------------------------------------------------------------------------------
    def _set(self, phi, phi_prev):
        self.phi = phi
        self.phi_prev = phi_prev
        self.Kphi = self.K @ phi
        self.mu = self.Kphi / self.w  # μ = −Δφ with the lumped mass: M_L μ = K φ

    def state(self) -> dict[str, np.ndarray]:
        s = {"phi": self.phi.copy(), "mu": self.mu.copy()}
        if self.phi_prev is not None:
            s["phi_prev"] = self.phi_prev.copy()
        if self.stab is not None:
            s["stab"] = np.array(self.stab)
        if self._z is not None:  # the warm starts of the constraint solves
            s["z_V"], s["z_A"] = self._z[0].copy(), self._z[1].copy()
        return s

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        phi = np.array(state["phi"], dtype=float).ravel()
        if phi.shape != self.phi.shape:
            raise ModelError(f"state has {phi.size} values, this FEM space has {self.phi.size}")
        prev = state.get("phi_prev")
        self._set(phi, None if prev is None else np.array(prev, dtype=float).ravel())
        self.stab = (tuple(float(v) for v in state["stab"]) if "stab" in state else None)
        self._z = ((np.array(state["z_V"], dtype=float).ravel(),
                    np.array(state["z_A"], dtype=float).ravel()) if "z_V" in state else None)

    # -- the step ----------------------------------------------------------------------------
    def explicit_rhs(self) -> np.ndarray:
        """⟨Rⁿ, v⟩ as a DOF vector (SPEC §4–§5); only the terms whose effect is on."""
        p, phi, mu = self.params, self.phi, self.mu
        if self.products == "quadrature":
            return self._explicit_rhs_quadrature()
        a, c = forms.bending_nodal(phi, mu, kappa=p.kappa, eps=p.eps, C=p.C_eff)
        if p.on("ade"):
            dA = diagnostics.area_difference(phi, self.Kphi, self.w, p)
            a2, c2 = forms.ade_nodal(phi, mu, gamma=forms.ade_coefficient(dA, p), eps=p.eps)
            a += a2
            c += c2
        if p.on("area"):
            A = diagnostics.area(phi, self.Kphi, self.w, p.eps)
            a2, c2 = forms.area_penalty_nodal(phi, coef=forms.area_penalty_coefficient(A, p),
                                              eps=p.eps)
            a += a2
            c += c2
        if p.on("volume"):
            c += forms.volume_penalty_coefficient(diagnostics.volume(phi, self.w), p)
        return self.K @ a + self.Mt @ c

    def _explicit_rhs_quadrature(self) -> np.ndarray:
        p, basis = self.params, self.ops.basis
        fields = {"phi": basis.interpolate(self.phi), "mu": basis.interpolate(self.mu),
                  "eps": p.eps}
        r = forms.bending_explicit.assemble(basis, kappa=p.kappa, C=p.C_eff, **fields)
        if p.on("ade"):
            dA = diagnostics.area_difference(self.phi, self.Kphi, self.w, p)
            r += forms.ade_explicit.assemble(basis, gamma=forms.ade_coefficient(dA, p), **fields)
        if p.on("area"):
            A = diagnostics.area(self.phi, self.Kphi, self.w, p.eps)
            r += forms.area_penalty_explicit.assemble(
                basis, coef=forms.area_penalty_coefficient(A, p), **fields)
        if p.on("volume"):
            r += forms.volume_penalty_coefficient(diagnostics.volume(self.phi, self.w), p) * self.w
        return r

    def step(self) -> dict:
        """One step of the scheme; returns {"krylov_its", "solve_s"} (+ λ_V, λ_A when exact).

        ``krylov_its`` and ``solve_s`` count all the step's PCG solves (three when exact).
        """
        if self.scheme == "paper" and not self.exact:
            return self._step_paper()
        p = self.params
        rhs = self.explicit_rhs()
        # −∇E_h(φⁿ) as a functional: −⟨Rⁿ, v⟩ − (−(2κ/ε)K + κεKM_L⁻¹K)φⁿ
        g = (2.0 * p.kappa / p.eps) * self.Kphi - p.kappa * p.eps * (self.K @ self.mu) - rhs
        low_rank = ()
        if self.scheme == "stabilized":
            A, dA = self._values()
            self.stab = ratchet_stabilization(self.stab, stabilization_coefficients(p, A, dA))
            self.solver = self._solver_for(self.stab)
            low_rank = self._low_rank(A, dA)
        x0 = np.zeros_like(self.phi) if self.phi_prev is None else self.phi - self.phi_prev
        t0 = time.perf_counter()
        delta, its = self.solver.solve(g, x0, ref=np.zeros_like(g),
                                       scale=_norm(g), low_rank=low_rank)
        extra = {}
        base = self.phi + delta
        if self.exact:
            base, lam_V, lam_A, its_z = self._constrained_update(base, low_rank)
            its += its_z
            extra = {"lambda_V": lam_V, "lambda_A": lam_A}
        solve_s = time.perf_counter() - t0
        self._set(base, self.phi)
        return {"krylov_its": int(its), "solve_s": solve_s, **extra}

    def _step_paper(self) -> dict:
        """The paper's scheme: S φⁿ⁺¹ = M_t φⁿ/Δt − ⟨Rⁿ, v⟩ (SPEC §4–§5)."""
        p = self.params
        rhs = self.explicit_rhs()
        b = self.Mt @ (self.phi / self.dt) - rhs
        # ‖b − Sφⁿ‖ = ‖−⟨Rⁿ, v⟩ + (2κ/ε)Kφⁿ − κεKμⁿ‖: the size of this step's change
        scale = _norm((2.0 * p.kappa / p.eps) * self.Kphi
                      - p.kappa * p.eps * (self.K @ self.mu) - rhs)
        x0 = self.phi if self.phi_prev is None else 2.0 * self.phi - self.phi_prev
        t0 = time.perf_counter()
        phi_new, its = self.solver.solve(b, x0, ref=self.phi, scale=scale)
        solve_s = time.perf_counter() - t0
        self._set(phi_new, self.phi)
        return {"krylov_its": int(its), "solve_s": solve_s}

    # -- the functionals of the constraints and of the penalties' rank-one Hessians -------------
    def _nodal(self, a, c):
        """K a + M_t c: a functional from nodal products, as in :meth:`explicit_rhs`."""
        return self.K @ a + self.Mt @ c

    def _area_functional(self, u, Ku):
        """⟨δA/δφ, v⟩ at u: (3√2/4)[ε(∇u, ∇v) + (1/ε)((u² − 1)u, v)].

        With M_t = M_L (the default) this is the exact gradient of the discrete A.
        """
        eps = self.params.eps
        return AREA_FACTOR * (eps * Ku + self.Mt @ ((u * u - 1.0) * u) / eps)

    def _low_rank(self, A, dA):
        """[(σ, b)]: the rank-one Hessian parts of the penalties made implicit (stabilized)."""
        p = self.params
        out = []
        if p.on("volume") and p.M1 > 0:
            out.append((2.0 * p.M1, 0.5 * self.w))
        if A is not None and p.M2 > 0:
            out.append((2.0 * p.M2, self._area_functional(self.phi, self.Kphi)))
        if dA is not None and p.kappa_bar > 0:
            a, c = forms.ade_nodal(self.phi, self.mu, gamma=-0.75 * p.D, eps=p.eps)
            out.append((p.kappa_bar * math.pi / (p.A0 * p.D**2), self._nodal(a, c)))
        return out

    def _constrained_update(self, base, low_rank):
        """φⁿ⁺¹ = base + a z_V + b z_A with V = α, A = β: (φⁿ⁺¹, λ_V, λ_A, PCG its)."""
        p, w = self.params, self.w
        bs = [0.5 * w, self._area_functional(self.phi, self.Kphi)]
        zs, its = [], 0
        for i, b in enumerate(bs):
            x0 = np.zeros_like(b) if self._z is None else self._z[i]
            z, k = self.solver.solve(b, x0, ref=np.zeros_like(b),
                                     scale=_norm(b), low_rank=low_rank)
            zs.append(z)
            its += k
        self._z = (zs[0], zs[1])
        Kb, Kz = self.K @ base, [self.K @ z for z in zs]
        JV = [_dot(bs[0], z) for z in zs]

        def fields(a, b):
            return base + a * zs[0] + b * zs[1], Kb + a * Kz[0] + b * Kz[1]

        def measure(a, b):
            u, Ku = fields(a, b)
            gA = self._area_functional(u, Ku)
            J = np.array([JV, [_dot(gA, z) for z in zs]])
            return diagnostics.volume(u, w), diagnostics.area(u, Ku, w, p.eps), J

        a, b, _ = solve_multipliers(measure, p.alpha, p.beta)
        return fields(a, b)[0], -a, -b, its

    def _project(self, phi):
        """Project the initial φ onto V = α, A = β (:func:`fem_ade.constraints.project`)."""
        p, w = self.params, self.w

        def measure(u):
            Ku = self.K @ u
            f = -p.eps * Ku / w - (u * u - 1.0) * u / p.eps  # f = εΔu − (1/ε)(u² − 1)u
            return (diagnostics.volume(u, w), diagnostics.area(u, Ku, w, p.eps),
                    np.full_like(u, 0.5), -AREA_FACTOR * f)

        phi, a, b, _ = project(phi, measure, lambda u, v: _dot(w, u * v), p.alpha, p.beta)
        return phi, a, b

    # -- measurements ------------------------------------------------------------------------
    def diagnostics(self) -> dict:
        return diagnostics.measure(self.phi, self.mu, self.Kphi, self.w, self.params)

    def max_abs_phi(self) -> float:
        if not np.all(np.isfinite(self.phi)):
            return float("nan")
        return float(np.max(np.abs(self.phi)))

    def fields(self) -> dict[str, np.ndarray]:
        """φ, μ at the DOFs and their coordinates ``points`` (dim, N), plus ``phi_grid``: φ on
        the uniform periodic grid x_j = jL/m (``x``), as the spectral backend gives it, for the
        shape analysis and pictures (m = order·n; exact for uniform meshes, interpolated else)."""
        out = {"phi": self.phi.copy(), "mu": self.mu.copy(), "points": self.ops.doflocs.copy()}
        out["phi_grid"], out["x"] = output.uniform_grid_field(self.mesh, self.ops, self.phi,
                                                              self.order * self.n)
        return out

    def output_mesh(self):
        """(points (P, 3), [(cell type, connectivity)]) with the periodic images closed.

        Tensor meshes: the grid of all DOF locations (Q2: its nodes as a twice finer grid of
        hexahedra) plus the closing layer at x = L. File meshes: the mesh's own vertices and
        cells (for Q2, φ is shown at the vertices).
        """
        if self._out is None:
            self._out = output.closed_mesh(self.mesh, self.ops)
        return self._out[0], self._out[1]

    def point_data(self) -> dict[str, np.ndarray]:
        """φ and μ at the points of :meth:`output_mesh`."""
        if self._out is None:
            self.output_mesh()
        index = self._out[2]
        return {"phi": self.phi[index], "mu": self.mu[index]}

    def info(self) -> dict:
        return {
            "backend": self.name,
            "order": self.order,
            "element": f"Q{self.order}",
            "n_dofs": int(self.ops.n_dofs),
            "mesh": self.mesh.describe(),
            "assembly": self.ops.assembly,
            "products": self.products,
            "mass": self.mass,
            "scheme": self.scheme,
            "constraints": "exact" if self.exact else "penalty",
            "solver": self.solver.kind,
            "rtol": self.solver.rtol,
            "amg_levels": self.solver.levels,
            "dt": self.dt,
            **{k: round(v, 4) for k, v in self._setup.items()},
        }
