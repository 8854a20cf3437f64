"""The sharp-interface reference (``sharp_ref``): exact values it must reproduce, its
discretization's convergence, continuity of its branches, and its command line."""

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sharp_ref.branches import LEVELS, solve
from sharp_ref.membrane import BranchError, Problem, Spheroidal, minimise

ROOT = Path(__file__).resolve().parents[1]


def test_sphere_is_exact():
    """w = 1 for a sphere of any size, its reduced area difference 1."""
    r = solve("sphere", 1.0)
    assert r.converged
    assert abs(r.w - 1.0) < 1e-8
    assert abs(r.v - 1.0) < 1e-10
    assert abs(r.da - 1.0) < 1e-8


def test_willmore_torus():
    """At fixed area only, the torus relaxes to the Clifford torus: w = π/2, generating
    radii in the ratio √2, reduced volume 3/(2√(√2π)) = 0.711637."""
    r = solve("torus", None)
    assert r.converged
    assert abs(r.w / (math.pi / 2) - 1.0) < 1e-4
    rr = np.real(r.geometry.r)
    centre, tube = 0.5 * (rr.max() + rr.min()), 0.5 * (rr.max() - rr.min())
    assert abs(centre / tube / math.sqrt(2.0) - 1.0) < 1e-4
    assert abs(r.v - 1.5 / math.sqrt(math.sqrt(2.0) * math.pi)) < 1e-6


def test_minimal_model_values():
    """Two-sided checks at v = 0.8 against the refined values (and the known ordering:
    prolate below oblate there)."""
    p, o = solve("prolate", 0.8), solve("oblate", 0.8)
    assert abs(p.w - 1.387440432444) < 1e-8
    assert abs(o.w - 1.452538628565) < 1e-8
    assert abs(p.v - 0.8) < 1e-9 and abs(o.v - 0.8) < 1e-9
    assert p.da > o.da > 0.0


def test_spectral_convergence_of_the_meridian():
    """The error in w of the prolate and the oblate at v = 0.75 against a fine meridian
    falls geometrically with the number of modes (a sine series of an analytic ψ): by at
    least 5× per two more modes, below 1e-10 by 8 (measured: prolate 6.4e-5, 4.7e-7, 2.8e-9,
    1.6e-11 at 2, 4, 6, 8 modes; oblate 4.6e-6, 2.4e-10, 1.4e-14, 4e-15)."""
    for branch in ("prolate", "oblate"):
        ws = [solve(branch, 0.75, levels=((m, 64),), tol=0.0).w for m in (2, 4, 6, 8, 16)]
        errors = [abs(w - ws[-1]) for w in ws[:-1]]
        assert errors[0] > 1e-6, (branch, errors)  # two modes are far from it
        for a, b in zip(errors, errors[1:], strict=False):
            assert b < a / 5 or b < 1e-12, (branch, errors)
        assert errors[-1] < 1e-10, (branch, errors)


def test_branches_near_their_crossing():
    """w along the prolate and oblate branches is smooth in v (second differences over
    Δv = 0.01 small against first differences), and the minimal model's lowest branch
    changes from prolate to oblate at v ≈ 0.652 (Seifert, Berndl & Lipowsky 1991). Each
    branch continued from v = 0.66 (``start``: the cold solves agree to 3e-14 in w and take
    1.5× as long)."""
    vs = (0.64, 0.65, 0.66)
    w = {}
    for b in ("prolate", "oblate"):
        r = solve(b, vs[-1], levels=LEVELS[:2], tol=1e-8)
        w[b] = [r.w]
        for v in vs[-2::-1]:
            r = solve(b, v, levels=LEVELS[:2], tol=1e-8, start=r)
            w[b].insert(0, r.w)
    for branch, (a, b, c) in w.items():
        assert c - a < 0 and abs(c - 2 * b + a) < 0.05 * abs(c - a), (branch, w)
    d = np.array(w["prolate"]) - np.array(w["oblate"])
    roots = [r.real for r in np.roots(np.polyfit(vs, d, 2)) if vs[0] <= r.real <= vs[-1]]
    assert len(roots) == 1 and abs(roots[0] - 0.652) < 0.005, (roots, d)


