"""The axisymmetric geometry's resolution and cost (issue 30, docs/model.md §11).

Stage ``resolution`` — how many nodes per ε the default needs: seeded steady states (the
``steady`` recipe to a relative energy change per step of 1e-11) of five shapes — the
prolate and the oblate at v = 0.8, the stomatocyte at v = 0.6, the Clifford torus (minimal
model) and the pear at v = 0.85 with ADE (κ̄/κ = 1.4, Δa₀ = 1.8) — at ε = 0.04, 0.02, 0.01,
for orders 4 and 8 at 1.5 … 4 nodes per ε, each against order 8 at 6 nodes per ε. The
default (``fem_ade.backends.fem.axisym.NODES_PER_EPS`` at ``DEFAULT_ORDER``) is the fewest nodes
per ε
whose error in E is below 1e-4 for every shape and ε.

Stage ``cost`` — what a steady state costs at equal accuracy, side by side in one run: the
prolate at v = 0.8 seeded from its sharp shape, ε = 0.01, to a steady state (the ``steady``
recipe, 1e-9), by the axisymmetric FEM (order 8, 1.5 … 4 nodes per ε), the 3D FEM (order
8, 96, 128, 160 nodes per axis) and the 3D spectral reference (n = 96, 128, 160): CPU
seconds (one thread; the backend's set-up and the loop, not the seed's sharp solve nor the
shape analysis after) against the error in E relative to the axisymmetric
run at 6 nodes per ε, and the time to each accuracy interpolated as ``studies/cost.py``
does. The ratio spectral / axisymmetric at equal accuracy is the issue's figure (goal ≥ 50).
Also: a steady state at ε = 0.0025 with the default resolution (goal: under a minute).

Writes ``OUT/axisymmetric.md`` and ``OUT/axisymmetric.json`` (every run: case, ε, method,
resolution, nodes, steps, E, CPU s, error), the figure ``OUT/axisymmetric-cost.png``, and
merges the cost figures into ``OUT/bench.json`` (its ``axisymmetric`` block, which
``studies/bench.py`` keeps). Every run is cached in ``OUT/axisymmetric/runs.json``
(resumable: nothing cached is redone).

    python studies/axisymmetric.py --out studies/results                 # both (~1.5 h)
    python studies/axisymmetric.py --out studies/results --stages cost
    python studies/axisymmetric.py --quick                               # seconds

One thread: this script sets ``OPENBLAS_NUM_THREADS=1`` and ``FEM_ADE_FFT_WORKERS=1`` unless
they are set.
"""

from __future__ import annotations

from _lib.cli import one_thread

one_thread()  # one thread: CPU seconds compare

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
from pathlib import Path  # noqa: E402
from types import SimpleNamespace  # noqa: E402

from _lib.fits import time_to  # noqa: E402
from fem_ade.plots.figures import save_figure  # noqa: E402
from fem_ade.store.output import write_json_atomic  # noqa: E402

OUT = Path("runs") / "studies"  # the committed results: --out studies/results
#: the shapes of the resolution stage: (name, vesicle parameters or "clifford")
CASES = {
    "prolate v=0.8": {"v": 0.8, "branch": "prolate"},
    "oblate v=0.8": {"v": 0.8, "branch": "oblate"},
    "stomatocyte v=0.6": {"v": 0.6, "branch": "stomatocyte"},
    "Clifford torus": "clifford",
    "pear v=0.85 ADE": {"v": 0.85, "branch": "pear", "kbar": 1.4, "da0": 1.8},
}
TOL = {"resolution": 1e-11, "cost": 1e-9}
Plan = SimpleNamespace
FULL = Plan(cases=tuple(CASES), eps=(0.04, 0.02, 0.01), orders=(4, 8),
            nodes_per_eps=(1.5, 2.0, 2.5, 3.0, 4.0), reference=(8, 6.0),
            cost_eps=0.01, cost_axi=(1.5, 2.0, 2.5, 3.0, 4.0), cost_3d=(96, 128, 160),
            fine_eps=0.0025)
QUICK = Plan(cases=("prolate v=0.8",), eps=(0.05,), orders=(4,), nodes_per_eps=(1.5, 2.5),
             reference=(4, 4.0), cost_eps=0.05, cost_axi=(1.5, 2.5), cost_3d=(24,),
             fine_eps=None)
