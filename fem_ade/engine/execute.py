"""Writing a run: the backend driven by the loop, into its run folder.

:func:`execute` is the one place :func:`fem_ade.engine.runs.simulate` and
:func:`fem_ade.engine.runs.resume` share. Given a checked configuration and a built backend,
it opens the folder's writers, runs :func:`fem_ade.engine.loop.run_loop` (with a checkpoint
every K steps, :mod:`fem_ade.engine.folder`), writes what was computed before any analysis,
then describes the final shape and adds the analysis, its :func:`verdict` and the pictures.
A write that fails mid-run ends it with :class:`WriteFailed`.

A run folder holds ``run.json`` (what :func:`fem_ade.engine.runs.resume` needs),
``history.csv`` (written row by row), ``summary.json``, ``final.npz``, and the ParaView series
``phi.xdmf`` (the mesh in ``phi.h5``, each saved step in ``phi-KKKKKKKK.h5``). With
``checkpoint_every`` it also holds a ``checkpoint.npz``, with ``shape_every`` a
``shapes.csv``, and with ``phi0`` given an ``initial.npz``. Unless ``render=False`` it has the
pictures ``shape.png`` and ``history.png``. The shape descriptors and the pictures are computed
once, from the fields in memory.

Why a module of its own: this is the inside of a run folder, which no caller of the API
calls, and it needs none of the API's checks. The API (:mod:`fem_ade.engine.runs`) stands
above it, and this module reads no backend option either.
"""

from __future__ import annotations

import os
import time
import warnings
from pathlib import Path

import numpy as np

from fem_ade.backends.base import Backend
from fem_ade.engine.config import RunConfig
from fem_ade.engine.folder import (
    checkpoint_spent,
    read_checkpoint,
    run_identity,
    write_checkpoint,
)
from fem_ade.engine.loop import AdaptiveDt, LoopState, RunResult, run_loop
from fem_ade.model.params import HISTORY_COLUMNS, ModelError
from fem_ade.scenes.catalogue import Scene, scene_to_mapping
from fem_ade.store.output import (
    HistoryWriter,
    package_versions,
    parse_cell,
    truncate_csv,
    truncate_history,
    write_fields,
    write_json_atomic,
)
from fem_ade.store.status import Status
from fem_ade.store.xdmf import XdmfSeries


class _Series:
    """The XDMF time series of a run (ParaView): the backend's point data at the start, every
    ``save_every`` steps and at the end, one file per step (crash-consistent:
    :class:`fem_ade.store.xdmf.XdmfSeries`). A resumed run reopens it from its checkpoint's step:
    the intact steps of the schedule up to there are kept (not the end of an interrupted
    sitting, nor its start again), so the series ends as the uninterrupted run's."""

    def __init__(self, path: Path, be: Backend, save_every: int | None,
                 resume_from: int | None = None):
        points, cells = be.output_mesh()

        def scheduled(step: int) -> bool:
            return step == 0 or bool(save_every) and step % save_every == 0

        self.xdmf = XdmfSeries(path, points, cells, resume_from=resume_from, keep=scheduled)
        self.be, self.last_step = be, None
        self.resume_from, self.scheduled = resume_from, scheduled

    def save(self, ls: LoopState) -> None:
        """Add the backend's current fields at step ``ls.k``, time ``ls.t``."""
        if ls.k == self.resume_from and not self.scheduled(ls.k):
            return  # a resumed run's start is the checkpoint, not a step of the schedule
        if ls.k == self.resume_from and any(e[0] == ls.k for e in self.xdmf.entries):
            self.last_step = ls.k
            return  # already in the series (kept from before)
        self.xdmf.write(ls.t, self.be.point_data(), step=ls.k)
        self.last_step = ls.k

    def close(self) -> None:
        self.xdmf.close()


