"""One time loop for every backend: stepping, recording, steady state, guards, adaptive Δt,
checkpoints and output.

:func:`run_loop` drives any object that implements :class:`fem_ade.backend.Backend`;
:func:`simulate` is the Python API behind the CLI (scene + backend + output folder) and
:func:`resume` continues a run from its checkpoint.

Stopping rules
--------------
* ``steps=K``: until step K.
* ``until_steady=TOL``: stop at the first record where the relative change of E_M per step,
  averaged over the last record interval, is below TOL::

      |E(k) − E(k − every)| / (every · |E(k)|) < TOL

  or after ``max_steps`` steps (status ``max_steps``).

Guards
------
After every step, a non-finite φ or max|φ| > 2 stops the run (status ``diverged``, exit code
3): the state of the last finite step is restored and saved, no non-finite row is written,
and the message names the step and the likely cause (:func:`fem_ade.model.diagnose_blowup`).
A diagnostics record with a non-finite value is treated the same way.

Adaptive Δt
-----------
With an :class:`AdaptiveDt`, E_M is measured after every step. A step that raises E_M by more
than ``tol``·|E_M| or trips a guard is rejected: the state is restored and Δt is halved (below
``dt_min`` the run stops as diverged). After ``grow_after`` accepted steps in a row with
decreasing energy, Δt grows by ``grow`` up to ``dt_max``. History gains a ``dt`` column.

Checkpoints
-----------
``checkpoint_every=K`` writes ``OUT/checkpoint.npz`` (backend state + loop state) every K steps,
atomically (write, then rename). Ctrl-C writes one and stops cleanly (status ``interrupted``,
exit code 130). :func:`resume` continues bit for bit.
"""

from __future__ import annotations

import json
import math
import time
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from .backend import Backend, make_backend
from .constraints import ConstraintError
from .constraints import check as check_constraints
from .model import HISTORY_COLUMNS, ModelError, check_resolution, diagnose_blowup, max_stable_dt
from .output import (
    HistoryWriter,
    check_out_dir,
    package_versions,
    read_json,
    truncate_history,
    write_fields,
    write_json_atomic,
)
from .render import render_run
from .scenes import Scene, scene_from_mapping, scene_to_mapping
from .shape import describe, extract_surface
from .xdmf import XdmfSeries

PHI_BOUND = 2.0

EXIT_OK, EXIT_BAD_INPUT, EXIT_DIVERGED, EXIT_INTERRUPTED = 0, 2, 3, 130

SCHEMES = ("paper", "stabilized")


@dataclass
class AdaptiveDt:
    """Bounds and factors of the adaptive time step (see the module docstring)."""

    dt_min: float
    dt_max: float
    grow: float = 1.25
    shrink: float = 0.5
    grow_after: int = 5
    tol: float = 1e-12

    def __post_init__(self):
        if not (0 < self.dt_min <= self.dt_max):
            raise ModelError(f"adaptive dt bounds must satisfy 0 < dt_min <= dt_max, "
                             f"got {self.dt_min:g}, {self.dt_max:g}")
        if not (self.grow > 1 and 0 < self.shrink < 1 and self.grow_after >= 1):
            raise ModelError("adaptive dt needs grow > 1, 0 < shrink < 1, grow_after >= 1")


@dataclass
class LoopState:
    """Where the loop is: what a checkpoint stores beside the backend's state."""

    k: int = 0
    t: float = 0.0
    dt: float = 0.0
    last_E: float = math.nan
    accepted: int = 0
    rejected: int = 0
    extra: dict = field(default_factory=dict)


@dataclass
class RunResult:
    """What a run ended with. ``status``: completed, steady, max_steps, diverged, interrupted."""

    status: str
    steps: int
    t: float
    final: dict
    message: str = ""
    wall_s: float = 0.0
    history: list[dict] = field(default_factory=list)
    dt: float = math.nan
    rejected: int = 0
    shape: dict | None = None

    @property
    def exit_code(self) -> int:
        codes = {"diverged": EXIT_DIVERGED, "interrupted": EXIT_INTERRUPTED}
        return codes.get(self.status, EXIT_OK)


def _finite(d: dict) -> bool:
    return all(math.isfinite(float(v)) for v in d.values())


