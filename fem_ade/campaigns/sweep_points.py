"""One point of a sweep (:mod:`fem_ade.campaigns.sweep` drives them): run, resumed or
skipped on a Dask worker in its run folder ``OUT/points/NAME`` (:func:`run_point`; a branch
point follows its branch there), whether the folder is still this point's
(:func:`changed`), and its row of the sweep's table (:func:`row`, :data:`COLUMNS`,
``sweep.csv``).

Why a module of its own: a point and its row are the part of a sweep that runs on the
workers and that a study reads back from the folders, without Dask's client; the driver
(:func:`fem_ade.campaigns.sweep.run_sweep`) only schedules them and writes the table.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from fem_ade.campaigns.sweep_file import Point, Sweep
from fem_ade.engine.jobs import failure_record, read_failure, record_failure
from fem_ade.model.params import ENERGY_COLUMNS, ModelError
from fem_ade.store.output import write_json_atomic
from fem_ade.store.status import ENDED, Status

#: the table's columns (the axes' names come first, after ``point``; no timings: a resumed
#: sweep's table is the uninterrupted one's, and each run's times are in its summary.json);
#: the energies are the history's (:data:`fem_ade.model.params.ENERGY_COLUMNS`: E, W, G)
COLUMNS = ("seed", "status", "steps", *ENERGY_COLUMNS, "e", "label", "components", "genus",
           "v_surface", "da_surface", "e_sharp_seed", "sharp_end", "reason")


# ---------------------------------------------------------------------------------------
# one point, on a worker
# ---------------------------------------------------------------------------------------
def run_point(point: Point, root: str, *started) -> dict:
    """Run (or resume, or skip) one point in ``root/points/NAME`` through
    :func:`fem_ade.engine.jobs.ensure`; its table row. A folder held by another process gives
    status ``busy`` (the driver tries again later). ``started``: the row of the point it
    starts from (Dask passes it once that one has run; the folder is what is read)."""
    from fem_ade.engine.jobs import ensure

    folder = Path(root) / "points" / point.name
    start = _start(point, Path(root))
    if start is not None and not isinstance(start, Path):  # its start is not there (yet)
        return start
    _record_point(point, folder)
    if point.branch:
        done = ensure(folder, make=lambda f: _follow(point, f))
    else:
        def scene():  # made only when the run starts: its errors are the point's failure
            made = point.scene()
            write_json_atomic(folder.with_name(point.name + ".seed.json"),
                        {"point": point.name, "seed": made.description,
                         "e_sharp": _seed_sharp_e(point)}, make_folder=True)
            return made

        done = ensure(folder, scene, options=point.options, after=start)
    if done.status == Status.BUSY:
        return {"point": point.name, "status": Status.BUSY, "reason": done.reason}
    return {**row(point, Path(root)), "task_s": done.seconds}


def _record_point(point: Point, folder: Path) -> None:
    """``NAME.point.json`` beside the point's folder: what the point is (its identity)."""
    write_json_atomic(folder.with_name(point.name + ".point.json"), point.identity(),
                      make_folder=True)


def _start(point: Point, root: Path) -> Path | dict | None:
    """The run folder a point starts from (``after``), None without one, or the point's row
    when it cannot start: ``busy`` while its start has not ended (the driver asks again),
    ``failed`` with the reason when its start ended without a result, ``skipped`` when it
    ended otherwise than ``when`` asks (looked at again on the next run of the sweep)."""
    if point.after is None:
        return None
    from fem_ade.engine.jobs import status_of
    from fem_ade.store.status import HAS_RESULT

    folder = root / "points" / point.name
    if (folder / "summary.json").is_file():  # it ran: a finished point is not looked at again
        return root / "points" / point.after
    start = root / "points" / point.after
    out = _head(point)
    status = (read_failure(start) or {}).get("status") or status_of(start)
    if status in HAS_RESULT and point.when and status not in point.when:
        reason = (f"not run: its start {point.after} ended {status}; it runs after "
                  f"{' or '.join(point.when)}")
        _record_point(point, folder)
        record_failure(folder, reason, status=Status.SKIPPED)
        return {**out, "status": Status.SKIPPED, "reason": reason}
    if status in HAS_RESULT:
        return start
    if status in ENDED | {Status.FAILED, Status.SKIPPED}:
        how = "was skipped" if status == Status.SKIPPED else f"ended {status}"
        reason = f"its start {point.after} {how}: there is no field to start from"
        _record_point(point, folder)
        record_failure(folder, reason)
        return {**out, "status": Status.FAILED, "reason": reason}
    return {**out, "status": Status.BUSY, "reason": f"waits for {point.after} to end"}


