"""The spectral reference: energy decay and self-convergence (model §4, §6, §8)."""

import numpy as np

from fem_ade.engine.loop import run_loop
from fem_ade.scenes.catalogue import get_scene
from spectral_ref import SpectralBackend


def test_energy_decreases_every_step_discocyte():
    """E_M is non-increasing over 200 steps of discocyte at n = 32 (consistent IC)."""
    scene = get_scene("discocyte")
    be = SpectralBackend(scene, n=32, dt=scene.dt)
    res = run_loop(be, dt=scene.dt, steps=200, every=1)
    E = np.array([r["E"] for r in res.history])
    dE = np.diff(E)
    print("largest increase", dE.max(), "E0", E[0], "E200", E[-1])
    assert res.status == "completed"
    assert np.all(dE <= 1e-10 * np.abs(E[1:]))


def test_spectral_self_convergence():
    """E, V, A after 50 steps at n = 32, 48, 64 approach the n = 96 values, fast: measured
    4.6e-4, 1.1e-5, 1.1e-7 (E), 1.2e-4, 1.2e-5, 4.1e-7 (V), 2.5e-5, 6.3e-7, 9.6e-8 (A); the
    bounds are 10× those, and each refinement gains at least 5× (exponential, not
    algebraic: a second-order scheme would gain 2.25× and 1.8×)."""
    scene = get_scene("discocyte")
    final = {}
    for n in (32, 48, 64, 96):
        be = SpectralBackend(scene, n=n, dt=scene.dt)
        final[n] = run_loop(be, dt=scene.dt, steps=50, every=50).final
    for key in ("E", "V", "A"):
        err = [abs(final[n][key] - final[96][key]) / abs(final[96][key]) for n in (32, 48, 64)]
        print(key, "relative differences to n=96 at n=32,48,64:", err)
        bound = {"E": (4.6e-3, 1.1e-4, 1.1e-6), "V": (1.2e-3, 1.2e-4, 4.1e-6),
                 "A": (2.5e-4, 6.3e-6, 9.6e-7)}[key]
        assert all(e < b for e, b in zip(err, bound, strict=True)), (err, bound)
        assert err[0] > 5 * err[1] and err[1] > 5 * err[2], err