class _Shapes:
    """The shape descriptors along a run (``shape_every``): rows of OUT/shapes.csv."""

    COLUMNS = ("step", "t", "label", "components", "genus", "arms", "reduced_volume",
               "reduced_area_difference", "elongation", "flatness", "necks", "dimple")

    def __init__(self, be: Backend, path: Path | None, monitor, resume_from: int | None):
        """``resume_from``: the checkpoint's step when a run resumes. The rows from that step
        on are dropped (the resumed loop observes its start again, and a run killed after
        its last checkpoint recorded steps it will make again); the earlier ones are kept."""
        self.be, self.monitor, self.rows = be, monitor, []
        self.file = None
        if path is not None:
            append = (resume_from is not None and path.is_file()
                      and path.read_text().startswith(",".join(self.COLUMNS)))
            if append:
                self.rows = [{c: parse_cell(v) for c, v in r.items()}
                             for r in truncate_csv(path, resume_from - 1)]
            self.file = open(path, "a" if append else "w")  # noqa: SIM115
            if not append:
                self.file.write(",".join(self.COLUMNS) + "\n")
                self.file.flush()

    def observe(self, ls: LoopState) -> None:
        shape, _ = describe_final(self.be, self.be.diagnostics())
        if shape is None:
            return
        body = shape.get("body") or {}
        row = {"step": ls.k, "t": ls.t, "label": shape["label"],
               "components": shape["components"],
               "genus": " ".join(map(str, shape["genus"])), "arms": shape["arms"],
               "reduced_volume": shape["reduced_volume"],
               "reduced_area_difference": shape["reduced_area_difference"],
               **{k: body.get(k, "") for k in ("elongation", "flatness", "necks", "dimple")}}
        self.rows.append(row)
        if self.file is not None:
            from fem_ade.store.interrupt import critical

            with critical():  # the row whole, or not at all
                self.file.write(",".join(str(row[c]) for c in self.COLUMNS) + "\n")
                self.file.flush()
        if self.monitor is not None:
            self.monitor(self.be, row)

    def close(self):
        if self.file is not None:
            self.file.close()


class WriteFailed(RuntimeError):
    """Writing the run folder failed mid-run (disk full, gone, not writable): one line, with
    what was kept (the command line's exit 3)."""


def execute(out: Path | None, scene: Scene, config: RunConfig, *, quiet: bool, be: Backend,
             start: tuple[dict, LoopState] | None = None, monitor=None) -> RunResult:
    """Run the backend ``be`` as ``config`` says; the one place simulate/resume share.

    A file system error while the folder is written (ENOSPC, EROFS, EIO, …) ends the run
    with :class:`WriteFailed`; every file a later step trusts is written whole or not at all
    (temporary name + rename), so the last checkpoint stays good for a resume."""
    try:
        return _execute_run(out, scene, config, quiet=quiet, be=be, start=start,
                            monitor=monitor)
    except OSError as err:
        if out is None:
            raise
        for leftover in out.glob("*.tmp*"):  # a write cut short: nothing will read it
            try:
                leftover.unlink()
            except OSError:
                pass
        where = err.filename or out
        reason = (os.strerror(err.errno) if err.errno else " ".join(str(err).split())[:200])
        kept = "no checkpoint was written (--checkpoint-every K keeps one)"
        if (out / "checkpoint.npz").is_file():
            try:
                kept = (f"its last checkpoint (step {read_checkpoint(out)[1].k}) is kept: "
                        f"python -m fem_ade.run --resume {out} continues from there")
            except ModelError:
                pass
        raise WriteFailed(f"cannot write {where}: {reason}; {kept}") from None


