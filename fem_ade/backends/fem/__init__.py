"""The finite-element backend: mixed (φ, μ) spectral elements of any order on periodic
hexahedral (quad) meshes.

- :mod:`.mesh`         periodic hexahedral / quad meshes: uniform, graded, from file
- :mod:`.gll`          Gauss–Lobatto–Legendre nodes, weights and 1D element matrices
- :mod:`.tensor`       the order-p space on a tensor mesh: matrix-free K (sum factorization)
- :mod:`.assemble`     the space of a run (tensor, or scikit-fem's Q1/Q2 on a mesh file)
- :mod:`.forms`        every functional and its gradient, once (the weak forms)
- :mod:`.terms`        the global terms (volume, area, ADE), one record each
- :mod:`.step`         the schemes: the paper's, the stabilized one, exact constraints
- :mod:`.solve`        the step's solve: fast diagonalization, or PCG with AMG (pyamg)
- :mod:`.petsc`        the same step distributed over MPI ranks (PETSc)
- :mod:`.output`       closed output mesh (XDMF) and φ on the uniform grid (shape analysis)
- :mod:`.backend`      :class:`FEMBackend`, the loop's Backend protocol (glue only)
"""

from fem_ade.backends.fem.backend import FEMBackend

__all__ = ["FEMBackend"]
