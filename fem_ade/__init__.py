"""fem_ade: phase-field vesicle membranes with area-difference elasticity.

A mixed (φ, μ) periodic finite-element backend and a Fourier-spectral reference share one
scene catalogue (:mod:`fem_ade.scenes`) and one time-stepping driver (:mod:`fem_ade.driver`).
"""

from .model import EFFECTS, ModelError, Params
from .scenes import SCENES, Scene, get_scene, load_scene_file

__version__ = "0.1.0"

__all__ = ["EFFECTS", "ModelError", "Params", "SCENES", "Scene", "get_scene", "load_scene_file",
           "__version__"]
