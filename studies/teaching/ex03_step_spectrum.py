r"""Where the paper's time-step limits come from: the spectrum of the mixed step operator.

Equation and split
------------------
The bending flow of ex02, φ_t = −κ(εΔ²φ + (2/ε)Δφ + N(φ)), with μ = −Δφ.

Time discretisation and weak form
---------------------------------
The semi-implicit step (model §4–§5), with μ eliminated by the lumped mass M_L, is

    S φⁿ⁺¹ = M φⁿ/Δt − κ N_h(φⁿ),    S = M/Δt + B,    B = κ(ε K M_L⁻¹ K − (2/ε) K).

Solvability (limit ε³/κ)
------------------------
The Fourier symbol of S/M is 1/Δt + κ(ε|k|⁴ − (2/ε)|k|²), smallest at |k| = 1/ε, where it is
1/Δt − κ/ε³. So S is positive definite only for Δt < ε³/κ; above it S is indefinite (CG's
guarantee is gone) and for some Δt singular. The discrete version: λ_min(S, M) =
1/Δt + λ_min(B, M), and the FEM limit is Δt* = −1/λ_min(B, M); the script computes
λ_min(B, M) with a shift-invert Lanczos (scipy `eigsh`) on the assembled matrices.
Measured: Δt* = 0.94 ε³/κ at n = 32 and 0.985 ε³/κ at n = 64 (M < M_L on the grid modes
pulls the discrete minimum a little lower): the FEM limit tends to ε³/κ from below.

Stability at the bulk (limit ε³/(10κ))
--------------------------------------
Linearised at φ = ±1 the explicit part is N'(±1) = −(6/ε)Δ + 4/ε³ (in weak form
(3/ε)K + (3/ε)M M_L⁻¹K + (4/ε³)M, nodal products), so a perturbation δ evolves by
S δⁿ⁺¹ = R δⁿ, R = M/Δt − κ[(3/ε)K + (3/ε)M M_L⁻¹K + (4/ε³)M], and by the factor

    G(k) = (1/Δt − κ(6|k|²/ε + 4/ε³)) / (1/Δt + κ(ε|k|⁴ − 2|k|²/ε))

per step. |G| ≤ 1 for all k iff Δt ≤ ε³/(10κ) (worst at |k|² = 4/ε²). Between ε³/(10κ) and
ε³/κ the step is solvable but amplifies the bulk: the paper's Δt (≈ ε³/100) sits well below.
The script measures the growth factor of S⁻¹R by 60 steps of power iteration from a seeded
random δ and compares it with max_k |G(k)| over the box's wavenumbers 2π(m₁, m₂).

Parameters
----------
κ = 1, ε = 0.05, Q1 on a periodic n × n mesh (n = 64; quick: 32), Δt = r ε³/κ with
r = 0.05, 0.25, 0.9, 1.1, 2.
"""

from __future__ import annotations

import argparse
import logging
import os
from pathlib import Path

import numpy as np
from scipy.sparse import diags
from scipy.sparse.linalg import eigsh, splu
from skfem import Basis, BilinearForm, ElementQuad1, MeshQuad1DG
from skfem.helpers import dot, grad

OUT = Path("runs") / "teaching"  # PNGs go here unless --out
KAPPA, EPS = 1.0, 0.05
RATIOS = (0.05, 0.25, 0.9, 1.1, 2.0)  # Δt / (ε³/κ)


@BilinearForm
def mass(u, v, _):
    return u * v


@BilinearForm
def laplace(u, v, _):
    return dot(grad(u), grad(v))


def symbols(k2, dt):
    """Fourier symbols: the step operator Δt·σ(k) and the bulk amplification G(k)."""
    sigma = 1 / dt + KAPPA * (EPS * k2**2 - 2 * k2 / EPS)
    return dt * sigma, (1 / dt - KAPPA * (6 * k2 / EPS + 4 / EPS**3)) / sigma


