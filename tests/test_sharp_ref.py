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
    """The error in w of the prolate and the oblate at v = 0.65 against a fine meridian
    falls geometrically with the number of modes (a sine series of an analytic ψ): by at
    least 5× per two more modes, below 1e-10 by 8 (measured: prolate 5.5e-4, 1.1e-7, 1.2e-8,
    2.9e-12 at 2, 4, 6, 8 modes; oblate 2.2e-5, 2.7e-9, 1.5e-13, 7e-15)."""
    for branch in ("prolate", "oblate"):
        ws = [solve(branch, 0.65, levels=((m, 64),), tol=0.0).w for m in (2, 4, 6, 8, 16)]
        errors = [abs(w - ws[-1]) for w in ws[:-1]]
        assert errors[0] > 1e-5, (branch, errors)  # two modes are far from it
        for a, b in zip(errors, errors[1:], strict=False):
            assert b < a / 5 or b < 1e-12, (branch, errors)
        assert errors[-1] < 1e-10, (branch, errors)


def test_branches_are_continuous_in_v():
    """w along the prolate and oblate branches is smooth: second differences over
    Δv = 0.01 are small against first differences."""
    for branch in ("prolate", "oblate"):
        w = [solve(branch, v, levels=LEVELS[:2], tol=1e-9).w for v in (0.74, 0.75, 0.76)]
        d1, d2 = w[2] - w[0], w[2] - 2 * w[1] + w[0]
        assert d1 < 0, (branch, w)  # bending grows as v falls
        assert abs(d2) < 0.05 * abs(d1), (branch, w)


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


def test_prolate_oblate_transition():
    """The minimal model's lowest branch is the prolate above v ≈ 0.652 and the oblate below
    (Seifert, Berndl & Lipowsky 1991)."""
    v = _crossing("prolate", "oblate", [0.64, 0.66])
    assert abs(v - 0.652) < 0.005, v


@pytest.mark.slow
def test_oblate_stomatocyte_transition():
    """… and the stomatocyte below v ≈ 0.592."""
    v = _crossing("oblate", "stomatocyte", [0.58, 0.60])
    assert abs(v - 0.592) < 0.005, v


def test_a_run_meets_its_sharp_shape():
    """fem_ade.sharp.compare: a final shape labelled prolate at v = 0.8 is set beside the sharp
    prolate there (e = 1.38744), with the run's e = (W + G)/(16√2πκ/3); no comparison for a
    shape without a branch or of several bodies; a branch missing there is said so."""
    from fem_ade.model import Params
    from fem_ade.sharp import SPHERE_W, compare

    p = Params(eps=0.02, alpha=0.02, beta=0.5, effects={"bending", "volume", "area"})
    shape = {"components": 1, "label": "prolate",
             "sharp": {"A": 4 * math.pi * 0.2**2, "reduced_volume": 0.8}}
    out = compare(p, shape, {"W": 1.45 * SPHERE_W, "G": 0.0})
    assert out["branch"] == "prolate" and abs(out["e_sharp"] - 1.387440432) < 1e-6
    assert abs(out["rel_diff"] - (1.45 / out["e_sharp"] - 1.0)) < 1e-12
    assert abs(out["eps_over_R0"] - 0.1) < 1e-12
    assert "sharp prolate at v = 0.800: e = 1.387; this run 1.45 (+4.5% at ε = 0.02" in out["line"]
    assert compare(p, {**shape, "label": "sphere"}, {"W": 1.0}) is None
    assert compare(p, {**shape, "components": 2}, {"W": 1.0}) is None
    missing = compare(p, {**shape, "label": "oblate", "sharp": {"A": 0.5, "reduced_volume": 0.45}},
                      {"W": 1.0})
    assert "missing" in missing and "no sharp oblate at v = 0.450" in missing["line"]