def _follow(point: Point, folder: Path) -> None:
    """A branch point: the branch followed (or gone on with, after a kill) in ``folder``,
    then its summary.json (status ``completed``: it is not followed again; ``seconds``: this
    call's wall time, its seed included)."""
    from fem_ade.campaigns.branch import follow

    t0 = time.perf_counter()
    b = point.branch
    rows = follow(point.scene(), param=b["param"], start=b["from"], stop=b["to"],
                  step=b["step"], out=folder, n=point.run.get("n"),
                  backend_options=point.run.get("backend_options"), quiet=True,
                  folds=b["folds"], stable=b.get("stability", True),
                  modes=b.get("modes", 0))
    # (no branch= check of the first point's shape: a sweep follows what its seed relaxes
    # to, and its table's label says what that is — studies/branches.py sets aside a seed
    # that is not on its branch, with the reason, in its report)
    last = rows[-1]
    forks = folder / "bifurcations.json"
    forks = json.loads(forks.read_text())["bifurcations"] if forks.is_file() else []
    write_json_atomic(folder / "summary.json", {
        "status": Status.COMPLETED, "branch": b, "points": len(rows), "end": last[b["param"]],
        "folds": [r["fold"] for r in rows if r.get("fold")], "last": last,
        **({"bifurcations": forks} if b.get("modes") else {}),
        "seconds": round(time.perf_counter() - t0, 1)}, make_folder=True)


def changed(point: Point, root: Path) -> str | None:
    """Why the point's folder (or failure record) is not this point's — its parameters,
    seed, run options or the physics' version differ from the recorded ones — or None (also
    when nothing was run yet)."""
    folder = root / "points" / point.name
    record = folder.with_name(point.name + ".point.json")
    made = [p for p in (folder, failure_record(folder),
                        folder.with_name(point.name + ".seed.json")) if p.exists()]
    if not made:
        return None
    try:
        recorded = json.loads(record.read_text())
    except (OSError, ValueError):
        return "its folder records no parameters (an older fem_ade made it)"
    from fem_ade.engine.runs import identity_difference

    difference = identity_difference(recorded, point.identity())
    return None if difference is None else difference.replace(" in run.json", " now").replace(
        "in the checkpoint", "when it ran")


def forget(point: Point, root: Path) -> None:
    """Remove what an earlier run of the point left (its run's files, its records)."""
    import shutil

    folder = root / "points" / point.name
    if folder.is_dir():
        shutil.rmtree(folder)
    failure_record(folder).unlink(missing_ok=True)
    for suffix in (".seed.json", ".point.json"):
        folder.with_name(point.name + suffix).unlink(missing_ok=True)


def check_points(sweep: Sweep, root: Path, rerun_changed: bool) -> None:
    """Before anything runs or is reported: the folder of every point must be that point's
    (:func:`changed`); with ``rerun_changed`` a changed one is removed, to run anew, else
    the sweep is refused with one line naming the first difference."""
    for point in sweep.points():
        why = changed(point, root)
        if why is None:
            continue
        if not rerun_changed:
            raise ModelError(f"point {point.name} in {root} was run with other settings "
                             f"({why}); give another --out, or --rerun-changed to run it "
                             "anew")
        forget(point, root)


def _head(point: Point) -> dict:
    """A row's first columns: the point, its parameters, its seed and its start."""
    return {"point": point.name, **point.values, "seed": point.seed,
            **({"after": point.after} if point.after else {})}


