"""Cost of the FEM backend (SPEC §9): setup, time per step, Krylov iterations, memory.

Prints, for periodic Q1 on the discocyte scene (experiment 1):

1. setup time (assembly of M, K + solver setup) and time per step at n = 32 and 64, with the
   spectral step at the same n for the ratio (target: setup ≤ 10 s and step ≤ 8× spectral at 64³);
2. PCG iterations per step and time per step for every solver choice (amg, chebyshev, jacobi,
   fft) at the paper's Δt and at 10× and 100× Δt (the first steps only: the paper's scheme
   itself blows up within tens of steps at 10× Δt, SPEC §7, §10 — this measures the solver);
3. the naive scikit-fem path (periodic ``MeshHex1DG.init_tensor`` + Basis + assembly) for
   comparison with the Kronecker assembly;
4. peak memory (``resource.getrusage``; after part 1, and for the whole process).

Run: ``python studies/bench_fem.py [--quick]`` (``--quick``: n = 16 and 24, fewer steps).
Times depend on the machine and its load; nothing here is asserted.
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

SOLVERS = ("amg", "chebyshev", "jacobi", "fft")


def _time_steps(backend, steps):
    backend.step()  # warm up (first extrapolation, caches)
    its, t0 = [], time.perf_counter()
    for _ in range(steps):
        its.append(backend.step()["krylov_its"])
    return (time.perf_counter() - t0) / steps, its


def setup_and_step(scene, sizes, steps, solvers=("amg", "chebyshev", "jacobi", "fft")):
    from fem_ade.fem import FEMBackend

    try:
        from spectral_ref.solver import SpectralBackend
    except ModuleNotFoundError:
        SpectralBackend = None
    print(f"\n1. Q1, paper dt, discocyte: setup and step (mean of {steps} steps after one)")
    print(f"{'n':>4} {'solver':>9} {'dofs':>8} {'assembly_s':>10} {'solver_s':>9} "
          f"{'setup_s':>8} {'step_ms':>8} {'its':>7} {'spectral_ms':>11} {'ratio':>6}")
    rows = []
    for n in sizes:
        sp_ms = float("nan")
        if SpectralBackend is not None:
            sp_ms = 1e3 * _time_steps_spectral(SpectralBackend(scene, n=n, dt=scene.dt), steps)
        for solver in solvers:
            b = FEMBackend(scene, n=n, dt=scene.dt, solver=solver)
            info = b.info()
            dt_step, its = _time_steps(b, steps)
            print(f"{n:4d} {solver:>9} {info['n_dofs']:8d} {info['assembly_s']:10.2f} "
                  f"{info['solver_setup_s']:9.2f} {info['setup_s']:8.2f} {1e3 * dt_step:8.1f} "
                  f"{min(its):3d}-{max(its):<3d} {sp_ms:11.1f} {1e3 * dt_step / sp_ms:6.1f}")
            rows.append({"n": n, "solver": solver, "step_s": dt_step, "its": max(its),
                         "spectral_s": sp_ms / 1e3})
    return rows


def _time_steps_spectral(s, steps):
    s.step()
    t0 = time.perf_counter()
    for _ in range(steps):
        s.step()
    return (time.perf_counter() - t0) / steps


def solver_table(scene, sizes, repeats, factors=(1, 10, 100)):
    """PCG its and time of the first step from φ₀ at f·Δt, repeated from the same state.

    The first step is what a solver sees at any Δt: the paper's scheme itself is unstable
    for the discocyte beyond ~3Δt (explicit area penalty, SPEC §7), so later steps at 10× and
    100× Δt would measure a blow-up, not the solver.
    """
    from fem_ade.fem import FEMBackend

    print("\n2. solver choices (Q1), discocyte: PCG its and ms of the first step from phi0")
    print(f"{'n':>4} {'solver':>10} " + " ".join(f"{f'{f}x dt':>16}" for f in factors))
    for n in sizes:
        for solver in SOLVERS:
            cells = []
            for f in factors:
                b = FEMBackend(scene, n=n, dt=f * scene.dt, solver=solver)
                state = b.state()
                t0 = time.perf_counter()
                for _ in range(repeats):
                    b.set_state(state)
                    its = b.step()["krylov_its"]
                cells.append(f"{its:4d} {1e3 * (time.perf_counter() - t0) / repeats:8.1f}ms")
            print(f"{n:4d} {solver:>10} " + " ".join(f"{c:>16}" for c in cells))


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def naive_skfem(n):
    """Periodic MeshHex1DG.init_tensor + Basis + assembly of M and K (the SPEC §9 baseline)."""
    from skfem import Basis, ElementHex1, MeshHex1DG

    from fem_ade.fem import forms

    x = np.linspace(0.0, 1.0, n + 1)
    t0 = time.perf_counter()
    mesh = MeshHex1DG.init_tensor(x, x, x, periodic=[0, 1, 2])
    basis = Basis(mesh, ElementHex1())
    t1 = time.perf_counter()
    forms.mass.assemble(basis)
    forms.laplace.assemble(basis)
    t2 = time.perf_counter()
    return t1 - t0, t2 - t1


def kron_assembly(n):
    from fem_ade.fem import assemble, mesh

    t0 = time.perf_counter()
    assemble.operators(mesh.uniform(3, n), 1)
    return time.perf_counter() - t0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes (a test runs this)")
    ap.add_argument("--out", help="unused (the benchmark prints its figures)")
    args = ap.parse_args(argv)
    from fem_ade.scenes import get_scene

    scene = get_scene("discocyte")
    sizes = (12, 16) if args.quick else (32, 64)
    steps = 3 if args.quick else 10
    rows = setup_and_step(scene, sizes, steps)
    print(f"   peak memory so far (ru_maxrss): {_peak_mb():.0f} MB")
    solver_table(scene, sizes, repeats=2 if args.quick else 3)
    n_naive = 8 if args.quick else 32
    mb, asm = naive_skfem(n_naive)
    print(f"\n3. naive scikit-fem periodic Q1 at {n_naive}^3: mesh+basis {mb:.2f} s, "
          f"assembly {asm:.2f} s; Kronecker assembly {kron_assembly(n_naive):.3f} s")
    print(f"\n4. peak memory of the whole benchmark (ru_maxrss): {_peak_mb():.0f} MB")
    return {"solvers": rows, "peak_mb": _peak_mb()}


if __name__ == "__main__":
    main()
