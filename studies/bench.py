"""What every step costs: the spectral-element step of each order against the spectral step,
set-up, iterations, memory and the time to a steady state, each figure beside its target
(issues 12 and 21).

Measured in one run, so that ratios compare like with like on a noisy machine: CPU time and
wall time per step (medians over ``--repeats`` steps after two warm-up steps), on
``discocyte`` (experiment 1), at 64³ nodes — the spectral grid n = 64 and the FEM of order p
with n = 64/p cells per axis — for every order on uniform and graded meshes, with the exact
solve (fast diagonalization; the FFT for p = 1 uniform) and with PCG + AMG on the low-order
refined operator. Writes ``OUT/bench.json`` (``--out``, default ``runs/studies``; the
committed figures: ``--out studies/results``) — every figure as
``{"value", "unit", "target", "op"}`` (``target`` null where there is none) — and prints the
table. ``--quick``: small grids, no 128³, no steady states (the test suite runs it; nothing
there is timed).

    python studies/bench.py                    # the full benchmark (~15 min on 2 cores)
    python studies/bench.py --quick --out /tmp/b

One thread: this script sets ``OPENBLAS_NUM_THREADS=1`` and ``FEM_ADE_FFT_WORKERS=1`` unless
they are set (CPU seconds then compare; export them to measure otherwise).
``studies/results/bench_history.md`` keeps each change with its figures before and after.
"""

from __future__ import annotations

import os

from _lib.cli import one_thread

one_thread()  # one thread: CPU seconds compare

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

OUT = Path("runs") / "studies"  # the committed figures: --out studies/results
SCENE = "discocyte"
ORDERS = (1, 2, 3, 4, 6, 8)


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
        print(f"  {name:62s} {shown:>10s} {unit:6s}{ok}", flush=True)

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


def time_interleaved(backends, repeats: int) -> list[dict]:
    """:func:`time_steps` of several backends with their steps interleaved (a, b, a, b, …),
    so that the machine's drift over the measurement falls on all of them alike: for ratios
    of runs that do the same work (a graded and a uniform mesh)."""
    for be in backends:
        for _ in range(2):
            be.step()
    cpus = [[] for _ in backends]
    walls = [[] for _ in backends]
    for _ in range(repeats):
        for j, be in enumerate(backends):
            w0, c0 = time.perf_counter(), time.process_time()
            be.step()
            walls[j].append(time.perf_counter() - w0)
            cpus[j].append(time.process_time() - c0)
    return [{"wall": statistics.median(w), "cpu": statistics.median(c)}
            for w, c in zip(walls, cpus, strict=True)]


def build(backend: str, scene, n: int, scheme: str, constraints: str = "penalty", **options):
    """A backend with Δt pushed (the set-up's wall and CPU seconds beside it)."""
    from fem_ade.backends.base import make_backend

    dt = scene.dt * (100 if scheme == "stabilized" else 1)
    t0, c0 = time.perf_counter(), time.process_time()
    be = make_backend(backend, scene, n=n, scheme=scheme, constraints=constraints, **options)
    be.set_dt(dt)
    return be, time.perf_counter() - t0, time.process_time() - c0


