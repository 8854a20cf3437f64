"""What a branch point costs with each solver (issue 42's targets), measured in one run.

At ε = 0.005 (the prolate at R₀ = 0.17 from v = 0.69, order 8, 2.5 nodes per ε: 66265
nodes) and, with ``--small``, at ε = 0.0025: one continuation point (the same predictor
from the same three points) corrected by Newton with the direct solve (the factored
Hessian in mixed form, docs/model.md §13) and with MINRES preconditioned by the bulk Hessian
(the path before), and the point's stability as its branch computes it
(:func:`fem_ade.campaigns.branch.stability_check`: shift-invert Lanczos on the factorization,
each block's shift near the lowest eigenvalue of the point before, which is checked first and
not timed) — the m = 0 block (its four lowest; also by ARPACK's regular mode, the path
before), and the blocks m = 0 … 8 — and the blocks m = 0 … 8 with no point before (as
``python -m fem_ade.stability`` computes them).
The direct path is measured with each sparse code installed (MKL's PARDISO, scipy's
SuperLU: ``FEM_ADE_SPARSE``), the default one first. Prints each time, the ratios, and the
targets of the issue (a point with its m = 0 stability in ≤ 10 s, with m ≤ 8 in ≤ 20 s, at
ε = 0.0025 in ≤ 60 s) by the default code, one thread, and writes
``OUT/solver_bench.json``. The branches it starts from are made once in
``OUT/solver_bench/`` (kept: a second run measures only).

    python studies/solver_bench.py --out studies/results [--small] [--no-old]
"""

from __future__ import annotations

from _lib.cli import one_thread, study_parser

one_thread()

import os  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from unittest import mock  # noqa: E402

import numpy as np  # noqa: E402

from fem_ade.backends.fem.direct import SPARSE_ENV  # noqa: E402

OUT = Path("runs") / "studies"
#: (ε, R₀, from, to): the branches the points are taken from
CASES = {0.005: (0.17, 0.69, 0.685), 0.0025: (0.17, 0.69, 0.688), 0.04: (0.2, 0.85, 0.84)}
TARGETS = {"point_m0_s": 10.0, "point_m8_s": 20.0, "point_small_s": 60.0}
#: a sparse code's figures kept beside the other's
CODE_KEYS = ("newton_direct_s", "newton_direct_iterations", "E_direct", "stability_m0_s",
             "stability_m8_s", "stability_m8_alone_s", "eigenvalues_m0", "point_m0_s",
             "point_m8_s")


def sparse_codes() -> list[str]:
    """The sparse codes installed, the default first (fem_ade.backends.fem.direct)."""
    from fem_ade.backends.fem import pardiso
    from fem_ade.backends.fem.direct import sparse_code

    default = sparse_code()
    other = "superlu" if default == "pardiso" else "pardiso"
    return [default] + ([other] if other == "superlu" or pardiso.available() else [])


def branch_folder(root: Path, eps: float) -> Path:
    """A prolate branch of three points at ε (made once, without stability)."""
    from fem_ade.campaigns.branch import follow, vesicle_for_branch

    R0, start, stop = CASES[eps]
    out = root / f"prolate-eps={eps:g}"
    scene = vesicle_for_branch({"branch": "prolate", "eps": eps, "R0": R0}, "v", start, stop)
    step = min(0.005, round(abs(start - stop), 12))  # a step within the branch's span
    follow(scene, param="v", start=start, stop=stop, step=step, out=out, quiet=True,
           stable=False, max_points=3)
    return out


def measure(folder: Path, old: bool) -> dict:
    """The times of one continuation point and of its stability, each solver."""
    import numpy as np

    from fem_ade.backends.fem.newton import NewtonSystem
    from fem_ade.campaigns.branch import stability_check
    from fem_ade.campaigns.branch_folder import load_points
    from fem_ade.campaigns.continuation import Continuation
    from fem_ade.campaigns.stability import axisymmetric, cartesian, load_state

    points = load_points(folder)[:3]
    be, _ = load_state(folder / "points" / f"{len(points) - 1:04d}")
    out = {"nodes": int(be.phi.size)}
    checks = {modes: stability_check(True, modes) for modes in (0, 8)}
    for check in checks.values():  # the point before, as its branch checked it (not timed)
        check(be)
    history = [(phi, row["v"]) for row, phi in points]
    for linear in ("direct", "minres") if old else ("direct",):
        cont = Continuation(be, "v")
        cont.sys = NewtonSystem(be, linear)
        cont.theta = points[-1][0]["theta"]
        be._set(points[-1][1], None)
        cont.set_p(points[-1][0]["v"])
        t0 = time.perf_counter()
        corrected, _ = cont.advance(history, None, points[-1][0]["ds_next"], 1e-4)
        out[f"newton_{linear}_s"] = round(time.perf_counter() - t0, 2)
        out[f"newton_{linear}_iterations"] = corrected[2]
        out[f"E_{linear}"] = float(be.diagnostics()["E"]) if corrected else None
        phi_new = corrected[0]
    be._set(phi_new, None)
    t0 = time.perf_counter()
    m0 = checks[0](be)
    out["stability_m0_s"] = round(time.perf_counter() - t0, 2)
    out["eigenvalues_m0"] = [float(x) for x in m0.modes[0]]
    t0 = time.perf_counter()
    allm = checks[8](be)
    out["stability_m8_s"] = round(time.perf_counter() - t0, 2)
    out["lowest_per_mode"] = {str(m): allm.lowest(m) for m in allm.modes}
    t0 = time.perf_counter()
    alone = axisymmetric(be, range(9), 1)  # with no point before (the command line's)
    out["stability_m8_alone_s"] = round(time.perf_counter() - t0, 2)
    out["lowest_agree"] = max(abs(alone.lowest(m) / allm.lowest(m) - 1) for m in allm.modes)
    if old:
        t0 = time.perf_counter()
        before = cartesian(be, 4)
        out["stability_m0_old_s"] = round(time.perf_counter() - t0, 2)
        out["eigenvalues_m0_old"] = [float(x) for x in before.eigenvalues]
        out["eigenvalues_agree"] = float(np.max(np.abs(np.asarray(before.eigenvalues)
                                                      / np.asarray(m0.modes[0]) - 1)))
    return out