def _execute_run(out, scene, config, *, quiet, be, start, monitor) -> RunResult:
    from fem_ade.store.interrupt import critical

    start_ls = start[1] if start is not None else None
    adaptive = AdaptiveDt(**config.adaptive) if config.adaptive else None
    columns = HISTORY_COLUMNS + tuple(be.extra_columns) + (("dt",) if adaptive else ())
    writer, series, earlier = _open_outputs(out, scene, config, be, start, columns)
    identity = run_identity(scene, config) if out is not None else None
    observers = [(config.save_every, series.save)] if series else []
    shapes = None
    if config.shape_every:
        shapes = _Shapes(be, out / "shapes.csv" if out else None, monitor,
                         start_ls.k if start_ls is not None else None)
        observers.append((config.shape_every, shapes.observe))

    # the seconds of the sittings before this one (a resume), to the checkpoint it starts at
    before = checkpoint_spent(out) if out is not None and start is not None else {
        "cpu_s": 0.0, "wall_s": 0.0}
    c0, w0 = time.process_time(), time.perf_counter()

    def checkpoint(ls):
        spent = {"cpu_s": before["cpu_s"] + time.process_time() - c0,
                 "wall_s": before["wall_s"] + time.perf_counter() - w0}
        with critical():
            write_checkpoint(out, be, ls, identity, spent)

    try:
        result = run_loop(
            be, dt=config.dt, steps=config.steps, until_steady=config.until_steady,
            max_steps=config.max_steps, every=config.every, quiet=quiet, history=writer,
            label=scene.name, adaptive=adaptive, checkpoint_every=config.checkpoint_every,
            on_checkpoint=checkpoint if out else None, observers=observers, start=start_ls,
            accelerate=config.accelerate)
    finally:
        if writer is not None:
            writer.close()
        if shapes is not None:
            shapes.close()
    result.cpu_s += before["cpu_s"]
    result.wall_s += before["wall_s"]
    result.shapes = shapes.rows if shapes is not None else []
    result.setup_cpu_s = getattr(be, "setup_cpu_s", 0.0) if start is None else 0.0
    phi_grid = np.asarray(be.grid_phi())
    result.final_grid = phi_grid
    rows = earlier + result.history
    if out is not None:  # what was computed is written first, before any analysis
        with critical():  # a signal now waits for the run's files
            summary = _write_results(out, be, result, config, series, phi_grid)
    grid = _analyse(be, result, phi_grid, sharp=config.sharp)
    if out is not None:
        with critical():
            _finish(out, be, result, config, summary, grid, rows)
    return result


def _open_outputs(out, scene, config, be, start, columns):
    """The run folder's writers before the loop (all None without a folder): the history
    (a new one with run.json, or the one being resumed, cut back to the start), the
    ParaView series, and the history rows written before the start."""
    if out is None:
        return None, None, []
    earlier: list[dict] = []
    out.mkdir(parents=True, exist_ok=True)
    if start is None:
        write_json_atomic(out / "run.json",
                          {"scene": scene_to_mapping(scene), **config.to_mapping()})
        writer = HistoryWriter(out / "history.csv", columns)
    else:
        earlier = truncate_history(out / "history.csv", start[1].k)
        writer = HistoryWriter(out / "history.csv", columns, append=True)
    # the ParaView series: the start, every save_every steps, the end
    series = _Series(out / "phi.xdmf", be, config.save_every,
                     None if start is None else start[1].k)
    return writer, series, earlier


def _analyse(be, result: RunResult, phi_grid: np.ndarray, *, sharp: bool = True):
    """Describe the final shape into ``result`` (with its sharp reference unless it
    diverged or ``sharp`` is False); a failure of the analysis is a warning and
    ``result.analysis_error``, never the run's. Returns the backend's (φ on the grid,
    surface, descriptors)."""
    grid = (phi_grid, None, None)
    try:
        result.shape, grid = be.describe_final(result.final, grid=phi_grid)
        if result.shape is not None and result.status != Status.DIVERGED and sharp:
            from fem_ade.analysis.sharp import compare

            result.shape["sharp_reference"] = compare(be.scene.params, result.shape,
                                                      result.final,
                                                      points=be.resolution_per_length())
    except Exception as err:  # noqa: BLE001 (the analysis must never cost the results)
        result.shape = None
        result.analysis_error = f"{type(err).__name__}: {err}"[:500]
        warnings.warn(f"the shape analysis failed ({result.analysis_error}); the run's "
                      "results are saved", stacklevel=3)
    return grid


def describe_final(be: Backend, final: dict):
    """(shape descriptors of the final φ = 0 surface or None, (φ on the grid, surface,
    descriptors)): the backend's :meth:`~fem_ade.backends.base.BackendBase.describe_final`."""
    return be.describe_final(final)


