"""The finite-element backend: periodic Q1/Q2 mixed (φ, μ) elements for SPEC §4–§5.

- :mod:`.mesh`         periodic hexahedral / quad meshes: uniform, graded, from file
- :mod:`.forms`        the weak forms of SPEC §5, one function per term (ADE: ``ade_*``)
- :mod:`.assemble`     M and K, assembled once (Kronecker for tensor meshes, else scikit-fem)
- :mod:`.solve`        the preconditioned Krylov solve of one step (pyamg)
- :mod:`.diagnostics`  E, W, G, V, A, ΔA on FEM fields
- :mod:`.output`       closed output mesh (XDMF) and φ on the uniform grid (shape analysis)
- :mod:`.backend`      :class:`FEMBackend`, the driver's Backend protocol
"""

from .backend import FEMBackend

__all__ = ["FEMBackend"]
