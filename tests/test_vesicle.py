"""The vesicle scene family (fem_ade.scenes.vesicle): physical parameters to the model's, its seeds,
and its use from Python, TOML and the command line."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fem_ade.model.params import ModelError
from fem_ade.scenes.catalogue import load_scene_file, vesicle_scene
from fem_ade.scenes.vesicle import spheroid_meridian

ROOT = Path(__file__).resolve().parents[1]


def _meridian_v(r, z) -> float:
    """Reduced volume of the surface of revolution of a polygonal meridian (pole to pole)."""
    r, z = np.asarray(r), np.asarray(z)
    d = np.hypot(np.diff(r), np.diff(z))
    area = np.sum(math.pi * (r[1:] + r[:-1]) * d)
    volume = abs(np.sum(math.pi / 3.0 * np.diff(z) * (r[1:] ** 2 + r[1:] * r[:-1]
                                                      + r[:-1] ** 2)))
    return volume / (4.0 * math.pi / 3.0 * (area / (4.0 * math.pi)) ** 1.5)


def test_parameters_map_to_the_model():
    """v, Δa₀ and κ̄ become α = (4π/3)R₀³v, β = 4πR₀², ΔA₀ = 8πDR₀Δa₀ with D = 2ε/3, the
    localized volume, ADE on only with κ̄ > 0 and Δa₀ given; n = 1.28/ε; the seed's meridian
    is the sharp shape's (its reduced volume v to 1e-3 on 201 points)."""
    s = vesicle_scene(v=0.85, da0=1.3, kbar=1.4, eps=0.04)
    p, R0 = s.params, s.ic.scale
    assert p.alpha == pytest.approx(4.0 / 3.0 * math.pi * R0**3 * 0.85, rel=1e-12)
    assert p.beta == pytest.approx(4.0 * math.pi * R0**2, rel=1e-12)
    assert p.delta_A0 == pytest.approx(8.0 * math.pi * (2.0 * 0.04 / 3.0) * R0 * 1.3, rel=1e-12)
    assert p.on("ade") and p.kappa_bar == 1.4 and p.volume_functional == "localized"
    assert s.n == 32 and "sharp shape (prolate)" in s.description
    assert abs(_meridian_v(s.ic.r, s.ic.z) - 0.85) < 1e-3
    # the prolate keeps 0.1 + 2ε from the faces (nearer, it merges with its images)
    assert np.ptp(s.ic.z) * R0 + 0.2 + 4 * 0.04 == pytest.approx(1.0, abs=1e-9)
    assert not vesicle_scene(v=0.85).params.on("ade")
    for kw in ({"kbar": 1.4}, {"da0": 1.3}):  # half of the ADE term is refused, not ignored
        with pytest.raises(ModelError, match="kbar and da0 go together"):
            vesicle_scene(v=0.85, **kw)


def test_spheroid_seed_and_bad_input():
    """The spheroid fallback has the reduced volume asked for and area 4π; a branch the sharp
    reference does not have there, or bad numbers, are one-line errors."""
    for v, prolate in [(0.7, True), (0.9, False)]:
        r, z = spheroid_meridian(v, prolate)
        assert abs(_meridian_v(r, z) - v) < 2e-3
        assert (np.ptp(z) > 2 * r.max()) == prolate
    with pytest.raises(ModelError, match="no sharp pear"):
        vesicle_scene(v=0.8, branch="pear")
    for kw, match in [({"v": 0.0}, "vesicle v"), ({"branch": "cube"}, "branch must be"),
                      ({"eps": 0.5}, "vesicle eps"), ({"colour": 1}, "unknown vesicle"),
                      ({"v": 0.9, "R0": 0.45}, "does not fit"),  # sharp seeds of ≤ 1 s
                      ({"v": 1e-9}, "below 0.2"), ({"eps": 0.125}, "eps thick")]:
        with pytest.raises(ModelError, match=match):
            vesicle_scene(**kw)


def test_from_toml_and_the_command_line(tmp_path):
    """base = "vesicle" with a [vesicle] table; a [vesicle] table without that base is
    refused; the CLI's vesicle options build the same scene and are refused for another."""
    path = tmp_path / "v.toml"
    path.write_text('base = "vesicle"\nn = 24\n[vesicle]\nv = 0.9\nbranch = "oblate"\n'
                    'eps = 0.06\n')
    s = load_scene_file(path)
    assert s.n == 24 and s.params.eps == 0.06 and "oblate" in s.description
    assert s.params.alpha == vesicle_scene(v=0.9, branch="oblate", eps=0.06).params.alpha
    path.write_text('base = "torus"\n[vesicle]\nv = 0.9\n')
    with pytest.raises(ModelError, match="needs base"):
        load_scene_file(path)

    def cli(*args):
        return subprocess.run([sys.executable, "-m", "fem_ade.run", *args], cwd=tmp_path,
                              capture_output=True, text=True, timeout=300,
                              env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})

    r = cli("vesicle", "--v", "0.9", "--branch", "oblate", "--eps", "0.08", "--backend",
            "spectral", "--steps", "2", "--no-render", "--quiet", "--out", "o")
    assert r.returncode == 0, r.stderr
    assert "sharp oblate" in r.stdout or "oblate" in r.stdout
    r = cli("torus", "--v", "0.8")
    assert r.returncode == 2 and "describe the vesicle scene" in r.stderr
    r = cli("vesicle", "--v", "1.3")
    assert r.returncode == 2 and "vesicle v must be" in r.stderr


def test_vesicle_mistakes_on_the_command_line_and_in_toml(tmp_path, cli):
    """What the vesicle family ignored or crashed on before: one line, exit 2, nothing
    written — --ic (the paper's ellipsoid's reading), a v no seed reaches, a vesicle thinner
    than 2 eps, half of the ADE term, and a TOML [params] key the [vesicle] table sets."""
    for args, word in ((["--ic", "printed"], "--ic"), (["--v", "1e-9"], "below 0.2"),
                       (["--eps", "0.125"], "eps thick"), (["--kbar", "1.4"], "go together")):
        r = cli(["vesicle", *args, "--out", tmp_path / "x"])
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
        assert word in r.stderr and not (tmp_path / "x").exists()
    from fem_ade.scenes.catalogue import load_scene_file

    path = tmp_path / "v.toml"
    path.write_text('base = "vesicle"\n[vesicle]\nv = 0.9\neps = 0.04\n[params]\neps = 0.02\n')
    with pytest.raises(ModelError, match=r"\[vesicle\] table sets"):
        load_scene_file(path)


def test_the_command_line_knows_every_vesicle_parameter():
    """fem_ade.cli.run's vesicle options are the Vesicle's fields (but the box's L, which the
    family keeps at 1): a field added to one is added to the other."""
    from fem_ade.cli.run import build_parser, vesicle_options
    from fem_ade.scenes.vesicle import Vesicle

    assert set(vesicle_options()) == set(Vesicle.__dataclass_fields__) - {"L"}
    dests = {a.dest for a in build_parser().options}
    assert set(vesicle_options()) <= dests, set(vesicle_options()) - dests


def test_a_vesicle_seeded_on_the_torus():
    """The torus is a branch of the family (the ADE plane's lowest at v <= 0.75): its seed
    is the sharp torus's tube, a closed meridian off the axis."""
    from fem_ade.scenes.catalogue import vesicle_scene

    scene = vesicle_scene(v=0.65, branch="torus", kbar=1.4, da0=1.2, eps=0.05)
    assert not scene.ic.spheroidal and min(scene.ic.r) > 0.1
    assert "seeded from the sharp shape (torus)" in scene.description
