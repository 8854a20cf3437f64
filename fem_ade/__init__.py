"""fem_ade: phase-field vesicle membranes with area-difference elasticity.

A mixed (φ, μ) periodic finite-element backend and a Fourier-spectral reference share one
scene catalogue (:mod:`fem_ade.scenes.catalogue`), one time loop (:mod:`fem_ade.engine.loop`)
and one run folder (:mod:`fem_ade.engine.runs`, whose :func:`simulate` is the Python API
behind the CLI). docs/architecture.md says which subpackage is which layer.
"""

import importlib

__version__ = "0.1.0"

#: name -> module: imported on first use, so that ``python -m fem_ade.run`` starts light
_LAZY = {"EFFECTS": "model.params", "ModelError": "model.params", "Params": "model.params",
         "SCENES": "scenes.catalogue", "Scene": "scenes.catalogue",
         "get_scene": "scenes.catalogue", "load_scene_file": "scenes.catalogue",
         "resume": "engine.runs", "simulate": "engine.runs"}

__all__ = [*_LAZY, "__version__"]


def __getattr__(name):
    if name in _LAZY:
        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module 'fem_ade' has no attribute {name!r}")