def _write_results(out: Path, be: Backend, result: RunResult, config: RunConfig, series,
                   phi_grid: np.ndarray) -> dict:
    """What the run computed, before any analysis: final.npz, the end of the series and
    summary.json (its shape, verdict and sharp comparison still None, ``analysis``
    "pending"); returns the summary."""
    fields = be.fields()
    if np.shape(fields["phi"]) != phi_grid.shape:  # the field is not on the uniform grid
        fields["phi_grid"] = phi_grid
        fields["x"] = np.arange(phi_grid.shape[0]) * (be.scene.params.L / phi_grid.shape[0])
    if np.all(np.isfinite(fields["phi"])):  # a non-finite field never replaces a good one
        write_fields(out / "final.npz", fields, step=result.steps, t=result.t, dt=result.dt,
                     status=result.status)
    if series is not None:
        if series.last_step != result.steps:
            series.save(LoopState(k=result.steps, t=result.t))
        series.close()
    summary = {
        "scene": be.scene.name,
        "figure": be.scene.figure,
        "parameters": be.scene.params.as_dict(),
        "backend": be.name,
        "backend_info": be.info(),
        **{k: getattr(config, k) for k in ("n", "dt", "scheme", "constraints", "ic",
                                           "perturb", "seed", "adaptive", "accelerate")},
        "momentum_restarts": result.restarts,
        "steps": result.steps,
        "t": result.t,
        "dt_final": result.dt,
        "rejected_steps": result.rejected,
        "status": result.status,
        "message": result.message,
        "final": result.final,
        "shape": None,
        "verdict": None,
        "sharp_reference": None,
        "analysis": "pending",
        "wall_s": result.wall_s,
        "cpu_s": result.cpu_s,
        "setup_cpu_s": getattr(be, "setup_cpu_s", None),
        "versions": package_versions(),
    }
    write_json_atomic(out / "summary.json", summary)
    return summary


def verdict(scene: Scene, shape: dict | None) -> dict | None:
    """How the run's final shape relates to the paper's (``scene.shape``): both labels, the
    numbers behind this run's, and ``same``."""
    if shape is None or not scene.shape:
        return None
    body = shape.get("body") or {}
    numbers = (f"{shape['components']} component{'s' if shape['components'] != 1 else ''}, "
               f"genus {', '.join(map(str, shape['genus'])) or '-'}, arms {shape['arms']}")
    if body:
        numbers += (f", axes ratios {body['elongation']:.2f} / {body['flatness']:.2f}, "
                    f"{body['necks']} neck(s), dimple {body['dimple']:.2f}")
    if scene.figure == "vesicle family":  # its shape is the branch it was seeded on
        from fem_ade.analysis.sharp import BRANCH_OF_LABEL

        branch = BRANCH_OF_LABEL.get(shape["label"], shape["label"])
        same = branch == scene.shape
        line = (f"seeded on the {scene.shape} branch; this run: {shape['label']} ({numbers}) "
                f"-> {'same branch' if same else 'left the branch'}")
        return {"branch": scene.shape, "run": shape["label"], "same": same, "line": line}
    same = shape["label"] == scene.shape
    line = (f"paper's shape: {scene.shape} ({scene.figure}); this run: {shape['label']} "
            f"({numbers}) -> {'same' if same else 'different'}")
    return {"paper": scene.shape, "run": shape["label"], "same": same, "line": line}


def _finish(out: Path, be: Backend, result: RunResult, config: RunConfig, summary: dict,
            grid, rows: list[dict]) -> None:
    """summary.json with the analysis (shape, verdict, sharp comparison, or why it failed)
    and the pictures."""
    phi_grid, surface, descriptors = grid
    error = getattr(result, "analysis_error", None)
    summary.update(shape=result.shape, verdict=verdict(be.scene, result.shape),
                   sharp_reference=(result.shape or {}).get("sharp_reference"),
                   analysis="failed: " + error if error else "done")
    write_json_atomic(out / "summary.json", summary)
    if config.render and np.all(np.isfinite(phi_grid)) and rows and not error:
        from fem_ade.plots.render import draw_run, run_label

        columns = {c: np.array([float(r.get(c, 0.0)) for r in rows]) for c in rows[0]}
        try:
            draw_run(out, phi_grid, be.scene.params, columns, descriptors, surface=surface,
                     label=run_label(summary, phi_grid.shape[0]),
                     physical_time=not config.accelerate)
        except Exception as err:  # noqa: BLE001 (a picture must never cost the run's results)
            warnings.warn(f"rendering {out} failed: {err}; the run's results are saved",
                          stacklevel=2)

