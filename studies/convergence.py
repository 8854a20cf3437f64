"""Convergence in space and in time: the spectral-element FEM of every order against the
spectral reference, from the paper's initial condition and from a resolved start (issue 21).

* ``spatial``: for ``discocyte`` (ε = 0.04) and ``three-arm`` (ε = 0.02), every
  discretisation runs the paper's scheme at the paper's Δt for ``steps`` steps, at the same
  Δt as a fine spectral reference — the difference is pure spatial error — from two starts:

  - ``paper``: the paper's initial ellipsoid, whose interface is about 2.2× thinner than the
    equilibrium profile (E falls from 312 to 40 in the discocyte's 50 steps): a hard
    transient, whose error depends on where the nodes fall in the layer;
  - ``resolved``: the reference's own state after ``start`` steps of the paper's recipe (a
    run folder, moved onto each discretisation's nodes by its Fourier series: the same
    smooth field to round-off), then ``steps`` steps more.

  Discretisations: spectral; the FEM of order p = 1, 2, 3, 4, 6, 8 on uniform meshes (exact
  fast-diagonalization solves), p = 1 and 4 on graded meshes. Levels are nodes per axis
  (n = nodes / p cells). Errors in E, W, G, V, A, ΔA (relative, signed in the JSON) and the
  relative L² error of φ on the discretisation's uniform grid (the reference resampled
  spectrally); rates fitted over the levels whose node spacing is at most ε.
* ``steady``: ``discocyte`` to its steady state (exact constraints, stabilized scheme at
  100× Δt, momentum, until 1e-10) at several levels of spectral, p = 1 and p = 4; errors
  against the finest spectral steady state.
* ``temporal``: the order in Δt of the paper's scheme and of the stabilized one (spectral),
  and the stabilized scheme's slowdown.

Every run goes through :func:`fem_ade.engine.runs.simulate` — the command line's API — and its row
carries the exact ``python -m fem_ade.run ...`` line that repeats it, its CPU seconds (set-up
and loop) and wall time. Times are one thread: this script sets ``OPENBLAS_NUM_THREADS=1`` and
``FEM_ADE_FFT_WORKERS=1`` unless they are set. ``studies/cost.py`` reads the rows.

Writes ``convergence.json``, ``convergence.md`` and ``convergence-*.png`` into ``--out``
(default ``runs/studies``; the committed results: ``--out studies/results``), the start
folders under ``--runs`` (default ``runs/convergence``). The full run takes about an hour
on 2 cores; ``--quick`` (the test suite) seconds.

    python studies/convergence.py [--parts spatial steady temporal] [--scenes discocyte]
    python studies/convergence.py --quick --out /tmp/c
"""

from __future__ import annotations

import os

from _lib.cli import one_thread

one_thread()  # one thread: CPU seconds compare

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from _lib.style import COLOURS  # noqa: E402
from fem_ade.plots.figures import save_figure  # noqa: E402

OUT = Path("runs") / "studies"  # the committed results: --out studies/results
QUANTITIES = ("E", "W", "G", "V", "A", "dA")

#: discretisation -> (backend, options)
METHODS = {
    "spectral": ("spectral", {}),
    **{f"p{p}": ("fem", {"order": p}) for p in (1, 2, 3, 4, 6, 8)},
    "p1 graded": ("fem", {"order": 1, "mesh": "graded"}),
    "p4 graded": ("fem", {"order": 4, "mesh": "graded"}),
    "p4 amg": ("fem", {"order": 4, "solver": "amg"}),
    # graded meshes refined at the box centre, where the paper's vesicles sit (the "graded"
    # part: where does grading pay?)
    **{f"p4 centred {g}": ("fem", {"order": 4, "mesh": f"graded:{g}@0.5"})
       for g in (0.3, 0.5, 0.7)},
}
#: the largest node count per axis a discretisation runs at (the iterative path: its cost
#: is shown, its error is p4's)
MAX_NODES = {"p4 amg": 64}

