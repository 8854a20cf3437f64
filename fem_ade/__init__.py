"""fem_ade: phase-field vesicle membranes with area-difference elasticity.

A mixed (φ, μ) periodic finite-element backend and a Fourier-spectral reference share one
scene catalogue (:mod:`fem_ade.scenes`), one time loop (:mod:`fem_ade.loop`) and one run
folder (:mod:`fem_ade.runs`, whose :func:`simulate` is the Python API behind the CLI).
"""

from .model import EFFECTS, ModelError, Params
from .runs import resume, simulate
from .scenes import SCENES, Scene, get_scene, load_scene_file

__version__ = "0.1.0"

__all__ = ["EFFECTS", "ModelError", "Params", "SCENES", "Scene", "get_scene", "load_scene_file",
           "resume", "simulate", "__version__"]
