"""One way to make a run folder's result exist: :func:`ensure`.

Every study, sweep point and branch point that runs something goes through it, so that
"run it, or resume it, or skip it because it is done, or wait for (or refuse) a folder
another process owns, or record why it failed" is written once:

* a folder whose summary.json ends in :data:`fem_ade.store.status.ENDED` is **skipped**: its
  summary is returned, nothing runs;
* a folder with a checkpoint and run.json is **resumed** (bit for bit the run that was
  interrupted); one that cannot be resumed (a checkpoint of an older version) is refused,
  or started again with ``restart=True``;
* a folder, ended or interrupted, that holds **another run** (another scene, or a choice a
  resume must match: :func:`holds_another`) gives :attr:`Status.FAILED` with the field that
  differs: nothing runs, nothing in it changes (``restart`` does not override this);
* otherwise the run **starts** (``simulate`` into the folder, or the job's own ``make``, e.g.
  following a branch); ``after=FOLDER`` starts it from that run's end (a kick, a
  continuation);
* a folder another live process holds gives :attr:`Status.BUSY` (``wait=True``: wait for it);
* a run that raises a model error (bad input, a field that cannot be resumed, a Newton that
  does not converge) gives :attr:`Status.FAILED`, with its reason written beside the folder
  in ``NAME.failed.json`` — a failure of before is tried again (``retry_failed=False``:
  reported as it was).

The result is an :class:`Outcome`: the status, the folder's summary (None without one), the
reason of a failure, the seconds this call took and whether it ran anything.

    >>> from fem_ade.engine.jobs import ensure
    >>> from fem_ade.scenes.catalogue import PAPER_SCENES
    >>> done = ensure("runs/torus-spectral", PAPER_SCENES["torus"],
    ...               options={"backend": "spectral", "n": 32, "steps": 20})  # doctest: +SKIP
    >>> done.status, done.summary["final"]["E"]                             # doctest: +SKIP
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from fem_ade.model.params import ModelError
from fem_ade.store.lock import FolderBusy
from fem_ade.store.output import write_json_atomic
from fem_ade.store.status import ENDED, Status

#: the errors that are a run's failure (recorded with their reason), not a bug of the caller:
#: ModelError (a ValueError), FloatingPointError and Newton's NewtonError (ArithmeticErrors)
RUN_ERRORS = (ValueError, ArithmeticError)
#: how often a waiting job looks at a busy folder again (seconds)
WAIT_POLL_S = 2.0


@dataclass
class Outcome:
    """What :func:`ensure` found or made in ``folder``."""

    folder: Path
    status: str
    summary: dict | None = None
    reason: str = ""
    seconds: float = 0.0
    ran: bool = False

    @property
    def ok(self) -> bool:
        """The run has ended (its summary says so): neither failed, busy nor interrupted."""
        return self.status in ENDED

    def check(self) -> Outcome:
        """This outcome, or ModelError (one line) if the job failed or is busy."""
        if self.status in (Status.FAILED, Status.BUSY):
            raise ModelError(f"{self.folder}: {self.reason}")
        return self


def failure_record(folder: str | Path) -> Path:
    """Where the reason of a failed job is kept: ``NAME.failed.json`` beside its folder
    (the folder itself may be incomplete, or removed to run anew)."""
    folder = Path(folder)
    return folder.with_name(folder.name + ".failed.json")


def record_failure(folder: str | Path, reason: str, seconds: float | None = None,
                   status: str = Status.FAILED) -> None:
    """Write the reason a job failed (or, ``status`` skipped, was not run) to its
    :func:`failure_record`."""
    folder = Path(folder)
    record = {"folder": folder.name, "reason": reason}
    if status != Status.FAILED:
        record["status"] = str(status)
    if seconds is not None:
        record["seconds"] = round(seconds, 2)
    write_json_atomic(failure_record(folder), record, make_folder=True)


def read_failure(folder: str | Path) -> dict | None:
    """The folder's failure record as {status, reason} (status ``failed``, or ``skipped``
    for a job not run), or None without one; an unreadable record is a failure."""
    path = failure_record(folder)
    if not path.is_file():
        return None
    try:
        rec = json.loads(path.read_text())
        return {"status": rec.get("status", Status.FAILED),
                "reason": str(rec.get("reason", "failed"))}
    except (OSError, ValueError, AttributeError):
        return {"status": Status.FAILED, "reason": "failed (its record is unreadable)"}


def read_summary(folder: str | Path) -> dict | None:
    """The folder's summary.json as a dict, or None (none yet, unreadable, not a table)."""
    try:
        s = json.loads((Path(folder) / "summary.json").read_text())
    except (OSError, ValueError):
        return None
    return s if isinstance(s, dict) else None


def status_of(folder: str | Path) -> str | None:
    """The status a folder's summary.json records (None before it has one)."""
    s = read_summary(folder)
    return None if s is None else s.get("status")


