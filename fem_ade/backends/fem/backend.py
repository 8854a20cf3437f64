"""The finite-element backend: the loop's Backend protocol over a periodic spectral-element
space of order p (quads in 2D, hexahedra in 3D).

The glue only: the mesh (:mod:`.mesh`), the space (:mod:`.assemble`, :mod:`.tensor`), the
initial field, the state (φ, μ = W⁻¹Kφ, φⁿ⁻¹ for the warm start) and the output fields. The
physics is in :mod:`.forms` (every functional and its gradient) and :mod:`.step` (the
schemes); the linear solve is :mod:`.solve`.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from fem_ade.backends.base import BackendBase, check_choice
from fem_ade.backends.fem import mesh as fmesh
from fem_ade.backends.fem import output
from fem_ade.backends.fem.assemble import FILE_MESH_ORDERS, space
from fem_ade.backends.fem.solve import EXACT, make_solver
from fem_ade.backends.fem.step import MixedStep
from fem_ade.model.params import ModelError, is_int
from fem_ade.registry import FEM_ORDERS, FEM_SOLVERS, LINALGS, RUN_ORDERS
from fem_ade.scenes.catalogue import Scene


class FEMBackend(BackendBase):
    """Periodic spectral elements of order p on hexahedra (quads in 2D); the Backend protocol.

    Options beyond the protocol's (scene, n, dt, ic, perturb, seed, scheme, constraints):

    - ``order``: p, 1 to 16 on tensor meshes (GLL nodes and quadrature; p·n nodes per axis),
      1 or 2 on a mesh file;
    - ``mesh``: None/"uniform" (n cells per side), "graded[:g][@c]" (smooth periodic grading
      toward c, largest/smallest cell (1 + g)/(1 − g), g = 0.3), a mesh file path (meshio; opposite
      faces must carry matching nodes) or a :class:`fem_ade.backends.fem.mesh.PeriodicMesh`;
    - ``solver``: "auto" (default) | "fdm" | "fft" | "amg" | "chebyshev" | "jacobi"
      (:mod:`fem_ade.backends.fem.solve`);
    - ``rtol``: PCG tolerance relative to ‖b − Sφⁿ‖ (default 1e-6; PCG solvers only).

    The schemes are those of :mod:`fem_ade.backends.fem.step`.
    """

    name = "fem"
    extra_columns = ("krylov_its", "solve_s")
    #: the geometry (``geometry="axisymmetric"``:
    #: :class:`fem_ade.backends.fem.axisym.AxisymmetricFEMBackend`)
    geometry = "cartesian"
    #: the linear algebra: NumPy/SciPy/pyamg in one process (``--linalg petsc``:
    #: :class:`fem_ade.backends.fem.petsc.PETScFEMBackend`, distributed over MPI ranks)
    linalg = "numpy"
    solver_factory = staticmethod(make_solver)

    def __init__(self, scene: Scene, *, n: int, dt: float | None = None,
                 ic: str = "consistent", perturb: float = 0.0, seed: int = 0,
                 scheme: str = "paper", constraints: str = "penalty", order: int = 1,
                 mesh=None, solver: str = "auto", rtol: float | None = None,
                 linalg: str = "numpy", start_state: dict | None = None,
                 geometry: str = "cartesian", domain=None):
        t0 = time.perf_counter()
        super().__init__(scene, n=n, scheme=scheme, constraints=constraints)
        check_choice("FEM order", order, FEM_ORDERS)
        check_choice("FEM solver", solver, FEM_SOLVERS)
        if linalg != self.linalg:
            raise ModelError(f"{type(self).__name__} runs with linalg={self.linalg!r}; "
                             f"make_backend('fem', ..., linalg={linalg!r}) builds the one "
                             "for it")
        if geometry != self.geometry or (domain is not None and geometry == "cartesian"):
            raise ModelError(f"{type(self).__name__} runs geometry={self.geometry!r}"
                             + ("" if domain is None else " without a --domain") + "; "
                             "make_backend('fem', ..., geometry=...) builds the one for it")
        self.order = order
        #: cells per axis (n/p on a tensor mesh; None for a mesh file, which sets its own)
        self.cells = self.cells_per_axis(n, order, mesh)
        self.mesh = self._make_mesh(self.cells, mesh)
        self.space = self._space()
        self.ops = self.space  # the space's operators (K, weights, doflocs)
        self.K, self.w = self.space.K, self.space.weights
        self.stepper = MixedStep(self.space, self.params, scheme=scheme, exact=self.exact,
                                 solver=solver,
                                 rtol=rtol, solver_factory=self.solver_factory)
        t1 = time.perf_counter()
        if start_state is not None:
            self.set_state(start_state)
        else:
            phi = np.asarray(self.initial_field(self.space.doflocs, ic=ic, perturb=perturb,
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

    #: memory per unknown (bytes, with margin) of a tensor space solved exactly — matrix-free:
    #: the state, the step's work vectors, a batched solve of up to six right sides
    #: (measured: 358 MB peak at 128³ nodes, p = 1, 4 or 8, 105 MB at 64³: 137 B per unknown
    #: over a 70 MB baseline) — of a tensor space with PCG + AMG (the assembled low-order
    #: refined matrix and its hierarchy: 1.6 GB at 128³, 760 B per unknown), and of a mesh
    #: file (scikit-fem's matrices and AMG: 2.7 kB per unknown measured for Q1)
    bytes_per_dof = 400.0
    bytes_per_krylov_dof = 1500.0
    #: the element order of a run that gives none (:data:`fem_ade.registry.RUN_ORDERS`;
    #: the constructor's own default stays 1)
    RUN_ORDER = RUN_ORDERS["tensor"]
    bytes_per_assembled_dof = 4000.0

    @classmethod
    def memory_bytes(cls, scene: Scene, n: int, *, order: int = 1, mesh=None,
                     solver: str = "auto", linalg: str = "numpy", rtol=None,
                     geometry: str = "cartesian", domain=None) -> float:
        nodes = float(n) ** scene.dim
        kind, _ = fmesh.parse_option(mesh)
        if kind not in ("uniform", "graded"):
            return cls.bytes_per_assembled_dof * (1.2 if order > 1 else 1.0) * nodes
        exact = solver in ("auto", *EXACT) and linalg != "petsc"
        return (cls.bytes_per_dof if exact else cls.bytes_per_krylov_dof) * nodes

    @classmethod
    def default_n(cls, scene: Scene, *, order: int = 1, **options) -> int:
        """The scene's grid in nodes per axis, rounded to whole cells of order p (at least
        :data:`fem_ade.backends.fem.mesh.MIN_CELLS` of them)."""
        if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or order <= 1:
            return scene.n
        return int(order) * max(fmesh.MIN_CELLS, round(scene.n / int(order)))

    @classmethod
    def run_options(cls, options: dict) -> dict:
        """The order of a run that gives none: :data:`RUN_ORDER` on a tensor mesh, 1 on a
        mesh file (which takes 1 or 2)."""
        options = dict(options)
        if "order" not in options:
            tensor = fmesh.parse_option(options.get("mesh"))[0] in ("uniform", "graded")
            options["order"] = cls.RUN_ORDER if tensor else RUN_ORDERS["mesh file"]
        return options

    @classmethod
    def is_tensor(cls, mesh) -> bool:
        """Whether ``mesh`` (the ``mesh`` option) is a tensor mesh, uniform or graded — whose
        n nodes per axis are n/p cells of p + 1 GLL nodes — rather than a mesh file, which
        sets its own resolution (its n is only the grid the shape is measured on)."""
        return fmesh.parse_option(mesh)[0] in ("uniform", "graded")

    @classmethod
    def cells_per_axis(cls, n: int, order: int, mesh=None) -> int | None:
        """The cells per axis of n nodes per axis on a tensor mesh (n/p), None for a mesh
        file; n is checked first (:meth:`check_n`)."""
        cls.check_n(n, order=order, mesh=mesh)
        return int(n) // int(order) if cls.is_tensor(mesh) else None

    @classmethod
    def check_n(cls, n, *, order: int = 1, mesh=None, **options) -> None:
        """n nodes per axis: on a tensor mesh p·c for c >= :meth:`min_cells` cells of
        order p; any n >= 8 on a mesh file (the grid its shape is measured on)."""
        counts = is_int(n, 1) and is_int(order, 1)
        if not (counts and cls.is_tensor(mesh)):
            return super().check_n(n, order=order, mesh=mesh, **options)
        least = cls.min_n(order=order, mesh=mesh, **options)
        if n < least:
            raise ModelError(f"n (--n) = {n}: the FEM of order {order} needs at least {least} "
                             f"nodes per axis ({least // order} cells of {order} + 1 nodes)")
        if n % order:
            low = n // order * order
            raise ModelError(f"n (--n) = {n} nodes per axis is not a multiple of the order "
                             f"{order} (the FEM has order x cells nodes per axis): give "
                             f"{max(low, least)} or {low + order}")

    @classmethod
    def nodes_per_axis(cls, n: int, *, mesh=None, **options) -> int | None:
        """n on a tensor mesh (uniform or graded); None for a mesh file."""
        return n if cls.is_tensor(mesh) else None

    @classmethod
    def min_cells(cls, *, order: int = 1, **options) -> int:
        """At least 3 cells per axis (a periodic mesh) and 8 nodes (p·c ≥ 8)."""
        if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or order < 1:
            return 8
        return max(fmesh.MIN_CELLS, -(-8 // int(order)))

    @classmethod
    def min_n(cls, *, order: int = 1, mesh=None, **options) -> int:
        """p times :meth:`min_cells` on a tensor mesh; 8 on a mesh file."""
        if not (is_int(order, 1) and cls.is_tensor(mesh)):
            return 8
        return int(order) * cls.min_cells(order=order, **options)

    @classmethod
    def check_options(cls, scene: Scene, n: int, *, order: int = 1, mesh=None,
                      solver: str = "auto", linalg: str = "numpy", rtol=None,
                      geometry: str = "cartesian", domain=None) -> float:
        """Order, solver, mesh, linear algebra and tolerance; the node spacing h_max/p (of a
        graded mesh or a mesh file too, which is read here: its own spacing, not n's)."""
        from fem_ade.registry import GEOMETRIES

        check_choice("geometry (--geometry)", geometry, GEOMETRIES)
        if geometry != cls.geometry:
            raise ModelError(f"--geometry {geometry}: check through "
                             "fem_ade.backends.base.check_backend")
        if domain is not None:
            raise ModelError("--domain R,z0,z1 sets the axisymmetric half-plane; a Cartesian "
                             "run's domain is the scene's periodic box")
        if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or \
                order not in FEM_ORDERS:
            raise ModelError(f"--order must be an integer from 1 to {FEM_ORDERS[-1]}, "
                             f"got {order!r}")
        check_choice("FEM solver", solver, FEM_SOLVERS)
        check_choice("linear algebra (--linalg)", linalg, LINALGS)
        if rtol is not None and not (isinstance(rtol, float | int) and 1e-14 <= rtol < 1):
            raise ModelError(f"--rtol must be a number in [1e-14, 1) (below it round-off "
                             f"never lets PCG stop), got {rtol}")
        kind, _ = fmesh.parse_option(mesh)
        tensor = kind in ("uniform", "graded")
        if not tensor and order not in FILE_MESH_ORDERS:
            raise ModelError(f"a mesh file takes --order 1 or 2 (scikit-fem's Lagrange "
                             f"hexahedra); order {order} needs a tensor mesh (uniform or "
                             "graded)")
        if linalg == "petsc":
            if cls.linalg != "petsc":
                raise ModelError("--linalg petsc: check through "
                                 "fem_ade.backends.base.check_backend")
        elif solver in EXACT and not tensor:
            raise ModelError(f"solver {solver!r} needs a tensor mesh (uniform or graded), "
                             "not a mesh file")
        elif solver == "fft" and (order != 1 or kind != "uniform"):
            raise ModelError("solver 'fft' needs equally spaced nodes (order 1 on a uniform "
                             "mesh); 'fdm' solves every tensor mesh exactly")
        exact = linalg != "petsc" and (solver in EXACT or (solver == "auto" and tensor))
        if rtol is not None and exact:
            raise ModelError("--rtol sets the tolerance of the PCG solvers (amg, chebyshev, "
                             "jacobi); this run solves each step exactly (fdm)")
        # the resolution: the mean node spacing of the largest cell, h/p (nodes per axis p·n;
        # the GLL gaps inside a cell range from 0.35 to 1.6 times it at p = 8)
        if kind == "uniform":
            return scene.params.L / n
        if kind == "graded":
            return fmesh.make(scene.dim, n // order, scene.params.L, mesh).h_max / order
        return fmesh.make(scene.dim, n, scene.params.L, mesh).h_max / order

    def set_dt(self, dt: float) -> None:
        """Change Δt: the step's solver depends on it (kept per Δt, and for the stabilized
        scheme per (s₀, s₂); before its first step, at φ⁰'s (s₀, s₂))."""
        if dt == self.dt:
            return
        t0 = time.perf_counter()
        self.dt = float(dt)
        self.stepper.set_dt(self.dt, self.phi, self.mu, self.Kphi)
        self._setup.setdefault("solver_setup_s", time.perf_counter() - t0)

    def _make_mesh(self, cells: int | None, mesh):
        """The mesh of ``cells`` per axis (:func:`fem_ade.backends.fem.mesh.make`)."""
        return fmesh.make(self.scene.dim, cells, self.params.L, mesh)

    def _space(self):
        """The FEM space (:func:`fem_ade.backends.fem.assemble.space`)."""
        return space(self.mesh, self.order)

    # -- state -------------------------------------------------------------------------------
    def _set(self, phi, phi_prev):
        self.phi = phi
        self.phi_prev = phi_prev
        self.mu = self.space.laplacian(phi)  # μ = W⁻¹Kφ, the discrete −Δφ
        self.Kphi = self.w * self.mu

    def state(self) -> dict[str, np.ndarray]:
        s = {"phi": self.phi.copy(), "mu": self.mu.copy(), **self.stepper.state(),
             **self.ramp_state()}
        if self.phi_prev is not None:
            s["phi_prev"] = self.phi_prev.copy()
        return s

    def extrapolate(self, anchor: dict, beta: float) -> None:
        """φ ← φ + β(φ − φ_anchor); φⁿ⁻¹ (the warm start) stays."""
        self._set(self.phi + beta * (self.phi - anchor["phi"]), self.phi_prev)

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        phi = np.array(state.get("phi", np.zeros(0)), dtype=float).ravel()
        if phi.shape != (self.space.n_dofs,):
            raise ModelError(f"the state has {phi.size} values of phi; this FEM space "
                             f"(order {self.order}, n = {self.n} nodes per axis) has "
                             f"{self.space.n_dofs}")
        prev = state.get("phi_prev")
        prev = None if prev is None else np.array(prev, dtype=float).ravel()
        self._set(phi, prev)
        self.stepper.set_state(state)
        self.set_ramp_state(state)
        self.stepper.ramp = self.ramp

    # -- the step ----------------------------------------------------------------------------
    def step(self) -> dict:
        """One step of the scheme (:meth:`fem_ade.backends.fem.step.MixedStep.step`)."""
        phi, extra = self.stepper.step(self.phi, self.mu, self.Kphi, self.phi_prev)
        self._set(phi, self.phi)
        return extra

    def explicit_rhs(self) -> np.ndarray:
        """⟨Rⁿ, v⟩ at the current state."""
        return self.stepper.explicit_rhs(self.phi, self.mu, self.Kphi)[0]

    # -- measurements ------------------------------------------------------------------------
    def diagnostics(self) -> dict:
        return self.stepper.diagnostics(self.phi, self.mu, self.Kphi)

    def fields(self) -> dict[str, np.ndarray]:
        """φ, μ at the DOFs and their coordinates ``points`` (dim, N)."""
        return {"phi": self.phi.copy(), "mu": self.mu.copy(),
                "points": self.space.doflocs.copy()}

    def grid_phi(self) -> np.ndarray:
        """φ on the uniform periodic grid x_j = jL/m, m = n: the element's own
        interpolant on tensor meshes (exact to its order; the nodes themselves for p = 1 on a
        uniform mesh), linear interpolation on a mesh file."""
        return output.uniform_grid_field(self.mesh, self.space, self.phi, self.n)[0]

    def resolution_per_length(self) -> float:
        """n: the nodes per axis of :meth:`grid_phi`."""
        return float(self.n)

    def output_mesh(self):
        """(points (P, 3), [(cell type, connectivity)]) with the periodic images closed.

        Tensor meshes: the grid of all nodes (for p > 1 the GLL nodes as a finer grid of
        hexahedra) plus the closing layer at x = L. File meshes: the mesh's own vertices and
        cells (for p = 2, φ is shown at the vertices).
        """
        if self._out is None:
            self._out = output.closed_mesh(self.mesh, self.space)
        return self._out[0], self._out[1]

    def point_data(self) -> dict[str, np.ndarray]:
        """φ and μ at the points of :meth:`output_mesh`."""
        self.output_mesh()
        index = self._out[2]
        return {"phi": self.phi[index], "mu": self.mu[index]}

    def info(self) -> dict:
        solver = self.stepper.solver
        kind = solver.kind if solver is not None else self.stepper.solver_kind
        basis = self.stepper.eigenbasis
        if solver is None and basis is not None:  # before the first Δt: what auto will take
            kind = "fft" if basis.fourier else "fdm"
        grid = (f"n = {self.n} nodes per axis, {self.cells} cells"
                if self.mesh.is_tensor else
                f"mesh file {Path(self.mesh.source).name}, {self.space.n_dofs} nodes")
        return {
            "resolution": f"order {self.order} (GLL), {grid}, solver {kind}",
            "backend": self.name,
            "order": self.order,
            "element": f"Q{self.order} (GLL)",
            "n_dofs": int(self.space.n_dofs),
            "mesh": self.mesh.describe(),
            "space": self.space.describe(),
            "assembly": self.space.assembly,
            "scheme": self.scheme,
            "constraints": self.constraints,
            "solver": kind,
            "rtol": getattr(solver, "rtol", None),
            "amg_levels": getattr(solver, "levels", None),
            "dt": self.dt,
            **{k: round(v, 4) for k, v in self._setup.items()},
            "setup_s": round(sum(self._setup.values()), 4),
        }
