"""Exact volume and area constraints: every scene starts under them (its targets ramp from the
initial V₀, A₀ to α, β), then V = α and A = β hold to 1e-8 and E_M decays."""

import json

import numpy as np
import pytest

from fem_ade.backends.base import make_backend
from fem_ade.engine.loop import run_loop
from fem_ade.model.constraints import ConstraintError, TargetRamp
from fem_ade.scenes.catalogue import PAPER_SCENES, get_scene
from fem_ade.store.output import read_history

ALPHA, BETA = 0.0289, 0.4880  # discocyte


def test_target_ramp():
    r = TargetRamp.between((1.0, 2.0), (1.05, 1.0), rate=0.01)
    assert r.max_increment == pytest.approx(1 / 50)  # |1/2 - 1| / 0.01 = 50 steps
    assert r.propose() == pytest.approx((1.001, 1.98))
    r.accept()
    assert r.moving and r.fraction == pytest.approx(0.02)
    assert r.slow_down() and r.propose() == pytest.approx(r._at(0.02 + 0.005))
    calls = []

    def fails_twice(targets):
        calls.append(targets)
        if len(calls) <= 2:
            raise ConstraintError("too far")
        return targets

    got = r.solve(fails_twice)
    assert got == calls[-1] and r.increment == pytest.approx(1.5 * 0.005 / 16)
    steps = 0
    while not r.done:
        r.solve(lambda t: t)
        steps += 1
    assert r.propose() == (1.05, 1.0) and r.moving and steps < 60
    r.solve(lambda t: t)
    assert not r.moving  # the targets stood still on this step
    assert TargetRamp.from_state(r.state()) == r
    assert not r.slow_down()


@pytest.mark.parametrize("scheme, dt, steps",
                         [("paper", "5e-7", 120), ("stabilized", "5e-5", 120)])
def test_exact_constraints_hold_and_energy_decays(cli, tmp_path, scheme, dt, steps):
    out = tmp_path / "X"
    r = cli(["discocyte", "--constraints", "exact", "--backend", "spectral", "--n", "32",
             "--scheme", scheme, "--dt", dt, "--steps", steps, "--every", "10", "--out", out,
             "--quiet", "--no-render"])
    assert r.returncode == 0, r.stderr
    h = read_history(out / "history.csv")
    done = h["ramp"] == 1.0
    assert done.sum() >= 8, "the ramp of discocyte takes 17 steps"
    dv = np.abs(h["V"][done] / ALPHA - 1).max()
    da = np.abs(h["A"][done] / BETA - 1).max()
    print(f"after the ramp: max |V/alpha - 1| = {dv:.2g}, max |A/beta - 1| = {da:.2g}")
    assert dv < 1e-8 and da < 1e-8
    assert np.allclose(h["E"], h["W"] + h["G"], rtol=1e-14)  # the penalties are off
    assert np.all(np.diff(h["E"][done]) <= 0)
    assert np.all(h["lambda_V"][1:] != 0) and np.all(np.isfinite(h["lambda_A"]))
    s = json.loads((out / "summary.json").read_text())
    assert s["constraints"] == "exact" and "volume" not in s["parameters"]["effects"]


def _start_under_exact(backend, name, n):
    scene = PAPER_SCENES[name]
    dt = 100 * scene.dt
    be = make_backend(backend, scene, n=n, scheme="stabilized", constraints="exact", dt=dt)
    ramp = 0
    while not be.ramp.done:
        be.step()
        ramp += 1
    res = run_loop(be, dt=dt, steps=10, every=1)
    p = scene.params
    E = np.array([row["E"] for row in res.history])
    dv, da = abs(res.final["V"] / p.alpha - 1), abs(res.final["A"] / p.beta - 1)
    print(f"{name} [{backend}]: ramp {ramp} steps, then |V/alpha - 1| = {dv:.1e}, "
          f"|A/beta - 1| = {da:.1e}")
    assert res.status == "completed", res.message
    assert dv < 1e-8 and da < 1e-8
    assert np.all(np.diff(E) <= 1e-12 * np.abs(E[1:]))


@pytest.mark.parametrize("name", list(PAPER_SCENES))
def test_every_paper_scene_starts_under_exact_constraints(name):
    """Issue 10: the paper's initial fields have A up to 2.2 β; the targets ramp from the
    initial V₀, A₀ (measured: 17–55 steps), then hold (spectral, n = 32; nested n = 48)."""
    _start_under_exact("spectral", name, 48 if name == "nested" else 32)


def test_fem_starts_under_exact_constraints():
    """Six-arm stopped at step 0 before the ramp (its projection did not converge); n = 32 is
    the coarsest grid where its multipliers converge through the ramp (at n = 24, h = 2ε, the
    Newton solve fails at step 28 and the run stops as diverged)."""
    _start_under_exact("fem", "six-arm", 32)


@pytest.mark.slow
@pytest.mark.parametrize("name", list(PAPER_SCENES))
def test_every_paper_scene_starts_under_exact_constraints_fem(name):
    _start_under_exact("fem", name, 48 if name == "nested" else 32)


def test_printed_ic_ramps_to_the_constraints(cli, tmp_path):
    """The printed discocyte IC (V = 4.8 α, A = 4.5 β) ramps in 80 steps, then holds."""
    out = tmp_path / "P"
    r = cli(["discocyte", "--constraints", "exact", "--ic", "printed", "--n", "24",
             "--allow-underresolved", "--backend", "spectral", "--steps", "90", "--every",
             "10", "--out", out, "--quiet", "--no-render"])
    assert r.returncode == 0, r.stderr
    h = read_history(out / "history.csv")
    assert h["V"][0] / ALPHA > 4 and h["A"][0] / BETA > 3
    assert abs(h["V"][-1] / ALPHA - 1) < 1e-8 and abs(h["A"][-1] / BETA - 1) < 1e-8
    assert list(h["ramp"][-2:]) == [1.0, 1.0]


def test_exact_constraints_report_the_same_V_and_A_in_every_backend():
    """Directly built backends obey the exact ⇒ no penalties rule (issue 9)."""
    scene = get_scene("discocyte")
    for backend in ("spectral", "fem"):
        be = make_backend(backend, scene, n=16, constraints="exact", dt=scene.dt,
                          **({"order": 1} if backend == "fem" else {}))
        assert not be.params.on("volume") and not be.params.on("area")
        assert be.scene.params is be.params
        d = be.diagnostics()
        assert d["E"] == d["W"] + d["G"]
