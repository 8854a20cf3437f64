"""One registry of what a run is made of: backends (with their options), schemes, constraints.

The command line builds its choices from here, :func:`fem_ade.backends.base.make_backend` finds
backends here, and the tests iterate over these tables, so adding an entry is one edit. Data
only: importing this module imports no backend.
"""

from __future__ import annotations

from dataclasses import dataclass

#: time schemes every backend implements (docs/model.md §4, §9)
SCHEMES = {
    "paper": "the paper's semi-implicit scheme (docs/model.md §4); needs dt < eps^3/kappa",
    "stabilized": "linear, one solve per step, energy-stable at >= 100x the paper's dt",
}

#: initial-condition variants of a catalogue scene: the two readings of the paper's printed
#: constant c (docs/model.md §7), and "seeded", the paper's figure's shape (fem_ade.scenes.seeds)
IC_VARIANTS = ("consistent", "printed", "seeded")
#: the branches a vesicle of the ``vesicle`` scene family can start on (fem_ade.scenes.vesicle)
VESICLE_BRANCHES = ("prolate", "oblate", "stomatocyte", "pear", "torus", "sphere")

#: how V = α and A = β are enforced
CONSTRAINTS = {
    "penalty": "the paper's penalties M1 (V - alpha)^2 + M2 (A - beta)^2",
    "exact": "V = alpha and A = beta at every step, by Lagrange multipliers inside the step",
}

#: the volume functional V that the volume penalty or constraint holds at α
VOLUMES = {
    "paper": "V = integral of (phi + 1)/2 over the box (the paper's; a far field below -1 "
             "carries part of it)",
    "localized": "V = integral of s(phi), s = (2 + 3 phi - phi^3)/4: s(-1) = 0, s(1) = 1, "
                 "s'(+-1) = 0, so the bulk carries none of it",
}

#: recipes: what a run is for; each sets defaults that explicit options override
RECIPES = {
    "paper": "the paper's recipe: its scheme, penalties and dt, for --steps steps (default: "
             "the scene's)",
    "steady": "to a steady state: the stabilized scheme at 100x the paper's dt, exact "
              "constraints, momentum (--accelerate), until E_M changes by < 1e-9 per step "
              "(at most 20000 steps)",
}
#: the settings of each recipe (dt_factor multiplies the scene's dt)
RECIPE_SETTINGS = {
    "paper": {},
    "steady": {"scheme": "stabilized", "dt_factor": 100.0, "constraints": "exact",
               "accelerate": True, "until_steady": 1e-9, "max_steps": 20000},
}

#: how the FEM step's system is solved (fem_ade.backends.fem.solve): exactly by fast diagonalization
#: (fdm; fft is fdm where it uses the FFT), or by PCG with an AMG, Chebyshev or Jacobi
#: preconditioner
FEM_SOLVERS = ("auto", "fdm", "fft", "amg", "chebyshev", "jacobi")
#: the FEM's element orders (GLL nodes): any of these on a tensor mesh, 1 or 2 on a mesh file
FEM_ORDERS = tuple(range(1, 17))
#: the FEM's linear algebra: one process (NumPy, SciPy, pyamg) or PETSc over MPI ranks
LINALGS = ("numpy", "petsc")
#: the FEM's geometries: the periodic box in 3D (2D), or a surface of revolution on its
#: meridional half-plane (r, z) (docs/model.md §11)
GEOMETRIES = ("cartesian", "axisymmetric", "octant")


@dataclass(frozen=True)
class Option:
    """A backend-specific option: its keyword, type, default, allowed values and help."""

    name: str
    type: type
    default: object
    choices: tuple | None
    help: str


@dataclass(frozen=True)
class BackendSpec:
    """A backend: where its class lives ("module:Class"), the options it takes, and the
    classes that stand in for it for some option values (``variants``: ((option, value),
    "module:Class"), e.g. the FEM distributed over MPI ranks for ``linalg="petsc"``)."""

    name: str
    target: str
    description: str
    options: tuple[Option, ...] = ()
    variants: tuple[tuple[tuple[str, object], str], ...] = ()

    def target_for(self, **options) -> str:
        """The "module:Class" of the class that runs these options."""
        for (option, value), target in self.variants:
            if options.get(option) == value:
                return target
        return self.target

    @property
    def option_names(self) -> tuple[str, ...]:
        return tuple(o.name for o in self.options)