def main(quick: bool = False, out: str | Path | None = OUT) -> dict:
    quick = quick or bool(os.environ.get("CI"))
    n = 32 if quick else 64
    x = np.linspace(0.0, 1.0, n + 1)
    basis = Basis(MeshQuad1DG.init_tensor(x, x, periodic=[0, 1]), ElementQuad1())
    M, K = mass.assemble(basis).tocsc(), laplace.assemble(basis).tocsc()
    iML = diags(1 / np.asarray(M.sum(axis=1)).ravel())                  # M_L⁻¹
    B = KAPPA * (EPS * K @ iML @ K - (2 / EPS) * K)                      # S = M/Δt + B
    Nlin = KAPPA * ((3 / EPS) * K + (3 / EPS) * M @ iML @ K + (4 / EPS**3) * M)  # κN'(±1)
    lam_B = eigsh(B, k=1, M=M, sigma=-2 * KAPPA / EPS**3, return_eigenvectors=False)[0]
    m = np.arange(-(n // 2), n // 2 + 1)
    k2 = (2 * np.pi) ** 2 * (m[:, None] ** 2 + m[None, :] ** 2).ravel()  # the box's |k|²

    rng = np.random.default_rng(0)
    rows = []
    for r in RATIOS:
        dt = r * EPS**3 / KAPPA
        step = splu((M / dt + B).tocsc())                               # S = M/Δt + B
        R = M / dt - Nlin                                                # R = M/Δt − κN'(±1)
        delta = rng.standard_normal(basis.N)
        for _ in range(50):
            delta = step.solve(R @ delta)
            delta /= np.linalg.norm(delta)
        norms = []
        for _ in range(10):
            delta = step.solve(R @ delta)
            norms.append(np.linalg.norm(delta))
            delta /= norms[-1]
        rows.append({"r": r, "dt_lam_min": 1 + dt * lam_B, "fourier": 1 - r,
                     "growth": float(np.exp(np.mean(np.log(norms)))),
                     "growth_fourier": float(np.max(np.abs(symbols(k2, dt)[1])))})
    print(f"Q1, n = {n}, ε = {EPS}: FEM limit Δt* = −1/λ_min(B, M) = "
          f"{-1 / lam_B:.4e} = {-KAPPA / (lam_B * EPS**3):.4f} ε³/κ")
    print(" Δt κ/ε³   Δt·λ_min(S,M)   1 − Δtκ/ε³   growth of S⁻¹R   max|G(k)|")
    for w in rows:
        print(f"{w['r']:8.2f}   {w['dt_lam_min']:13.4f}   {w['fourier']:10.4f}"
              f"   {w['growth']:14.4g}   {w['growth_fourier']:9.4g}")
    result = {"dt_star_ratio": float(-KAPPA / (lam_B * EPS**3)), "rows": rows}
    if out is not None:
        result["png"] = str(plot(rows, Path(out)))
    return result


def plot(rows, out: Path) -> Path:
    from matplotlib.figure import Figure

    k = np.linspace(0.0, 3.0 / EPS, 400)
    fig = Figure(figsize=(9, 3.6), layout="constrained")
    ax_s, ax_g = fig.subplots(1, 2)
    for i, w in enumerate(rows):
        s, g = symbols(k**2, w["r"] * EPS**3 / KAPPA)
        ax_s.plot(k * EPS, s, color=f"C{i}", label=f"Δt = {w['r']} ε³/κ")
        ax_s.plot(1.0, w["dt_lam_min"], "o", color=f"C{i}")
        ax_g.semilogy(k * EPS, np.abs(g), color=f"C{i}", label=f"Δt = {w['r']} ε³/κ")
        ax_g.axhline(w["growth"], color=f"C{i}", ls="--", lw=0.8)
    ax_s.axhline(0.0, color="k", lw=0.6)
    ax_s.set(xlabel="|k| ε", ylabel="Δt · symbol of S", ylim=(-1.5, 3),
             title="step operator (dots: FEM Δt·λ_min)")
    ax_g.axhline(1.0, color="k", lw=0.6)
    ax_g.set(xlabel="|k| ε", ylabel="|G(k)|", ylim=(1e-2, 1e3),
             title="bulk amplification (dashed: FEM)")
    ax_s.legend(fontsize=8)
    out.mkdir(parents=True, exist_ok=True)
    fig.savefig(out / "ex03_step_spectrum.png", dpi=110)
    return out / "ex03_step_spectrum.png"


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a small mesh (also when CI is set)")
    parser.add_argument("--out", default=OUT, help="folder for the PNG")
    args = parser.parse_args()
    logging.getLogger("skfem").setLevel(logging.ERROR)  # silence a note on internal array copies
    main(quick=args.quick, out=args.out)
