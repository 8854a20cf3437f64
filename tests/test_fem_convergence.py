"""FEM against the spectral reference at the same Δt (SPEC §5): the difference is pure spatial
error and must fall at rate 2 (Q1) and at least 3 (Q2). All meshes have h < ε (SPEC warning:
with h/ε > 1 the rates are erratic)."""

import numpy as np
import pytest

from fem_ade.fem import FEMBackend
from fem_ade.scenes import Scene, get_scene

spectral = pytest.importorskip("spectral_ref.solver")

QUANTITIES = ("E", "V", "A")


def ellipse_2d() -> Scene:
    """The catalogue's 2D teaching ellipse (targets near the initial diffuse values)."""
    return get_scene("ellipse-2d")


def run(backend, steps):
    for _ in range(steps):
        backend.step()
    return backend.diagnostics()


def rates(scene, ref, ns, steps, **fem):
    errs = []
    for n in ns:
        d = run(FEMBackend(scene, n=n, dt=scene.dt, **fem), steps)
        errs.append([abs(d[q] - ref[q]) for q in QUANTITIES])
    errs = np.array(errs)
    h = 1.0 / np.array(ns)
    observed = {q: np.polyfit(np.log(h), np.log(errs[:, j]), 1)[0]
                for j, q in enumerate(QUANTITIES)}
    for n, e in zip(ns, errs, strict=True):
        cells = (f"|d{q}|={v:.3e}" for q, v in zip(QUANTITIES, e, strict=True))
        print(f"  n={n}: " + ", ".join(cells))
    print("  observed rates: " + ", ".join(f"{q} {r:.2f}" for q, r in observed.items()))
    return observed


@pytest.fixture(scope="module")
def ellipse_reference():
    scene = ellipse_2d()
    ref = run(spectral.SpectralBackend(scene, n=256, dt=scene.dt), 100)
    return scene, ref


@pytest.mark.parametrize("order,ns,minimum", [(1, (32, 48, 64, 96), 1.7),
                                              (2, (24, 32, 48), 3.0)])
def test_2d_rate_against_spectral(ellipse_reference, order, ns, minimum):
    scene, ref = ellipse_reference
    print(f"\nQ{order}, 2D ellipse, 100 steps against spectral n=256:")
    observed = rates(scene, ref, ns, 100, order=order)
    for q, r in observed.items():
        assert r >= minimum, f"Q{order}: observed rate {r:.2f} in {q} < {minimum}"


def test_quadrature_products_agree(ellipse_reference):
    """Nonlinear products at quadrature points (scikit-fem LinearForms) instead of nodal
    interpolation: errors of the same size against the spectral reference (within a factor 3;
    measured at n = 24: E 6.1e-2 vs 6.5e-2, V 1.7e-5 vs 1.7e-5, A 7.1e-5 vs 3.4e-5)."""
    scene, ref = ellipse_reference
    errs = {}
    for products in ("nodal", "quadrature"):
        d = run(FEMBackend(scene, n=24, dt=scene.dt, order=2, products=products), 100)
        errs[products] = np.array([abs(d[q] - ref[q]) for q in QUANTITIES])
    print(f"\nQ2 n=24 errors in {QUANTITIES}: {errs}")
    ratio = errs["quadrature"] / errs["nodal"]
    assert ((ratio > 1 / 3) & (ratio < 3)).all(), ratio


@pytest.mark.slow
def test_3d_discocyte_rate_against_spectral():
    """SPEC §5: discocyte, 50 steps, Q1 against spectral n = 96 (resolved to ~1e-7 in E).

    n = 32, 48, 64 (h/ε = 0.78, 0.52, 0.39): n = 24 has h > ε and is pre-asymptotic
    (measured |dE| = 2.95, 2.51, 1.22, 0.70 at n = 24, 32, 48, 64). The ``fft`` solver gives
    the same solution as ``amg`` (to the Krylov tolerance) in a fraction of the time.
    """
    scene = get_scene("discocyte")
    ref = run(spectral.SpectralBackend(scene, n=96, dt=scene.dt), 50)
    print("\nQ1, discocyte, 50 steps against spectral n=96:")
    observed = rates(scene, ref, (32, 48, 64), 50, order=1, solver="fft")
    for q in QUANTITIES:
        assert observed[q] >= 1.7, f"observed rate {observed[q]:.2f} in {q}"
