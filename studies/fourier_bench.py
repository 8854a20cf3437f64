"""What the coarse step buys the Fourier–(r, z) Newton solve (docs/model.md §13), measured in
one run.

The state: the (r, z) oblate at v = 0.84 (R₀ = 0.25, no ADE; unstable in m = 2) at
ε = 0.02, order 8, 4 nodes per ε, kicked by ψ cos 2θ (ψ its m = 2 eigenvector, max |ψ| = 1)
on n_θ = 8 angles, V and A restored: a non-axisymmetric start like a branch predictor's.
(The window's oblate, v = 0.7 and Δa₀ = 1.08 with κ̄/κ = 1.4 at R₀ = 0.195, is a torus at
ε = 0.02: its dimple closes.) ``--quick``: the same at ε = 0.04 on n_θ = 4 (the default
mesh). Measured, one thread, CPU seconds:

- **one bordered solve** (Newton's first system at the start, :class:`fem_ade.backends.fem.
  fourier.KKTSolver`): by GMRES with the θ-mean blocks alone (degree 0), with the coarse
  step of degree 4 made for it, and with that coarse step kept (made before, as a Newton
  step reuses it while φ stays within ``REUSE``): each one's set-up, solve and GMRES
  iterations, and how far the solutions differ;
- **Newton to the steady state** from the start, the amplitude pinned (the branch's
  system): with the coarse step (the default, kept while φ stays near) and without it
  (``coarse_degree=0``): iterations, GMRES iterations a step, CPU, and E of each.

Prints the ratios (blocks alone over coarse step) and writes ``OUT/fourier_bench.json``.
The (r, z) line it starts from is made once in ``OUT/fourier_bench/`` (kept: a second run
measures only).

    python studies/fourier_bench.py --out studies/results
    python studies/fourier_bench.py --quick
"""

from __future__ import annotations

from _lib.cli import one_thread, results, study_parser

one_thread()

import time  # noqa: E402
from pathlib import Path  # noqa: E402

from _lib.branches import make_branch  # noqa: E402

OUT = Path("runs") / "studies"
#: (ε, nodes per L, n_θ, the line's arguments): the case and the quick mode's
CASE = (0.02, 200, 8, ["--R0", "0.25", "--param", "v", "--from", "0.85", "--to", "0.84",
                       "--step", "0.01"])
QUICK_CASE = (0.04, None, 4, ["--R0", "0.25", "--param", "v", "--from", "0.85", "--to",
                              "0.84", "--step", "0.01"])
#: the kick's amplitude (max |ψ| = 1; φ's range is 2)
KICK = 1.0


def start(root: Path, quick: bool):
    """(the Fourier state kicked along ψ cos 2θ with V, A restored, the amplitude's pin,
    the case's figures)."""
    from fem_ade.backends.fem.fourier import FourierState
    from fem_ade.backends.fem.modes import lowest_mode
    from fem_ade.backends.fem.newton import NewtonSystem, linearize
    from fem_ade.campaigns.stability import load_state

    eps, n, n_theta, line = QUICK_CASE if quick else CASE
    args = ["vesicle", "--branch", "oblate", "--eps", str(eps), *line]
    made = make_branch(root / f"oblate-eps={eps:g}", args + ([] if n is None else
                                                             ["--n", str(n)]))
    if isinstance(made, str):
        raise SystemExit(f"fourier_bench: the (r, z) line was not made: {made}")
    be, _ = load_state(sorted((made / "points").iterdir())[-1])
    sys2 = NewtonSystem(be)
    _, psi = lowest_mode(sys2, linearize(sys2, be.phi), 2)
    st = FourierState.of(be, 2, n_theta, {1: KICK * psi})
    pin = st.space.weights * st.space.from_modes({1: psi})
    case = {"eps": eps, "n_theta": n_theta, "rz_nodes": int(be.phi.size),
            "unknowns": int(st.phi.size), "kick": KICK}
    return st, pin, case


