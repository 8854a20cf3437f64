"""Momentum with adaptive restart (``accelerate``): the same steady state as the scheme,
reached in far fewer steps (fem_ade.engine.loop)."""

import numpy as np
import pytest

from fem_ade.backends.base import make_backend
from fem_ade.engine.loop import AdaptiveDt, run_loop
from fem_ade.engine.runs import simulate
from fem_ade.model.params import ModelError
from fem_ade.scenes.catalogue import get_scene


@pytest.mark.parametrize("backend", ["spectral", "fem"])
def test_momentum_reaches_a_steady_state_of_the_scheme(backend):
    """2D ellipse, stabilized 100× Δt. Measured (n = 32, to 1e-8): 140 (spectral) and 160
    (FEM) steps with momentum against 3260 and 5500 without, E equal to 3e-6 and 7e-6
    relative (the plain runs stop a little above the minimum)."""
    scene = get_scene("ellipse-2d")
    dt = 100 * scene.dt
    fast = simulate(scene, backend=backend, n=32, dt=dt, scheme="stabilized",
                    until_steady=1e-8, every=20, accelerate=True)
    plain = simulate(scene, backend=backend, n=32, dt=dt, scheme="stabilized",
                     steps=fast.steps, every=20)
    print(f"{backend}: momentum {fast.steps} steps, E {fast.final['E']:.10f} "
          f"({fast.restarts} restarts); plain after as many steps: E {plain.final['E']:.10f}")
    assert fast.status == "steady" and fast.steps <= 400
    assert fast.final["E"] < plain.final["E"]
    # a fixed point of the plain scheme: continuing without momentum hardly moves it
    again = simulate(scene, backend=backend, n=32, dt=dt, scheme="stabilized", steps=200,
                     every=200, phi0=fast.final_grid)
    drift = abs(again.final["E"] - fast.final["E"]) / abs(fast.final["E"])
    print(f"  a plain continuation of 200 steps moves E by {drift:.2e} relative")
    assert drift < 1e-5


def test_momentum_refuses_adaptive_dt():
    scene = get_scene("ellipse-2d")
    be = make_backend("spectral", scene, n=32, scheme="stabilized")
    with pytest.raises(ModelError, match="accelerate"):
        run_loop(be, dt=scene.dt, steps=5, accelerate=True, adaptive=AdaptiveDt(1e-9, 1e-3))


def test_momentum_restarts_when_the_energy_rises():
    """Every accepted iterate has E_M no higher than the one before (restart rule)."""
    scene = get_scene("ellipse-2d")
    be = make_backend("spectral", scene, n=32, scheme="stabilized")
    res = run_loop(be, dt=100 * scene.dt, steps=150, every=1, accelerate=True)
    E = np.array([r["E"] for r in res.history])
    print(f"restarts: {res.restarts}; largest rise {np.diff(E).max():.2e}")
    assert res.restarts >= 1
    assert np.all(np.diff(E) <= 1e-12 * np.abs(E[1:]))
