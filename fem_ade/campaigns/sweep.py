"""Parameter sweeps on Dask: many runs to a steady state, resumable, and their table and
phase diagram.

    python -m fem_ade.sweep SWEEP.toml [--out DIR] [--workers N | --scheduler ADDRESS]
                            [--report-only] [--quiet]

A sweep file names a base scene, the fixed and the swept parameters, the seeds of each point
and the run's options, or a branch per point, or points listed one by one
(:mod:`fem_ade.campaigns.sweep_file`: its format, each mistake refused before anything
runs).

Each point (one value per axis and one seed) is one run folder ``OUT/points/NAME`` (NAME from
its parameters, e.g. ``v=0.7_seed=prolate``), run by
:func:`fem_ade.campaigns.sweep_points.run_point` on a Dask worker: a
``LocalCluster`` of ``--workers`` processes (one thread each) by default, or the scheduler at
``--scheduler ADDRESS`` (or the scheduler's JSON file: one started by ``dask scheduler`` /
``dask worker``, ``dask-mpi`` or dask-jobqueue on Slurm/PBS; docs/cluster.md).
Killed at any moment and started again, a sweep skips the finished points, resumes those with
a checkpoint and never runs a point twice at once (the run folder's lock: a point whose
folder another process holds is waited for). A point that fails (bad parameters, an error)
is recorded with its reason in ``OUT/points/NAME.failed.json`` and the sweep goes on
(started again, it skips that point unless ``--retry-failed``).

Written: ``OUT/sweep.csv`` (one row per point, rebuilt from the run folders after each point:
an interrupted and resumed sweep ends with the table of an uninterrupted one),
``OUT/phase-diagram.png`` (each point coloured by its end state; the lowest-energy state per
point ringed; where seeds end in different states, marked; with the sharp reference's lowest
branch behind) and ``OUT/montage.png`` (the end shapes, when the runs render).

This module is the driver and the command: the Dask cluster or scheduler
(:func:`connect`), the points scheduled in the order they start from each other
(:func:`run_sweep`) and :func:`main`; a point on its worker and its row are
:mod:`fem_ade.campaigns.sweep_points`.
"""

from __future__ import annotations

import argparse
import gc
import json
import logging
import os
import signal
import sys
import time
from pathlib import Path

from fem_ade.campaigns.sweep_file import Sweep, load_sweep
from fem_ade.campaigns.sweep_points import check_points, row, run_point, write_sweep_table
from fem_ade.engine.jobs import record_failure
from fem_ade.model.params import ModelError
from fem_ade.store.output import write_json_atomic
from fem_ade.store.status import ENDED, Status


def check_out(out: Path) -> None:
    """``--out``: a sweep's folder (it holds sweep.json) or a new or empty folder that can be
    made there; ModelError (one line) otherwise — nothing is made here."""
    if str(out) in ("", "."):
        raise ModelError("--out needs a folder name")
    if out.exists() or out.is_symlink():
        if not out.is_dir():
            raise ModelError(f"--out {out} is not a folder")
        if any(out.iterdir()) and not (out / "sweep.json").is_file():
            raise ModelError(f"--out {out} holds other files and no sweep: give a new or empty "
                             "folder, or the folder of this sweep")
        if not os.access(out, os.W_OK | os.X_OK):
            raise ModelError(f"--out {out} is not writable")
        return
    parent = out.parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        raise ModelError(f"cannot make --out {out}: {parent} is not a writable folder")


#: Dask's nanny sets MALLOC_TRIM_THRESHOLD_=65536 in each worker it starts. An explicit trim
#: threshold turns off glibc's dynamic mmap threshold, so that every array above 128 KiB is
#: mapped and unmapped anew, page faults and all: a point of the axisymmetric ε ladder (105 x
#: 257 nodes, 230 steps) took 6.0 s of CPU in a worker against 1.56 s without it (1.4-1.7 s
#: in the driver's own process); the same in one process with the variable set, 5.9-6.4 s.
#: The workers of a LocalCluster are started without it (docs/cluster.md: external workers)
NANNY_ENVIRON = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}
#: the -W option of multiprocessing's resource tracker (:func:`connect`)
QUIET_TRACKER = "ignore:resource_tracker:UserWarning"