def row(point: Point, root: Path) -> dict:
    """The table row of a point, from its run folder (or its failure record)."""

    folder = root / "points" / point.name
    out = _head(point)
    failed = read_failure(folder)
    if failed is not None:
        return {**out, **failed}
    try:
        s = json.loads((folder / "summary.json").read_text())
    except (OSError, ValueError):
        return {**out, "status": Status.PENDING}
    if not isinstance(s, dict):
        return {**out, "status": Status.DAMAGED, "reason": "its summary.json is not a table"}
    try:
        seed = json.loads(folder.with_name(point.name + ".seed.json").read_text())
    except (OSError, ValueError):
        seed = {}
    if not isinstance(seed, dict):
        seed = {}
    try:
        if "branch" in s:
            return _row_of_branch(out, s)
        return _row_of_summary(out, s, seed)
    except (KeyError, TypeError, ValueError, AttributeError) as err:
        return {**out, "status": Status.DAMAGED,
                "reason": f"its summary.json is damaged ({type(err).__name__}: {err})"}


def _row_of_summary(out: dict, s: dict, seed: dict) -> dict:
    from fem_ade.analysis.sharp import reduced_energy

    f, shape = s.get("final", {}), s.get("shape") or {}
    sharp = shape.get("sharp") or {}
    ref = s.get("sharp_reference") or {}
    out.update(status=s["status"], steps=s["steps"], **{k: f.get(k) for k in ENERGY_COLUMNS},
               e=reduced_energy(f, s["parameters"]["kappa"]) if "W" in f else None,
               label=shape.get("label"), components=shape.get("components"),
               genus=" ".join(str(g) for g in shape.get("genus", [])),
               v_surface=sharp.get("reduced_volume"),
               da_surface=sharp.get("reduced_area_difference"),
               e_sharp_seed=seed.get("e_sharp"), sharp_end=ref.get("e_sharp"),
               reason="" if s["status"] != Status.DIVERGED else s.get("message", ""))
    return out


def _row_of_branch(out: dict, s: dict) -> dict:
    from fem_ade.campaigns.branch_folder import row_digest

    last = s["last"]
    record = last.get("integrity")
    if isinstance(record, dict) and record.get("row") != row_digest(last):
        return {**out, "status": Status.DAMAGED,
                "reason": "its summary.json's last point was changed after it was saved"}
    out.update(status=s["status"], steps=s["points"], end=s["end"],
               folds=" ".join(str(f) for f in s["folds"]),
               **{k: last.get(k) for k in (*ENERGY_COLUMNS, "e", "label", "v_surface",
                                          "da_surface")})
    return out


def _seed_sharp_e(point: Point) -> float | None:
    """The sharp energy of the seed's branch at the point (vesicle family), if it exists
    (the solve that seeded it, cached in this process)."""
    if point.base != "vesicle":
        return None
    from fem_ade.scenes.vesicle import sharp_of

    res = sharp_of(point.seed, **point.fixed, **point.values)
    return None if res is None else float(res.e)


# ---------------------------------------------------------------------------------------
# the table
# ---------------------------------------------------------------------------------------
def write_sweep_table(rows: list[dict], path: Path, axes: list[str]) -> None:
    """A sweep's rows as its sweep.csv (:func:`fem_ade.store.tables.write_table`): the point,
    its axes, :data:`COLUMNS` (a branch sweep's end and folds; a listed sweep's after)."""
    from fem_ade.store.tables import write_table

    cols = ["point", *axes, *COLUMNS]
    if any("end" in r for r in rows):  # a branch sweep's
        cols[cols.index("steps") + 1:cols.index("steps") + 1] = ["end", "folds"]
    if any(r.get("after") for r in rows):  # listed points that start from another's end
        cols.insert(cols.index("seed") + 1, "after")
    write_table(path, cols, rows)


#: a sweep table's columns that stay text (a seed "1" is a name, not a number)
TEXT_COLUMNS = ("point", "seed", "genus", "label", "status", "reason", "folds", "after")


def read_sweep_table(path: Path) -> list[dict]:
    """The rows of a sweep.csv, numbers as numbers, empty cells None (what :func:`row` gives,
    without the run folders: a committed sweep's table is enough to draw and report it
    again)."""
    from fem_ade.store.tables import read_table

    return read_table(path, text=TEXT_COLUMNS, empty=None)
