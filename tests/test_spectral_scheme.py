"""The spectral reference: energy decay and self-convergence (model §4, §6, §8)."""

import numpy as np

from fem_ade.loop import run_loop
from fem_ade.scenes import get_scene
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
    """E, V, A after 50 steps at n = 32, 48, 64 approach the n = 96 values, fast."""
    scene = get_scene("discocyte")
    final = {}
    for n in (32, 48, 64, 96):
        be = SpectralBackend(scene, n=n, dt=scene.dt)
        final[n] = run_loop(be, dt=scene.dt, steps=50, every=50).final
    for key in ("E", "V", "A"):
        err = [abs(final[n][key] - final[96][key]) / abs(final[96][key]) for n in (32, 48, 64)]
        print(key, "relative differences to n=96 at n=32,48,64:", err)
        assert err[0] > err[1] > err[2]
        assert err[2] < 1e-3
