"""The finite-element backend: the mixed (φ, μ) semi-implicit step of SPEC §4–§5.

One step: find φⁿ⁺¹ (and μⁿ⁺¹ = M_L⁻¹Kφⁿ⁺¹, the lumped-mass −Δφ) with

    (M_t/Δt − (2κ/ε)K + κε K M_L⁻¹ K) φⁿ⁺¹ = M_t φⁿ/Δt − ⟨Rⁿ, v⟩,
    ⟨Rⁿ, v⟩ = κ⟨N(φⁿ), v⟩ + ⟨h(φⁿ), v⟩ + M₁(Vⁿ − α)(1, v) − (3√2/2)M₂(Aⁿ − β)⟨f(φⁿ), v⟩,

the terms of ⟨Rⁿ, v⟩ being those of :mod:`fem_ade.fem.forms`. Default (``products="nodal"``,
``mass="lumped"``): nonlinear products are interpolated at the nodes and every mass product is
the nodal quadrature M_L = diag(M·1), so ⟨Rⁿ, v⟩ = K a + M_L c (one sparse product) and the step
matrix is SPD for every Δt < ε³/κ, like the spectral symbol (with the consistent M in the time
derivative, ``mass="consistent"``, it is not: see :mod:`fem_ade.fem.solve`). Observed rates
against the spectral reference: 2 (Q1) and 4 (Q2) in E, V, A. A term whose effect is off is
never evaluated. M and K are assembled once (:mod:`fem_ade.fem.assemble`); the solve is
:class:`fem_ade.fem.solve.StepSolver`.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from ..constraints import check as check_constraints
from ..constraints import project
from ..model import AREA_FACTOR, ModelError
from ..scenes import Scene
from . import diagnostics, forms, output
from . import mesh as fmesh
from .assemble import operators
from .solve import StepSolver


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

    ``scheme="stabilized"`` (SPEC §10) is not implemented here and raises ModelError;
    ``constraints="exact"`` holds V = α and A = β by :func:`fem_ade.constraints.project`.
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
        if scheme != "paper":
            raise ModelError(f"the FEM backend implements the paper's scheme only (SPEC §4), "
                             f"not {scheme!r}; use --backend spectral for it")
        if mass not in ("lumped", "consistent"):
            raise ModelError(f"mass must be 'lumped' or 'consistent', got {mass!r}")
        if products not in ("nodal", "quadrature"):
            raise ModelError(f"products must be 'nodal' or 'quadrature', got {products!r}")
        self.scene = scene
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
        self._solver_opts = {"kind": solver, "rtol": rtol}
        self._solvers: dict[float, StepSolver] = {}
        self.set_dt(self.dt)
        t2 = time.perf_counter()
        phi = np.asarray(scene.initial_phi(self.ops.doflocs, ic=ic, perturb=perturb, seed=seed),
                         dtype=float)
        self.exact = check_constraints(constraints) == "exact"
        if self.exact:  # V = α, A = β held by projection (fem_ade.constraints)
            self.extra_columns = FEMBackend.extra_columns + ("lambda_V", "lambda_A")
            phi = self._project(phi)[0]
        self._set(phi, None)
        self._out = None
        self._setup = {"assembly_s": t1 - t0, "solver_setup_s": t2 - t1,
                       "setup_s": time.perf_counter() - t0}

    def set_dt(self, dt: float) -> None:
        """Change Δt: the step matrix and its preconditioner depend on it (kept per Δt)."""
        self.dt = float(dt)
        if self.dt not in self._solvers:
            p = self.params
            if len(self._solvers) >= 4:  # adaptive Δt: keep the few most recent
                self._solvers.pop(next(iter(self._solvers)))
            self._solvers[self.dt] = StepSolver(self.Mt, self.K, self.w, dt=self.dt,
                                                kappa=p.kappa, eps=p.eps, grid=self._fft_grid(),
                                                **self._solver_opts)
        self.solver = self._solvers[self.dt]

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
        return s

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        phi = np.array(state["phi"], dtype=float).ravel()
        if phi.shape != self.phi.shape:
            raise ModelError(f"state has {phi.size} values, this FEM space has {self.phi.size}")
        prev = state.get("phi_prev")
        self._set(phi, None if prev is None else np.array(prev, dtype=float).ravel())

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
        """One semi-implicit step; returns {"krylov_its", "solve_s"}."""
        p = self.params
        rhs = self.explicit_rhs()
        b = self.Mt @ (self.phi / self.dt) - rhs
        # ‖b − Sφⁿ‖ = ‖−⟨Rⁿ, v⟩ + (2κ/ε)Kφⁿ − κεKμⁿ‖: the size of this step's change
        scale = np.linalg.norm((2.0 * p.kappa / p.eps) * self.Kphi
                               - p.kappa * p.eps * (self.K @ self.mu) - rhs)
        x0 = self.phi if self.phi_prev is None else 2.0 * self.phi - self.phi_prev
        t0 = time.perf_counter()
        phi_new, its = self.solver.solve(b, x0, ref=self.phi, scale=scale)
        solve_s = time.perf_counter() - t0
        extra = {"krylov_its": int(its), "solve_s": solve_s}
        if self.exact:
            phi_new, a, b = self._project(phi_new)
            extra.update(lambda_V=-a / self.dt, lambda_A=-b / self.dt)
        self._set(phi_new, self.phi)
        return extra

    def _project(self, phi):
        """Hold V = α and A = β exactly (:func:`fem_ade.constraints.project`): (φ, a, b)."""
        p, w = self.params, self.w

        def measure(u):
            Ku = self.K @ u
            f = -p.eps * Ku / w - (u * u - 1.0) * u / p.eps  # f = εΔu − (1/ε)(u² − 1)u
            return (diagnostics.volume(u, w), diagnostics.area(u, Ku, w, p.eps),
                    np.full_like(u, 0.5), -AREA_FACTOR * f)

        phi, a, b, _ = project(phi, measure, lambda u, v: float(w @ (u * v)), p.alpha, p.beta)
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
            "solver": self.solver.kind,
            "rtol": self.solver.rtol,
            "amg_levels": self.solver.levels,
            "dt": self.dt,
            **{k: round(v, 4) for k, v in self._setup.items()},
        }