FULL = {
    "scenes": {
        "discocyte": {"ref": 128, "start": 50, "steps": 50,
                      "nodes": (24, 32, 40, 48, 64, 72, 80, 96)},
        "three-arm": {"ref": 192, "start": 50, "steps": 50,
                      "nodes": (48, 64, 72, 80, 96, 128)},
    },
    "methods": ("spectral", "p1", "p2", "p3", "p4", "p6", "p8", "p1 graded", "p4 graded",
                "p4 amg"),
    "graded": {
        "scenes": {
            "discocyte": {"ref": 128, "start": 50, "steps": 50, "nodes": (32, 48, 64, 96)},
            "chain": {"ref": 192, "start": 50, "steps": 50, "nodes": (48, 64, 96, 128)},
        },
        "methods": ("p4", "p4 graded", "p4 centred 0.3", "p4 centred 0.5", "p4 centred 0.7"),
    },
    "steady": {"scene": "discocyte", "ref": 96, "levels": {"spectral": (32, 48, 64),
                                                           "p1": (32, 48, 64, 96),
                                                           "p4": (24, 32, 48, 64)}},
    "temporal": {"scene": "discocyte", "n": 32, "steps": 64, "factors": (8, 4, 2, 1),
                 "stabilized": (1, 4, 16, 64, 100)},
}
#: the quick mode runs the 2D teaching ellipse (seconds): the same code paths, 2D grids
QUICK = {
    "scenes": {"ellipse-2d": {"ref": 192, "start": 20, "steps": 20,
                              "nodes": (32, 48, 64, 96)}},
    "methods": ("spectral", "p1", "p2", "p4", "p4 graded", "p4 amg"),
    "graded": {"scenes": {"ellipse-2d": {"ref": 192, "start": 20, "steps": 20,
                                         "nodes": (32, 48)}},
               "methods": ("p4", "p4 centred 0.5")},
    "steady": {"scene": "ellipse-2d", "ref": 96, "levels": {"spectral": (32, 48),
                                                            "p1": (32, 48, 64),
                                                            "p4": (32, 48)}},
    "temporal": {"scene": "ellipse-2d", "n": 32, "steps": 16, "factors": (8, 4, 2, 1),
                 "stabilized": (1, 10)},
}


#: the archive's JSON without spaces or indents (a third fewer bytes; `python -m json.tool`
#: shows it indented)
COMPACT = (",", ":")


def order_of(label: str) -> int:
    return METHODS[label][1].get("order", 1)