def _guard(backend: Backend) -> str | None:
    m = backend.max_abs_phi()
    if not math.isfinite(m):
        return "phi is not finite"
    if m > PHI_BOUND:
        return f"max|phi| = {m:.3g} > {PHI_BOUND:g}"
    return None


def run_loop(
    backend: Backend,
    *,
    dt: float,
    steps: int | None = None,
    until_steady: float | None = None,
    max_steps: int = 100_000,
    every: int = 10,
    quiet: bool = True,
    history: HistoryWriter | None = None,
    label: str = "",
    adaptive: AdaptiveDt | None = None,
    checkpoint_every: int | None = None,
    on_checkpoint=None,
    save_every: int | None = None,
    on_save=None,
    start: LoopState | None = None,
) -> RunResult:
    """Advance ``backend`` from ``start`` (default: step 0) and record every ``every`` steps.

    ``on_checkpoint(state: LoopState)`` is called every ``checkpoint_every`` steps and on
    Ctrl-C, ``on_save(state)`` at the start and every ``save_every`` steps, each with the
    backend in the state of ``state.k``. Returns a :class:`RunResult`; the backend is left in
    the last finite state.
    """
    if (steps is None) == (until_steady is None):
        raise ModelError("give exactly one of steps and until_steady")
    if every < 1:
        raise ModelError(f"--every must be >= 1, got {every}")
    for name, value in (("checkpoint-every", checkpoint_every), ("save-every", save_every)):
        if value is not None and value < 1:
            raise ModelError(f"--{name} must be >= 1, got {value}")
    total = steps if steps is not None else max_steps
    if total < 0:
        raise ModelError(f"steps must be >= 0, got {total}")
    params = backend.scene.params
    rows: list[dict] = []
    t_wall = time.perf_counter()
    ls = start or LoopState(dt=dt, extra={c: 0 for c in backend.extra_columns})

    def record(diag: dict) -> None:
        row = {"step": ls.k, "t": ls.t, **{c: diag[c] for c in HISTORY_COLUMNS[2:]}, **ls.extra}
        if adaptive is not None:
            row["dt"] = ls.dt
        rows.append(row)
        if history is not None:
            history.write(row)

    def result(status, message, diag):
        return RunResult(status, ls.k, ls.t, diag, message, time.perf_counter() - t_wall, rows,
                         ls.dt, ls.rejected)

    diag = backend.diagnostics()
    if not _finite(diag):
        return result("diverged", "the state to start from is not finite", diag)
    if start is None:
        record(diag)
        ls.last_E = diag["E"]
    if on_save is not None:
        on_save(ls)
    last_diag, last_recorded_E = diag, ls.last_E
    status, message = "completed", ""
    bar = tqdm(total=total, initial=ls.k, disable=quiet, desc=label or "run", unit="step",
               mininterval=0.5, dynamic_ncols=True)
    good, good_k = None, None
    try:
        while ls.k < total:
            good, good_k = backend.state(), ls.k
            try:
                extra = backend.step()
                bad = _guard(backend)
            except ConstraintError as err:
                extra, bad = {}, str(err)
            is_record = (ls.k + 1) % every == 0 or ls.k + 1 == total
            if bad is None and (is_record or adaptive is not None):
                diag = backend.diagnostics()
                if not _finite(diag):
                    bad = "a diagnostic is not finite"
            if (adaptive is not None and bad is None
                    and diag["E"] > ls.last_E + adaptive.tol * abs(ls.last_E)):
                bad = f"E_M rose from {ls.last_E:.6g} to {diag['E']:.6g}"
            can_shrink = adaptive is not None and ls.dt * adaptive.shrink >= adaptive.dt_min
            if bad is not None and can_shrink:
                backend.set_state(good)  # reject: halve dt and retry
                ls.dt *= adaptive.shrink
                ls.rejected += 1
                ls.accepted = 0
                backend.set_dt(ls.dt)
                continue
            if bad is not None:
                backend.set_state(good)
                status = "diverged"
                message = (f"diverged at step {ls.k + 1} (t = {ls.t + ls.dt:.4g}): {bad}; "
                           f"likely cause: {diagnose_blowup(params, ls.dt, last_diag)}. "
                           f"The last finite state (step {ls.k}) is saved.")
                last_diag = backend.diagnostics()
                if ls.k > 0 and rows and rows[-1]["step"] != ls.k and _finite(last_diag):
                    record(last_diag)  # the last finite state, for the record
                break
            ls.k += 1
            ls.t += ls.dt
            ls.extra = {**ls.extra, **extra}
            bar.update(1)
            if adaptive is not None:
                ls.accepted = ls.accepted + 1 if diag["E"] <= ls.last_E else 0
                ls.last_E, last_diag = diag["E"], diag
                if ls.accepted >= adaptive.grow_after and ls.dt < adaptive.dt_max:
                    ls.dt = min(ls.dt * adaptive.grow, adaptive.dt_max)
                    ls.accepted = 0
                    backend.set_dt(ls.dt)
            if is_record:
                record(diag)
                last_diag = diag
                bar.set_postfix(t=f"{ls.t:.3g}", E=f"{diag['E']:.6g}", refresh=False)
                if until_steady is not None and ls.k % every == 0:
                    scale = every * max(abs(diag["E"]), 1e-300)
                    change = abs(diag["E"] - last_recorded_E) / scale
                    if change < until_steady:
                        status = "steady"
                        message = (f"steady at step {ls.k}: relative energy change per step "
                                   f"{change:.3g} < {until_steady:g}")
                        break
                last_recorded_E = diag["E"]
                if adaptive is None:
                    ls.last_E = diag["E"]
            if on_checkpoint is not None and checkpoint_every and ls.k % checkpoint_every == 0:
                on_checkpoint(ls)
            if on_save is not None and save_every and ls.k % save_every == 0:
                on_save(ls)
        else:
            if until_steady is not None:
                status = "max_steps"
                message = f"not steady after max_steps = {total} steps"
    except KeyboardInterrupt:
        if good is not None and good_k == ls.k:
            backend.set_state(good)  # the interrupted step may be half done
        status = "interrupted"
        message = f"interrupted at step {ls.k}"
        last_diag = backend.diagnostics()
        if on_checkpoint is not None:
            on_checkpoint(ls)
            message += "; checkpoint written"
    finally:
        bar.close()
    if status == "completed":
        message = f"completed {ls.k} steps"
    if adaptive is not None:
        message += f" (dt now {ls.dt:.3g}, {ls.rejected} rejected steps)"
    return result(status, message, last_diag)


