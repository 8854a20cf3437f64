"""Exact volume and area constraints (issue 6): held to 1e-8 at every record, energy decays."""

import json

import numpy as np
import pytest

from fem_ade.constraints import ConstraintError, project
from fem_ade.output import read_history
from fem_ade.scenes import get_scene
from spectral_ref import SpectralBackend
from spectral_ref.solver import area, area_gradient, volume

ALPHA, BETA = 0.0289, 0.4880  # discocyte


@pytest.mark.parametrize("scheme, dt, steps",
                         [("paper", "5e-7", 200), ("stabilized", "5e-5", 300)])
def test_exact_constraints_hold_and_energy_decays(cli, tmp_path, scheme, dt, steps):
    out = tmp_path / "X"
    r = cli(["discocyte", "--constraints", "exact", "--backend", "spectral", "--n", "32",
             "--scheme", scheme, "--dt", dt, "--steps", steps, "--every", "10", "--out", out,
             "--quiet", "--no-render"])
    assert r.returncode == 0, r.stderr
    h = read_history(out / "history.csv")
    dv, da = np.abs(h["V"] / ALPHA - 1).max(), np.abs(h["A"] / BETA - 1).max()
    print(f"max |V/alpha - 1| = {dv:.2g}, max |A/beta - 1| = {da:.2g}")
    assert dv < 1e-8 and da < 1e-8
    assert np.allclose(h["E"], h["W"] + h["G"], rtol=1e-14)  # the penalties are off
    assert np.all(np.diff(h["E"]) <= 0)
    assert np.all(h["lambda_V"][1:] != 0) and np.all(np.isfinite(h["lambda_A"]))
    s = json.loads((out / "summary.json").read_text())
    assert s["constraints"] == "exact" and "volume" not in s["parameters"]["effects"]


def test_projection_converges_quadratically_on_a_sphere():
    """The Newton projection of a slightly wrong sphere needs only a few iterations."""
    scene = get_scene("sphere")
    be = SpectralBackend(scene, n=32, dt=scene.dt, constraints="exact")
    p = scene.params
    d = be.diagnostics()
    assert abs(d["V"] / p.alpha - 1) < 1e-10 and abs(d["A"] / p.beta - 1) < 1e-10
    x = np.arange(32) / 32
    X = np.stack(np.meshgrid(x, x, x, indexing="ij"))
    phi = scene.initial_phi(X, perturb=0.02, seed=1)

    def measure(u):
        lap = be._inv(-be.k2 * be._fwd(u))
        return (volume(u, be.dV), area(u, lap, p, be.dV), np.full_like(u, 0.5),
                area_gradient(u, lap, p))

    _, a, b, its = project(phi, measure, lambda u, v: be.dV * np.sum(u * v), p.alpha, p.beta)
    print("Newton iterations:", its)
    assert its <= 6


def test_unreachable_constraints_fail_clearly(cli, tmp_path):
    """The printed IC (A = 4.5 β) cannot be projected: exit 2 with the reason."""
    r = cli(["discocyte", "--constraints", "exact", "--ic", "printed", "--n", "32",
             "--backend", "spectral", "--out", tmp_path / "never"])
    assert r.returncode == 2 and "cannot be projected" in r.stderr
    assert not (tmp_path / "never").exists()
    with pytest.raises(ConstraintError):
        project(np.zeros(4), lambda u: (0.0, 0.0, u + 1, u + 1), lambda u, v: np.sum(u * v),
                1.0, 1.0)