def levels(label: str, nodes) -> list[int]:
    """The cell counts n of a discretisation: the node counts divisible by its order, ≥ 3
    cells."""
    p = order_of(label)
    top = MAX_NODES.get(label, max(nodes))
    return [N // p for N in nodes if N % p == 0 and N // p >= 3 and N <= top]


def command(scene: str, label: str, n: int, steps: int, phi0: str | None = None,
            extra: tuple = ()) -> str:
    """The command line that repeats a run."""
    backend, options = METHODS[label]
    parts = ["python -m fem_ade.run", scene, "--backend", backend]
    for key, value in options.items():
        parts += [f"--{key}", str(value)]
    parts += ["--n", str(n * order_of(label)), "--steps", str(steps), "--every", str(steps)]
    if phi0:
        parts += ["--phi0", phi0]
    parts += [*extra, "--allow-underresolved", "--no-render", "--quiet"]
    return " ".join(parts)


def resample(phi: np.ndarray, m: int) -> np.ndarray:
    """A periodic grid field (n,)*d onto (m,)*d points by its Fourier series."""
    from fem_ade.scenes.fields import resample_fourier

    if phi.shape[0] == m:
        return phi
    x = np.arange(m) / m
    return resample_fourier(phi, 1.0, [x] * phi.ndim)


#: each run is repeated this many times and its least CPU time kept (set by main)
REPEATS = 1


def run(scene, label: str, n: int, steps: int, *, phi0: str | None = None, out=None) -> dict:
    """One run through the command line's API: final diagnostics, φ on its uniform grid,
    CPU (set-up + loop; the least of :data:`REPEATS` runs) and wall seconds."""
    from fem_ade.engine.runs import simulate

    backend, options = METHODS[label]
    t0 = time.perf_counter()
    cpu = []
    for _ in range(REPEATS if out is None else 1):
        r = simulate(scene, backend=backend, n=n * order_of(label), steps=steps, every=steps,
                     phi0=phi0,
                     backend_options=dict(options), allow_underresolved=True, render=False,
                     out=out, force=out is not None)
        cpu.append(r.cpu_s + r.setup_cpu_s)
    p = order_of(label)
    return {"label": label, "method": backend, "order": p if backend == "fem" else None,
            "mesh": options.get("mesh", "uniform"), "n": n,
            "nodes": n * (p if backend == "fem" else 1),
            "cpu_s": min(cpu), "loop_cpu_s": r.cpu_s, "wall_s":
            (time.perf_counter() - t0) / len(cpu), "steps": steps, "status": r.status,
            "final": {q: float(r.final[q]) for q in QUANTITIES},
            "grid": np.asarray(r.final_grid)}


def errors(row: dict, ref: dict) -> dict:
    """Signed relative errors of the diagnostics and the relative L² error of φ."""
    out = {}
    for q in QUANTITIES:
        scale = abs(ref["final"][q]) or 1.0
        out[q] = (row["final"][q] - ref["final"][q]) / scale
    g = row["grid"]
    r = resample(ref["grid"], g.shape[0])
    out["phi_L2"] = float(np.linalg.norm(g - r) / np.linalg.norm(r))
    return out


def fit(hs, errs, eps) -> float | None:
    """The slope of log|error| against log(h) over the levels with h ≤ ε (≥ 2 of them)."""
    pts = [(h, abs(e)) for h, e in zip(hs, errs, strict=True)
           if h <= eps * (1 + 1e-9) and e != 0]
    if len(pts) < 2:
        return None
    h, e = np.array(pts).T
    return float(np.polyfit(np.log(h), np.log(e), 1)[0])


def spatial(plan: dict, runs: Path) -> dict:
    """Every discretisation of ``plan["methods"]`` at every level, from both starts, against
    the spectral reference."""
    from fem_ade.scenes.catalogue import get_scene

    out = {}
    for name, cfg in plan["scenes"].items():
        scene = get_scene(name)
        p = scene.params
        start_dir = runs / f"{name}-start-{cfg['start']}"
        # the resolved start: the reference's state after cfg["start"] steps (a run folder)
        run(scene, "spectral", cfg["ref"], cfg["start"], out=start_dir)
        start_cmd = (command(name, "spectral", cfg["ref"], cfg["start"]).replace(
            " --allow-underresolved", "") + f" --out {start_dir}")
        out[name] = {"eps": p.eps, "steps": cfg["steps"], "ref_n": cfg["ref"],
                     "start_steps": cfg["start"], "start_command": start_cmd, "starts": {}}
        for start, phi0 in (("paper", None), ("resolved", str(start_dir))):
            ref = run(scene, "spectral", cfg["ref"], cfg["steps"], phi0=phi0)
            rows = []
            for label in plan["methods"]:
                for n in levels(label, cfg["nodes"]):
                    if label == "spectral" and n >= cfg["ref"]:
                        continue
                    row = run(scene, label, n, cfg["steps"], phi0=phi0)
                    row["h"] = p.L / row["nodes"]
                    row["errors"] = errors(row, ref)
                    row["command"] = command(name, label, n, cfg["steps"], phi0)
                    rows.append(row)
                    e = row["errors"]
                    print(f"  {name:10s} {start:8s} {label:9s} n={n:3d} nodes={row['nodes']:3d}"
                          f" cpu {row['cpu_s']:6.2f} s  E {e['E']:+.2e} V {e['V']:+.2e} "
                          f"A {e['A']:+.2e} phi {e['phi_L2']:.2e}", flush=True)
            rates = {}
            for label in dict.fromkeys(r["label"] for r in rows):
                sel = [r for r in rows if r["label"] == label]
                rates[label] = {q: fit([r["h"] for r in sel], [r["errors"][q] for r in sel],
                                       p.eps) for q in (*QUANTITIES, "phi_L2")}
            out[name]["starts"][start] = {"ref": ref["final"], "ref_cpu_s": ref["cpu_s"],
                                          "ref_command": command(name, "spectral", cfg["ref"],
                                                                 cfg["steps"], phi0),
                                          "rows": rows, "rates": rates}
    return out


def steady(plan: dict) -> dict:
    """Each level to its steady state; errors against the finest spectral steady state."""
    from fem_ade.engine.runs import simulate
    from fem_ade.scenes.catalogue import get_scene

    cfg = plan["steady"]
    scene = get_scene(cfg["scene"])
    extra = ("--recipe", "steady", "--until-steady", "1e-10")

    def one(label, n):
        backend, options = METHODS[label]
        t0 = time.perf_counter()
        r = simulate(scene, backend=backend, n=n * order_of(label), dt=100 * scene.dt,
                     scheme="stabilized", constraints="exact", accelerate=True,
                     until_steady=1e-10, every=50,
                     max_steps=20000, backend_options=dict(options), allow_underresolved=True,
                     out=None, render=False)
        sh = r.shape or {}
        p = order_of(label) if backend == "fem" else 1
        cmd = command(cfg["scene"], label, n, 0, extra=extra).replace(
            " --steps 0 --every 0", " --every 50")
        return {"label": label, "n": n, "nodes": n * p, "wall_s": time.perf_counter() - t0,
                "cpu_s": r.cpu_s + r.setup_cpu_s, "steps": r.steps, "status": r.status,
                "final": {q: float(r.final[q]) for q in QUANTITIES}, "command": cmd,
                "shape": {k: sh.get(k) for k in ("label", "components", "genus",
                                                 "reduced_volume", "reduced_area_difference")}}

    ref = one("spectral", cfg["ref"])
    rows = []
    for label, nodes in cfg["levels"].items():
        for n in levels(label, nodes):
            row = one(label, n)
            row["errors"] = {q: abs(row["final"][q] - ref["final"][q]) / abs(ref["final"][q])
                             for q in ("E", "V", "A")}
            for k in ("reduced_volume", "reduced_area_difference"):
                if row["shape"][k] is not None and ref["shape"][k] is not None:
                    row["errors"][k] = abs(row["shape"][k] - ref["shape"][k])
            row["h"] = scene.params.L / row["nodes"]
            rows.append(row)
            print(f"  steady: {label:8s} nodes={row['nodes']:3d} {row['status']} "
                  f"{row['steps']} steps E {row['errors']['E']:.2e} v "
                  f"{row['shape']['reduced_volume']} {row['shape']['label']} "
                  f"({row['cpu_s']:.0f} s)", flush=True)
    rates = {lab: {q: fit([r["h"] for r in rows if r["label"] == lab],
                          [r["errors"][q] for r in rows if r["label"] == lab],
                          scene.params.eps) for q in ("E", "V", "A")}
             for lab in cfg["levels"]}
    return {"scene": cfg["scene"], "ref": ref, "rows": rows, "rates": rates}


def temporal(plan: dict) -> dict:
    """Order in Δt at t = T (T = steps × Δt₀), against the paper's scheme at Δt₀/8; and the
    stabilized scheme's slowdown (spectral: the time error is the same on every backend)."""
    from fem_ade.scenes.catalogue import get_scene

    cfg = plan["temporal"]
    scene = get_scene(cfg["scene"])
    n, dt0, T = cfg["n"], scene.dt, cfg["steps"] * scene.dt
    ref, ref_phi = _run_to(scene, n, "paper", dt0 / 8, T)
    rows = _temporal_rows(scene, n, T, cfg, ref, ref_phi)
    orders = {}
    for scheme in ("paper", "stabilized"):
        sel = [r for r in rows if r["scheme"] == scheme]
        if len(sel) >= 2:
            orders[scheme] = float(np.polyfit(np.log([r["dt"] for r in sel]),
                                              np.log([r["errors"]["phi_L2"] for r in sel]), 1)[0])
    slow = [_slowdown(scene, n, T, f, ref.final["E"]) for f in cfg["stabilized"]]
    return {"scene": cfg["scene"], "n": n, "T": T, "dt0": dt0, "rows": rows, "orders": orders,
            "slowdown": slow}


def _run_to(scene, n: int, scheme: str, dt: float, T: float):
    """A spectral run of ``scheme`` at ``dt`` to t = T: its result and its final φ."""
    from fem_ade.backends.base import make_backend
    from fem_ade.engine.loop import run_loop

    be = make_backend("spectral", scene, n=n, scheme=scheme)
    steps = int(round(T / dt))
    r = run_loop(be, dt=dt, steps=steps, every=max(1, steps // 50))
    return r, np.array(be.grid_phi())


def _temporal_rows(scene, n: int, T: float, cfg: dict, ref, ref_phi) -> list[dict]:
    """Each scheme's error at t = T against the reference, at each Δt of the plan (the
    paper's scheme only below its stability limit ε³)."""
    dt0 = scene.dt
    rows = []
    for scheme, factors in (("paper", [1 / f for f in cfg["factors"][1:]] + [2.0]),
                            ("stabilized", cfg["stabilized"])):
        for f in factors:
            dt = dt0 * f
            if scheme == "paper" and dt >= scene.params.eps**3:
                continue
            r, phi = _run_to(scene, n, scheme, dt, T)
            err = {q: abs(r.final[q] - ref.final[q]) / abs(ref.final[q]) for q in ("E", "V", "A")}
            err["phi_L2"] = float(np.linalg.norm(phi - ref_phi) / np.linalg.norm(ref_phi))
            rows.append({"scheme": scheme, "dt": dt, "factor": f, "errors": err,
                         "E": float(r.final["E"]), "steps": r.steps})
            print(f"  temporal: {scheme:10s} dt = {f:g} dt0: E err {err['E']:.2e}, "
                  f"phi {err['phi_L2']:.2e}", flush=True)
    return rows


class _Reached(Exception):
    """The run has reached the target energy (raised by :class:`_Watch`)."""


class _Watch:
    """A history writer that stops the run at the first row with E <= ``target``."""

    def __init__(self, target: float):
        self.target, self.hit = target, None

    def write(self, row):
        if row["E"] <= self.target:
            self.hit = row
            raise _Reached


def _slowdown(scene, n: int, T: float, f: float, target: float) -> dict:
    """When the stabilized scheme at ``f`` × Δt₀ reaches the energy ``target`` (the paper's
    scheme's at T): its time, as a multiple of T, beside the predicted 1 + s₀Δt."""
    from fem_ade.backends.base import make_backend
    from fem_ade.engine.loop import run_loop

    be = make_backend("spectral", scene, n=n, scheme="stabilized")
    dt = f * scene.dt
    watch = _Watch(target)
    try:
        run_loop(be, dt=dt, steps=int(200 * T / dt) + 1, every=1, history=watch)
    except _Reached:
        pass
    hit = watch.hit
    s0 = be.stab[0] if be.stab else float("nan")
    entry = {"factor": f, "dt": dt, "s0": s0, "t_reach": hit["t"] if hit else None,
             "slowdown": hit["t"] / T if hit else None, "predicted": (1.0 / dt + s0) * dt}
    print(f"  slowdown: stabilized dt = {f:g} dt0 reaches E_paper(T) at t = "
          f"{entry['t_reach']} ({entry['slowdown']}x T; 1 + s0 dt = "
          f"{entry['predicted']:.3g})", flush=True)
    return entry


def _strip(obj):
    if isinstance(obj, dict):
        return {k: _strip(v) for k, v in obj.items() if k != "grid"}
    if isinstance(obj, list):
        return [_strip(v) for v in obj]
    return obj


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="seconds (the test suite)")
    ap.add_argument("--parts", nargs="*", default=["spatial", "graded", "steady", "temporal"])
    ap.add_argument("--out", default=str(OUT))
    ap.add_argument("--runs", default=None,
                    help="where the resolved starts' run folders go (default runs/convergence)")
    ap.add_argument("--scenes", nargs="*", default=None,
                    help="the spatial part for these scenes only (the others' results kept)")
    ap.add_argument("--repeats", type=int, default=None,
                    help="run each point this many times, keep the least CPU time (default 2; "
                         "quick 1)")
    args = ap.parse_args(argv)
    global REPEATS
    REPEATS = args.repeats or (1 if args.quick else 2)
    quick = args.quick
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
    runs = Path(args.runs) if args.runs else Path("runs") / "convergence"
    name = "convergence_quick.json" if quick else "convergence.json"
    path = out / name
    results = json.loads(path.read_text()) if path.is_file() and not quick else {}
    t0 = time.perf_counter()
    for part, fn in (("spatial", lambda: spatial(plan, runs)),
                     ("graded", lambda: spatial(plan["graded"], runs)),
                     ("steady", lambda: steady(plan)), ("temporal", lambda: temporal(plan))):
        if part in args.parts:
            print(f"{part}:", flush=True)
            t1 = time.perf_counter()
            new = _strip(fn())
            results[part] = ({**results.get(part, {}), **new} if part in ("spatial", "graded")
                             else new)
            results.setdefault("part_s", {})[part] = time.perf_counter() - t1
            path.write_text(json.dumps(results, separators=COMPACT))  # resumable by part
    results.pop("q2", None)  # the earlier study's Q2 diagnosis: see convergence_notes.md
    results["run_s"] = sum(results.get("part_s", {}).values()) or time.perf_counter() - t0
    from fem_ade.store.output import package_versions

    results["machine"] = {"cores": os.cpu_count(), "versions": package_versions(),
                          "threads": {k: os.environ.get(k) for k in
                                      ("OPENBLAS_NUM_THREADS", "FEM_ADE_FFT_WORKERS")}}
    path.write_text(json.dumps(results, separators=COMPACT))
    report(results, out, quick)
    return results


def _rate(v) -> str:
    return f"{v:.2f}" if v is not None else "—"


def report(results: dict, out: Path, quick: bool) -> None:
    """convergence.md and the error-against-nodes plots."""

    suffix = "_quick" if quick else ""
    m = results["machine"]
    lines = ["# Convergence in space and in time", "",
             f"Generated by `studies/convergence.py` ({'quick' if quick else 'full'} mode; "
             f"{results.get('run_s', 0):.0f} s on {m['cores']} cores, one thread; numpy "
             f"{m['versions'].get('numpy')}, scipy {m['versions'].get('scipy')}). Errors are "
             "relative and signed (the sign of the error changes from grid to grid where the "
             "nodes fall differently in the interface layer); rates are the slopes of |error| "
             "over the levels with node spacing h = L/nodes ≤ ε. `pP` is the FEM of order P "
             "(GLL nodes, exact fast-diagonalization solve); CPU seconds include the set-up.",
             ""]
    for part, title in (("spatial", ""), ("graded", "graded meshes: ")):
        lines += _spatial_section(results.get(part, {}), title, out, suffix,
                                  "" if part == "spatial" else "-graded")
    if "steady" in results:
        st = results["steady"]
        lines += [f"## Steady state of {st['scene']} (exact constraints, stabilized 100× Δt, "
                  f"momentum, until 1e-10), against spectral n = {st['ref']['n']}", "",
                  f"Reference: E = {st['ref']['final']['E']:.10g}, "
                  f"{st['ref']['shape']['label']}, v = {st['ref']['shape']['reduced_volume']}",
                  "", "| discretisation | n | nodes | steps | CPU s | label | err E | err V | "
                  "err A | Δv | Δ(Δa) |", "|---|---|---|---|---|---|---|---|---|---|---|"]
        for row in st["rows"]:
            e = row["errors"]
            lines.append(f"| {row['label']} | {row['n']} | {row['nodes']} | {row['steps']} | "
                         f"{row['cpu_s']:.0f} | {row['shape']['label']} | {e['E']:.2e} | "
                         f"{e['V']:.2e} | {e['A']:.2e} | "
                         f"{e.get('reduced_volume', float('nan')):.2e} | "
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
    (out / f"convergence{suffix}.md").write_text("\n".join(lines) + "\n")


def _spatial_section(sp: dict, title: str, out: Path, suffix: str, tag: str) -> list[str]:
    lines = []
    for name, r in sp.items():
        for start, s in r["starts"].items():
            what = ("the paper's initial condition" if start == "paper" else
                    f"the spectral state after {r['start_steps']} steps (resolved start)")
            lines += [f"## {title}{name} from {what}: {r['steps']} steps of the paper's scheme "
                      f"against spectral n = {r['ref_n']} (ε = {r['eps']})", "",
                      f"Reference: E = {s['ref']['E']:.10g} (`{s['ref_command']}`)", ""]
            if start == "resolved":
                lines += [f"Start: `{r['start_command']}`", ""]
            lines += ["| discretisation | n | nodes | h/ε | CPU s | " + " | ".join(
                f"err {q}" for q in (*QUANTITIES, "phi_L2")) + " |",
                "|---|---|---|---|---|" + "---|" * (len(QUANTITIES) + 1)]
            for row in s["rows"]:
                lines.append(f"| {row['label']} | {row['n']} | {row['nodes']} | "
                             f"{row['h'] / r['eps']:.2f} | {row['cpu_s']:.2f} | " + " | ".join(
                                 f"{row['errors'][q]:+.2e}" for q in QUANTITIES) +
                             f" | {row['errors']['phi_L2']:.2e} |")
            lines += ["", "Observed rates (h ≤ ε):", "",
                      "| discretisation | " + " | ".join((*QUANTITIES, "phi_L2")) + " |",
                      "|---|" + "---|" * (len(QUANTITIES) + 1)]
            for label, rates in s["rates"].items():
                lines.append(f"| {label} | " + " | ".join(
                    _rate(rates[q]) for q in (*QUANTITIES, "phi_L2")) + " |")
            png = f"convergence{tag}-{name}-{start}{suffix}.png"
            lines += ["", f"![|error in E| against nodes per axis]({png})", ""]
            _plot(s["rows"], f"{title}{name}, {start} start", out / png)
    return lines


def _plot(rows, title, path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.4, 4.6), dpi=110)
    ax = fig.subplots()
    for label in dict.fromkeys(r["label"] for r in rows):
        sel = [r for r in rows if r["label"] == label]
        ax.loglog([r["nodes"] for r in sel], [max(abs(r["errors"]["E"]), 1e-16) for r in sel],
                  "o-" if "graded" not in label else "s--", label=label,
                  color=COLOURS.get(label), lw=1.6, ms=5)
    ticks = sorted({r["nodes"] for r in rows})
    ax.set_xticks(ticks, [str(t) for t in ticks])
    ax.minorticks_off()
    ax.set(xlabel="nodes per axis", ylabel="|relative error in E|", title=title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, ncol=2)
    fig.tight_layout()
    save_figure(fig, path, colours=64)


if __name__ == "__main__":
    main()