# ---------------------------------------------------------------------------------------
# Runs with an output folder
# ---------------------------------------------------------------------------------------
def _write_checkpoint(out: Path, backend: Backend, ls: LoopState) -> None:
    state = {f"state__{k}": v for k, v in backend.state().items()}
    write_fields(out / "checkpoint.npz", state, loop=json.dumps(asdict(ls)))


def _read_checkpoint(out: Path) -> tuple[dict, LoopState]:
    with np.load(out / "checkpoint.npz") as z:
        state = {k[len("state__"):]: z[k] for k in z.files if k.startswith("state__")}
        ls = LoopState(**json.loads(str(z["loop"])))
    return state, ls


def _shape(be: Backend, fields: dict, final: dict) -> dict | None:
    """Shape descriptors of the final φ = 0 surface (3D only; see :mod:`fem_ade.shape`)."""
    p = be.scene.params
    phi = fields.get("phi_grid", fields["phi"])
    if be.scene.dim != 3 or not np.all(np.isfinite(phi)):
        return None
    surface = extract_surface(phi, p.L)
    d = describe(phi, p.L, surface=surface)  # the sharp surface's reduced values: sphere v = 1
    keys = ("components", "genus", "nested", "reduced_volume", "reduced_area_difference", "arms")
    shape = {k: d[k] for k in keys}
    diffuse = describe(phi, p.L, V=final.get("V"), A=final.get("A"),
                       dA=final.get("dA") if p.on("ade") else None, D=p.D, surface=surface)
    shape["diffuse"] = {k: diffuse[k] for k in ("reduced_volume", "reduced_area_difference")}
    shape["sharp"] = d["sharp"]
    return shape