def ensure(folder: str | Path, scene=None, *, options: dict | Callable | None = None,
           make: Callable[[Path], object] | None = None, after: str | Path | None = None,
           quiet: bool = True, restart: bool = False, wait: bool = False,
           retry_failed: bool = True) -> Outcome:
    """Make the result of the run in ``folder`` exist, and say how it stands (module
    docstring). ``scene`` and ``options`` (keyword arguments of
    :func:`fem_ade.engine.runs.simulate`) define a run; ``make(folder)`` instead runs a job of its
    own (it must leave a summary.json with a status, and continue itself when called
    again); ``after``: start from the end of that run (simulate's ``phi0``). ``scene`` may
    be a function that makes the scene and ``options`` one of the scene that makes them:
    they are called only when a run starts, and their errors are the job's failure."""
    folder = Path(folder)
    if (scene is None) == (make is None):
        raise TypeError("ensure() needs a scene (with its options) or a make function")
    t0 = time.perf_counter()
    failed = failure_record(folder)
    while True:
        summary = read_summary(folder)
        ended = summary is not None and summary.get("status") in ENDED
        if ended or _resumable(folder):  # never skip to, or resume, another run
            # restart=True starts an interrupted folder again over a run.json it cannot read
            other = holds_another(folder, scene, options, after,
                                  unreadable_ok=restart and not ended)
            if other:
                return Outcome(folder, Status.FAILED, summary, other,
                               time.perf_counter() - t0)
        if ended:
            return Outcome(folder, summary["status"], summary,
                           seconds=time.perf_counter() - t0)
        if failed.is_file() and not retry_failed:
            return Outcome(folder, Status.FAILED, summary, read_failure(folder)["reason"],
                           time.perf_counter() - t0)
        failed.unlink(missing_ok=True)  # a failure of before is tried again
        try:
            _run(folder, scene, options or {}, make, after, quiet, restart)
        except FolderBusy as err:
            if wait:
                time.sleep(WAIT_POLL_S)
                continue
            return Outcome(folder, Status.BUSY, summary, str(err), time.perf_counter() - t0)
        except RUN_ERRORS as err:
            reason = f"{type(err).__name__}: {err}"
            seconds = time.perf_counter() - t0
            record_failure(folder, reason, seconds)
            return Outcome(folder, Status.FAILED, read_summary(folder), reason, seconds,
                           ran=True)
        summary = read_summary(folder)
        status = summary.get("status") if summary else Status.FAILED
        reason = "" if summary else "the run left no summary.json"
        return Outcome(folder, status, summary, reason, time.perf_counter() - t0, ran=True)


def holds_another(folder: Path, scene, options, after=None, *,
                  unreadable_ok: bool = False) -> str:
    """Why a folder's run (ended or interrupted) is not the one asked for ('' when it is, or
    when that cannot be told here; with ``unreadable_ok`` also when the two cannot be
    compared, e.g. an older version's run.json): its run.json against the run
    ``simulate(scene, **options)`` would make — the scene as run and every choice a resume
    must match (:func:`fem_ade.engine.folder.run_identity`); with a start field (``after``,
    ``phi0``) the initial condition is that field's, not compared. A ``make`` job, or a
    scene or options given as functions (made only when a run starts), are the caller's to
    check: a sweep compares each point's NAME.point.json
    (:func:`fem_ade.campaigns.sweep_points.changed`)."""
    if scene is None or callable(scene) or callable(options):
        return ""
    from fem_ade.engine.folder import identity_difference
    from fem_ade.engine.runs import folder_identity, planned_identity

    options = options or {}
    try:
        asked = planned_identity(scene, options)
        held = folder_identity(folder)
    except (ModelError, TypeError) as err:
        if unreadable_ok:
            return ""
        return f"the folder holds a run that cannot be compared with the one asked for ({err})"
    if after is not None or options.get("phi0") is not None:
        for identity in (asked, held):
            identity["scene"].pop("ic", None)
    difference = identity_difference(held, asked)
    if difference is None:
        return ""
    difference = difference.replace("in the checkpoint", "in the folder").replace(
        "in run.json", "asked for")
    return (f"the folder holds another run ({difference}): give another folder, or remove "
            "this one to run it anew")


def _resumable(folder: Path) -> bool:
    """The folder holds an interrupted run's checkpoint and its run.json."""
    return (folder / "checkpoint.npz").is_file() and (folder / "run.json").is_file()


def _run(folder: Path, scene, options: dict, make, after, quiet: bool, restart: bool):
    from fem_ade.engine.runs import resume, simulate

    if make is not None:
        return make(folder)
    if _resumable(folder):
        try:
            return resume(folder, quiet=quiet)
        except ModelError as err:
            if isinstance(err, FolderBusy) or not restart:
                raise
            if not quiet:
                print(f"  {folder}: not resumable ({err}); starting again", flush=True)
    if callable(scene):
        scene = scene()
    if callable(options):
        options = options(scene)
    if after is not None:
        options = {**options, "phi0": str(after)}
    options = {"quiet": quiet, **options}
    return simulate(scene, out=folder, force=folder.is_dir(), **options)
