"""Every teaching example (studies/teaching/exNN_*.py) runs in quick mode with the right physics.

The examples are found by glob; each one's ``main(quick=True)`` returns the figures it checks
(rates, iteration counts, energies) and the matching ``check_*`` below asserts them, printing
the observed figure on failure. An example without a check fails, so none goes untested.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

TEACHING = Path(__file__).resolve().parents[1] / "studies" / "teaching"
EXAMPLES = sorted(TEACHING.glob("ex[0-9][0-9]_*.py"))


def load(path: Path):
    spec = importlib.util.spec_from_file_location(f"teaching_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def check_ex01_mixed_biharmonic(r):
    """Periodic mixed method: optimal L² rates p + 1 for φ and μ."""
    for element, theory in (("Q1", 2.0), ("Q2", 3.0)):
        for field in ("phi", "mu"):
            rate = r[f"rate_{field}_{element}"]
            assert abs(rate - theory) < 0.15, f"{element} {field}: rate {rate:.2f}, theory {theory}"


def check_ex02_semi_implicit_step(r):
    """PCG with the (M + sK) M_L⁻¹ (M + sK) preconditioner: flat iterations, W decreasing."""
    assert r["pcg_growth"] < 1.5, f"PCG iterations {r['pcg_mean_its']} grow under refinement"
    expected = r["h_ratio"] ** 2  # κ(S) ~ h⁻⁴, CG iterations ~ √κ(S) ~ h⁻²
    assert r["cg_growth"] > 0.7 * expected, f"plain CG grew {r['cg_growth']:.1f}×, not ~h⁻²"
    assert r["W_decreasing"], "the bending energy W rose during a step"
    assert abs(r["W0"] / r["W_sharp"] - 1) < 0.05, f"W(0) = {r['W0']:.3f} vs {r['W_sharp']:.3f}"


def check_ex03_step_spectrum(r):
    """The step operator loses definiteness at Δt = ε³/κ; the bulk is stable below ε³/(10κ)."""
    assert 0.9 < r["dt_star_ratio"] < 1.05, f"FEM limit Δt* = {r['dt_star_ratio']:.3f} ε³/κ"
    for row in r["rows"]:
        assert (row["dt_lam_min"] > 0) == (row["r"] < 1), f"sign of λ_min at {row}"
        # Δt·λ_min = 1 + Δt·λ_min(B, M): the discrete λ_min(B, M) is within 10 % of −κ/ε³
        assert abs(row["dt_lam_min"] - row["fourier"]) < 0.1 * row["r"], f"Fourier vs {row}"
    stable, unstable = r["rows"][0], r["rows"][1]  # Δt = 0.05 and 0.25 ε³/κ
    assert stable["growth"] <= 1.0, f"growth {stable['growth']:.3f} > 1 at Δt = ε³/(20κ)"
    assert abs(unstable["growth"] / unstable["growth_fourier"] - 1) < 0.1, f"{unstable}"


def check_ex04_vesicle_2d_api(r):
    """Energy decreases, the penalties hold V and A; FEM agrees with spectral (measured 3e-3
    after the quick mode's 200 steps)."""
    for name in ("spectral", "fem"):
        assert r[name]["E_decreasing"], f"{name}: E_M rose between records"
        assert abs(r[name]["V_rel"] - 1) < 0.05, f"{name}: V/α = {r[name]['V_rel']:.4f}"
        assert abs(r[name]["A_rel"] - 1) < 0.05, f"{name}: A/β = {r[name]['A_rel']:.4f}"
    assert r["E_rel_diff"] < 0.01, f"|E_fem/E_spectral − 1| = {r['E_rel_diff']:.3e}"


def check_ex05_spectral_elements(r):
    """Eigenvalue rate 2p at equal nodes (measured 2.00, 4.01, 7.99 in quick mode); at 32 nodes
    3.2e-3 (p = 1) against 1.4e-9 (p = 4); the fast diagonalization is the exact solve
    (4.8e-15 from a sparse LU)."""
    for p, theory in ((1, 2.0), (2, 4.0), (4, 8.0)):
        rate = r[f"rate_p{p}"]
        assert abs(rate - theory) < 0.1 * theory, f"p = {p}: rate {rate:.2f}, theory {theory}"
    assert r["err32_p1"] > 1e-3 and r["err32_p4"] < 1e-8
    assert r["fd_diff"] < 1e-12 and r["fd_residual"] < 1e-12, r


def test_examples_found():
    assert len(EXAMPLES) >= 3, f"teaching examples not found in {TEACHING}"


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_example(path, tmp_path, capsys):
    module = load(path)
    assert capsys.readouterr().out == "", "importing the example printed something"
    check = globals().get(f"check_{path.stem}")
    assert check is not None, f"add check_{path.stem} to tests/test_teaching.py"
    assert Path(module.OUT).parts[0] == "runs", "an example writes under runs/ by default"
    result = module.main(quick=True, out=tmp_path)
    assert Path(result["png"]).is_file() and Path(result["png"]).parent == tmp_path
    assert all(np.isfinite(v) for v in result.values() if isinstance(v, float))
    check(result)