def _finish(out: Path, be: Backend, result: RunResult, config: dict, series) -> None:
    fields = be.fields()
    write_fields(out / "final.npz", fields, step=result.steps, t=result.t, dt=result.dt,
                 status=result.status)
    if series is not None:
        if series.last_step != result.steps:
            series.save(LoopState(k=result.steps, t=result.t))
        series.close()
    result.shape = _shape(be, fields, result.final)
    write_json_atomic(out / "summary.json", {
        "scene": config["scene"]["name"],
        "figure": config["scene"]["figure"],
        "parameters": config["scene"]["params"],
        "backend": be.name,
        "backend_info": be.info(),
        **{k: config.get(k) for k in ("n", "dt", "scheme", "constraints", "ic", "perturb",
                                      "seed")},
        "adaptive": config["adaptive"],
        "steps": result.steps,
        "t": result.t,
        "dt_final": result.dt,
        "rejected_steps": result.rejected,
        "status": result.status,
        "message": result.message,
        "final": result.final,
        "shape": result.shape,
        "wall_s": result.wall_s,
        "versions": package_versions(),
    })
    if config.get("render", True) and result.shape is not None:
        try:
            render_run(out, quiet=True)
        except Exception as err:  # a picture must never cost the run's results
            warnings.warn(f"rendering {out} failed: {err}; the run's results are saved",
                          stacklevel=2)


def _execute(out: Path | None, scene: Scene, config: dict, *, quiet: bool,
             start: tuple[dict, LoopState] | None = None) -> RunResult:
    """Build the backend from ``config`` and run it; the one place simulate/resume share."""
    try:
        be = make_backend(config["backend"], scene, n=config["n"], dt=config["dt"],
                          ic=config["ic"], perturb=config["perturb"], seed=config["seed"],
                          scheme=config["scheme"],
                          constraints=config.get("constraints", "penalty"),
                          **config["backend_options"])
    except ConstraintError as err:
        raise ModelError(f"the initial condition cannot be projected: {err}") from None
    start_ls = None
    if start is not None:
        state, start_ls = start
        be.set_state(state)
        if start_ls.dt != config["dt"]:
            be.set_dt(start_ls.dt)
    adaptive = AdaptiveDt(**config["adaptive"]) if config["adaptive"] else None
    columns = HISTORY_COLUMNS + tuple(be.extra_columns) + (("dt",) if adaptive else ())
    writer = None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        if start is None:
            write_json_atomic(out / "run.json", config)
            writer = HistoryWriter(out / "history.csv", columns)
        else:
            truncate_history(out / "history.csv", start_ls.k)
            writer = HistoryWriter(out / "history.csv", columns, append=True)
    on_checkpoint = (lambda ls: _write_checkpoint(out, be, ls)) if out is not None else None
    series = on_save = None
    if out is not None:  # the ParaView series: the start, every save_every steps, the end
        name = "phi.xdmf" if start is None else f"phi-from-{start_ls.k}.xdmf"
        series = _Series(out / name, be)
        on_save = series.save
    try:
        result = run_loop(
            be, dt=config["dt"], steps=config["steps"], until_steady=config["until_steady"],
            max_steps=config["max_steps"], every=config["every"], quiet=quiet, history=writer,
            label=scene.name, adaptive=adaptive, checkpoint_every=config["checkpoint_every"],
            on_checkpoint=on_checkpoint, save_every=config.get("save_every"), on_save=on_save,
            start=start_ls)
    finally:
        if writer is not None:
            writer.close()
    if out is not None:
        _finish(out, be, result, config, series)
    return result


class _Series:
    """The XDMF time series of a run (ParaView): the backend's point data every K steps."""

    def __init__(self, path: Path, be: Backend):
        mesh = be.output_mesh()
        if mesh is None:
            self.xdmf = XdmfSeries.from_grid(path, be.n, be.scene.params.L, dim=be.scene.dim)
        else:
            self.xdmf = XdmfSeries(path, *mesh)
        self.be, self.last_step = be, None

    def save(self, ls: LoopState) -> None:
        """Add the backend's current fields at step ``ls.k``, time ``ls.t``."""
        self.xdmf.write(ls.t, self.be.point_data())
        self.last_step = ls.k

    def close(self) -> None:
        self.xdmf.close()


MESH_SUFFIXES = (".vtu", ".vtk", ".msh", ".xdmf", ".xml", ".mesh", ".med", ".inp")