def test_constraints_hold_at_the_minimum():
    fam = Spheroidal(range(2, 25, 2), 64)
    x0 = np.zeros(13)
    x0[0], x0[-1] = -0.1, math.pi
    x, ok, _, residual = minimise(fam, Problem(0.9), x0)
    g = fam.geometry(x[:-1], x[-1])
    assert ok and residual < 1e-8
    assert abs(np.real(g.area) / (4 * math.pi) - 1) < 1e-10
    assert abs(np.real(g.reduced_volume) - 0.9) < 1e-10


def test_pear_needs_area_difference_elasticity():
    """In the minimal model at v = 0.8 a kicked prolate relaxes back up-down symmetric: no
    pear there, a BranchError (the command line exits 2)."""
    with pytest.raises(BranchError, match="symmetric"):
        solve("pear", 0.8)


def test_continuation_in_the_relaxed_area_difference():
    """solve(start=) continues a branch: the prolate at v = 0.85, κ̄/κ = 1.4 continued from
    m₀ = 1.2 to 1.24 is the one solved there directly (to 1e-9); the pear, found by its
    anchor at m₀ = 1.8, continued down to 1.76 (where its stiffness is the prolate's
    opposite: m follows m₀, 1.2812 -> 1.2795, while the prolate's m stays at 1.08480 to
    1e-5 over m₀ 1.2 -> 1.24, as a P2 + P4 family at this v shows too: its da spans 0.0015
    while its w rises by 0.13); a start of another branch is refused."""
    levels = LEVELS[:2]
    a = solve("prolate", 0.85, m0=1.2, kbar=1.4, tol=1e-7, levels=levels)
    b = solve("prolate", 0.85, m0=1.24, kbar=1.4, tol=1e-7, levels=levels, start=a)
    direct = solve("prolate", 0.85, m0=1.24, kbar=1.4, tol=1e-7, levels=levels)
    assert abs(b.e - direct.e) < 1e-9 and abs(b.da - direct.da) < 1e-9
    assert abs(a.da - 1.0848) < 1e-4 and abs(b.da - a.da) < 1e-5
    assert 1.39 < b.e < 1.41  # w = 1.2857 plus q (m - m0)^2 = 4.669 x 0.155^2
    pear = solve("pear", 0.85, m0=1.8, kbar=1.4, tol=1e-7, levels=levels)
    lower = solve("pear", 0.85, m0=1.76, kbar=1.4, tol=1e-7, levels=levels, start=pear)
    assert 1.27 < lower.da < pear.da - 1e-3 < 1.29, (pear.da, lower.da)
    assert lower.e < pear.e and lower.e < b.e + 2.0
    with pytest.raises(ValueError, match="start"):
        solve("oblate", 0.85, m0=1.2, kbar=1.4, levels=levels, start=a)


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "sharp_ref", *args, "--quiet"],
                          capture_output=True, text=True, cwd=ROOT, timeout=300)


def test_cli_json():
    p = _cli("torus", "--json")
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    for key in ("branch", "v", "w", "e", "da", "converged", "r", "z"):
        assert key in out
    assert out["branch"] == "torus" and out["converged"]
    assert abs(out["w"] - math.pi / 2) < 1e-6
    assert len(out["r"]) == len(out["z"]) > 50


def test_cli_missing_branch_and_bad_input():
    p = _cli("pear", "--v", "0.8")
    assert p.returncode == 2
    assert len(p.stderr.strip().splitlines()) == 1 and "no pear here" in p.stderr
    for args, text in ((("prolate",), "needs --v"), (("oblate", "--v", "1.5"), "(0, 1]"),
                       (("prolate", "--v", "nan"), "finite"), (("cube", "--v", "0.8"),
                                                                "invalid choice")):
        p = _cli(*args)
        assert p.returncode == 2 and text in p.stderr, (args, p.stderr)


def _crossing(upper, lower, vs):
    d = [solve(upper, v).w - solve(lower, v).w for v in vs]
    assert d[0] > 0 > d[-1], d
    return float(np.interp(0.0, d[::-1], vs[::-1]))


@pytest.mark.slow
def test_oblate_stomatocyte_transition():
    """… and the stomatocyte below v ≈ 0.592."""
    v = _crossing("oblate", "stomatocyte", [0.58, 0.60])
    assert abs(v - 0.592) < 0.005, v


