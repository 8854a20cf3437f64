"""fem_ade: phase-field vesicle membranes with area-difference elasticity.

A mixed (φ, μ) periodic finite-element backend and a Fourier-spectral reference share one
scene catalogue (:mod:`fem_ade.scenes`), one time loop (:mod:`fem_ade.loop`) and one run
folder (:mod:`fem_ade.runs`, whose :func:`simulate` is the Python API behind the CLI).
"""

import importlib

__version__ = "0.1.0"

#: name -> module: imported on first use, so that ``python -m fem_ade.run`` starts light
_LAZY = {"EFFECTS": "model", "ModelError": "model", "Params": "model", "SCENES": "scenes",
         "Scene": "scenes", "get_scene": "scenes", "load_scene_file": "scenes",
         "resume": "runs", "simulate": "runs"}

__all__ = [*_LAZY, "__version__"]


def __getattr__(name):
    if name in _LAZY:
        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module 'fem_ade' has no attribute {name!r}")