def simulate(
    scene: Scene,
    *,
    backend: str = "fem",
    n: int | None = None,
    dt: float | None = None,
    steps: int | None = None,
    until_steady: float | None = None,
    max_steps: int = 100_000,
    every: int = 10,
    ic: str = "consistent",
    perturb: float = 0.0,
    seed: int = 0,
    scheme: str = "paper",
    constraints: str = "penalty",
    adaptive: bool | dict = False,
    checkpoint_every: int | None = None,
    save_every: int | None = None,
    render: bool = True,
    out: str | Path | None = None,
    force: bool = False,
    quiet: bool = True,
    allow_underresolved: bool = False,
    backend_options: dict | None = None,
) -> RunResult:
    """Run ``scene`` with ``backend`` and, if ``out`` is given, write its results there.

    Writes ``out/history.csv`` (row by row), ``out/summary.json`` (with the shape descriptors
    of the final surface under ``shape``), ``out/final.npz`` (the final field; on divergence the
    last finite one), ``out/run.json`` (what :func:`resume` needs), with ``checkpoint_every``
    ``out/checkpoint.npz``, the ParaView series ``out/phi.xdmf`` (+ .h5: the first state, every
    ``save_every`` steps, the last),
    and unless ``render=False`` the pictures ``out/shape.png`` and ``out/history.png``.
    All input is checked before anything is written; bad input raises
    :class:`fem_ade.model.ModelError`.

    ``adaptive=True`` lets Δt range over [Δt/1000, 1000Δt] (the paper's scheme: below ε³/κ);
    a dict gives the fields of :class:`AdaptiveDt`.
    """
    n = scene.n if n is None else n
    dt = scene.dt if dt is None else dt
    if steps is None and until_steady is None:
        steps = scene.steps
    if scheme not in SCHEMES:
        raise ModelError(f"unknown scheme {scheme!r}; valid: {', '.join(SCHEMES)}")
    if check_constraints(constraints) == "exact":  # the penalties are replaced, not added
        scene = scene.with_(effects=scene.params.effects - {"volume", "area"})
    scene.params.validate()
    options = backend_options or {}
    check_resolution(scene.params, n, dt, allow_underresolved=allow_underresolved,
                     check_dt=scheme == "paper", nodes_per_cell=options.get("order", 1),
                     check_h=not (options.get("mesh") or "").endswith(MESH_SUFFIXES))
    if perturb < 0:
        raise ModelError(f"--perturb must be >= 0, got {perturb}")
    if until_steady is not None and not until_steady > 0:
        raise ModelError(f"--until-steady must be positive, got {until_steady}")
    if adaptive is True:
        dt_max = 1000 * dt if scheme == "stabilized" else min(1000 * dt,
                                                               0.9 * max_stable_dt(scene.params))
        adaptive = {"dt_min": dt / 1000, "dt_max": max(dt, dt_max)}
    adaptive = asdict(AdaptiveDt(**adaptive)) if adaptive else None
    out = check_out_dir(out, force=force) if out is not None else None
    config = {"scene": scene_to_mapping(scene), "backend": backend, "n": n, "dt": dt,
              "steps": steps, "until_steady": until_steady, "max_steps": max_steps,
              "every": every, "ic": ic, "perturb": perturb, "seed": seed, "scheme": scheme,
              "constraints": constraints,
              "adaptive": adaptive, "checkpoint_every": checkpoint_every,
              "save_every": save_every, "render": render,
              "backend_options": options}
    return _execute(out, scene, config, quiet=quiet)


def resume(out: str | Path, *, steps: int | None = None, quiet: bool = True) -> RunResult:
    """Continue the run in ``out`` from its checkpoint up to step ``steps`` (default: as before).

    The continued run is bit for bit the uninterrupted one.
    """
    out = Path(out)
    if not (out / "run.json").is_file() or not (out / "checkpoint.npz").is_file():
        raise ModelError(f"cannot resume {out}: it has no run.json and checkpoint.npz "
                         "(run with --checkpoint-every K, or interrupt with Ctrl-C)")
    config = read_json(out / "run.json")
    if steps is not None:
        if config["until_steady"] is not None:
            config["max_steps"] = steps
        else:
            config["steps"] = steps
    scene = scene_from_mapping(config["scene"], where=str(out / "run.json"))
    state, ls = _read_checkpoint(out)
    total = config["steps"] if config["until_steady"] is None else config["max_steps"]
    if total < ls.k:
        raise ModelError(f"the checkpoint is at step {ls.k}, past --steps {total}")
    return _execute(out, scene, config, quiet=quiet, start=(state, ls))
