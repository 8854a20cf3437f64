"""Scale-out of ``fem_ade.campaigns.sweep``, measured: one sweep on 1 and on 2 local Dask workers,
and
through an external scheduler started from the command line (``dask scheduler`` +
``dask worker``, as on a cluster).

The sweep: vesicles of the ``vesicle`` family seeded as spheres of the target volume (no sharp
solve: a point's work is its run), spectral, exact constraints, a fixed number of steps. For
each way of running it: the sweep's wall time (driver start to table), the cluster's start-up
(a cluster of the same workers made and closed alone), the wall per point, the points' own
time (each task's, measured inside the worker) and the overhead per task,

    (wall − start-up) × workers − Σ task time) / points,

what Dask and the driver add to each point. Run with nothing else on the machine.

    python studies/sweep_scaling.py --out studies/results     # ~3 min
    python studies/sweep_scaling.py --quick                   # seconds (runs/studies)
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _lib.cli import study_parser
from fem_ade.campaigns.sweep import run_sweep
from fem_ade.campaigns.sweep_file import Sweep
from fem_ade.store.status import Status

DEFAULT_OUT = Path("runs/studies")
FULL = {"v": [0.7, 0.75, 0.8, 0.85, 0.9, 0.95, 0.97, 0.99], "n": 32, "eps": 0.05, "steps": 300}
QUICK = {"v": [0.8, 0.9], "n": 16, "eps": 0.08, "steps": 10}


def make_sweep(plan) -> Sweep:
    return Sweep(name="scaling", base="vesicle", axes={"v": plan["v"]},
                 fixed={"eps": plan["eps"]}, seeds=["sphere"],
                 run={"backend": "spectral", "n": plan["n"], "steps": plan["steps"],
                      "scheme": "stabilized", "constraints": "exact", "render": False,
                      "allow_underresolved": True})


def startup(workers: int) -> float:
    from dask.distributed import Client, LocalCluster

    t0 = time.perf_counter()
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                      dashboard_address=":0", silence_logs=40) as cluster, Client(cluster):
        pass
    return time.perf_counter() - t0


def external(workers: int, folder: Path):
    """A scheduler and ``workers`` worker processes started as on a cluster's nodes; returns
    (address, processes, start-up seconds)."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
           "FEM_ADE_FFT_WORKERS": "1",  # and the workers' Dask settings (docs/cluster.md)
           "DASK_CONFIG": str(Path(__file__).resolve().parent / "sweeps" / "dask")}
    dask = [sys.executable, "-m", "distributed.cli.dask_scheduler"]
    file = folder / "scheduler.json"
    t0 = time.perf_counter()
    sched = subprocess.Popen([*dask, "--scheduler-file", str(file), "--port", "0",
                              "--dashboard-address", ":0"], env=env,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    while not file.is_file():
        time.sleep(0.05)
    address = json.loads(file.read_text())["address"]
    worker = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address,
                               "--nworkers", str(workers), "--nthreads", "1"], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    from dask.distributed import Client

    with Client(address) as client:
        client.wait_for_workers(workers, timeout=120)
    return address, (sched, worker), time.perf_counter() - t0


def measure(plan, how: str, workers: int, scratch: Path) -> dict:
    sweep = make_sweep(plan)
    out = scratch / f"{how}-{workers}"
    shutil.rmtree(out, ignore_errors=True)
    procs = ()
    if how == "local":
        start = startup(workers)
        t0 = time.perf_counter()
        rows = run_sweep(sweep, out, workers=workers, quiet=True)
    else:
        address, procs, start = external(workers, scratch)
        t0 = time.perf_counter()
        rows = run_sweep(sweep, out, scheduler=address, quiet=True)
    wall = time.perf_counter() - t0
    for p in procs:
        p.terminate()
        p.wait(timeout=60)
    tasks = [r["task_s"] for r in rows if "task_s" in r]
    assert len(tasks) == len(rows) and all(r["status"] == Status.COMPLETED for r in rows), rows
    n = len(rows)
    work = wall if how == "external" else wall - start  # run_sweep starts its own cluster
    return {"how": how, "workers": workers, "points": n, "wall_s": wall, "startup_s": start,
            "wall_per_point_s": wall / n, "task_s_mean": sum(tasks) / n,
            "overhead_per_task_s": (work * workers - sum(tasks)) / n,
            "speedup": None}


def main(argv=None) -> dict:
    ap = study_parser(__doc__, DEFAULT_OUT, first_line=True,
                      out_help="default %(default)s; the committed results: studies/results",
                      quick="")
    args = ap.parse_args(argv)
    plan = QUICK if args.quick else FULL
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        scratch = Path(tmp)
        rows = [measure(plan, "local", 1, scratch), measure(plan, "local", 2, scratch),
                measure(plan, "external", 2, scratch)]
    one = rows[0]["wall_s"] - rows[0]["startup_s"]
    for r in rows:
        work = r["wall_s"] - (r["startup_s"] if r["how"] == "local" else 0.0)
        r["speedup"] = one / work
    suffix = "_quick" if args.quick else ""
    lines = ["# Sweeps on Dask: one, two local workers and an external scheduler", "",
             f"Written by `studies/sweep_scaling.py`: {len(plan['v'])} points (vesicles seeded "
             f"as spheres, spectral, n = {plan['n']}, ε = {plan['eps']}, {plan['steps']} steps "
             "each, exact constraints), this 2-core machine. Start-up: making the cluster "
             "(local: a LocalCluster made and closed alone; external: `dask scheduler` and "
             "`dask worker --nworkers 2` started from the command line, until the workers "
             "joined). Overhead per task: ((wall − local start-up) × workers − Σ task) / "
             "points.", "",
             "| how | workers | wall s | start-up s | wall per point s | task s (mean) | "
             "overhead per task s | speed-up |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['how']} | {r['workers']} | {r['wall_s']:.2f} | {r['startup_s']:.2f} "
                     f"| {r['wall_per_point_s']:.2f} | {r['task_s_mean']:.2f} | "
                     f"{r['overhead_per_task_s']:.3f} | {r['speedup']:.2f} |")
    (args.out / f"sweep_scaling{suffix}.md").write_text("\n".join(lines) + "\n")
    (args.out / f"sweep_scaling{suffix}.json").write_text(json.dumps(rows, indent=1) + "\n")
    print("\n".join(lines))
    return {"rows": rows}


if __name__ == "__main__":
    main()