#: the FEM's element order where a run gives none — the one place each geometry's default is
#: stated: a tensor mesh's is the cost study's best at moderate accuracy
#: (studies/results/cost.md), the axisymmetric geometry's its resolution study's
#: (studies/results/axisymmetric.md), a mesh file's the order it can be read at (1 or 2);
#: ``FEMBackend(scene, n=...)`` built directly keeps its constructor's 1
RUN_ORDERS = {"tensor": 4, "axisymmetric": 8, "mesh file": 1}

BACKENDS = {
    "fem": BackendSpec(
        "fem", "fem_ade.backends.fem.backend:FEMBackend",
        "mixed (phi, mu) periodic finite elements on hexahedra (quads in 2D)",
        (
            Option("order", int, 1, None,
                   f"element order p, 1 to 16 (a run's default: {RUN_ORDERS['tensor']}, the "
                   "cost study's best at moderate accuracy; "
                   f"{RUN_ORDERS['axisymmetric']} axisymmetric; {RUN_ORDERS['mesh file']} on "
                   "a mesh file, which takes 1 or 2; FEMBackend's own: 1): Lagrange elements "
                   "with their nodes at the Gauss-Lobatto-Legendre points, --n/p cells per "
                   "axis"),
            Option("mesh", str, None, None,
                   "a periodic hexahedral mesh file (read with meshio), graded[:g][@c] for a "
                   "tensor mesh graded toward c (grading g in [0, 1)), or uniform (the "
                   "default: n/p cells per direction)"),
            Option("solver", str, "auto", FEM_SOLVERS,
                   "how the step's system is solved: auto (default: fdm on tensor meshes, "
                   "else chebyshev where the system is mass-dominated on near-uniform cells, "
                   "else amg); fdm (tensor meshes: exact, by fast diagonalization); fft (fdm "
                   "on order 1, uniform: by the FFT); PCG preconditioned by amg (on the "
                   "low-order refined operator for p > 1: flat iteration counts in h, p and "
                   "dt), chebyshev or jacobi"),
            Option("rtol", float, None, None,
                   "PCG tolerance relative to the step's initial residual (default 1e-6; "
                   "the exact solvers fdm and fft take none)"),
            Option("linalg", str, "numpy", LINALGS,
                   "numpy (default: one process) or petsc (PETSc KSP + hypre/GAMG, the mesh "
                   "distributed over the ranks of mpirun; docs/cluster.md)"),
            Option("geometry", str, "cartesian", GEOMETRIES,
                   "cartesian (default: the periodic box) or axisymmetric: a shape that is a "
                   "surface of revolution about a vertical axis, on its meridional half-plane "
                   "(r, z) with the measure 2 pi r dr dz (docs/model.md §11; by default order 8, "
                   "a mesh graded to the membrane and --n from eps: 2.5 nodes per eps); or "
                   "octant: a 3D state with the mirror planes x, y, z = L/2, on one eighth "
                   "of the box (docs/model.md §14)"),
            Option("domain", str, None, None,
                   "axisymmetric: the half-plane R,z0,z1 (r <= R, z0 <= z <= z1; default "
                   "L/sqrt(pi),0,L: the box's volume and height)"),
        ),
        variants=((("geometry", "axisymmetric"),
                   "fem_ade.backends.fem.axisym:AxisymmetricFEMBackend"),
                  (("geometry", "octant"), "fem_ade.backends.fem.octant:OctantFEMBackend"),
                  (("linalg", "petsc"), "fem_ade.backends.fem.petsc:PETScFEMBackend")),
    ),
    "spectral": BackendSpec(
        "spectral", "spectral_ref.solver:SpectralBackend",
        "the compact Fourier-spectral reference (docs/model.md §6)",
    ),
}
