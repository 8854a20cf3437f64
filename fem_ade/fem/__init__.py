"""The finite-element backend: periodic Q1/Q2 mixed (φ, μ) elements for SPEC §4–§5.

- :mod:`.mesh`         periodic hexahedral / quad meshes: uniform, graded, from file
- :mod:`.forms`        every functional of SPEC §2 and its gradient, once (the weak forms)
- :mod:`.step`         the schemes: the paper's, the stabilized one, exact constraints
- :mod:`.assemble`     M and K, assembled once (Kronecker for tensor meshes, else scikit-fem)
- :mod:`.solve`        the preconditioned Krylov solve of one step (pyamg)
- :mod:`.output`       closed output mesh (XDMF) and φ on the uniform grid (shape analysis)
- :mod:`.backend`      :class:`FEMBackend`, the loop's Backend protocol (glue only)
"""

from .backend import FEMBackend

__all__ = ["FEMBackend"]
