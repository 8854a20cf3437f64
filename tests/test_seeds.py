"""Seeded initial conditions (``--ic seeded``): the paper figure's shape, sized so that its
diffuse V and A are α and β on the scene's own grid (fem_ade.scenes.seeds)."""

import numpy as np
import pytest

from fem_ade.analysis.shape import describe
from fem_ade.backends.base import make_backend
from fem_ade.model.params import ModelError
from fem_ade.scenes.catalogue import PAPER_SCENES
from fem_ade.scenes.seeds import NO_SEED, SIZES


@pytest.mark.parametrize("name", list(SIZES))
def test_seed_has_the_targets_and_the_paper_shape(name):
    scene = PAPER_SCENES[name]
    be = make_backend("spectral", scene, n=scene.n, ic="seeded")
    d = be.diagnostics()
    p = scene.params
    print(f"{name}: V/alpha {d['V'] / p.alpha:.6f}, A/beta {d['A'] / p.beta:.6f}")
    assert abs(d["V"] / p.alpha - 1) < 1e-4 and abs(d["A"] / p.beta - 1) < 1e-4
    shape = describe(be.grid_phi(), p.L)
    assert shape["label"] == scene.shape, shape["label"]


def test_every_paper_scene_has_a_seed_or_a_reason():
    assert set(SIZES) | set(NO_SEED) == set(PAPER_SCENES)
    scene = PAPER_SCENES["gourd"]
    with pytest.raises(ModelError, match="eps = 0.05"):
        scene.initial_phi(np.zeros((3, 4, 4, 4)), ic="seeded")
