"""Effects: a term a scene leaves off is never evaluated and reports 0 (model §2)."""

import numpy as np
import pytest

import spectral_ref.solver as spectral
from fem_ade.engine.loop import run_loop
from fem_ade.model.params import ModelError
from fem_ade.scenes.catalogue import get_scene


def _run(scene, steps=40, n=24):
    be = spectral.SpectralBackend(scene, n=n, dt=scene.dt)
    return run_loop(be, dt=scene.dt, steps=steps, every=10)


def test_ade_off_equals_kappa_bar_zero():
    base = get_scene("discocyte")
    off = _run(base.with_(effects=base.params.effects - {"ade"}))
    zero = _run(base.with_(kappa_bar=0.0))
    for row in off.history:
        assert row["G"] == 0.0 and row["dA"] == 0.0
    for a, b in zip(off.history, zero.history, strict=True):
        for key in ("E", "W", "V", "A"):
            assert a[key] == pytest.approx(b[key], rel=1e-12), key
        assert b["G"] == 0.0 and b["dA"] != 0.0


@pytest.mark.parametrize(
    "effect, functions",
    [("ade", ("area_difference", "area_difference_gradient")),
     ("area", ("area_gradient",))],
)
def test_off_term_is_never_evaluated(monkeypatch, effect, functions):
    calls = dict.fromkeys(functions, 0)
    for name in functions:
        original = getattr(spectral, name)

        def counted(*args, _name=name, _f=original):
            calls[_name] += 1
            return _f(*args)

        monkeypatch.setattr(spectral, name, counted)
    scene = get_scene("discocyte")
    _run(scene, steps=3)
    assert all(c > 0 for c in calls.values()), calls  # the counters see calls when on
    calls.update(dict.fromkeys(functions, 0))
    _run(scene.with_(effects=scene.params.effects - {effect}), steps=3)
    assert calls == dict.fromkeys(functions, 0)


def test_penalties_off_report_zero_and_bending_only_sphere():
    scene = get_scene("sphere-bending")
    res = _run(scene, steps=20, n=32)
    d = res.final
    assert d["G"] == 0.0 and d["dA"] == 0.0 and d["T1"] == 0.0 and d["T2"] == 0.0
    assert d["E"] == d["W"]
    assert d["W"] == pytest.approx(16 * np.sqrt(2) * np.pi / 3, rel=2e-3)


def test_effect_validation():
    scene = get_scene("discocyte")
    with pytest.raises(ModelError, match="bending"):
        scene.with_(effects={"ade"}).params.validate()
    with pytest.raises(ModelError, match="unknown effect"):
        scene.with_(effects={"bending", "gravity"}).params.validate()
    with pytest.raises(ModelError, match="spontaneous_curvature"):
        scene.with_(C=1.0).params.validate()
