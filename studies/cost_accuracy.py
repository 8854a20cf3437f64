"""What accuracy costs in time: error in E, V, A against wall time, for every discretisation.

For one scene (default ``discocyte``, 50 steps at the paper's Δt, consistent IC), every
discretisation runs the same scheme from the same initial condition; the error at the final
time is measured against a fine spectral reference (n = 96), so it is the spatial error alone
(SPEC §5: at a fixed Δt the FEM converges to the spectral solution). Each run's wall time is
split into setup (mesh, assembly, AMG) and stepping.

Writes ``cost_accuracy.md`` (the table) and ``cost_accuracy.png`` (error against time, one
curve per discretisation) into ``--out`` (default ``studies/results``).

    python studies/cost_accuracy.py            # the full study (~10 min on 2 cores)
    python studies/cost_accuracy.py --quick    # a smoke run (also when CI is set)
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

from fem_ade.runs import simulate
from fem_ade.scenes import get_scene

QUANTITIES = ("E", "V", "A")

FULL = {
    "reference": ("spectral", {}, 96),
    "spectral": ("spectral", {}, [24, 32, 48, 64]),
    "FEM Q1": ("fem", {"order": 1}, [24, 32, 48, 64]),
    "FEM Q2": ("fem", {"order": 2}, [12, 16, 24, 32]),
}
QUICK = {
    "reference": ("spectral", {}, 32),
    "spectral": ("spectral", {}, [16, 24]),
    "FEM Q1": ("fem", {"order": 1}, [16, 24]),
    "FEM Q2": ("fem", {"order": 2}, [8, 12]),
}


def run_one(scene, backend: str, options: dict, n: int, steps: int) -> dict:
    """Final diagnostics and wall time (setup + steps) of one discretisation."""
    t0 = time.perf_counter()
    result = simulate(scene, backend=backend, n=n, steps=steps, every=steps, quiet=True,
                      allow_underresolved=True, backend_options=options)
    wall = time.perf_counter() - t0
    return {"n": n, "wall_s": wall, "step_s": result.wall_s / max(steps, 1),
            "setup_s": wall - result.wall_s, **{q: result.final[q] for q in QUANTITIES}}


def study(scene_name: str = "discocyte", steps: int = 50, quick: bool = False) -> dict:
    """Run every discretisation; return {label: [row, ...]} with relative errors added."""
    plan = QUICK if quick else FULL
    scene = get_scene(scene_name)
    backend, options, n_ref = plan["reference"]
    ref = run_one(scene, backend, options, n_ref, steps)
    rows = {}
    for label, (backend, options, ns) in plan.items():
        if label == "reference":
            continue
        rows[label] = []
        for n in ns:
            r = run_one(scene, backend, options, n, steps)
            for q in QUANTITIES:
                r[f"err_{q}"] = abs(r[q] - ref[q]) / abs(ref[q])
            rows[label].append(r)
            print(f"{label:9s} n={n:3d}  wall {r['wall_s']:7.2f} s (setup {r['setup_s']:.2f} s,"
                  f" step {1e3 * r['step_s']:.1f} ms)  "
                  + "  ".join(f"err {q} {r[f'err_{q}']:.2e}" for q in QUANTITIES), flush=True)
    return {"scene": scene_name, "steps": steps, "reference": ref, "rows": rows}


def write(results: dict, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    ref = results["reference"]
    lines = [f"# What accuracy costs: `{results['scene']}`, {results['steps']} steps at the "
             "paper's Δt", "",
             f"Reference: spectral n = {ref['n']} (E = {ref['E']:.8g}, V = {ref['V']:.8g}, "
             f"A = {ref['A']:.8g}). Errors are relative, at the final step; wall time is setup "
             "plus stepping on this 2-core machine (one run, so ratios matter more than the "
             "absolute figures).", "",
             "| discretisation | n | wall (s) | setup (s) | step (ms) | err E | err V | err A |",
             "|---|---|---|---|---|---|---|---|"]
    fig, axes = plt.subplots(1, 3, figsize=(13, 4.2), constrained_layout=True)
    for label, rows in results["rows"].items():
        for r in rows:
            lines.append(f"| {label} | {r['n']} | {r['wall_s']:.2f} | {r['setup_s']:.2f} | "
                         f"{1e3 * r['step_s']:.1f} | {r['err_E']:.2e} | {r['err_V']:.2e} | "
                         f"{r['err_A']:.2e} |")
        for ax, q in zip(axes, QUANTITIES, strict=True):
            ax.loglog([r["wall_s"] for r in rows], [max(r[f"err_{q}"], 1e-16) for r in rows],
                      "o-", label=label)
            for r in rows:
                ax.annotate(str(r["n"]), (r["wall_s"], max(r[f"err_{q}"], 1e-16)),
                            textcoords="offset points", xytext=(4, 4), fontsize=8)
    for ax, q in zip(axes, QUANTITIES, strict=True):
        ax.set_xlabel("wall time of the run (s)")
        ax.set_ylabel(f"relative error in {q}")
        ax.set_title(f"{q}: error against cost")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.suptitle(f"{results['scene']}, {results['steps']} steps: accuracy against wall time "
                 "(labels: n per direction)")
    fig.savefig(out / "cost_accuracy.png", dpi=110)
    (out / "cost_accuracy.md").write_text("\n".join(lines) + "\n\n![](cost_accuracy.png)\n")


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="discocyte")
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--quick", action="store_true", help="smoke run (also when CI is set)")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results"))
    args = ap.parse_args(argv)
    quick = args.quick or bool(os.environ.get("CI"))
    results = study(args.scene, 5 if quick else args.steps, quick=quick)
    write(results, Path(args.out))
    return results


if __name__ == "__main__":
    main()
