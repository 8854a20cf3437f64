"""What every step costs: spectral and FEM steps, set-up, iterations, memory, time to a steady
state, each figure beside its target (issue 12).

Measured in one run, so that ratios compare like with like on a noisy machine: CPU time and
wall time per step (medians over ``--repeats`` steps after two warm-up steps), on
``discocyte`` (experiment 1). Writes ``studies/results/bench.json`` — every figure as
``{"value", "unit", "target", "op"}`` (``target`` null where there is none), so a script can
check each target without knowing the names — and prints the table. ``--quick``: small grids,
no 128³, no steady states (the test suite runs it; nothing there is timed).

    python studies/bench.py                    # the full benchmark (~20 min on 2 cores)
    python studies/bench.py --quick --out /tmp/b

The threads of the FFTs follow ``FEM_ADE_FFT_WORKERS`` (default: all cores); numpy's BLAS
follows ``OPENBLAS_NUM_THREADS``. ``studies/results/bench_history.md`` keeps each change with
its figures before and after.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

OUT = Path(__file__).resolve().parent / "results"
SCENE = "discocyte"


class Figures:
    """The benchmark's figures, printed as they come and kept for bench.json."""

    def __init__(self):
        self.items: dict[str, dict] = {}

    def add(self, name, value, unit, target=None, op="<="):
        self.items[name] = {"value": value, "unit": unit, "target": target,
                            "op": op if target is not None else None}
        ok = ""
        if target is not None:
            met = value <= target if op == "<=" else value >= target
            ok = f"  target {op} {target:g}: {'met' if met else 'NOT MET'}"
        shown = f"{value:.4g}" if isinstance(value, float) else str(value)
        print(f"  {name:58s} {shown:>10s} {unit:8s}{ok}", flush=True)

    def missed(self) -> list[str]:
        out = []
        for name, f in self.items.items():
            if f["target"] is None:
                continue
            met = f["value"] <= f["target"] if f["op"] == "<=" else f["value"] >= f["target"]
            if not met:
                out.append(name)
        return out


def time_steps(be, repeats: int) -> dict:
    """Median wall and CPU time of one step (after two warm-up steps), and the iterations."""
    for _ in range(2):
        be.step()
    walls, cpus, its = [], [], []
    for _ in range(repeats):
        w0, c0 = time.perf_counter(), time.process_time()
        extra = be.step()
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
        its.append(extra.get("krylov_its", 0))
    return {"wall": statistics.median(walls), "cpu": statistics.median(cpus),
            "its": statistics.median(its), "its_max": max(its)}


def build(backend: str, scene, n: int, scheme: str, **options):
    from fem_ade.backend import make_backend

    dt = scene.dt * (100 if scheme == "stabilized" else 1)
    t0 = time.perf_counter()
    be = make_backend(backend, scene, n=n, scheme=scheme, dt=dt, **options)
    return be, time.perf_counter() - t0


def auto_choice(be) -> str:
    """The solver ``auto`` takes for this backend's step where the fft path does not apply."""
    from fem_ade.fem.solve import StepSolver

    st = be.stepper
    p = st.params
    return StepSolver(st.Mt, st.K, st.w, dt=be.dt, kappa=p.kappa, eps=p.eps, kind="auto",
                      s0=(st.stab or (0.0, 0.0))[0], s2=(st.stab or (0.0, 0.0))[1],
                      lumped=st.mass == "lumped").kind


def fft_pair(n: int, repeats: int) -> float:
    import numpy as np
    from scipy import fft

    from fem_ade.backend import fft_workers

    u = np.random.default_rng(0).standard_normal((n, n, n))
    times = []
    for _ in range(repeats + 2):
        t0 = time.perf_counter()
        fft.irfftn(fft.rfftn(u, workers=fft_workers()), s=u.shape, workers=fft_workers())
        times.append(time.perf_counter() - t0)
    return statistics.median(times[2:])


