"""What each digit of accuracy costs: error against time, for transients and steady shapes.

Reads the runs of ``studies/convergence.py`` (``convergence.json``: every discretisation and
level of the spatial study with its error and its time, and the steady-state study) and adds
its own runs at the same reference: the FEM Q1 solvers (``amg``, ``chebyshev`` beside the
direct ``fft`` path) and the stabilized scheme at larger Δt (fewer steps to the same time
T, so its error includes the time error). Every point is one (backend, order, mesh, n,
scheme, Δt, solver) run.

Writes ``cost.json``, ``cost.md`` (the tables: time to reach 1 %, 0.1 %, 0.01 % error in E,
per discretisation, for the transient and for the steady state) and ``cost-SCENE.png`` (error
in E against CPU time, every point, the Pareto front drawn) into ``--out``.

Times are CPU seconds of the process (set-up included; one FFT/BLAS thread): on a shared
machine they move less than wall time. Time to an accuracy is interpolated (log–log) along
each discretisation's measured points, never extrapolated: "—" means no measured level
reached it.

    python studies/cost.py                       # needs convergence.json (full mode)
    python studies/cost.py --quick --out /tmp/c  # its own small 2D study (seconds)
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import time
from pathlib import Path

OUT = Path(__file__).resolve().parent / "results"
TARGETS = (1e-2, 1e-3, 1e-4)

#: the runs this study adds, per scene: (label, n, scheme, Δt factor, options)
EXTRA_FULL = {
    "discocyte": [("Q1", n, "paper", 1, {"solver": s}) for s in ("amg", "chebyshev")
                  for n in (32, 48, 64)]
    + [(lab, n, "stabilized", f, {}) for lab in ("spectral", "Q1") for n in (48, 64)
       for f in (5, 25)],
}
QUICK_SPATIAL = {
    "steps": 10,
    "scenes": {"ellipse-2d": {"ref": 96, "spectral": (24, 32, 48), "Q1": (24, 32, 48, 64),
                              "Q2": (12, 16, 24)}},
}
EXTRA_QUICK = {
    "ellipse-2d": [("Q1", n, "paper", 1, {"solver": "amg"}) for n in (32, 48)]
    + [("spectral", 48, "stabilized", 5, {}), ("Q1", 48, "stabilized", 5, {})],
}


def _convergence():
    path = Path(__file__).resolve().parent / "convergence.py"
    spec = importlib.util.spec_from_file_location("convergence", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def time_to(points: list[tuple[float, float]], target: float) -> float | None:
    """The time at which a discretisation's error first reaches ``target``, interpolated in
    log–log between its measured (time, error) points in order of time; None if none does."""
    pts = sorted(points)
    best = math.inf
    prev = None
    for t, e in pts:
        e = min(e, best)  # a finer, dearer level is never worse than a cheaper one was
        if e <= target:
            if prev is None or prev[1] <= target:
                return t
            (t0, e0), (t1, e1) = prev, (t, e)
            w = (math.log(target) - math.log(e0)) / (math.log(e1) - math.log(e0))
            return math.exp(math.log(t0) + w * (math.log(t1) - math.log(t0)))
        best = e
        prev = (t, e)
    return None


def pareto(points: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """The points no other point beats in both time and error, in order of time."""
    front, best = [], math.inf
    for t, e in sorted(points):
        if e < best:
            front.append((t, e))
            best = e
    return front


def extra_runs(conv, scene_name: str, plan: list, steps: int, ref_n: int) -> list[dict]:
    """The solver and Δt variants, against the same reference as the spatial study."""
    from fem_ade.scenes import get_scene

    scene = get_scene(scene_name)
    ref = conv.run(scene, "spectral", ref_n, steps)
    rows = []
    for label, n, scheme, f, options in plan:
        m = max(1, round(steps / f))
        row = conv.run(scene, label, n, m, scheme=scheme, dt=scene.dt * steps / m, **options)
        row.update(h=scene.params.L / (n * conv.DISCRETISATIONS[label][2]),
                   errors=conv.errors(row, ref, scene.params.L))
        rows.append(row)
        print(f"  {scene_name} {label} n={n} {scheme} dt x{steps / m:g} {options or ''}: "
              f"E err {row['errors']['E']:.2e}, {row['cpu_s']:.1f} s cpu", flush=True)
    return rows


def key(row: dict) -> str:
    """The discretisation a point belongs to (its curve in the plots and tables)."""
    name = row["label"]
    solver = (row.get("options") or {}).get("solver")
    if solver and name == "Q1" and solver != "fft":
        name += f" {solver}"
    if row.get("scheme", "paper") != "paper":
        factor = row["dt"] / row["dt_ref"] if row.get("dt_ref") else None
        name += f" stabilized Δt×{factor:g}" if factor else " stabilized"
    return name


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="its own small 2D study (seconds)")
    ap.add_argument("--convergence", default=str(OUT / "convergence.json"),
                    help="the convergence study's results (full mode)")
    ap.add_argument("--out", default=str(OUT))
    args = ap.parse_args(argv)
    quick = args.quick or bool(os.environ.get("CI"))
    os.environ.setdefault("FEM_ADE_FFT_WORKERS", "1")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    conv = _convergence()
    t0 = time.perf_counter()
    if quick:
        spatial = conv._strip(conv.spatial(QUICK_SPATIAL, True))
        steady = None
        extra_plan = EXTRA_QUICK
    else:
        path = Path(args.convergence)
        if not path.is_file():
            raise SystemExit(f"cost.py: {path} not found: run studies/convergence.py first")
        data = json.loads(path.read_text())
        spatial, steady = data.get("spatial", {}), data.get("steady")
        extra_plan = EXTRA_FULL
    cached = out / ("cost.json" if not quick else "cost_quick.json")
    previous = json.loads(cached.read_text()) if cached.is_file() and not quick else {}
    scenes = {}
    from fem_ade.scenes import get_scene

    for name, r in spatial.items():
        dt0 = get_scene(name).dt
        rows = [dict(row, dt_ref=dt0) for row in r["rows"]]
        extra = previous.get("scenes", {}).get(name, {}).get("extra")
        if extra is None and name in extra_plan:
            extra = conv._strip(extra_runs(conv, name, extra_plan[name], r["steps"], r["ref_n"]))
        rows += [dict(row, dt_ref=dt0) for row in extra or []]
        curves: dict[str, list] = {}
        for row in rows:
            curves.setdefault(key(row), []).append((row["cpu_s"], row["errors"]["E"]))
        scenes[name] = {
            "steps": r["steps"], "ref_n": r["ref_n"], "extra": extra or [],
            "points": [{"curve": key(row), "n": row["n"], "cpu_s": row["cpu_s"],
                        "wall_s": row["wall_s"], "err_E": row["errors"]["E"]} for row in rows],
            "time_to": {c: {f"{t:g}": time_to(p, t) for t in TARGETS}
                        for c, p in sorted(curves.items())},
            "pareto": [{"cpu_s": t, "err_E": e,
                        "curve": next(key(row) for row in rows
                                      if row["cpu_s"] == t and row["errors"]["E"] == e)}
                       for t, e in pareto([p for c in curves.values() for p in c])]}
        cached.write_text(json.dumps({"scenes": scenes}, indent=1))
    steady_table = None
    if steady:
        curves = {}
        for row in steady["rows"]:
            curves.setdefault(row["label"], []).append((row.get("cpu_s", row["wall_s"]),
                                                        row["errors"]["E"]))
        steady_table = {"scene": steady["scene"],
                        "time_to": {c: {f"{t:g}": time_to(p, t) for t in TARGETS}
                                    for c, p in sorted(curves.items())},
                        "points": [{"curve": row["label"], "n": row["n"], "steps": row["steps"],
                                    "cpu_s": row.get("cpu_s", row["wall_s"]),
                                    "err_E": row["errors"]["E"]} for row in steady["rows"]]}
    from fem_ade.output import package_versions

    result = {"scenes": scenes, "steady": steady_table, "run_s": time.perf_counter() - t0,
              "machine": {"cores": os.cpu_count(), "versions": package_versions()}}
    cached.write_text(json.dumps(result, indent=1))
    report(result, out, quick)
    return result


def _fmt(t):
    return "—" if t is None else f"{t:.3g}"


def report(result: dict, out: Path, quick: bool) -> None:
    from matplotlib.figure import Figure

    suffix = "_quick" if quick else ""
    v = result["machine"]["versions"]
    lines = ["# What accuracy costs", "",
             f"Generated by `studies/cost.py` ({'quick' if quick else 'full'} mode; "
             f"{result['run_s']:.0f} s on {result['machine']['cores']} cores; numpy "
             f"{v.get('numpy')}, scipy {v.get('scipy')}, pyamg {v.get('pyamg')}, scikit-fem "
             f"{v.get('scikit-fem', v.get('skfem'))}). Times are CPU seconds (set-up "
             "included, one FFT thread); errors are relative errors in E against the fine "
             "spectral reference of `studies/convergence.py`.", ""]
    for name, s in result["scenes"].items():
        lines += [f"## {name}: transient ({s['steps']} steps of the paper's Δt, reference "
                  f"spectral n = {s['ref_n']})", "",
                  "CPU seconds to reach a relative error in E of:", "",
                  "| discretisation | 1 % | 0.1 % | 0.01 % |", "|---|---|---|---|"]
        for c, tt in s["time_to"].items():
            lines.append(f"| {c} | " + " | ".join(_fmt(tt[f"{t:g}"]) for t in TARGETS) + " |")
        lines += ["", "Pareto front (no other run is both cheaper and more accurate):", "",
                  "| CPU s | err E | discretisation |", "|---|---|---|"]
        lines += [f"| {p['cpu_s']:.3g} | {p['err_E']:.2e} | {p['curve']} |" for p in s["pareto"]]
        lines += ["", f"![error against time]({'cost-' + name + suffix + '.png'})", ""]
        fig = Figure(figsize=(6.4, 4.6), dpi=100)
        ax = fig.subplots()
        curves = sorted({p["curve"] for p in s["points"]})
        for c in curves:
            pts = sorted((p["cpu_s"], p["err_E"]) for p in s["points"] if p["curve"] == c)
            ax.loglog(*zip(*pts, strict=True), "o-" if "stabilized" not in c else "s--",
                      label=c, ms=4)
        front = [(p["cpu_s"], p["err_E"]) for p in s["pareto"]]
        ax.loglog(*zip(*front, strict=True), color="k", lw=2.5, alpha=0.25, label="Pareto front")
        for t in TARGETS:
            ax.axhline(t, color="0.7", lw=0.8, ls=":")
        ax.set(xlabel="CPU time (s)", ylabel="relative error in E",
               title=f"{name}: error against cost")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(out / f"cost-{name}{suffix}.png")
    st = result.get("steady")
    if st:
        lines += [f"## {st['scene']}: steady state (exact constraints, stabilized 100× Δt, "
                  "momentum)", "", "CPU seconds to reach a relative error in E of:", "",
                  "| discretisation | 1 % | 0.1 % | 0.01 % |", "|---|---|---|---|"]
        for c, tt in st["time_to"].items():
            lines.append(f"| {c} | " + " | ".join(_fmt(tt[f"{t:g}"]) for t in TARGETS) + " |")
        lines += ["", "| discretisation | n | steps | CPU s | err E |", "|---|---|---|---|---|"]
        lines += [f"| {p['curve']} | {p['n']} | {p['steps']} | {p['cpu_s']:.3g} | "
                  f"{p['err_E']:.2e} |" for p in st["points"]]
        lines.append("")
    (out / f"cost{suffix}.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