def connect(scheduler: str | None, workers: int):
    """(client, cluster or None): a LocalCluster of ``workers`` processes, or a client of the
    scheduler at ``scheduler`` (an address, or a scheduler file) within 10 s; ModelError
    (one line) for an address that does not answer, resolve or parse, or a file that is no
    scheduler's."""
    import dask
    from dask.distributed import Client, LocalCluster

    # Garbage first: a Client left unclosed (one whose connection failed in its constructor)
    # closes itself in __del__, and when the collector ran that inside LoopRunner.start,
    # under distributed's lock, the start failed (``assert loop is not None`` after 10 s, in
    # a fresh-clone CI) or hung (the next CI; py-spy: Client.__del__ → LoopRunner.stop inside
    # LoopRunner.start). A collection here runs those finalizers before any loop starts.
    gc.collect()

    if scheduler is None:
        # Workers stopped mid-point (Ctrl-C, SIGTERM) leave their semaphores to
        # multiprocessing's resource tracker, which frees them and then warns, on stderr after
        # the sweep's one line: "There appear to be 2 leaked semaphore objects". The tracker
        # is a process of its own started with this interpreter's -W options: ignore it there.
        if QUIET_TRACKER not in sys.warnoptions:
            sys.warnoptions.append(QUIET_TRACKER)
        if os.environ.get("MALLOC_TRIM_THRESHOLD_") == "65536":  # a Dask nanny's, left in this
            del os.environ["MALLOC_TRIM_THRESHOLD_"]              # process: workers inherit it
        # Logs at CRITICAL only: a worker that heartbeats while an interrupted sweep closes
        # the scheduler logs an ERROR with its traceback (31 lines on stderr after the sweep's
        # one; seen once in the suite). A point's failure reaches the sweep as its task's
        # exception and is written in the point's folder, not in the workers' logs.
        with dask.config.set(NANNY_ENVIRON):
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   dashboard_address=":0", silence_logs=logging.CRITICAL)
        return Client(cluster), cluster
    if not scheduler.strip():
        raise ModelError("--scheduler needs an address (tcp://HOST:PORT) or a scheduler file")
    path = Path(scheduler)
    try:
        if path.is_file():
            try:
                info = json.loads(path.read_text())
            except (OSError, ValueError) as err:
                raise ModelError(f"--scheduler {scheduler} is not a scheduler file ({err})") \
                    from None
            if not isinstance(info, dict) or "address" not in info:
                raise ModelError(f"--scheduler {scheduler} is not a scheduler file (no "
                                 "address in it)")
            return Client(scheduler_file=str(path), timeout="10s"), None
        return Client(scheduler, timeout="10s"), None
    except ModelError:
        raise
    except Exception as err:  # noqa: BLE001 (dask raises OSError, TimeoutError, ValueError...)
        text = " ".join(str(err).split())[:200] or type(err).__name__
        raise ModelError(f"cannot reach the Dask scheduler at {scheduler}: {text}") from None