def one_solve(st, pin) -> dict:
    """Newton's first bordered system at the start by the three preconditioners."""
    import numpy as np

    from fem_ade.backends.fem.fourier import FourierNewtonSystem, KKTSolver
    from fem_ade.backends.fem.newton import linearize

    sys_ = FourierNewtonSystem(st, pins=[pin])
    phi = sys_.restore(st.phi.copy())
    lin = linearize(sys_, phi)
    out, kept, x = {}, None, {}
    for name, degree in (("blocks", 0), ("coarse", None), ("kept", None)):
        cpu = time.process_time()
        solver = KKTSolver(sys_, lin, degree=degree, coarse=kept)
        made = time.process_time() - cpu
        x[name] = solver.solve(-lin.grad, -lin.violation)[0]
        out[name] = {"setup_s": round(made, 2),
                     "solve_s": round(time.process_time() - cpu - made, 2),
                     "gmres": solver.iterations[0]}
        out[name]["total_s"] = round(out[name]["setup_s"] + out[name]["solve_s"], 2)
        kept = solver.coarse if name == "coarse" else kept
        print(f"  one solve, {name}: set-up {out[name]['setup_s']} s, solve "
              f"{out[name]['solve_s']} s, GMRES {out[name]['gmres']}", flush=True)
    ref = np.linalg.norm(x["blocks"])
    out["solutions_differ"] = max(float(np.linalg.norm(x[k] - x["blocks"]) / ref)
                                  for k in ("coarse", "kept"))
    return out


def newton(st, pin, degree) -> dict:
    """Newton from the start, the amplitude pinned, with the coarse step of ``degree``."""
    from fem_ade.backends.fem.fourier import FourierNewtonSystem
    from fem_ade.backends.fem.newton import solve_steady

    phi0 = st.phi.copy()
    sys_ = FourierNewtonSystem(st, pins=[pin], coarse_degree=degree)
    cpu = time.process_time()
    res = solve_steady(st, system=sys_)
    cpu = time.process_time() - cpu
    row = {"converged": res.converged, "iterations": res.iterations, "gmres": res.krylov,
           "cpu_s": round(cpu, 2), "E": res.E}
    st.phi = phi0
    return row


def main(argv=None) -> dict:
    ap = study_parser(__doc__, OUT, quick="the oblate at eps = 0.04 on 4 angles: seconds")
    args = ap.parse_args(argv)
    return results(args, "fourier_bench", lambda: compute(args))


def compute(args) -> dict:
    st, pin, result = start(args.out / "fourier_bench", args.quick)
    print(f"eps = {result['eps']:g}: {result['rz_nodes']} (r, z) nodes x {result['n_theta']}"
          f" angles = {result['unknowns']} unknowns, kicked by {KICK:g} psi cos 2theta",
          flush=True)
    solve = result["one_solve"] = one_solve(st, pin)
    for name, degree in (("newton_coarse", None), ("newton_blocks", 0)):
        r = result[name] = newton(st, pin, degree)
        print(f"  Newton, {name}: converged {r['converged']} in {r['iterations']} (GMRES "
              f"{r['gmres']}), {r['cpu_s']} s CPU, E = {r['E']:.13g}", flush=True)
    b, c, k = solve["blocks"], solve["coarse"], solve["kept"]
    result["ratios"] = {
        "gmres": round(b["gmres"] / c["gmres"], 2),
        "solve_made": round(b["total_s"] / c["total_s"], 2),
        "solve_kept": round(b["total_s"] / k["total_s"], 2),
        "newton": round(result["newton_blocks"]["cpu_s"] / result["newton_coarse"]["cpu_s"],
                        2)}
    result["newton_E_differ"] = abs(result["newton_coarse"]["E"] /
                                    result["newton_blocks"]["E"] - 1)
    r = result["ratios"]
    print(f"  blocks alone / coarse step: {r['gmres']}x the GMRES iterations; one solve "
          f"{r['solve_made']}x the CPU (coarse step made for it), {r['solve_kept']}x (kept); "
          f"Newton {r['newton']}x the CPU; solutions differ by "
          f"{solve['solutions_differ']:.1e}, Newton's E by {result['newton_E_differ']:.1e}")
    return result


if __name__ == "__main__":
    main()