def test_a_run_meets_its_sharp_shape(monkeypatch):
    """fem_ade.analysis.sharp.compare: a final shape labelled prolate at v = 0.8 is set beside the
    sharp
    prolate there (e = 1.38744), with the run's e = (W + G)/(16√2πκ/3); no comparison for a
    shape without a branch or of several bodies; a branch missing there is said so."""
    from fem_ade.analysis.sharp import SPHERE_W, compare
    from fem_ade.model.params import Params

    p = Params(eps=0.02, alpha=0.02, beta=0.5, effects={"bending", "volume", "area"})
    shape = {"components": 1, "label": "prolate",
             "sharp": {"A": 4 * math.pi * 0.2**2, "reduced_volume": 0.8}}
    out = compare(p, shape, {"W": 1.45 * SPHERE_W, "G": 0.0})
    assert out["branch"] == "prolate" and abs(out["e_sharp"] - 1.387440432) < 1e-6
    assert abs(out["rel_diff"] - (1.45 / out["e_sharp"] - 1.0)) < 1e-12
    assert abs(out["eps_over_R0"] - 0.1) < 1e-12
    assert "sharp prolate at v = 0.800: e = 1.387; this run 1.45 (+4.5% at ε = 0.02" in out["line"]
    assert compare(p, {**shape, "label": "sphere"}, {"W": 1.0}) is None
    assert compare(p, shape, {"W": 1.0}, points=49) is None  # 0.98 points per ε
    assert compare(p, shape, {"W": 1.0}, points=50)["branch"] == "prolate"
    assert compare(p, {**shape, "components": 2}, {"W": 1.0}) is None
    import fem_ade.analysis.sharp

    def nowhere(branch, v, *args):  # what sharp_ref says where a branch does not exist
        raise BranchError(f"no {branch} here: the meridian crosses itself")

    monkeypatch.setattr(fem_ade.analysis.sharp, "solve_cached", nowhere)
    missing = compare(p, {**shape, "label": "oblate"}, {"W": 1.0})
    assert missing["missing"].startswith("no oblate here")
    assert missing["line"].startswith("no sharp oblate at v = 0.800 to compare with")


@pytest.mark.parametrize("args, code, word", [
    (["prolate", "--v", "2"], 2, "--v must be"),
    (["cube"], 2, "invalid choice"),
    (["prolate", "--v", "0.8", "--da", "1.2"], 2, "--kbar"),
    (["prolate", "--v", "0.8", "--kbar", "1e9", "--da", "2", "--max-seconds", "3"], 2,
     "did not converge within 3 s"),
])
def test_command_line_mistakes_are_one_line(args, code, word):
    """Usage errors, ADE half given, and a solve that cannot converge (within a bounded
    time): one line on stderr, exit 2."""
    r = _cli(*args)
    assert r.returncode == code and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert word in r.stderr, r.stderr


def test_command_line_under_an_ascii_locale_and_to_a_full_device():
    import os

    env = {**os.environ, "LC_ALL": "C", "PYTHONIOENCODING": "ascii"}
    r = subprocess.run([sys.executable, "-m", "sharp_ref", "--help"], capture_output=True,
                       env=env, timeout=60)
    assert r.returncode == 0 and b"usage" in r.stdout
    if os.path.exists("/dev/full"):
        with open("/dev/full", "w") as full:
            r = subprocess.run([sys.executable, "-m", "sharp_ref", "sphere", "--v", "1",
                                "--quiet"], stdout=full, stderr=subprocess.PIPE, text=True,
                               timeout=60)
        assert r.returncode == 3 and "cannot write" in r.stderr


def test_kept_geometries_change_no_bit(monkeypatch):
    """The optimiser's objective keeps the geometries it computed (the energy, the
    constraints and their complex-step gradients are asked for at the same points): the
    same solve without that keeps every bit of the result, and computes more geometries."""
    from sharp_ref import membrane

    calls = []
    at = membrane.Spheroidal.at
    monkeypatch.setattr(membrane.Spheroidal, "at", lambda self, *a: calls.append(1) or at(self, *a))
    results = {}
    for keep in (membrane._Objective.KEEP, 0):
        monkeypatch.setattr(membrane._Objective, "KEEP", keep)
        calls.clear()
        r = solve("prolate", 0.93, levels=LEVELS[:1], tol=1e-6)
        results[keep] = (len(calls), r.x.tobytes(), r.e, r.residual)
    (kept, *a), (fresh, *b) = results.values()
    assert a == b and fresh > 1.5 * kept, (kept, fresh)
