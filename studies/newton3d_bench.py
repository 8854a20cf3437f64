"""What a 3D steady state costs by Newton's method: with and without its pins (issue 44's
cost targets), with and without the coarse space of shape modes (issue 42's target 3),
measured in one run.

The state: a prolate with ADE (v = 0.85, κ̄/κ = 1.4, Δa₀ = 1.2, R₀ = 0.18) whose axis lies
along none of the mesh's, (0.45, 0.3, 0.84), and whose centre is off the nodes, on the 3D
tensor FEM of order 4 — ε = 0.02 on 64³ nodes (1.28 nodes per ε, what 3D affords there);
``--quick``: ε = 0.04 on 32³. The steady recipe's flow relaxes it to a change of 1e-6 per
step; from there Newton (:func:`fem_ade.backends.fem.newton.solve_steady`) runs three times
from the same field: with the pins (P times the starting state's rigid motions, docs/model.md
§12) and MINRES preconditioned by the bulk Hessian P and the coarse space
(:mod:`fem_ade.backends.fem.coarse`, ``linear="coarse"``: the default from 10⁵ nodes); the
same with P alone (``linear="minres"``, the path before the coarse space); and without the
pins, with the coarse space. Prints and writes, per case, the
iterations, the MINRES iterations per Newton step, the coarse spaces made, the CPU seconds,
E, how far the pins' values and the centroid moved; the ratios of the MINRES iterations and
of the CPU seconds, P alone over the coarse space (target: ≥ 5× fewer iterations at 64³,
ε = 0.02, with the same converged state), and of the pinned and free Newton times, beside
issue 44's target (a 3D steady state at ε = 0.02 in ≤ 60 s). Then the pinned state's 3D
stability (:func:`fem_ade.campaigns.stability.cartesian`, its 4 lowest eigenvalues) with
ARPACK's default 20 Lanczos vectors and with the 140 it keeps now: CPU seconds, the ratio,
how far the eigenvalues differ. One thread, one process, CPU seconds.

    python studies/newton3d_bench.py --out studies/results
    python studies/newton3d_bench.py --quick
"""

from __future__ import annotations

from _lib.cli import one_thread, study_parser

one_thread()

import time  # noqa: E402
from pathlib import Path  # noqa: E402

OUT = Path("runs") / "studies"
#: (ε, nodes per axis): the case, and the quick mode's
CASE, QUICK_CASE = (0.02, 64), (0.04, 32)
AXIS, CENTRE = (0.45, 0.3, 0.84), (0.5123, 0.4871, 0.5057)
TARGET_S = 60.0


def tilted_prolate(eps: float, n: int):
    """The backend at the flow's 1e-6 stop, and the flow's steps and CPU seconds."""
    import dataclasses

    import numpy as np

    from fem_ade.backends.base import make_backend
    from fem_ade.engine.loop import run_loop
    from fem_ade.scenes.catalogue import vesicle_scene

    scene = vesicle_scene(v=0.85, branch="prolate", eps=eps, R0=0.18, kbar=1.4, da0=1.2)
    axis = np.array(AXIS) / np.linalg.norm(AXIS)
    scene = scene.with_(ic=dataclasses.replace(scene.ic, axis=tuple(axis), centre=CENTRE))
    be = make_backend("fem", scene, n=n, order=4, scheme="stabilized", constraints="exact",
                      dt=100 * scene.dt)
    c0 = time.process_time()
    flow = run_loop(be, dt=100 * scene.dt, until_steady=1e-6, max_steps=5000, every=10,
                    accelerate=True)
    return be, flow.steps, time.process_time() - c0


def newton(be, phi0, pins, pinned: bool, linear: str = "coarse") -> dict:
    """Newton from ``phi0`` with the pins or without them (the pins' values measured by the
    pinned system's functionals ``pins`` in both), by the ``linear`` solver."""
    import numpy as np

    from fem_ade.backends.fem.newton import NewtonSystem, solve_steady

    def centroid():
        inside = be.space.weights * (be.phi + 1.0)
        return np.array([np.sum(inside * x) / np.sum(inside) for x in be.space.doflocs])

    original = NewtonSystem._translations
    if not pinned:
        NewtonSystem._translations = lambda self: []
    try:
        be._set(phi0.copy(), None)
        c0, t0 = centroid(), np.array([p @ phi0 for p in pins])
        cpu = time.process_time()
        result = solve_steady(be, max_iterations=40, linear=linear)
        cpu = time.process_time() - cpu
    finally:
        NewtonSystem._translations = original
    return {"converged": result.converged, "iterations": result.iterations,
            "minres": result.krylov, "coarse": result.coarse, "cpu_s": round(cpu, 2),
            "E": result.E, "phi": be.phi.copy(),
            "pins_moved": float(np.abs(np.array([p @ be.phi for p in pins]) - t0).max()),
            "centroid_moved": float(np.abs(centroid() - c0).max())}