def main(argv=None) -> dict:
    from fem_ade.store.output import write_json_atomic

    ap = study_parser(__doc__, OUT, quick="ε = 0.04: the code, in seconds")
    ap.add_argument("--small", action="store_true", help="also ε = 0.0025")
    ap.add_argument("--no-old", dest="old", action="store_false",
                    help="without the paths before (MINRES, ARPACK's regular mode)")
    args = ap.parse_args(argv)
    root = args.out / ("solver_bench_quick" if args.quick else "solver_bench")
    result = {}
    first = 0.04 if args.quick else 0.005
    codes = sparse_codes()
    for eps in (first, 0.0025) if args.small else (first,):
        folder = branch_folder(root, eps)
        r = {}
        for code in codes:
            with mock.patch.dict(os.environ, {SPARSE_ENV: code}):  # restored after
                rc = measure(folder, args.old and eps == first and code == codes[0])
            rc["point_m0_s"] = round(rc["newton_direct_s"] + rc["stability_m0_s"], 2)
            rc["point_m8_s"] = round(rc["newton_direct_s"] + rc["stability_m8_s"], 2)
            r = r or rc  # the default code's figures at the top
            r[code] = {k: rc[k] for k in CODE_KEYS}
            print(f"eps = {eps:g} ({rc['nodes']} nodes), {code}: Newton {rc['newton_direct_s']} "
                  f"s ({rc['newton_direct_iterations']} iterations), stability m = 0 "
                  f"{rc['stability_m0_s']} s, m = 0..8 {rc['stability_m8_s']} s (with no "
                  f"point before {rc['stability_m8_alone_s']} s); a point with "
                  f"m = 0 {rc['point_m0_s']} s, with m <= 8 {rc['point_m8_s']} s", flush=True)
        r["code"] = codes[0]
        if len(codes) > 1:
            a, b = (r[c] for c in codes[:2])
            r["code_ratios"] = {k: round(b[k] / a[k], 2) for k in CODE_KEYS if k.endswith("_s")}
            r["codes_agree"] = {"E": abs(a["E_direct"] / b["E_direct"] - 1), "eigenvalues_m0":
                                float(np.max(np.abs(np.asarray(a["eigenvalues_m0"])
                                                    / np.asarray(b["eigenvalues_m0"]) - 1)))}
            print(f"  {codes[1]} / {codes[0]}: " + ", ".join(
                f"{k} {v}x" for k, v in r["code_ratios"].items())
                + f"; E equal to {r['codes_agree']['E']:.1e}, the m = 0 eigenvalues to "
                f"{r['codes_agree']['eigenvalues_m0']:.1e}", flush=True)
        if "newton_minres_s" in r:
            r["point_before_s"] = round(r["newton_minres_s"] + r["stability_m0_old_s"], 2)
            r["speedup_point_m0"] = round(r["point_before_s"] / r["point_m0_s"], 1)
            r["speedup_newton"] = round(r["newton_minres_s"] / r["newton_direct_s"], 1)
            r["speedup_stability_m0"] = round(r["stability_m0_old_s"] / r["stability_m0_s"], 1)
            print(f"  before: Newton-MINRES {r['newton_minres_s']} s, ARPACK regular mode "
                  f"{r['stability_m0_old_s']} s: a point {r['point_before_s']} s; "
                  f"{r['speedup_point_m0']}x (Newton {r['speedup_newton']}x, stability "
                  f"{r['speedup_stability_m0']}x); eigenvalues agree to "
                  f"{r['eigenvalues_agree']:.1e}", flush=True)
        result[f"{eps:g}"] = r
    small = result.get("0.0025")
    checks = {"point_m0_s": result[f"{first:g}"]["point_m0_s"],
              "point_m8_s": result[f"{first:g}"]["point_m8_s"],
              "point_small_s": small["point_m0_s"] if small else None}
    for key, value in checks.items():
        if value is not None:
            print(f"  target {key} <= {TARGETS[key]:g} s: {value} s "
                  f"({'met' if value <= TARGETS[key] else 'not met'})")
    name = "solver_bench_quick.json" if args.quick else "solver_bench.json"
    write_json_atomic(args.out / name, {"cases": result, "targets": TARGETS, "checks": checks})
    return result


if __name__ == "__main__":
    main()
