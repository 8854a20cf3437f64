"""The finite-element backend: the loop's Backend protocol over a periodic Q1/Q2 space.

The glue only: the mesh (:mod:`.mesh`), M and K (:mod:`.assemble`), the initial field, the
state (φ, μ = M_L⁻¹Kφ, φⁿ⁻¹ for the warm start) and the output fields. The physics is in
:mod:`.forms` (every functional and its gradient) and :mod:`.step` (the schemes); the linear
solve is :mod:`.solve`.
"""

from __future__ import annotations

import time

import numpy as np

from ..backend import BackendBase, check_choice
from ..model import ModelError
from ..registry import FEM_SOLVERS, LINALGS
from ..scenes import Scene
from . import mesh as fmesh
from . import output
from .assemble import operators
from .solve import StepSolver
from .step import MixedStep


class FEMBackend(BackendBase):
    """Periodic Q1/Q2 finite elements on hexahedra (quads in 2D); the Backend protocol.

    Options beyond the protocol's (scene, n, dt, ic, perturb, seed, scheme, constraints):

    - ``order``: 1 or 2 (Q1, Q2);
    - ``mesh``: None/"uniform" (n cells per side), "graded[:g]" (smooth periodic grading,
      largest/smallest cell (1 + g)/(1 − g), g = 0.3), a mesh file path (meshio; opposite
      faces must carry matching nodes) or a :class:`fem_ade.fem.mesh.PeriodicMesh`;
    - ``solver``: "auto" (default) | "amg" | "chebyshev" | "jacobi" | "fft"
      (:mod:`fem_ade.fem.solve`);
    - ``rtol``: PCG tolerance relative to ‖b − Sφⁿ‖ (default 1e-6);
    - ``products``: "nodal" (default) or "quadrature" (scikit-fem LinearForms);
    - ``mass``: "lumped" (default) or "consistent" mass in the time derivative and products;
    - ``assembly``: "auto" (Kronecker for tensor meshes), "kron" or "skfem".

    The schemes are those of :mod:`fem_ade.fem.step`.
    """

    name = "fem"
    extra_columns = ("krylov_its", "solve_s")
    #: the linear algebra: NumPy/SciPy/pyamg in one process (``--linalg petsc``:
    #: :class:`fem_ade.fem.petsc.PETScFEMBackend`, distributed over MPI ranks)
    linalg = "numpy"
    solver_class = StepSolver

    def __new__(cls, *args, linalg: str = "numpy", **kwargs):
        if linalg == "petsc" and cls is FEMBackend:
            from .petsc import PETScFEMBackend

            return super().__new__(PETScFEMBackend)
        return super().__new__(cls)

    def __init__(self, scene: Scene, *, n: int, dt: float | None = None,
                 ic: str = "consistent", perturb: float = 0.0, seed: int = 0,
                 scheme: str = "paper", constraints: str = "penalty", order: int = 1,
                 mesh=None, solver: str = "auto", rtol: float | None = None,
                 products: str = "nodal", mass: str = "lumped", assembly: str = "auto",
                 linalg: str = "numpy", start_state: dict | None = None):
        t0 = time.perf_counter()
        super().__init__(scene, n=n, scheme=scheme, constraints=constraints)
        check_choice("FEM order", order, (1, 2))
        check_choice("FEM solver", solver, FEM_SOLVERS)
        self.order = order
        p = self.params
        self.mesh = fmesh.make(self.scene.dim, n, p.L, mesh)
        self.ops = self._operators("skfem" if products == "quadrature" else assembly)
        self.K, self.w = self.ops.K, self.ops.weights
        self.stepper = MixedStep(self.ops, p, scheme=scheme, exact=self.exact, mass=mass,
                                 products=products, solver=solver, rtol=rtol,
                                 fft_grid=self._fft_grid(), solver_class=self.solver_class)
        t1 = time.perf_counter()
        if start_state is not None:
            self.set_state(start_state)
        else:
            phi = np.asarray(self.initial_field(self.ops.doflocs, ic=ic, perturb=perturb,
                                                seed=seed), dtype=float)
            self._set(phi, None)
            if self.exact:
                d = self.diagnostics()
                self.start_ramp(d["V"], d["A"])
                self.stepper.ramp = self.ramp
        self._out = None
        self._setup = {"assembly_s": t1 - t0, "initial_s": time.perf_counter() - t1}
        if dt is not None:
            self.set_dt(dt)

    #: memory per unknown of Q1 (measured: 712 MB peak for a 64³ run with AMG, 2.7 kB per
    #: unknown; with margin), Q2's matrices have 125 entries per row instead of 27
    bytes_per_dof = 4000.0

    @classmethod
    def memory_bytes(cls, scene: Scene, n: int, *, order: int = 1, mesh=None,
                     solver: str = "auto", linalg: str = "numpy", rtol=None) -> float:
        return cls.bytes_per_dof * (4.6 if order == 2 else 1.0) * float(order * n) ** scene.dim

    @classmethod
    def check_options(cls, scene: Scene, n: int, *, order: int = 1, mesh=None,
                      solver: str = "auto", linalg: str = "numpy", rtol=None) -> float:
        """Order, solver, mesh, linear algebra and tolerance; the largest node spacing (of a
        graded mesh or a mesh file too, which is read here: its own spacing, not n's)."""
        check_choice("FEM order", order, (1, 2))
        check_choice("FEM solver", solver, FEM_SOLVERS)
        check_choice("linear algebra (--linalg)", linalg, LINALGS)
        if rtol is not None and not (isinstance(rtol, float | int) and 0 < rtol < 1):
            raise ModelError(f"--rtol must be a number in (0, 1), got {rtol}")
        if linalg == "petsc":
            from .petsc import check_options as check_petsc

            check_petsc(scene, n, order=order, mesh=mesh, solver=solver)
        kind, _ = fmesh.parse_option(mesh)
        if solver == "fft" and (order != 1 or kind != "uniform"):
            raise ModelError("solver 'fft' needs a uniform tensor mesh with Q1 elements")
        if kind == "uniform":
            return scene.params.L / (n * order)
        return fmesh.make(scene.dim, n, scene.params.L, mesh).h_max / order

    def set_dt(self, dt: float) -> None:
        """Change Δt: the step matrix and its preconditioner depend on it (kept per Δt, and
        for the stabilized scheme per (s₀, s₂); before its first step, at φ⁰'s (s₀, s₂))."""
        if dt == self.dt:
            return
        t0 = time.perf_counter()
        self.dt = float(dt)
        self.stepper.set_dt(self.dt, self.phi, self.mu, self.Kphi)
        self._setup.setdefault("solver_setup_s", time.perf_counter() - t0)

    def _operators(self, assembly: str):
        """M, K, weights, DOF coordinates (:func:`fem_ade.fem.assemble.operators`)."""
        return operators(self.mesh, self.order, assembly)

    def _fft_grid(self):
        """(cells, spacing) when the DOFs form a uniform Q1 grid (the ``fft`` solver), else None."""
        if self.ops.assembly != "kron" or self.order != 1 or self.mesh.kind != "uniform":
            return None
        return (tuple(self.mesh.cells_per_axis),
                tuple(float(a[1] - a[0]) for a in self.mesh.axes))

    # -- state -------------------------------------------------------------------------------
    def _set(self, phi, phi_prev):
        if self.stepper.fourier is not None:  # the direct path keeps φ̂ as the state
            self._set_hat(self.stepper.fourier.fwd(phi), phi_prev)
            return
        self.phi = phi
        self.phi_prev = phi_prev
        self.Kphi = self.K @ phi
        self.mu = self.Kphi / self.w  # μ = −Δφ with the lumped mass: M_L μ = K φ

    def _set_hat(self, phi_hat, phi_prev):
        """The direct Fourier path (uniform Q1, ``fft``): φ, Kφ and μ from φ̂, so that φ̂
        alone is the state (a resumed run is bit for bit the uninterrupted one)."""
        F = self.stepper.fourier
        self.phi_hat = F.hermitian(phi_hat)
        self.phi = F.inv(phi_hat)
        self.phi_prev = phi_prev
        self.Kphi = F.inv(F.Kh * phi_hat)
        self.mu = self.Kphi / self.w

    def state(self) -> dict[str, np.ndarray]:
        s = {"phi": self.phi.copy(), "mu": self.mu.copy(), **self.stepper.state(),
             **self.ramp_state()}
        if self.stepper.fourier is not None:
            s["phi_hat"] = self.phi_hat  # replaced, never mutated, by step()
        if self.phi_prev is not None:
            s["phi_prev"] = self.phi_prev.copy()
        return s

    def extrapolate(self, anchor: dict, beta: float) -> None:
        """φ ← φ + β(φ − φ_anchor); φⁿ⁻¹ (the warm start) stays."""
        if self.stepper.fourier is not None:
            self._set_hat(self.phi_hat + beta * (self.phi_hat - anchor["phi_hat"]),
                          self.phi_prev)
            return
        self._set(self.phi + beta * (self.phi - anchor["phi"]), self.phi_prev)

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        phi = np.array(state.get("phi", np.zeros(0)), dtype=float).ravel()
        if phi.shape != (self.ops.n_dofs,):
            raise ModelError(f"the state has {phi.size} values of phi; this FEM space "
                             f"(Q{self.order}, n = {self.n}) has {self.ops.n_dofs}")
        prev = state.get("phi_prev")
        prev = None if prev is None else np.array(prev, dtype=float).ravel()
        if self.stepper.fourier is not None and "phi_hat" in state:
            self._set_hat(np.array(state["phi_hat"]), prev)
        else:
            self._set(phi, prev)
        self.stepper.set_state(state)
        self.set_ramp_state(state)
        self.stepper.ramp = self.ramp

    # -- the step ----------------------------------------------------------------------------
    def step(self) -> dict:
        """One step of the scheme (:meth:`fem_ade.fem.step.MixedStep.step`, or its direct
        Fourier path on uniform Q1 meshes)."""
        if self.stepper.fourier is not None:
            new, extra = self.stepper.fourier_step(self.phi_hat, self.phi, self.mu, self.Kphi)
            self._set_hat(new, self.phi)
            return extra
        phi, extra = self.stepper.step(self.phi, self.mu, self.Kphi, self.phi_prev)
        self._set(phi, self.phi)
        return extra

    def explicit_rhs(self) -> np.ndarray:
        """⟨Rⁿ, v⟩ at the current state (SPEC §4–§5)."""
        return self.stepper.explicit_rhs(self.phi, self.mu, self.Kphi)[0]

    # -- measurements ------------------------------------------------------------------------
    def diagnostics(self) -> dict:
        return self.stepper.diagnostics(self.phi, self.mu, self.Kphi)

    def fields(self) -> dict[str, np.ndarray]:
        """φ, μ at the DOFs and their coordinates ``points`` (dim, N)."""
        return {"phi": self.phi.copy(), "mu": self.mu.copy(), "points": self.ops.doflocs.copy()}

    def grid_phi(self) -> np.ndarray:
        """φ on the uniform periodic grid x_j = jL/m, m = order·n (exact for uniform meshes,
        interpolated else)."""
        return output.uniform_grid_field(self.mesh, self.ops, self.phi, self.order * self.n)[0]

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
        self.output_mesh()
        index = self._out[2]
        return {"phi": self.phi[index], "mu": self.mu[index]}

    def info(self) -> dict:
        solver = self.stepper.solver
        direct = self.stepper.fourier is not None
        return {
            "backend": self.name,
            "order": self.order,
            "element": f"Q{self.order}",
            "n_dofs": int(self.ops.n_dofs),
            "mesh": self.mesh.describe(),
            "assembly": self.ops.assembly,
            "products": self.stepper.products,
            "mass": self.stepper.mass,
            "scheme": self.scheme,
            "constraints": self.constraints,
            "solver": "fft (direct)" if direct else solver.kind if solver else
            self.stepper.solver_opts["kind"],
            "rtol": solver.rtol if solver else None,
            "amg_levels": solver.levels if solver else None,
            "dt": self.dt,
            **{k: round(v, 4) for k, v in self._setup.items()},
            "setup_s": round(sum(self._setup.values()), 4),
        }