def stability(be) -> dict:
    """The 4 lowest eigenvalues of the state's 3D stability and their CPU seconds with
    ARPACK's default 20 Lanczos vectors and with :data:`fem_ade.campaigns.stability.
    ARNOLDI_VECTORS`; the ratio and how far the eigenvalues differ."""
    import numpy as np

    from fem_ade.campaigns.stability import ARNOLDI_VECTORS, cartesian

    stab = {"vectors": ARNOLDI_VECTORS}
    for name, ncv in (("ncv_20", 20), (f"ncv_{ARNOLDI_VECTORS}", ARNOLDI_VECTORS)):
        cpu = time.process_time()
        values = cartesian(be, 4, ncv=ncv).eigenvalues
        stab[name] = {"cpu_s": round(time.process_time() - cpu, 2),
                      "eigenvalues": [float(x) for x in values]}
        print(f"  3D stability, {ncv} Lanczos vectors: {stab[name]['cpu_s']} s CPU, "
              f"lowest {', '.join(f'{x:.6e}' for x in values)}", flush=True)
    old, new = stab["ncv_20"], stab[f"ncv_{ARNOLDI_VECTORS}"]
    stab["speedup"] = round(old["cpu_s"] / new["cpu_s"], 2)
    stab["eigenvalues_agree"] = float(np.max(np.abs(np.array(new["eigenvalues"])
                                                    / np.array(old["eigenvalues"]) - 1)))
    return stab


def main(argv=None) -> dict:
    import numpy as np

    from fem_ade.backends.fem.newton import NewtonSystem
    from fem_ade.store.output import write_json_atomic

    ap = study_parser(__doc__, OUT, quick="ε = 0.04 on 32³: the code, in seconds")
    args = ap.parse_args(argv)
    eps, n = QUICK_CASE if args.quick else CASE
    be, steps, flow_s = tilted_prolate(eps, n)
    phi0 = be.phi.copy()
    pins = NewtonSystem(be).translations
    result = {"eps": eps, "nodes": n, "order": 4, "unknowns": int(phi0.size),
              "flow_steps": steps, "flow_cpu_s": round(flow_s, 2), "pins": len(pins)}
    print(f"eps = {eps:g}, {n}^3 nodes of order 4: the flow to 1e-6 took {steps} steps, "
          f"{flow_s:.1f} s CPU; {len(pins)} pins", flush=True)
    for name, pinned, linear in (("pinned", True, "coarse"), ("P_alone", True, "minres"),
                                 ("free", False, "coarse")):
        r = result[name] = newton(be, phi0, pins, pinned, linear)
        spaces = "; ".join(f"a coarse space of {c['functions']} functions, {c['deflated']} "
                           f"deflated, in {c['seconds']} s" for c in r["coarse"])
        print(f"  Newton {name}: converged {r['converged']} in {r['iterations']} "
              f"(MINRES {r['minres']}{'; ' + spaces if spaces else ''}), {r['cpu_s']} s "
              f"CPU, E = {r['E']:.13g}; the pins moved {r['pins_moved']:.2g}, the centroid "
              f"{r['centroid_moved']:.2g}", flush=True)
    plain, coarse = result["P_alone"], result["pinned"]
    result["minres_ratio"] = round(sum(plain["minres"]) / sum(coarse["minres"]), 2)
    result["coarse_speedup"] = round(plain["cpu_s"] / coarse["cpu_s"], 2)
    result["coarse_E_difference"] = coarse["E"] / plain["E"] - 1
    result["coarse_phi_difference"] = float(np.abs(coarse["phi"] - plain["phi"]).max())
    result["speedup"] = round(result["free"]["cpu_s"] / result["pinned"]["cpu_s"], 2)
    result["E_difference"] = result["free"]["E"] / result["pinned"]["E"] - 1
    result["target_s"] = TARGET_S
    be._set(coarse["phi"], None)
    for r in (plain, coarse, result["free"]):
        del r["phi"]
    stab = result["stability"] = stability(be)
    print(f"  P alone / coarse space: {result['minres_ratio']}x the MINRES iterations "
          f"(target >= 5x), {result['coarse_speedup']}x the CPU; E differs by "
          f"{result['coarse_E_difference']:.2g}, phi by {result['coarse_phi_difference']:.2g}")
    print(f"  3D stability: {stab['speedup']}x less CPU with {stab['vectors']} Lanczos vectors "
          f"than 20; the eigenvalues agree to {stab['eigenvalues_agree']:.1e}")
    print(f"  free / pinned: {result['speedup']}x the CPU; E free / pinned - 1 = "
          f"{result['E_difference']:.2g}; target (eps = 0.02, <= {TARGET_S:g} s): Newton "
          f"{result['pinned']['cpu_s']} s, flow + Newton "
          f"{round(flow_s + result['pinned']['cpu_s'], 1)} s")
    name = "newton3d_bench_quick.json" if args.quick else "newton3d_bench.json"
    args.out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out / name, result)
    return result


if __name__ == "__main__":
    main()