# ---------------------------------------------------------------------------------------
# the driver
# ---------------------------------------------------------------------------------------
def run_sweep(sweep: Sweep, out: Path, *, workers: int = 2, scheduler: str | None = None,
              quiet: bool = False, retry_s: float = 2.0, retry_failed: bool = False,
              rerun_changed: bool = False) -> list[dict]:
    """Run every unfinished point on Dask (``retry_failed``: the failed ones too) — on the
    ``scheduler``'s workers, or on a local cluster of at most ``workers`` processes and no
    more than the points to run (none when every point has ended: a finished sweep's table
    in under a second); the table's rows (also written to sweep.csv). A point's folder made
    with other settings is refused (:func:`fem_ade.campaigns.sweep_points.check_points`)
    or, with ``rerun_changed``, run anew."""
    from dask.distributed import as_completed

    from fem_ade.store.lock import FolderLock

    check_out(out)
    for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
              "FEM_ADE_FFT_WORKERS"):
        os.environ.setdefault(k, "1")  # one thread per worker process
    if out.is_dir() and not rerun_changed:  # its points must be this sweep's: nothing made
        check_points(sweep, out, rerun_changed=False)
    client = cluster = None
    if scheduler is not None:  # a refused scheduler: nothing written
        client, cluster = connect(scheduler, workers)
    try:
        out.mkdir(parents=True, exist_ok=True)
        lock = FolderLock(out).acquire()  # one driver per sweep folder
    except BaseException:
        if client is not None:
            client.close()
        raise
    if rerun_changed:  # under the lock: remove the changed points' runs
        check_points(sweep, out, rerun_changed=True)
    points = sweep.points()
    axes = sweep.columns()
    write_json_atomic(out / "sweep.json", {"name": sweep.name, "base": sweep.base,
                                     "axes": sweep.axes, "scene": sweep.fixed,
                                     "seeds": sweep.seeds, "run": sweep.run,
                                     **({"branch": sweep.branch} if sweep.branch else {}),
                                     **({"listed": sweep.listed} if sweep.listed else {}),
                                     "points": [p.name for p in points]}, make_folder=True)
    rows = {p.name: row(p, out) for p in points}
    done = ENDED | {Status.FAILED} if not retry_failed else ENDED
    todo = [p for p in points if rows[p.name]["status"] not in done]
    try:
        if client is None and todo:  # a local cluster of no more workers than points to run
            client, cluster = connect(None, min(workers, len(todo)))
        say = (lambda text: None) if quiet else (lambda text: print(text, flush=True))
        say(f"sweep {sweep.name}: {len(points)} points, {len(points) - len(todo)} done, "
            f"{len(todo)} to run" + (f" on {_workers_text(client)}; dashboard "
                                     f"{client.dashboard_link}" if client else ""))
        if todo:
            _drive(client, todo, out, rows, axes, quiet, retry_s, as_completed)
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
        write_sweep_table([rows[p.name] for p in points], out / "sweep.csv", axes)
        lock.release()
    return [rows[p.name] for p in points]


def _workers_text(client) -> str:
    n = len(client.scheduler_info().get("workers", {}))
    return f"{n} worker{'s' if n != 1 else ''}"


def _drive(client, todo, out, rows, axes, quiet, retry_s, as_completed):
    from tqdm import tqdm

    by_name, submitted = {p.name: p for p in todo}, {}
    for p in todo:  # a listed point after the one it starts from: Dask runs them in order
        deps = [submitted[p.after]] if p.after in submitted else []
        submitted[p.name] = client.submit(run_point, p, str(out), *deps, key=f"point-{p.name}",
                                          pure=False)
    futures = as_completed(list(submitted.values()))
    failed = 0
    started = time.perf_counter()
    n_workers = max(1, _n(client))
    bar = tqdm(total=len(todo), disable=quiet, unit="point", dynamic_ncols=True)
    try:
        for fut in futures:
            try:
                r = fut.result()
            except Exception as err:  # noqa: BLE001 - a worker lost, an unexpected error
                name = fut.key.removeprefix("point-")
                record_failure(out / "points" / name, f"{type(err).__name__}: {err}")
                r = row(by_name[name], out)
            if r["status"] == Status.BUSY:  # another process runs it: ask again later
                time.sleep(retry_s)
                futures.add(client.submit(run_point, by_name[r["point"]], str(out),
                                          pure=False))
                continue
            rows[r["point"]] = r
            failed += r["status"] in (Status.FAILED, Status.DIVERGED)
            bar.update(1)
            bar.set_postfix_str(f"failed {failed}, running {min(len(todo) - bar.n, n_workers)}")
            write_sweep_table(list(rows.values()), out / "sweep.csv", axes)
    finally:
        bar.close()
    if not quiet:
        took = time.perf_counter() - started
        print(f"ran {len(todo)} point(s) in {took:.1f} s ({failed} failed)", flush=True)


