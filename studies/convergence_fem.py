"""Spatial convergence of the FEM backend against the spectral reference (SPEC §5).

At a fixed Δt both backends run the same time scheme (SPEC §4), so the difference of their
E, V, A after the same number of steps is pure spatial error of the FEM: it should fall at
rate 2 for Q1 and 3–4 for Q2 once h < ε (SPEC: with h/ε > 1 the rates are erratic).

Two studies:

- ``ellipse-2d``: a 2D ellipse (ε = 0.05, 100 steps of Δt = 2e-6), Q1 and Q2 against
  spectral n = 256;
- ``discocyte``: the paper's experiment 1 (3D, ε = 0.04, 50 steps of Δt = 5e-7), Q1 at
  n = 24, 32, 48, 64 against spectral n = 128.

The FEM runs use ``solver="auto"`` (the exact fft solve for uniform Q1): every solver gives
the same step to the Krylov tolerance (``tests/test_fem_backend.py``), and the rates here are
about space, not about the solver.

Run: ``python studies/convergence_fem.py [--quick] [--study ellipse-2d|discocyte|all]``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

QUANTITIES = ("E", "V", "A", "W", "dA")


def _run(backend, steps):
    for _ in range(steps):
        backend.step()
    return backend.diagnostics()


def _rates(h, errs):
    return {q: float(np.polyfit(np.log(h), np.log(errs[:, j]), 1)[0])
            for j, q in enumerate(QUANTITIES)}


def study(scene, *, steps, n_ref, runs):
    """Print |FEM − spectral| per quantity and the observed rates; return {label: rates}."""
    from fem_ade.fem import FEMBackend
    from spectral_ref.solver import SpectralBackend

    t0 = time.perf_counter()
    ref = _run(SpectralBackend(scene, n=n_ref, dt=scene.dt), steps)
    print(f"\n{scene.name}: {steps} steps of dt = {scene.dt:g}, eps = {scene.params.eps}, "
          f"spectral n = {n_ref} ({time.perf_counter() - t0:.1f} s): "
          + ", ".join(f"{q} = {ref[q]:.8g}" for q in QUANTITIES))
    out = {}
    for label, order, ns in runs:
        errs = []
        for n in ns:
            t0 = time.perf_counter()
            d = _run(FEMBackend(scene, n=n, dt=scene.dt, order=order, solver="auto"), steps)
            errs.append([abs(d[q] - ref[q]) for q in QUANTITIES])
            print(f"  {label} n={n:3d} h/eps={scene.params.L / n / scene.params.eps:.2f} "
                  + " ".join(f"|d{q}|={e:.3e}" for q, e in zip(QUANTITIES, errs[-1], strict=True))
                  + f"  ({time.perf_counter() - t0:.1f} s)")
        errs = np.array(errs)
        h = scene.params.L / np.array(ns)
        rates = _rates(h, errs)
        print(f"  {label} observed rates: " + ", ".join(f"{q} {r:.2f}" for q, r in rates.items()))
        out[label] = rates
        resolved = h < scene.params.eps
        if 2 <= resolved.sum() < len(ns):  # SPEC: rates are meaningful for h < ε
            rates = _rates(h[resolved], errs[resolved])
            print(f"  {label} rates over h < eps only: "
                  + ", ".join(f"{q} {r:.2f}" for q, r in rates.items()))
            out[f"{label} h<eps"] = rates
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes (a test runs this)")
    ap.add_argument("--study", choices=("ellipse-2d", "discocyte", "all"), default="all")
    ap.add_argument("--out", help="unused (the study prints its figures)")
    args = ap.parse_args(argv)
    from fem_ade.scenes import get_scene

    results = {}
    if args.study in ("ellipse-2d", "all"):
        runs = ([("Q1", 1, (32, 48, 64)), ("Q2", 2, (24, 32, 48))] if args.quick else
                [("Q1", 1, (32, 48, 64, 96, 128)), ("Q2", 2, (24, 32, 48, 64))])
        results["ellipse-2d"] = study(get_scene("ellipse-2d"), steps=100, n_ref=256, runs=runs)
    if args.study in ("discocyte", "all") and not args.quick:
        results["discocyte"] = study(get_scene("discocyte"), steps=50, n_ref=128,
                                     runs=[("Q1", 1, (24, 32, 48, 64))])
    return results


if __name__ == "__main__":
    main()