def peak_rss_mb(n: int, solver: str, order: int = 1) -> float:
    """Peak resident memory (MB) of a fresh process that builds a Q``order`` run and steps:
    its VmHWM (ru_maxrss would carry the parent's peak over the fork, on Linux)."""
    code = (
        "from fem_ade.backend import make_backend\n"
        "from fem_ade.scenes import get_scene\n"
        f"s = get_scene({SCENE!r})\n"
        f"be = make_backend('fem', s, n={n}, dt=s.dt, solver={solver!r}, order={order})\n"
        "be.step(); be.step()\n"
        "hwm = [l for l in open('/proc/self/status') if l.startswith('VmHWM')][0]\n"
        "print(float(hwm.split()[1]) / 1024.0)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=3600)
    if r.returncode != 0:
        raise RuntimeError(f"the {n}^3 memory run failed: {r.stderr[-500:]}")
    return float(r.stdout.split()[-1])


def time_to_steady(backend: str, scene, n: int, tol: float, **options) -> dict:
    """Wall time of the best numerics to a steady state: stabilized at 100× Δt, exact
    constraints, momentum, from the paper's initial condition."""
    from fem_ade.runs import simulate

    t0 = time.perf_counter()
    r = simulate(scene, backend=backend, n=n, dt=100 * scene.dt, scheme="stabilized",
                 constraints="exact", accelerate=True, until_steady=tol, every=50,
                 max_steps=20000, backend_options=options)
    return {"wall": time.perf_counter() - t0, "steps": r.steps, "E": r.final["E"],
            "status": r.status, "label": r.shape["label"] if r.shape else None,
            "v": r.shape["reduced_volume"] if r.shape else None}


def machine() -> dict:
    from fem_ade.output import package_versions

    cpu = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "platform": platform.platform(),
            "fft_workers": os.environ.get("FEM_ADE_FFT_WORKERS", "all"),
            "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS", "default"),
            "date": time.strftime("%Y-%m-%d %H:%M"), "versions": package_versions()}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="small grids (the test suite)")
    ap.add_argument("--repeats", type=int, default=None)
    ap.add_argument("--out", default=str(OUT))
    args = ap.parse_args(argv)
    from fem_ade.scenes import get_scene

    quick = args.quick
    repeats = args.repeats or (2 if quick else 7)
    scene = get_scene(SCENE)
    small, big = (12, 16) if quick else (32, 64)
    F = Figures()
    info = machine()
    print(f"bench: {info['cpu']} ({info['cores']} cores), FFT workers {info['fft_workers']}, "
          f"{info['date']}")
    t_start = time.perf_counter()

    print("\n1. FFT and the spectral step")
    F.add(f"fft pair rfftn+irfftn {big}^3 wall", 1e3 * fft_pair(big, repeats), "ms")
    spectral = {}
    for n in (small, big) if quick else (32, 64, 96):
        for scheme in ("paper", "stabilized"):
            be, _ = build("spectral", scene, n, scheme)
            t = time_steps(be, repeats)
            spectral[(n, scheme)] = t
            F.add(f"spectral step {n}^3 {scheme} wall", 1e3 * t["wall"], "ms")
            F.add(f"spectral step {n}^3 {scheme} cpu", 1e3 * t["cpu"], "ms")

    print("\n2. FEM Q1 on uniform meshes: set-up, step, iterations (ratio: same-n spectral "
          "step, CPU)")
    targets = {("fft", "paper"): 2.5, ("fft", "stabilized"): 4.0}
    general = {"paper": 12.0, "stabilized": 10.0}
    its = {}
    for n in (small, big):
        for solver in ("amg", "chebyshev", "jacobi", "fft"):
            for scheme in ("paper", "stabilized"):
                be, setup = build("fem", scene, n, scheme, solver=solver)
                t = time_steps(be, repeats)
                its[(n, solver, scheme)] = t["its"]
                ratio = t["cpu"] / spectral[(n, scheme)]["cpu"]
                choice = auto_choice(be) if solver != "fft" else None
                is_general = solver == choice  # what auto takes where fft does not apply
                tag = (f"FEM Q1 {n}^3 {solver}{' (fft direct)' if solver == 'fft' else ''}"
                       f"{' = auto without fft' if is_general else ''} {scheme}")
                F.add(f"{tag} step wall", 1e3 * t["wall"], "ms")
                target = targets.get((solver, scheme)) or (general[scheme] if is_general else
                                                           None)
                F.add(f"{tag} step / spectral (cpu)", ratio, "x", target if n == big else None)
                if solver != "fft":
                    F.add(f"{tag} PCG its (median)", float(t["its"]), "its",
                          10.0 if is_general and n == big else None)
                if scheme == "paper":
                    F.add(f"FEM Q1 {n}^3 {solver} set-up wall", setup, "s",
                          5.0 if n == big and solver == "amg" else None)
    for solver in ("amg", "chebyshev", "jacobi"):
        for scheme in ("paper", "stabilized"):
            r = its[(big, solver, scheme)] / max(its[(small, solver, scheme)], 1)
            F.add(f"PCG its {big}^3 / {small}^3, {solver} {scheme}", r, "x",
                  1.2 if solver == "chebyshev" else None)

    print("\n3. the general-mesh solver (auto) on a graded mesh; Q2")
    for scheme in ("paper", "stabilized"):
        graded = {}
        for n in (small, big):
            be, setup = build("fem", scene, n, scheme, mesh="graded", solver="auto")
            t = time_steps(be, repeats)
            graded[n] = t["its"]
            tag = f"FEM graded Q1 {n}^3 auto ({be.info()['solver']}) {scheme}"
            F.add(f"{tag} step wall", 1e3 * t["wall"], "ms")
            F.add(f"{tag} step / spectral (cpu)", t["cpu"] / spectral[(n, scheme)]["cpu"], "x",
                  general[scheme] if n == big else None)
            F.add(f"{tag} PCG its (median)", float(t["its"]), "its", 10.0 if n == big else None)
        F.add(f"graded PCG its {big}^3 / {small}^3 {scheme}", graded[big] / max(graded[small], 1),
              "x", 1.2)
        be, setup = build("fem", scene, small, scheme, order=2, solver="auto")
        t = time_steps(be, repeats)
        tag = f"FEM Q2 {small}^3 auto ({be.info()['solver']}) {scheme}"
        F.add(f"{tag} step wall", 1e3 * t["wall"], "ms")
        F.add(f"{tag} PCG its (median)", float(t["its"]), "its")
        if (2 * small, scheme) in spectral:  # the same nodes per direction
            F.add(f"{tag} step / spectral {2 * small}^3 (cpu)",
                  t["cpu"] / spectral[(2 * small, scheme)]["cpu"], "x")
        if scheme == "paper":
            F.add(f"FEM Q2 {small}^3 auto set-up wall", setup, "s")

    print("\n4. effects: ADE off")
    no_ade = scene.with_(effects=scene.params.effects - {"ade"})
    for backend, options in (("spectral", {}), ("fem", {"solver": "fft"}),
                             ("fem", {"solver": "chebyshev"})):
        on, _ = build(backend, scene, big, "paper", **options)
        off, _ = build(backend, no_ade, big, "paper", **options)
        t_on, t_off = time_steps(on, repeats)["cpu"], time_steps(off, repeats)["cpu"]
        name = backend + (f" {options['solver']}" if options else "")
        F.add(f"{name} {big}^3 step with ADE / without (cpu)", t_on / t_off, "x",
              1.0 / 0.85 if backend == "fem" and options["solver"] == "fft" else None, ">=")

    print("\n5. memory")
    F.add(f"peak RSS, FEM Q1 {big}^3 amg run", peak_rss_mb(big, "amg"), "MB",
          1024.0 if not quick else None)
    if not quick:
        F.add("peak RSS, FEM Q1 128^3 amg run", peak_rss_mb(128, "amg"), "MB", 16384.0)

    if not quick:
        print("\n6. time to a steady state (discocyte 64^3: stabilized 100x dt, exact "
              "constraints, momentum, until 1e-9)")
        cases = [("spectral", {}, 120.0), ("fem", {"solver": "fft"}, 900.0),
                 ("fem", {"solver": "amg"}, 3600.0)]  # amg: the general-mesh solver
        ends = {}
        for backend, options, target in cases:
            r = time_to_steady(backend, scene, 64, 1e-9, **options)
            name = backend + (f" {options['solver']}" if options else "")
            ends[name] = r
            F.add(f"time to steady state 64^3, {name}", r["wall"], "s", target)
            F.add(f"  steps to steady state 64^3, {name}", float(r["steps"]), "steps")
            print(f"    ends: {r['status']}, E = {r['E']:.8g}, {r['label']}, v = {r['v']:.4f}")
        ref = ends["fem fft"]["E"]
        F.add("|E fem amg / E fem fft - 1| at the steady state",
              abs(ends["fem amg"]["E"] / ref - 1), "", 1e-4)
        print("\n   the same steady state without momentum (32^3, spectral, plain stabilized "
              "scheme to 1e-9):")
        plain = time_to_steady_plain(scene, 32)
        fast = time_to_steady("spectral", scene, 32, 1e-9)
        F.add("|E momentum / E plain - 1| (32^3 spectral)", abs(fast["E"] / plain["E"] - 1),
              "", 1e-4)
        F.add("steps plain / steps momentum (32^3 spectral)", plain["steps"] / fast["steps"],
              "x")

    total = time.perf_counter() - t_start
    print(f"\nfull run: {total:.0f} s; targets not met: {F.missed() or 'none'}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    name = "bench_quick.json" if quick else "bench.json"
    (out / name).write_text(json.dumps({"machine": info, "run_s": total,
                                        "figures": F.items}, indent=1) + "\n")
    return {"figures": F.items, "missed": F.missed(), "machine": info}


def time_to_steady_plain(scene, n: int) -> dict:
    from fem_ade.runs import simulate

    t0 = time.perf_counter()
    r = simulate(scene, backend="spectral", n=n, dt=100 * scene.dt, scheme="stabilized",
                 constraints="exact", until_steady=1e-9, every=50, max_steps=40000)
    return {"wall": time.perf_counter() - t0, "steps": r.steps, "E": r.final["E"]}


if __name__ == "__main__":
    main()