def _n(client) -> int:
    try:
        return len(client.scheduler_info().get("workers", {}))
    except Exception:  # noqa: BLE001
        return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m fem_ade.sweep",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("sweep", help="the sweep file (TOML)")
    ap.add_argument("--out", help="the sweep folder (default runs/sweeps/NAME)")
    where = ap.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=2,
                       help="local Dask worker processes, at most one per point left to run "
                            "(default 2)")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="an existing Dask scheduler: tcp://HOST:PORT or its scheduler file")
    ap.add_argument("--retry-failed", action="store_true",
                    help="run the points recorded as failed again (they are skipped otherwise)")
    ap.add_argument("--rerun-changed", action="store_true",
                    help="run anew the points whose folder was made with other settings (a "
                         "sweep refuses them otherwise)")
    ap.add_argument("--report-only", action="store_true",
                    help="rebuild the table and the pictures from the folders; run nothing")
    ap.add_argument("--quiet", action="store_true")
    args = ap.parse_args(argv)
    from fem_ade.store.lock import FolderBusy

    def stop(signum, frame):  # a kill ends the sweep as Ctrl-C does: workers closed
        raise KeyboardInterrupt

    if argv is None:  # SIGINT too: a shell that starts us in the background has it ignored
        signal.signal(signal.SIGTERM, stop)
        signal.signal(signal.SIGINT, stop)
    try:
        if args.workers < 1:
            raise ModelError(f"--workers must be >= 1, got {args.workers}")
        if args.out == "":
            raise ModelError("--out needs a folder name")
        sweep = load_sweep(args.sweep)
        out = Path(args.out or Path("runs") / "sweeps" / sweep.name)
        if args.report_only:
            rows = report_rows(sweep, out)
        else:
            rows = run_sweep(sweep, out, workers=args.workers, scheduler=args.scheduler,
                             quiet=args.quiet, retry_failed=args.retry_failed,
                             rerun_changed=args.rerun_changed)
    except FolderBusy as err:
        print(f"fem_ade.sweep: error: {err}", file=sys.stderr)
        return 2
    except ModelError as err:
        print(f"fem_ade.sweep: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("fem_ade.sweep: interrupted; run the same command again to go on",
              file=sys.stderr)
        return 130
    from fem_ade.plots.sweep_plot import draw

    pictures = [] if sweep.branch else draw(rows, sweep, out)  # each branch draws its own
    return _say_ended(sweep, rows, out, pictures)


def report_rows(sweep: Sweep, out: Path) -> list[dict]:
    """``--report-only``: the rows from the folders (sweep.csv written again), nothing run."""
    if not (out / "sweep.json").is_file():
        raise ModelError(f"{out} holds no sweep to report on (run it first)")
    check_points(sweep, out, rerun_changed=False)
    rows = [row(p, out) for p in sweep.points()]
    write_sweep_table(rows, out / "sweep.csv", sweep.columns())
    return rows


def _say_ended(sweep: Sweep, rows: list[dict], out: Path, pictures: list) -> int:
    """The sweep's last line; its exit code (1 while a point has not ended)."""
    done = sum(r["status"] in ENDED for r in rows)
    bad = sum(r["status"] == Status.FAILED for r in rows)
    skipped = sum(r["status"] == Status.SKIPPED for r in rows)
    print(f"{sweep.name}: {done} of {len(rows)} points finished, {bad} failed"
          + (f", {skipped} skipped" if skipped else "") + f"; {out / 'sweep.csv'}"
          + "".join(f", {p}" for p in pictures))
    return 0 if done + bad + skipped == len(rows) else 1


if __name__ == "__main__":
    sys.exit(main())
