"""What each digit of accuracy costs: CPU time against the error in E, for every
discretisation of ``studies/convergence.py`` (issue 21).

Reads ``convergence.json`` — every run of the spatial study (scene × start × discretisation ×
level) with its errors, its CPU seconds (set-up and loop, one thread) and the command that
repeats it — and writes

* ``cost.json``: one entry per run, ``{"scene", "start", "method", "order", "mesh", "n",
  "nodes", "cpu_s", "E_err", "V_err", "A_err", "command"}`` (errors relative, unsigned), and
  per (scene, start) the time to each accuracy of every discretisation and the Pareto front;
* ``cost.md``: the tables — CPU seconds to reach 1e-2, 1e-3, 1e-4, 1e-5 in E, the best FEM
  against the spectral reference at each accuracy — and the steady-state table;
* ``cost-SCENE-START.png``: error in E against CPU time, every point, the Pareto front drawn.

Time to an accuracy is interpolated (log–log) along each discretisation's measured points in
order of cost, never extrapolated ("—": no measured level reached it); a dearer level never
counts as worse than a cheaper one of the same discretisation did (the error of a transient
is not monotone in the resolution).

    python studies/cost.py                        # needs convergence.json (full mode)
    python studies/cost.py --quick --out /tmp/c   # its own quick 2D convergence (seconds)
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time
from pathlib import Path

from _lib.fits import time_to
from _lib.style import COLOURS
from fem_ade.plots.figures import save_figure

OUT = Path("runs") / "studies"  # the committed results: --out studies/results
TARGETS = (1e-2, 1e-3, 1e-4, 1e-5)


def pareto(points: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """The points no other point beats in both time and error, in order of time."""
    front, best = [], math.inf
    for t, e in sorted(points):
        if e < best:
            front.append((t, e))
            best = e
    return front


def entries(spatial: dict) -> list[dict]:
    """cost.json's runs: one per (scene, start, discretisation, level)."""
    out = []
    for scene, r in spatial.items():
        for start, s in r["starts"].items():
            for row in s["rows"]:
                e = row["errors"]
                out.append({"scene": scene, "start": start, "label": row["label"],
                            "method": row["method"], "order": row["order"],
                            "mesh": row["mesh"], "n": row["n"], "nodes": row["nodes"],
                            "cpu_s": row["cpu_s"], "E_err": abs(e["E"]), "V_err": abs(e["V"]),
                            "A_err": abs(e["A"]), "command": row["command"]})
    return out


def summarize(runs: list[dict]) -> dict:
    """Per (scene, start): time to each target per discretisation, the best FEM against the
    spectral reference, the Pareto front."""
    out = {}
    for key in dict.fromkeys((r["scene"], r["start"]) for r in runs):
        sel = [r for r in runs if (r["scene"], r["start"]) == key]
        curves: dict[str, list] = {}
        for r in sel:
            curves.setdefault(r["label"], []).append((r["cpu_s"], r["E_err"]))
        tt = {c: {f"{t:g}": time_to(p, t) for t in TARGETS} for c, p in curves.items()}
        best = {}
        for t in TARGETS:
            spec = tt.get("spectral", {}).get(f"{t:g}")
            fem = [(v[f"{t:g}"], c) for c, v in tt.items()
                   if c != "spectral" and v[f"{t:g}"] is not None]
            b = min(fem) if fem else (None, None)
            best[f"{t:g}"] = {"spectral_s": spec, "fem_s": b[0], "fem": b[1],
                              "ratio": b[0] / spec if b[0] is not None and spec else None}
        front = [{"cpu_s": t, "E_err": e,
                  "label": next(r["label"] for r in sel if r["cpu_s"] == t and r["E_err"] == e)}
                 for t, e in pareto([p for c in curves.values() for p in c])]
        out[f"{key[0]}/{key[1]}"] = {"time_to": tt, "best_fem": best, "pareto": front}
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="its own quick 2D study (seconds)")
    ap.add_argument("--convergence", default=None,
                    help="the convergence study's results (default: OUT/convergence.json)")
    ap.add_argument("--out", default=str(OUT))
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    if args.quick:  # the convergence study's quick spatial part first, as a script
        subprocess.run([sys.executable, str(Path(__file__).with_name("convergence.py")),
                        "--quick", "--parts", "spatial", "--out", str(out)], check=True)
        data = json.loads((out / "convergence_quick.json").read_text())
    else:
        path = Path(args.convergence) if args.convergence else out / "convergence.json"
        if not path.is_file():
            raise SystemExit(f"cost.py: {path} not found: run studies/convergence.py first")
        data = json.loads(path.read_text())
    runs = entries(data.get("spatial", {}))
    steady = data.get("steady")
    result = {"runs": runs, "summary": summarize(runs), "steady": steady_table(steady),
              "run_s": time.perf_counter() - t0, "machine": data.get("machine")}
    suffix = "_quick" if args.quick else ""
    (out / f"cost{suffix}.json").write_text(json.dumps(result, separators=(",", ":")) + "\n")
    report(result, out, suffix)
    return result


def steady_table(steady: dict | None) -> dict | None:
    if not steady:
        return None
    curves: dict[str, list] = {}
    for row in steady["rows"]:
        curves.setdefault(row["label"], []).append((row["cpu_s"], row["errors"]["E"]))
    return {"scene": steady["scene"],
            "time_to": {c: {f"{t:g}": time_to(p, t) for t in TARGETS} for c, p in curves.items()},
            "points": [{"label": row["label"], "n": row["n"], "nodes": row["nodes"],
                        "steps": row["steps"], "cpu_s": row["cpu_s"],
                        "E_err": row["errors"]["E"], "command": row["command"]}
                       for row in steady["rows"]]}