def peak_rss_mb(nodes: int, order: int, solver: str) -> float:
    """Peak resident memory (MB) of a fresh process that builds a run of ``nodes``³ nodes and
    steps: its VmHWM (ru_maxrss would carry the parent's peak over the fork, on Linux)."""
    code = (
        "from fem_ade.backends.base import make_backend\n"
        "from fem_ade.scenes.catalogue import get_scene\n"
        f"s = get_scene({SCENE!r})\n"
        f"be = make_backend('fem', s, n={nodes}, dt=s.dt, solver={solver!r}, "
        f"order={order})\n"
        "be.step(); be.step()\n"
        "hwm = [l for l in open('/proc/self/status') if l.startswith('VmHWM')][0]\n"
        "print(float(hwm.split()[1]) / 1024.0)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=3600)
    if r.returncode != 0:
        raise RuntimeError(f"the {nodes}^3 memory run failed: {r.stderr[-500:]}")
    return float(r.stdout.split()[-1])


def time_to_steady(backend: str, scene, n: int, tol: float, **options) -> dict:
    """CPU time of the steady recipe (stabilized at 100× Δt, exact constraints, momentum)
    from the paper's initial condition."""
    from fem_ade.engine.runs import simulate

    t0 = time.perf_counter()
    r = simulate(scene, backend=backend, n=n, dt=100 * scene.dt, scheme="stabilized",
                 constraints="exact", accelerate=True, until_steady=tol, every=50,
                 max_steps=20000, backend_options=options, render=False)
    return {"wall": time.perf_counter() - t0, "cpu": r.cpu_s + r.setup_cpu_s,
            "steps": r.steps, "E": r.final["E"], "status": r.status,
            "label": r.shape["label"] if r.shape else None,
            "v": r.shape["reduced_volume"] if r.shape else None}


def machine() -> dict:
    from fem_ade.store.output import package_versions

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


def spectral_steps(F: Figures, scene, nodes: int, repeats: int) -> dict:
    """Section 1: the spectral step of each scheme; returns its timings by scheme."""
    print(f"\n1. the spectral step at {nodes}^3")
    spectral = {}
    for scheme in ("paper", "stabilized"):
        be, _, _ = build("spectral", scene, nodes, scheme)
        spectral[scheme] = t = time_steps(be, repeats)
        F.add(f"spectral step {nodes}^3 {scheme} cpu", 1e3 * t["cpu"], "ms")
    return spectral


def fem_steps(F: Figures, scene, nodes: int, orders, repeats: int, quick: bool,
              spectral: dict) -> None:
    """Section 2: the FEM step of each order on both meshes, ÷ the spectral step, and the
    graded ÷ uniform ratio from interleaved steps."""
    print(f"\n2. the FEM step at {nodes}^3 nodes, each order (n = {nodes}/p cells), ÷ the "
          "spectral step (CPU)")
    for p in orders:
        for mesh in ("uniform", "graded"):
            for scheme in ("paper", "stabilized"):
                options = {"order": p, **({"mesh": "graded"} if mesh == "graded" else {})}
                be, setup, setup_cpu = build("fem", scene, nodes, scheme, **options)
                t = time_steps(be, repeats)
                solver = be.info()["solver"]
                tag = f"FEM p={p} {mesh} {solver} {scheme}"
                F.add(f"{tag} step / spectral", t["cpu"] / spectral[scheme]["cpu"], "x",
                      3.0 if p >= 4 and not quick else None)
                if scheme == "paper":
                    F.add(f"FEM p={p} {mesh} {solver} set-up wall", setup, "s",
                          2.0 if not quick else None)
        # the same work on both meshes: their ratio from interleaved steps (drift cancels)
        pair = [build("fem", scene, nodes, "paper", order=p, **mesh_option)[0]
                for mesh_option in ({}, {"mesh": "graded"})]
        uniform, graded = time_interleaved(pair, 2 * repeats)
        F.add(f"FEM p={p} graded / uniform step (paper, interleaved)",
              graded["cpu"] / uniform["cpu"], "x", 1.2 if p >= 4 and not quick else None)


def exact_constraint_steps(F: Figures, scene, nodes: int, repeats: int, quick: bool) -> None:
    """End of section 2: the steady recipe's step (exact constraints), spectral and FEM p=4."""
    print("\n   the steady recipe's step (stabilized + exact constraints: four right sides)")
    for backend, options in (("spectral", {}), ("fem", {"order": 4})):
        be, _, _ = build(backend, scene, nodes, "stabilized", constraints="exact", **options)
        t = time_steps(be, repeats)
        name = backend + (" p=4 fdm" if options else "")
        F.add(f"{name} exact-constraint step {nodes}^3 cpu", 1e3 * t["cpu"], "ms")
        if backend == "spectral":
            base = t["cpu"]
        else:
            F.add("FEM p=4 exact-constraint step / spectral's", t["cpu"] / base, "x",
                  3.0 if not quick else None)


def amg_steps(F: Figures, scene, nodes: int, repeats: int, quick: bool,
              spectral: dict) -> None:
    """Section 3: PCG + AMG on the low-order refined operator: its step and iterations."""
    print(f"\n3. PCG + AMG on the low-order refined operator, {nodes}^3 nodes")
    amg_orders = (1, 4) if quick else (1, 2, 4, 8)
    for p in amg_orders:
        for scheme in ("paper", "stabilized"):
            be, setup, _ = build("fem", scene, nodes, scheme, order=p, solver="amg")
            t = time_steps(be, repeats)
            tag = f"FEM p={p} amg {scheme}"
            F.add(f"{tag} step / spectral", t["cpu"] / spectral[scheme]["cpu"], "x")
            F.add(f"{tag} PCG its (median)", float(t["its"]), "its",
                  11.0 if not quick else None)
            if scheme == "paper":
                F.add(f"FEM p={p} amg set-up wall", setup, "s")


def ade_share(F: Figures, scene, nodes: int, repeats: int) -> None:
    """Section 4: the step with the ADE term ÷ the step without it."""
    print("\n4. effects: ADE off")
    no_ade = scene.with_(effects=scene.params.effects - {"ade"})
    for backend, options in (("spectral", {}), ("fem", {"order": 4})):
        on, _, _ = build(backend, scene, nodes, "paper", **options)
        off, _, _ = build(backend, no_ade, nodes, "paper", **options)
        t_on, t_off = time_steps(on, repeats)["cpu"], time_steps(off, repeats)["cpu"]
        name = backend + (" p=4" if options else "")
        # no target: the ADE terms are pointwise products, whose share of the step falls as
        # the rest gets faster (the off terms' not being evaluated is tests' business)
        F.add(f"{name} {nodes}^3 step with ADE / without (cpu)", t_on / t_off, "x")


def memory(F: Figures, nodes: int, quick: bool) -> None:
    """Section 5: the peak memory of fresh processes (at 128³ too unless quick)."""
    print("\n5. memory (a fresh process: build, two steps)")
    F.add(f"peak RSS, FEM p=4 {nodes}^3 nodes, fdm", peak_rss_mb(nodes, 4, "auto"), "MB")
    if not quick:
        for p, solver, target in ((4, "auto", 2048.0), (8, "auto", 2048.0), (1, "auto", None),
                                  (4, "amg", None)):
            F.add(f"peak RSS, FEM p={p} 128^3 nodes, {solver}", peak_rss_mb(128, p, solver),
                  "MB", target)


def steady_states(F: Figures, scene) -> None:
    """Section 6: the time to a steady state at 64³, spectral and FEM p = 4 and 1, and how
    far their energies end apart."""
    print("\n6. time to a steady state (discocyte, 64^3 nodes: stabilized 100x dt, exact "
          "constraints, momentum, until 1e-9)")
    cases = [("spectral", 64, {}), ("fem", 64, {"order": 4}), ("fem", 64, {"order": 1})]
    ends = {}
    for backend, n, options in cases:
        r = time_to_steady(backend, scene, n, 1e-9, **options)
        name = backend + (f" p={options['order']}" if options else "")
        ends[name] = r
        F.add(f"time to steady state 64^3, {name} (cpu)", r["cpu"], "s")
        F.add(f"  steps to steady state 64^3, {name}", float(r["steps"]), "steps")
        print(f"    ends: {r['status']}, E = {r['E']:.10g}, {r['label']}, v = {r['v']:.4f}")
    ref = ends["spectral"]["E"]
    for name in ("fem p=4", "fem p=1"):
        F.add(f"|E {name} / E spectral - 1| at the steady state",
              abs(ends[name]["E"] / ref - 1), "")
    F.add("time to steady state, fem p=4 / spectral (cpu)",
          ends["fem p=4"]["cpu"] / ends["spectral"]["cpu"], "x")


def write_figures(out: Path, name: str, data: dict) -> None:
    """Write ``data`` to ``out/name``, keeping the axisymmetric block already there."""
    out.mkdir(parents=True, exist_ok=True)
    try:  # the axisymmetric cost figures (studies/axisymmetric.py) are that study's: kept
        kept = json.loads((out / name).read_text()).get("axisymmetric")
    except (OSError, ValueError):
        kept = None
    if kept is not None:
        data["axisymmetric"] = kept
    (out / name).write_text(json.dumps(data, indent=1) + "\n")


def main(argv=None) -> dict:
    """Run every section, print the figures, write bench.json (bench_quick.json if quick);
    returns the figures, the targets missed and the machine."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="small grids (the test suite)")
    ap.add_argument("--repeats", type=int, default=None)
    ap.add_argument("--out", default=str(OUT))
    args = ap.parse_args(argv)
    from fem_ade.scenes.catalogue import get_scene

    quick = args.quick
    repeats = args.repeats or (2 if quick else 9)
    scene = get_scene(SCENE)
    nodes = 16 if quick else 64
    orders = (1, 2, 4) if quick else ORDERS
    F = Figures()
    info = machine()
    print(f"bench: {info['cpu']} ({info['cores']} cores), BLAS threads {info['blas_threads']},"
          f" FFT workers {info['fft_workers']}, {info['date']}")
    t_start = time.perf_counter()

    spectral = spectral_steps(F, scene, nodes, repeats)
    fem_steps(F, scene, nodes, orders, repeats, quick, spectral)
    exact_constraint_steps(F, scene, nodes, repeats, quick)
    amg_steps(F, scene, nodes, repeats, quick, spectral)
    ade_share(F, scene, nodes, repeats)
    memory(F, nodes, quick)
    if not quick:
        steady_states(F, scene)

    total = time.perf_counter() - t_start
    print(f"\nfull run: {total:.0f} s; targets not met: {F.missed() or 'none'}")
    name = "bench_quick.json" if quick else "bench.json"
    write_figures(Path(args.out), name, {"machine": info, "run_s": total, "figures": F.items})
    return {"figures": F.items, "missed": F.missed(), "machine": info}


if __name__ == "__main__":
    main()
