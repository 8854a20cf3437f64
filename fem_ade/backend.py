"""What the driver asks of a backend, and how backends are found by name.

A backend knows how to build its state from a scene, take one step of the scheme, and
measure E, W, G, V, A, ΔA (SPEC §6) on its state. It never writes files and never decides
when to stop: that is the driver's job (:mod:`fem_ade.driver`).
"""

from __future__ import annotations

import importlib
from typing import Protocol, runtime_checkable

import numpy as np

from .model import ModelError
from .scenes import Scene


@runtime_checkable
class Backend(Protocol):
    """The interface of a backend (the spectral reference and the FEM implement it).

    Construction: ``Backend(scene, n=..., dt=..., ic=..., perturb=..., seed=..., scheme=...,
    **options)``; ``scheme`` is ``"paper"`` (SPEC §4) or ``"stabilized"`` (the large-step
    scheme, see :func:`fem_ade.model.stabilization_coefficients`).
    """

    #: short name used in the CLI and in summary.json
    name: str
    #: the scene the backend was built from
    scene: Scene
    #: extra history columns this backend appends after step,t,E,W,G,V,A,dA
    extra_columns: tuple[str, ...]

    def step(self) -> dict:
        """Advance one step in place; return the values of ``extra_columns`` for this step."""

    def set_dt(self, dt: float) -> None:
        """Change the time step (adaptive Δt); rebuild whatever depends on it."""

    def diagnostics(self) -> dict:
        """E, W, G, V, A, dA of the current state (terms that are off report 0)."""

    def max_abs_phi(self) -> float:
        """max |φ| over the degrees of freedom (NaN if any is not finite)."""

    def state(self) -> dict[str, np.ndarray]:
        """The full state as arrays the backend will not mutate later (for guards, checkpoints)."""

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        """Restore a state returned by :meth:`state`."""

    def fields(self) -> dict[str, np.ndarray]:
        """Arrays for ``final.npz``: at least ``phi`` and the coordinates it lives on; a
        backend whose ``phi`` is not on the uniform grid x_j = jL/n also gives ``phi_grid``
        (n per direction) and ``x``, which the shape descriptors and pictures read."""

    def output_mesh(self):
        """(points, cells) for the XDMF series, periodic images closed; None for the grid."""

    def point_data(self) -> dict[str, np.ndarray]:
        """Fields for one XDMF step: at the points of :meth:`output_mesh` (or on the grid)."""

    def info(self) -> dict:
        """JSON-serialisable description (resolution, element, solver...) for summary.json."""


#: backend name -> "module:Class"
BACKENDS = {
    "spectral": "spectral_ref.solver:SpectralBackend",
    "fem": "fem_ade.fem.backend:FEMBackend",
}


def make_backend(name: str, scene: Scene, **kwargs) -> Backend:
    """Build backend ``name`` for ``scene``. Unknown names raise :class:`ModelError`."""
    try:
        target = BACKENDS[name]
    except KeyError:
        raise ModelError(f"unknown backend {name!r}; valid: {', '.join(BACKENDS)}") from None
    module_name, cls_name = target.split(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as err:
        if err.name and module_name.startswith(err.name):
            raise ModelError(f"the {name!r} backend is not available yet in this version") from None
        raise
    return getattr(module, cls_name)(scene, **kwargs)
