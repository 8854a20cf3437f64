r"""Mixed finite elements for a fourth-order problem: (c + εΔ²)φ = f on the periodic square.

Equation
--------
    c φ + ε Δ²φ = f    in Ω = [0, 1)², periodic in x and y.

Operator split
--------------
Lagrange elements (Q1, Q2) are continuous but not C¹: Δ²φ has no weak form on them. Write
the fourth-order equation as two second-order ones by naming the Laplacian, μ = −Δφ:

    c φ − ε Δμ = f,        μ + Δφ = 0.

Weak form
---------
Find (φ, μ) in V_h × V_h (the same Lagrange space twice) such that for all (v, q)

    c (φ, v) + ε (∇μ, ∇v) = (f, v)
    (μ, q) − (∇φ, ∇q)     = 0

Integration by parts leaves no boundary terms: the box is periodic. With the mass matrix M
and the stiffness matrix K this is one 2 × 2 block system,

    [ cM   εK ] [φ]   [F]
    [ −K   M  ] [μ] = [0].

Time discretisation
-------------------
None: a steady problem. ex02 adds the time step of the vesicle model.

Parameters and exact solution
-----------------------------
c = 1, ε = 0.01, φ = sin(2πx) cos(4πy): Δ²φ = |k|⁴φ with |k|² = 20π², so f = (c + ε|k|⁴)φ
and μ = |k|²φ.

What theory says
----------------
Let R_h be the Ritz projection ((∇R_h u, ∇q) = (∇u, ∇q)) and e_φ = R_hφ − φ_h,
e_μ = R_hμ − μ_h. Testing the error equations with v = e_φ and q = εe_μ cancels the
gradient cross terms:  c‖e_φ‖² + ε‖e_μ‖² = −c(φ − R_hφ, e_φ) − ε(μ − R_hμ, e_μ).
So on a periodic box both errors are as small as the Ritz projection's: O(h^{p+1}) in L²
for Q_p, rate 2 for Q1 and 3 for Q2, for φ and for μ alike. (On a domain with a clamped
boundary, the Ciarlet–Raviart method, μ carries no boundary condition and rates are lost.)
The script prints the observed rates (slope of log error against log h).
"""

from __future__ import annotations

import argparse
import logging
import os
from pathlib import Path

import numpy as np
from scipy.sparse import bmat
from scipy.sparse.linalg import spsolve
from skfem import (
    Basis,
    BilinearForm,
    ElementQuad1,
    ElementQuad2,
    Functional,
    LinearForm,
    MeshQuad1DG,
)
from skfem.helpers import dot, grad

OUT = Path("runs") / "teaching"  # PNGs go here unless --out
C, EPS = 1.0, 0.01
K2 = 20 * np.pi**2  # |k|² of the Fourier mode sin(2πx) cos(4πy)
THEORY = {"Q1": 2.0, "Q2": 3.0}  # L² rate p + 1 for φ and μ


def phi_exact(x):
    return np.sin(2 * np.pi * x[0]) * np.cos(4 * np.pi * x[1])


@BilinearForm
def mass(u, v, _):
    """(u, v)"""
    return u * v


@BilinearForm
def laplace(u, v, _):
    """(∇u, ∇v)"""
    return dot(grad(u), grad(v))


@LinearForm
def source(v, w):
    """(f, v) with f = (c + ε|k|⁴)φ."""
    return (C + EPS * K2**2) * phi_exact(w.x) * v


@Functional
def l2_error_sq(w):
    """‖u_h − scale·φ‖² (scale = 1 for φ, |k|² for μ)."""
    return (w["u"] - w["scale"] * phi_exact(w.x)) ** 2


def solve(n: int, element) -> tuple[float, float]:
    """L² errors of φ and μ on an n × n periodic mesh."""
    x = np.linspace(0.0, 1.0, n + 1)
    mesh = MeshQuad1DG.init_tensor(x, x, periodic=[0, 1])
    basis = Basis(mesh, element, intorder=2 * element.maxdeg + 2)
    M, K, F = mass.assemble(basis), laplace.assemble(basis), source.assemble(basis)
    A = bmat([[C * M, EPS * K],    # c(φ, v) + ε(∇μ, ∇v) = (f, v)
              [-K, M]], "csc")     # (μ, q) − (∇φ, ∇q) = 0
    phi, mu = np.split(spsolve(A, np.concatenate([F, np.zeros_like(F)])), 2)
    err = [np.sqrt(l2_error_sq.assemble(basis, u=basis.interpolate(u), scale=s))
           for u, s in ((phi, 1.0), (mu, K2))]
    return err[0], err[1]


def rate(h, err) -> float:
    """Observed order: the slope of log error against log h."""
    return float(np.polyfit(np.log(h), np.log(err), 1)[0])


def main(quick: bool = False, out: str | Path | None = OUT) -> dict:
    quick = quick or bool(os.environ.get("CI"))
    ns = np.array([8, 16, 32] if quick else [8, 16, 32, 64])
    result, errors = {}, {}
    for name, element in (("Q1", ElementQuad1()), ("Q2", ElementQuad2())):
        errors[name] = np.array([solve(n, element) for n in ns])
        for j, field in enumerate(("phi", "mu")):
            result[f"rate_{field}_{name}"] = rate(1.0 / ns, errors[name][:, j])
    print("   n   Q1 ‖φ − φ_h‖  Q1 ‖μ − μ_h‖   Q2 ‖φ − φ_h‖  Q2 ‖μ − μ_h‖")
    for i, n in enumerate(ns):
        print(f"{n:4d}" + "".join(f"  {e:12.3e}" for e in (*errors["Q1"][i], *errors["Q2"][i])))
    print("rate" + "".join(f"  {result[f'rate_{f}_{q}']:12.2f}" for q in THEORY
                           for f in ("phi", "mu")), "  (theory: 2, 2, 3, 3)")
    if out is not None:
        result["png"] = str(plot(1.0 / ns, errors, Path(out)))
    return result


def plot(h, errors, out: Path) -> Path:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(5, 4), layout="constrained")
    ax = fig.subplots()
    for (name, err), color in zip(errors.items(), ("C0", "C1"), strict=True):
        ax.loglog(h, err[:, 0], "o-", color=color, label=f"{name}: ‖φ − φ_h‖")
        ax.loglog(h, err[:, 1] / K2, "s--", color=color, label=f"{name}: ‖μ − μ_h‖ / |k|²")
        ax.loglog(h, err[-1, 0] * (h / h[-1]) ** THEORY[name], ":", color="gray",
                  label=f"h^{THEORY[name]:.0f} (theory)")
    ax.set(xlabel="h", ylabel="L² error", title="mixed (φ, μ) biharmonic: rates 2 (Q1), 3 (Q2)")
    ax.legend(fontsize=8)
    out.mkdir(parents=True, exist_ok=True)
    fig.savefig(out / "ex01_mixed_biharmonic.png", dpi=110)
    return out / "ex01_mixed_biharmonic.png"


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small meshes (also when CI is set)")
    parser.add_argument("--out", default=OUT, help="folder for the PNG")
    args = parser.parse_args()
    logging.getLogger("skfem").setLevel(logging.ERROR)  # silence a note on internal array copies
    main(quick=args.quick, out=args.out)