def _fmt(t):
    return "—" if t is None else f"{t:.3g}"


def report(result: dict, out: Path, suffix: str) -> None:
    """Write ``OUT/cost{suffix}.md`` — a section per (scene, start) with its figure, the
    steady state's, the axisymmetric geometry's from axisymmetric.md — and the figures."""
    machine = result.get("machine") or {}
    v = machine.get("versions", {})
    lines = ["# What accuracy costs", "",
             f"Generated by `studies/cost.py` from `convergence{suffix}.json` (numpy "
             f"{v.get('numpy')}, scipy {v.get('scipy')}; {machine.get('cores')} cores). Times "
             "are CPU seconds of one thread (set-up and loop); errors are relative errors in E "
             "against the fine spectral reference. `pP`: the FEM of order P (GLL nodes, exact "
             "fast-diagonalization solve). Each run's command is in `cost.json`.", ""]
    for key, s in result["summary"].items():
        scene, start = key.split("/")
        png = f"cost-{scene}-{start}{suffix}.png"
        lines += _start_section(scene, start, s, png)
        _plot([r for r in result["runs"] if (r["scene"], r["start"]) == (scene, start)],
              s["pareto"], f"{scene}, {start} start: error against cost", out / png)
    if result.get("steady"):
        lines += _steady_section(result["steady"])
    if not suffix:
        lines += _axisymmetric_section(out)
    notes = out / "cost_notes.md"
    if notes.is_file() and not suffix:
        lines += [notes.read_text()]
    (out / f"cost{suffix}.md").write_text("\n".join(lines) + "\n")


def _time_to_table(time_to: dict) -> list[str]:
    """CPU seconds of each discretisation to reach each target error in E."""
    return ["| discretisation | " + " | ".join(f"{t:g}" for t in TARGETS) + " |",
            "|---|" + "---|" * len(TARGETS)] + [
        f"| {c} | " + " | ".join(_fmt(tt[f"{t:g}"]) for t in TARGETS) + " |"
        for c, tt in time_to.items()]


def _start_section(scene: str, start: str, s: dict, png: str) -> list[str]:
    """The section of one scene and start: the time to each accuracy, the best FEM against
    the spectral reference, the Pareto front and its figure."""
    what = "the paper's initial condition" if start == "paper" else "a resolved start"
    lines = [f"## {scene} from {what}", "", "CPU seconds to reach a relative error in E of:",
             "", *_time_to_table(s["time_to"])]
    lines += ["", "The best FEM against the spectral reference:", "",
              "| error in E | spectral s | best FEM s | which | FEM / spectral |",
              "|---|---|---|---|---|"]
    for t in TARGETS:
        b = s["best_fem"][f"{t:g}"]
        lines.append(f"| {t:g} | {_fmt(b['spectral_s'])} | {_fmt(b['fem_s'])} | "
                     f"{b['fem'] or '—'} | {_fmt(b['ratio'])} |")
    lines += ["", "Pareto front (no other run is both cheaper and more accurate):", "",
              "| CPU s | err E | discretisation |", "|---|---|---|"]
    lines += [f"| {p['cpu_s']:.3g} | {p['E_err']:.2e} | {p['label']} |" for p in s["pareto"]]
    return lines + ["", f"![error against time]({png})", ""]


def _steady_section(st: dict) -> list[str]:
    """The steady state's section: the time to each accuracy and every run."""
    lines = [f"## {st['scene']}: steady state (exact constraints, stabilized 100× Δt, "
             "momentum)", "", "CPU seconds to reach a relative error in E of:", "",
             *_time_to_table(st["time_to"])]
    lines += ["", "| discretisation | n | nodes | steps | CPU s | err E |",
              "|---|---|---|---|---|---|"]
    lines += [f"| {p['label']} | {p['n']} | {p['nodes']} | {p['steps']} | "
              f"{p['cpu_s']:.3g} | {p['E_err']:.2e} |" for p in st["points"]]
    return lines + [""]


def _axisymmetric_section(out: Path) -> list[str]:
    """The axisymmetric geometry's cost, copied from axisymmetric.md's section "What a steady
    state costs" (its own study); nothing without it."""
    axi = out / "axisymmetric.md"
    if not axi.is_file():
        return []
    text = axi.read_text()
    start = text.find("## What a steady state costs")
    if start < 0:
        return []
    end = text.find("\n## ", start + 3)
    section = text[start:] if end < 0 else text[start:end]
    return ["## The axisymmetric geometry against 3D (from `axisymmetric.md`, "
            "written by `studies/axisymmetric.py`)", "",
            section.split("\n", 1)[1].strip(), ""]


def _plot(runs, front, title, path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.6, 4.8), dpi=110)
    ax = fig.subplots()
    for label in dict.fromkeys(r["label"] for r in runs):
        pts = sorted((r["cpu_s"], max(r["E_err"], 1e-16)) for r in runs if r["label"] == label)
        ax.loglog(*zip(*pts, strict=True), "o-" if "graded" not in label else "s--",
                  label=label, ms=4, lw=1.4, color=COLOURS.get(label))
    pts = [(p["cpu_s"], max(p["E_err"], 1e-16)) for p in front]
    ax.loglog(*zip(*pts, strict=True), color="k", lw=5, alpha=0.18, label="Pareto front")
    for t in TARGETS:
        ax.axhline(t, color="0.7", lw=0.8, ls=":")
    ax.set(xlabel="CPU seconds (one thread)", ylabel="|relative error in E|", title=title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    save_figure(fig, path, colours=64)


if __name__ == "__main__":
    main()