TARGETS = (1e-3, 1e-4, 1e-5)


def scene_of(case: str, eps: float):
    """The case's scene at ε (the vesicle family, or the Clifford torus of the minimal model
    with the localized volume: R = 0.16 L, r = R/√2)."""
    from fem_ade.scenes.catalogue import vesicle_scene

    spec = CASES[case]
    if spec != "clifford":
        return vesicle_scene(eps=eps, **spec)
    from fem_ade.model.params import Params
    from fem_ade.scenes.catalogue import Scene
    from fem_ade.scenes.initial import Torus

    R = 0.16
    r = R / math.sqrt(2.0)
    params = Params(eps=eps, alpha=2 * math.pi**2 * R * r * r, beta=4 * math.pi**2 * R * r,
                    effects=frozenset({"bending", "volume", "area"}),
                    volume_functional="localized")
    return Scene("clifford", params, 0.0075 * eps**3, Torus((0.5, 0.5, 0.5), R, r),
                 n=max(16, round(1.28 / eps)))


def cells(eps: float, order: int, nodes_per_eps: float) -> int:
    return max(4, math.ceil(nodes_per_eps / (eps * order) - 1e-9))


def run(case: str, eps: float, method: str, resolution, tol: float) -> dict:
    """One seeded steady state: method "axi" (resolution (order, nodes per ε)), "fem3d"
    (order 8, resolution = nodes per axis) or "spectral" (n)."""
    from fem_ade.engine.runs import recipe, simulate

    scene = scene_of(case, eps)
    if method == "axi":
        order, npe = resolution
        kw = {"backend": "fem", "n": cells(eps, order, npe) * order,  # nodes per L
              "backend_options": {"geometry": "axisymmetric", "order": order}}
    elif method == "fem3d":
        kw = {"backend": "fem", "n": resolution // 8 * 8, "backend_options": {"order": 8}}
    else:
        kw = {"backend": "spectral", "n": resolution}
    steady = {**recipe("steady", scene), "until_steady": tol, "max_steps": 60000}
    res = simulate(scene, **steady, **kw, every=10, render=False, sharp=False,
                   allow_underresolved=True)
    # the backend's set-up and the loop; not the seed's sharp solve nor the analysis after
    cpu, wall = res.setup_cpu_s + res.cpu_s, res.wall_s
    info = res.shape or {}
    return {"case": case, "eps": eps, "method": method,
            "resolution": list(resolution) if isinstance(resolution, tuple) else resolution,
            "n": kw["n"], "status": res.status, "steps": res.steps, "E": res.final["E"],
            "W": res.final["W"], "G": res.final["G"], "label": info.get("label"),
            "cpu_s": round(cpu, 3), "wall_s": round(wall, 3), "tol": tol}


def key(r_or_case, eps=None, method=None, resolution=None, tol=None) -> str:
    if isinstance(r_or_case, dict):
        r = r_or_case
        return key(r["case"], r["eps"], r["method"], r["resolution"], r["tol"])
    res = "x".join(str(x) for x in (resolution if isinstance(resolution, (list, tuple))
                                    else [resolution]))
    return f"{r_or_case}|{eps:g}|{method}|{res}|{tol:g}"


class Runs:
    """The cache of runs, written after each (resumable)."""

    def __init__(self, path: Path):
        self.path = path
        self.rows = json.loads(path.read_text()) if path.is_file() else {}

    def get(self, case, eps, method, resolution, tol, compute=True):
        k = key(case, eps, method, resolution, tol)
        if k not in self.rows and compute:
            row = run(case, eps, method, resolution, tol)
            print(f"  {k}: E = {row['E']:.10f}, {row['steps']} steps, {row['label']}, "
                  f"{row['cpu_s']} s CPU", flush=True)
            self.rows[k] = row
            self.path.parent.mkdir(parents=True, exist_ok=True)
            write_json_atomic(self.path, self.rows, indent=0)
        return self.rows.get(k)


# ---------------------------------------------------------------------------------------------
# stage resolution
# ---------------------------------------------------------------------------------------------
def resolution_stage(runs: Runs, plan, compute=True) -> list[dict]:
    """Per (case, ε, order, nodes per ε): E and its error against the reference."""
    out = []
    for case in plan.cases:
        for eps in plan.eps:
            ref = runs.get(case, eps, "axi", plan.reference, TOL["resolution"], compute)
            if ref is None:
                continue
            for order in plan.orders:
                for npe in plan.nodes_per_eps:
                    r = runs.get(case, eps, "axi", (order, npe), TOL["resolution"], compute)
                    if r is None:
                        continue
                    out.append({"case": case, "eps": eps, "order": order,
                                "nodes_per_eps": npe, "E": r["E"], "E_ref": ref["E"],
                                "error": abs(r["E"] / ref["E"] - 1.0), "label": r["label"],
                                "ref_label": ref["label"], "steps": r["steps"]})
    return out


def default_choice(rows: list[dict], order: int, limit: float = 1e-4) -> float | None:
    """The fewest nodes per ε at ``order`` with every error below ``limit``."""
    for npe in sorted({r["nodes_per_eps"] for r in rows}):
        errs = [r["error"] for r in rows if r["order"] == order and r["nodes_per_eps"] == npe]
        if errs and max(errs) < limit:
            return npe
    return None


# ---------------------------------------------------------------------------------------------
# stage cost
# ---------------------------------------------------------------------------------------------
def cost_stage(runs: Runs, plan, compute=True) -> dict:
    case, eps, tol = "prolate v=0.8", plan.cost_eps, TOL["cost"]
    ref = runs.get(case, eps, "axi", plan.reference, TOL["resolution"], compute)
    if ref is None:
        return {}
    methods = {"axisymmetric FEM (p = 8)": [("axi", (8, npe)) for npe in plan.cost_axi],
               "3D FEM (p = 8)": [("fem3d", n) for n in plan.cost_3d],
               "3D spectral": [("spectral", n) for n in plan.cost_3d]}
    table = {}
    for name, items in methods.items():
        pts = []
        for method, res in items:
            r = runs.get(case, eps, method, res, tol, compute)
            if r is None:
                continue
            err = abs(r["E"] / ref["E"] - 1.0)
            pts.append({"resolution": r["resolution"], "n": r["n"], "steps": r["steps"],
                        "cpu_s": r["cpu_s"], "error": err, "label": r["label"]})
        table[name] = pts
    times = {name: {str(t): time_to([(p["cpu_s"], p["error"]) for p in pts], t)
                    for t in TARGETS} for name, pts in table.items()}
    axi = times["axisymmetric FEM (p = 8)"]
    ratio = {str(t): (times["3D spectral"][str(t)] / axi[str(t)]
                      if times["3D spectral"][str(t)] and axi[str(t)] else None)
             for t in TARGETS}
    ratio_fem = {str(t): (times["3D FEM (p = 8)"][str(t)] / axi[str(t)]
                          if times["3D FEM (p = 8)"][str(t)] and axi[str(t)] else None)
                 for t in TARGETS}
    fine = None
    if plan.fine_eps:
        from fem_ade.backends.fem.axisym import DEFAULT_ORDER, NODES_PER_EPS

        fine = runs.get(case, plan.fine_eps, "axi", (DEFAULT_ORDER, NODES_PER_EPS), tol,
                        compute)
    return {"case": case, "eps": eps, "reference_E": ref["E"], "runs": table,
            "time_to": times, "spectral_over_axisymmetric": ratio,
            "fem3d_over_axisymmetric": ratio_fem, "fine": fine}


# ---------------------------------------------------------------------------------------------
# the report
# ---------------------------------------------------------------------------------------------
def report(runs: Runs, out: Path, plan, compute=False) -> dict:
    """axisymmetric.md and .json (and the cost figure, bench.json's block) from the runs."""
    rows = resolution_stage(runs, plan, compute=compute)
    cost = cost_stage(runs, plan, compute=compute)
    lines = ["# The axisymmetric geometry: resolution and cost", "",
             "Written by `studies/axisymmetric.py` (docs/model.md §11). CPU seconds of one "
             "thread (set-up and loop); errors are relative errors in E.", ""]
    choice = {}
    if rows:
        section, choice = resolution_section(rows, plan)
        lines += section
    if cost and any(cost["runs"].values()):
        lines += cost_section(cost, plan)
        cost_figure(cost, out / "axisymmetric-cost.png")
    notes = out / "axisymmetric" / "notes.md"
    if notes.is_file():
        lines += [notes.read_text().strip(), ""]
    (out / "axisymmetric.md").write_text("\n".join(lines))
    payload = {"resolution": rows, "default_nodes_per_eps": choice, "cost": cost}
    (out / "axisymmetric.json").write_text(json.dumps(payload, indent=1) + "\n")
    if cost and any(cost["runs"].values()):
        merge_bench(out / "bench.json", cost)
    return payload


def resolution_section(rows: list[dict], plan) -> tuple[list[str], dict]:
    """The table of errors against order and nodes per ε; (lines, the default per order)."""
    lines = ["## How many nodes per ε", "",
             f"Seeded steady states (relative energy change per step < "
             f"{TOL['resolution']:g}); the error in E against order "
             f"{plan.reference[0]} at {plan.reference[1]:g} nodes per ε, the largest "
             "over the shapes "
             f"({', '.join(plan.cases)}):", "",
             "| order | nodes per ε | " + " | ".join(f"ε = {e:g}" for e in plan.eps)
             + " | worst shape |", "|---|---|" + "---|" * (len(plan.eps) + 1)]
    choice = {}
    for order in plan.orders:
        for npe in plan.nodes_per_eps:
            mine = [r for r in rows if r["order"] == order and r["nodes_per_eps"] == npe]
            worst = max(mine, key=lambda r: r["error"], default=None)
            cells_ = []
            for eps in plan.eps:
                errs = [r["error"] for r in mine if r["eps"] == eps]
                cells_.append(f"{max(errs):.1e}" if errs else "")
            lines.append(f"| {order} | {npe:g} | " + " | ".join(cells_) + " | "
                         + (worst["case"] if worst else "") + " |")
        choice[order] = default_choice(rows, order)
    lines += ["", "The fewest nodes per ε with every error below 1e-4: "
              + "; ".join(f"order {o}: {'—' if c is None else f'{c:g}'}"
                          for o, c in choice.items()) + ".", ""]
    changed = [r for r in rows if r["label"] != r["ref_label"]]
    if changed:
        lines += ["Runs whose shape label differs from the reference's: "
                  + ", ".join(f"{r['case']} ε = {r['eps']:g} p = {r['order']} "
                              f"{r['nodes_per_eps']:g}/ε: {r['label']}"
                              for r in changed) + ".", ""]
    return lines, choice


def cost_section(cost: dict, plan) -> list[str]:
    """What a steady state costs, per method, and the time to each accuracy."""
    lines = [f"## What a steady state costs ({cost['case']}, ε = {cost['eps']:g})", "",
             "Seeded from the sharp shape, the `steady` recipe to a relative energy "
             f"change per step of {TOL['cost']:g}; the error in E against the "
             f"axisymmetric run at {plan.reference[1]:g} nodes per ε "
             f"(E = {cost['reference_E']:.10f}).", "",
             "| method | resolution | steps | CPU s | error in E |", "|---|---|---|---|---|"]
    for name, pts in cost["runs"].items():
        for p in pts:
            res = p["resolution"]
            res = (f"{res[1]:g} nodes per ε" if isinstance(res, list) else
                   f"{res} nodes per axis")
            lines.append(f"| {name} | {res} | {p['steps']} | {p['cpu_s']:.3g} | "
                         f"{p['error']:.1e} |")
    lines += ["", "CPU seconds to reach an error in E of:", "",
              "| method | " + " | ".join(f"{t:g}" for t in TARGETS) + " |",
              "|---|" + "---|" * len(TARGETS)]
    for name, tt in cost["time_to"].items():
        lines.append(f"| {name} | " + " | ".join(
            "—" if tt[str(t)] is None else f"{tt[str(t)]:.3g}" for t in TARGETS) + " |")
    lines.append("| **3D spectral / axisymmetric** | " + " | ".join(
        "—" if cost["spectral_over_axisymmetric"][str(t)] is None
        else f"**{cost['spectral_over_axisymmetric'][str(t)]:.0f}×**" for t in TARGETS)
        + " |")
    lines.append("| 3D FEM / axisymmetric | " + " | ".join(
        "—" if cost["fem3d_over_axisymmetric"][str(t)] is None
        else f"{cost['fem3d_over_axisymmetric'][str(t)]:.0f}×" for t in TARGETS) + " |")
    lines += ["", "(— : no measured resolution of that method reached the accuracy.)", "",
              "![error in E against CPU time](axisymmetric-cost.png)", ""]
    if cost.get("fine"):
        f = cost["fine"]
        lines += [f"A steady state at ε = {f['eps']:g} with the default resolution "
                  f"(order {f['resolution'][0]}, {f['resolution'][1]:g} nodes per ε, "
                  f"n = {f['n']}): {f['steps']} steps, {f['cpu_s']:.3g} s CPU, "
                  f"{f['wall_s']:.3g} s wall (one thread).", ""]
    return lines


def cost_figure(cost: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    def level(p):  # nodes per ε (axisymmetric) or nodes per axis
        return p["resolution"][1] if isinstance(p["resolution"], list) else p["resolution"]

    for (name, pts), marker in zip(cost["runs"].items(), "os^", strict=False):
        if pts:
            pts = sorted(pts, key=level)  # in order of resolution (a coarse run may take
            line, = ax.loglog([p["cpu_s"] for p in pts],  # more steps, so more time)
                              [max(p["error"], 1e-12) for p in pts], marker + "-", label=name)
            for p in pts:
                ax.annotate(f"{level(p):g}", (p["cpu_s"], max(p["error"], 1e-12)),
                            textcoords="offset points", xytext=(4, 3), fontsize=7,
                            color=line.get_color())
    for t in TARGETS:
        ax.axhline(t, color="0.8", lw=0.7, zorder=0)
    ax.set(xlabel="CPU seconds (one thread)", ylabel="relative error in E",
           title=f"{cost['case']}, ε = {cost['eps']:g}: a steady state\n(labels: nodes per ε "
                 "(axisymmetric), nodes per axis (3D))")
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path, dpi=110, colours=64)
    plt.close(fig)


def merge_bench(path: Path, cost: dict) -> None:
    """bench.json's ``axisymmetric`` block: the figures of the cost stage (kept by
    studies/bench.py when it rewrites the rest)."""
    data = json.loads(path.read_text()) if path.is_file() else {}
    figures = {}
    for t in TARGETS:
        r = cost["spectral_over_axisymmetric"][str(t)]
        if r is not None:
            figures[f"3D spectral / axisymmetric CPU to {t:g} in E, prolate v=0.8 eps="
                    f"{cost['eps']:g}"] = {"value": r, "unit": "x",
                                           "target": 50.0 if t == 1e-4 else None,
                                           "op": ">=" if t == 1e-4 else None}
        a = cost["time_to"]["axisymmetric FEM (p = 8)"][str(t)]
        if a is not None:
            figures[f"axisymmetric CPU to {t:g} in E, prolate v=0.8 eps={cost['eps']:g}"] = {
                "value": a, "unit": "s", "target": None, "op": None}
    if cost.get("fine"):
        figures[f"axisymmetric steady state eps={cost['fine']['eps']:g} wall"] = {
            "value": cost["fine"]["wall_s"], "unit": "s", "target": 60.0, "op": "<="}
    data["axisymmetric"] = {"threads": 1, "figures": figures}
    write_json_atomic(path, data, indent=1)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--stages", nargs="+", choices=("resolution", "cost"),
                    default=["resolution", "cost"])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--report-only", action="store_true")
    args = ap.parse_args(argv)
    plan = QUICK if args.quick else FULL
    runs = Runs(args.out / "axisymmetric" / "runs.json")
    if not args.report_only:
        if "resolution" in args.stages:
            resolution_stage(runs, plan)
        if "cost" in args.stages:
            cost_stage(runs, plan)
    payload = report(runs, args.out, plan)
    print(f"wrote {args.out / 'axisymmetric.md'}")
    return payload


if __name__ == "__main__":
    main()
