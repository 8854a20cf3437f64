"""Convergence in space and in time, for transients and for steady shapes (issue 13).

* ``spatial``: for ``discocyte`` (ε = 0.04), ``torus`` (ε = 0.03) and ``three-arm``
  (ε = 0.02), every discretisation runs the paper's scheme at the paper's Δt for ``STEPS``
  steps from the same initial condition; the errors in E, W, G, V, A, ΔA and the L² error
  of φ (on the discretisation's own uniform grid, the reference resampled spectrally) are
  measured against a fine spectral reference at the same Δt — pure spatial error (SPEC §5).
  Rates are fitted over the levels whose node spacing is at most ε (coarser levels are
  pre-asymptotic: shown, not fitted). Discretisations: spectral, FEM Q1 on uniform meshes
  (its exact Fourier path), FEM Q1 on graded meshes (AMG), FEM Q2 (AMG).
* ``q2``: why the 3D Q2 error stalled (4.5e-4 at n = 24 and 32 in the first cost study):
  Q2 at the same levels with the products at quadrature points, and with the consistent
  mass, against the default (nodal products, lumped mass).
* ``steady``: ``discocyte`` to its steady state (exact constraints, stabilized scheme at
  100× Δt, momentum, until 1e-10) at every level of spectral and FEM Q1; errors in E, V, A
  and the shape descriptors against the finest spectral steady state.
* ``temporal``: the order in Δt of the paper's scheme and of the stabilized one, at a fixed
  time against the paper's scheme at Δt₀/8 on the same grid; and the stabilized scheme's
  slowdown: the time it takes to reach the energy the paper's scheme has at t = T.

Writes ``convergence.json`` (every run, with its wall time: ``studies/cost.py`` reads it),
``convergence.md`` and ``convergence-*.png`` into ``--out`` (default ``studies/results``).
The full run takes hours on 2 cores; ``--quick`` (the test suite) seconds.

    python studies/convergence.py [--parts spatial q2 steady temporal]
    python studies/convergence.py --quick --out /tmp/c
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parent / "results"
QUANTITIES = ("E", "W", "G", "V", "A", "dA")

FULL = {
    "steps": 50,
    "scenes": {
        "discocyte": {"ref": 128, "spectral": (24, 32, 48, 64, 96), "Q1": (24, 32, 48, 64, 96),
                      "Q1 graded": (32, 48, 64, 96), "Q2": (12, 16, 24, 32)},
        "torus": {"ref": 128, "spectral": (32, 48, 64, 96), "Q1": (32, 48, 64, 96),
                  "Q1 graded": (48, 64), "Q2": (16, 24, 32)},
        "three-arm": {"ref": 160, "spectral": (48, 64, 96, 128), "Q1": (48, 64, 96, 128),
                      "Q2": (24, 32, 40)},
    },
    "q2": {"scene": "discocyte", "ns": (12, 16, 24, 32)},
    "steady": {"scene": "discocyte", "ref": 96, "spectral": (32, 48, 64), "Q1": (32, 48, 64, 96)},
    "temporal": {"scene": "discocyte", "n": 32, "steps": 64, "factors": (8, 4, 2, 1),
                 "stabilized": (1, 4, 16, 64, 100)},
}
#: the quick mode runs the 2D teaching ellipse (seconds): the same code paths, 2D grids
QUICK = {
    "steps": 20,
    "scenes": {"ellipse-2d": {"ref": 128, "spectral": (32, 48), "Q1": (32, 48, 64),
                              "Q1 graded": (32, 48), "Q2": (16, 24, 32)}},
    "q2": {"scene": "ellipse-2d", "ns": (16, 24)},
    "steady": {"scene": "ellipse-2d", "ref": 96, "spectral": (32, 48), "Q1": (32, 48, 64)},
    "temporal": {"scene": "ellipse-2d", "n": 32, "steps": 16, "factors": (8, 4, 2, 1),
                 "stabilized": (1, 10)},
}

#: one colour per discretisation in every plot
COLOURS = {"spectral": "#d62728", "Q1": "#1f77b4", "Q1 graded": "#ff7f0e", "Q2": "#2ca02c",
           "Q2 quadrature": "#9467bd", "Q2 consistent": "#8c564b"}
#: discretisation label -> (backend, backend options, nodes per cell)
DISCRETISATIONS = {
    "spectral": ("spectral", {}, 1),
    "Q1": ("fem", {"solver": "fft"}, 1),
    "Q1 graded": ("fem", {"mesh": "graded", "solver": "amg"}, 1),
    "Q2": ("fem", {"order": 2, "solver": "amg"}, 2),
    "Q2 quadrature": ("fem", {"order": 2, "solver": "amg", "products": "quadrature"}, 2),
    "Q2 consistent": ("fem", {"order": 2, "solver": "amg", "mass": "consistent"}, 2),
}


def resample(phi: np.ndarray, m: int) -> np.ndarray:
    """A smooth periodic grid field (n,)*d on (m,)*d points by Fourier interpolation."""
    n, d = phi.shape[0], phi.ndim
    if m == n:
        return phi
    F = np.fft.fftn(phi)
    G = np.zeros((m,) * d, dtype=complex)
    k = min(n, m) // 2  # the modes |j| < min(n, m)/2 (negative ones counted from the end)
    idx = np.ix_(*[np.r_[0:k, -k + 1:0]] * d)
    G[idx] = F[idx]
    return np.real(np.fft.ifftn(G)) * (m / n) ** d


def run(scene, label: str, n: int, steps: int, *, scheme="paper", dt=None, **extra) -> dict:
    """One run: its final diagnostics, φ on its uniform grid, wall time (set-up included)."""
    from fem_ade.backend import make_backend
    from fem_ade.loop import run_loop

    backend, options, _ = DISCRETISATIONS[label]
    dt = scene.dt if dt is None else dt
    t0, c0 = time.perf_counter(), time.process_time()
    be = make_backend(backend, scene, n=n, scheme=scheme, **{**options, **extra})
    setup = time.perf_counter() - t0
    r = run_loop(be, dt=dt, steps=steps, every=steps)
    return {"label": label, "n": n, "wall_s": time.perf_counter() - t0, "setup_s": setup,
            "cpu_s": time.process_time() - c0, "scheme": scheme, "dt": dt, "steps": steps,
            "options": {**options, **extra},
            "final": {q: float(r.final[q]) for q in QUANTITIES}, "grid": np.array(be.grid_phi())}


def errors(row: dict, ref: dict, L: float) -> dict:
    """Relative errors of the diagnostics and the relative L² error of φ."""
    out = {}
    for q in QUANTITIES:
        scale = abs(ref["final"][q]) or 1.0
        out[q] = abs(row["final"][q] - ref["final"][q]) / scale
    g = row["grid"]
    r = resample(ref["grid"], g.shape[0])
    out["phi_L2"] = float(np.linalg.norm(g - r) / np.linalg.norm(r))
    return out


def fit(hs, errs, eps) -> float | None:
    """The slope of log(error) against log(h) over the levels with h ≤ ε (≥ 2 of them)."""
    pts = [(h, e) for h, e in zip(hs, errs, strict=True) if h <= eps * (1 + 1e-9) and e > 0]
    if len(pts) < 2:
        return None
    h, e = np.array(pts).T
    return float(np.polyfit(np.log(h), np.log(e), 1)[0])


def spatial(plan: dict, quick: bool) -> dict:
    from fem_ade.scenes import get_scene

    out = {}
    for name, levels in plan["scenes"].items():
        scene = get_scene(name)
        p = scene.params
        ref = run(scene, "spectral", levels["ref"], plan["steps"])
        rows = []
        for label, ns in levels.items():
            if label == "ref":
                continue
            for n in ns:
                row = run(scene, label, n, plan["steps"])
                h = p.L / (n * DISCRETISATIONS[label][2])
                row.update(h=h, errors=errors(row, ref, p.L))
                rows.append(row)
                print(f"  {name:10s} {label:10s} n={n:4d} h/eps={h / p.eps:5.2f} "
                      f"{row['wall_s']:7.1f} s  " + "  ".join(
                          f"{q} {row['errors'][q]:.2e}" for q in ("E", "V", "A", "phi_L2")),
                      flush=True)
        rates = {}
        for label in {r["label"] for r in rows}:
            sel = [r for r in rows if r["label"] == label]
            rates[label] = {q: fit([r["h"] for r in sel], [r["errors"][q] for r in sel], p.eps)
                            for q in (*QUANTITIES, "phi_L2")}
        out[name] = {"eps": p.eps, "steps": plan["steps"], "ref_n": levels["ref"],
                     "ref": ref["final"], "rows": rows, "rates": rates}
    return out


def q2_diagnosis(plan: dict) -> dict:
    """Q2 with nodal products and lumped mass (default), products at quadrature points, and
    the consistent mass: which one removes the 3D stall?"""
    from fem_ade.scenes import get_scene

    scene = get_scene(plan["q2"]["scene"])
    p = scene.params
    ref = run(scene, "spectral", 4 * max(plan["q2"]["ns"]), plan["steps"])
    rows = []
    for label in ("Q2", "Q2 quadrature", "Q2 consistent"):
        for n in plan["q2"]["ns"]:
            row = run(scene, label, n, plan["steps"])
            row.update(h=p.L / (2 * n), errors=errors(row, ref, p.L))
            rows.append(row)
            print(f"  q2: {label:14s} n={n:3d} E {row['errors']['E']:.2e} V "
                  f"{row['errors']['V']:.2e} A {row['errors']['A']:.2e} phi "
                  f"{row['errors']['phi_L2']:.2e} ({row['wall_s']:.0f} s)", flush=True)
    return {"scene": plan["q2"]["scene"], "ref_n": 4 * max(plan["q2"]["ns"]), "rows": rows}


def steady(plan: dict) -> dict:
    """Each level to its steady state; errors against the finest spectral steady state."""
    from fem_ade.runs import simulate
    from fem_ade.scenes import get_scene

    cfg = plan["steady"]
    scene = get_scene(cfg["scene"])

    def one(label, n):
        backend, options, _ = DISCRETISATIONS[label]
        t0, c0 = time.perf_counter(), time.process_time()
        r = simulate(scene, backend=backend, n=n, dt=100 * scene.dt, scheme="stabilized",
                     constraints="exact", accelerate=True, until_steady=1e-10, every=50,
                     max_steps=20000, backend_options=options, allow_underresolved=True,
                     out=None)
        sh = r.shape or {}
        return {"label": label, "n": n, "wall_s": time.perf_counter() - t0,
                "cpu_s": time.process_time() - c0, "steps": r.steps,
                "status": r.status, "final": {q: float(r.final[q]) for q in QUANTITIES},
                "shape": {k: sh.get(k) for k in ("label", "components", "genus",
                                                 "reduced_volume", "reduced_area_difference")}}

    ref = one("spectral", cfg["ref"])
    rows = []
    for label in ("spectral", "Q1"):
        for n in cfg[label]:
            row = one(label, n)
            row["errors"] = {q: abs(row["final"][q] - ref["final"][q]) / abs(ref["final"][q])
                             for q in ("E", "V", "A")}
            for k in ("reduced_volume", "reduced_area_difference"):
                if row["shape"][k] is not None and ref["shape"][k] is not None:
                    row["errors"][k] = abs(row["shape"][k] - ref["shape"][k])
            row["h"] = scene.params.L / n
            rows.append(row)
            print(f"  steady: {label:8s} n={n:3d} {row['status']} {row['steps']} steps "
                  f"E {row['errors']['E']:.2e} v {row['shape']['reduced_volume']} "
                  f"{row['shape']['label']} ({row['wall_s']:.0f} s)", flush=True)
    rates = {lab: {q: fit([r["h"] for r in rows if r["label"] == lab],
                          [r["errors"][q] for r in rows if r["label"] == lab],
                          scene.params.eps) for q in ("E", "V", "A")}
             for lab in ("spectral", "Q1")}
    return {"scene": cfg["scene"], "ref": ref, "rows": rows, "rates": rates}


def temporal(plan: dict) -> dict:
    """Order in Δt at t = T (T = steps × Δt₀), against the paper's scheme at Δt₀/8; and the
    stabilized scheme's slowdown."""
    from fem_ade.backend import make_backend
    from fem_ade.loop import run_loop
    from fem_ade.scenes import get_scene

    cfg = plan["temporal"]
    scene = get_scene(cfg["scene"])
    n, dt0, T = cfg["n"], scene.dt, cfg["steps"] * scene.dt

    def at_T(scheme, dt):
        be = make_backend("spectral", scene, n=n, scheme=scheme)
        steps = int(round(T / dt))
        r = run_loop(be, dt=dt, steps=steps, every=max(1, steps // 50))
        return r, np.array(be.grid_phi())

    ref, ref_phi = at_T("paper", dt0 / 8)
    rows = []
    for scheme, factors in (("paper", [1 / f for f in cfg["factors"][1:]] + [2.0]),
                            ("stabilized", cfg["stabilized"])):
        for f in factors:
            dt = dt0 * f
            if scheme == "paper" and dt >= scene.params.eps**3:
                continue
            r, phi = at_T(scheme, dt)
            err = {q: abs(r.final[q] - ref.final[q]) / abs(ref.final[q]) for q in ("E", "V", "A")}
            err["phi_L2"] = float(np.linalg.norm(phi - ref_phi) / np.linalg.norm(ref_phi))
            rows.append({"scheme": scheme, "dt": dt, "factor": f, "errors": err,
                         "E": float(r.final["E"]), "steps": r.steps})
            print(f"  temporal: {scheme:10s} dt = {f:g} dt0: E err {err['E']:.2e}, "
                  f"phi {err['phi_L2']:.2e}", flush=True)
    orders = {}
    for scheme in ("paper", "stabilized"):
        sel = [r for r in rows if r["scheme"] == scheme]
        if len(sel) >= 2:
            orders[scheme] = float(np.polyfit(np.log([r["dt"] for r in sel]),
                                              np.log([r["errors"]["phi_L2"] for r in sel]), 1)[0])
    # slowdown: how long the stabilized scheme takes to reach E_paper(T)
    target = ref.final["E"]

    class Reached(Exception):
        pass

    class Watch:  # a history writer that stops the run at the first row with E <= target
        hit = None

        def write(self, row):
            if row["E"] <= target:
                self.hit = row
                raise Reached

    slow = []
    for f in cfg["stabilized"]:
        be = make_backend("spectral", scene, n=n, scheme="stabilized")
        dt = f * dt0
        watch = Watch()
        try:
            run_loop(be, dt=dt, steps=int(200 * T / dt) + 1, every=1, history=watch)
        except Reached:
            pass
        hit = watch.hit
        s0 = be.stab[0] if be.stab else float("nan")
        entry = {"factor": f, "dt": dt, "s0": s0,
                 "t_reach": hit["t"] if hit else None,
                 "slowdown": hit["t"] / T if hit else None,
                 "predicted": (1.0 / dt + s0) * dt}
        slow.append(entry)
        print(f"  slowdown: stabilized dt = {f:g} dt0 reaches E_paper(T) at t = "
              f"{entry['t_reach']} ({entry['slowdown']}x T; 1 + s0 dt = "
              f"{entry['predicted']:.3g})", flush=True)
    return {"scene": cfg["scene"], "n": n, "T": T, "dt0": dt0, "rows": rows, "orders": orders,
            "slowdown": slow}


def _strip(obj):
    if isinstance(obj, dict):
        return {k: _strip(v) for k, v in obj.items() if k != "grid"}
    if isinstance(obj, list):
        return [_strip(v) for v in obj]
    return obj


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="seconds (the test suite)")
    ap.add_argument("--parts", nargs="*", default=["spatial", "q2", "steady", "temporal"])
    ap.add_argument("--out", default=str(OUT))
    ap.add_argument("--scenes", nargs="*", default=None,
                    help="the spatial part for these scenes only (the others' results kept)")
    args = ap.parse_args(argv)
    quick = args.quick or bool(os.environ.get("CI"))
    plan = QUICK if quick else FULL
    if args.scenes:
        unknown = set(args.scenes) - set(plan["scenes"])
        if unknown:
            ap.error(f"no spatial study of {', '.join(sorted(unknown))}; "
                     f"choose from {', '.join(plan['scenes'])}")
        plan = {**plan, "scenes": {k: v for k, v in plan["scenes"].items()
                                   if k in args.scenes}}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    name = "convergence_quick.json" if quick else "convergence.json"
    path = out / name
    results = json.loads(path.read_text()) if path.is_file() and not quick else {}
    t0 = time.perf_counter()
    for part, fn in (("spatial", lambda: spatial(plan, quick)), ("q2", lambda: q2_diagnosis(plan)),
                     ("steady", lambda: steady(plan)), ("temporal", lambda: temporal(plan))):
        if part in args.parts:
            print(f"{part}:", flush=True)
            t1 = time.perf_counter()
            new = _strip(fn())
            results[part] = ({**results.get(part, {}), **new} if part == "spatial" else new)
            results.setdefault("part_s", {})[part] = time.perf_counter() - t1
            path.write_text(json.dumps(results, indent=1))  # resumable by part
    results["run_s"] = sum(results.get("part_s", {}).values()) or time.perf_counter() - t0
    from fem_ade.output import package_versions

    results["machine"] = {"cores": os.cpu_count(), "versions": package_versions()}
    path.write_text(json.dumps(results, indent=1))
    report(results, out, quick)
    return results


def report(results: dict, out: Path, quick: bool) -> None:
    """convergence.md and the error-against-h plots."""
    from matplotlib.figure import Figure

    lines = ["# Convergence in space and in time", "",
             f"Generated by `studies/convergence.py` ({'quick' if quick else 'full'} mode; "
             f"{results.get('run_s', 0):.0f} s on {results['machine']['cores']} cores; "
             f"numpy {results['machine']['versions'].get('numpy')}, scipy "
             f"{results['machine']['versions'].get('scipy')}, pyamg "
             f"{results['machine']['versions'].get('pyamg')}). Errors are relative; rates are "
             "fitted over the levels with node spacing h ≤ ε.", ""]
    sp = results.get("spatial", {})
    for name, r in sp.items():
        lines += [f"## {name}: the paper's scheme, {r['steps']} steps, against spectral "
                  f"n = {r['ref_n']} (ε = {r['eps']})", "",
                  "| discretisation | n | h/ε | wall s | " + " | ".join(
                      f"err {q}" for q in (*QUANTITIES, "phi_L2")) + " |",
                  "|---|---|---|---|" + "---|" * (len(QUANTITIES) + 1)]
        for row in r["rows"]:
            lines.append(f"| {row['label']} | {row['n']} | {row['h'] / r['eps']:.2f} | "
                         f"{row['wall_s']:.1f} | " + " | ".join(
                             f"{row['errors'][q]:.2e}" for q in (*QUANTITIES, "phi_L2")) + " |")
        lines += ["", "Observed rates (h ≤ ε):", "",
                  "| discretisation | " + " | ".join((*QUANTITIES, "phi_L2")) + " |",
                  "|---|" + "---|" * (len(QUANTITIES) + 1)]
        for label, rates in sorted(r["rates"].items()):
            lines.append(f"| {label} | " + " | ".join(
                f"{rates[q]:.2f}" if rates[q] is not None else "—"
                for q in (*QUANTITIES, "phi_L2")) + " |")
        lines.append("")
    if "q2" in results:
        lines += [f"## Q2: what limits it ({results['q2'].get('scene', '')})", "",
                  "| variant | n | err E | err V | err A | err φ |", "|---|---|---|---|---|---|"]
        for row in results["q2"]["rows"]:
            e = row["errors"]
            lines.append(f"| {row['label']} | {row['n']} | {e['E']:.2e} | {e['V']:.2e} | "
                         f"{e['A']:.2e} | {e['phi_L2']:.2e} |")
        lines.append("")
    if "steady" in results:
        st = results["steady"]
        lines += [f"## Steady state of {st['scene']} (exact constraints, stabilized 100× Δt, "
                  f"momentum, until 1e-10), against spectral n = {st['ref']['n']}", "",
                  f"Reference: E = {st['ref']['final']['E']:.8g}, {st['ref']['shape']['label']},"
                  f" v = {st['ref']['shape']['reduced_volume']}", "",
                  "| discretisation | n | steps | wall s | label | err E | err V | err A | "
                  "Δv | Δ(Δa) |", "|---|---|---|---|---|---|---|---|---|---|"]
        for row in st["rows"]:
            e = row["errors"]
            lines.append(f"| {row['label']} | {row['n']} | {row['steps']} | {row['wall_s']:.0f}"
                         f" | {row['shape']['label']} | {e['E']:.2e} | {e['V']:.2e} | "
                         f"{e['A']:.2e} | {e.get('reduced_volume', float('nan')):.2e} | "
                         f"{e.get('reduced_area_difference', float('nan')):.2e} |")
        lines += ["", "Rates: " + "; ".join(
            f"{lab}: " + ", ".join(f"{q} {v:.2f}" for q, v in rates.items() if v is not None)
            for lab, rates in st["rates"].items()), ""]
    if "temporal" in results:
        tm = results["temporal"]
        lines += [f"## Time: {tm['scene']}, spectral n = {tm['n']}, t = T = {tm['T']:.3g}, "
                  f"against the paper's scheme at Δt₀/8 (Δt₀ = {tm['dt0']:g})", "",
                  "| scheme | Δt/Δt₀ | err E | err V | err A | err φ |",
                  "|---|---|---|---|---|---|"]
        for row in tm["rows"]:
            e = row["errors"]
            lines.append(f"| {row['scheme']} | {row['factor']:g} | {e['E']:.2e} | {e['V']:.2e}"
                         f" | {e['A']:.2e} | {e['phi_L2']:.2e} |")
        lines += ["", "Orders (slope of err φ against Δt): " + ", ".join(
            f"{k} {v:.2f}" for k, v in tm["orders"].items()), "",
                  "The stabilized scheme's slowdown: the time it needs to reach the energy the "
                  "paper's scheme has at T, over T; beside it (1/Δt + s₀)Δt, the factor by "
                  "which s₀ slows the slow modes:", "",
                  "| Δt/Δt₀ | s₀ | t to E_paper(T) / T | (1/Δt + s₀)Δt |", "|---|---|---|---|"]
        for s in tm["slowdown"]:
            reached = "not reached" if s["slowdown"] is None else f"{s['slowdown']:.3g}"
            lines.append(f"| {s['factor']:g} | {s['s0']:.3g} | {reached} | "
                         f"{s['predicted']:.3g} |")
        lines.append("")
    notes = out / "convergence_notes.md"
    if notes.is_file() and not quick:
        lines += [notes.read_text()]
    if sp:
        fig = Figure(figsize=(5.0 * len(sp), 4.2), dpi=100)
        axes = fig.subplots(1, len(sp), squeeze=False)[0]
        for ax, (name, r) in zip(axes, sp.items(), strict=True):
            for label in sorted({row["label"] for row in r["rows"]}):
                sel = [row for row in r["rows"] if row["label"] == label]
                ax.loglog([row["h"] / r["eps"] for row in sel],
                          [max(row["errors"]["E"], 1e-16) for row in sel], "o-", label=label,
                          color=COLOURS.get(label))
            ax.axvline(1.0, color="0.6", ls=":", lw=1)
            ax.set(xlabel="node spacing h / ε", ylabel="relative error in E", title=name)
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(out / ("convergence_quick.png" if quick else "convergence.png"))
        png = "convergence_quick.png" if quick else "convergence.png"
        lines += [f"![error in E against h]({png})"]
    (out / ("convergence_quick.md" if quick else "convergence.md")).write_text(
        "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
