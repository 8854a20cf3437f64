"""Runs with an output folder: the Python API behind the command line.

:func:`simulate` checks every input, builds the backend, drives it with
:func:`fem_ade.engine.loop.run_loop` and writes the run folder; :func:`resume` continues a run from
its
checkpoint. Nothing here knows which backend it runs: backend-specific options are checked by
the backend's own :meth:`~fem_ade.backends.base.Backend.check` and passed through unread.

A run folder holds ``run.json`` (what :func:`resume` needs), ``history.csv`` (written row by
row), ``summary.json``, ``final.npz``, the ParaView series ``phi.xdmf`` (the mesh in
``phi.h5``, each saved step in ``phi-KKKKKKKK.h5``), with
``checkpoint_every`` a ``checkpoint.npz``, with ``phi0`` given as an array ``initial.npz``, and
unless ``render=False`` the pictures ``shape.png`` and ``history.png``. The shape descriptors
and the pictures are computed once, from the fields in memory.
"""

from __future__ import annotations

import json
import os
import time
import warnings
from pathlib import Path

import numpy as np

from fem_ade.backends.base import Backend, backend_class, make_backend
from fem_ade.backends.threads import limit_threads
from fem_ade.engine.config import RunConfig, option, upgraded
from fem_ade.engine.loop import AdaptiveDt, LoopState, RunResult, run_loop
from fem_ade.model.params import HISTORY_COLUMNS, ModelError, is_real
from fem_ade.scenes.catalogue import Scene, scene_from_mapping, scene_to_mapping
from fem_ade.scenes.fields import check_grid_field
from fem_ade.scenes.initial import FieldIC
from fem_ade.store.output import (
    HistoryWriter,
    check_history,
    check_out_dir,
    history_digest,
    package_versions,
    parse_cell,
    prepare_out_dir,
    read_json,
    truncate_csv,
    truncate_history,
    write_fields,
    write_json_atomic,
)
from fem_ade.store.status import Status
from fem_ade.store.xdmf import XdmfSeries


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


def recipe(name: str, scene: Scene) -> dict:
    """The :func:`simulate` keyword arguments of a recipe (:data:`fem_ade.registry.RECIPES`)
    for ``scene``: ``simulate(scene, **{**recipe("steady", scene), **yours})``."""
    from fem_ade.registry import RECIPE_SETTINGS

    if name not in RECIPE_SETTINGS:
        raise ModelError(f"unknown recipe {name!r}; choose from {', '.join(RECIPE_SETTINGS)}")
    kw = dict(RECIPE_SETTINGS[name])
    if "dt_factor" in kw:
        kw["dt"] = kw.pop("dt_factor") * scene.dt
    return kw


@limit_threads
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
    phi0=None,
    scheme: str = "paper",
    constraints: str = "penalty",
    adaptive: bool | dict = False,
    accelerate: bool = False,
    checkpoint_every: int | None = None,
    save_every: int | None = None,
    shape_every: int | None = None,
    monitor=None,
    render: bool = True,
    sharp: bool = True,
    out: str | Path | None = None,
    force: bool = False,
    quiet: bool = True,
    allow_underresolved: bool = False,
    backend_options: dict | None = None,
    dry_run: bool = False,
    fresh: bool = False,
    config: RunConfig | None = None,
) -> RunResult | str:
    """Run ``scene`` with ``backend`` and, if ``out`` is given, write its run folder there.

    ``phi0``: start from this field instead of the scene's initial condition: an array on a
    uniform periodic grid (m,)*dim of the scene's box, or the path of an earlier run folder or
    of its final.npz; it is resampled to the backend's points. All input is checked before
    anything is written; bad input raises :class:`fem_ade.model.params.ModelError`.

    ``adaptive=True`` lets Δt range over [Δt/1000, 1000Δt] (the paper's scheme: below ε³/κ);
    a dict gives the fields of :class:`fem_ade.engine.loop.AdaptiveDt`. ``accelerate=True`` iterates
    the step with momentum towards a steady state (:mod:`fem_ade.engine.loop`; not a time history).

    ``sharp=False`` leaves out the comparison of the end shape with its sharp membrane
    (``sharp_reference``: a sharp_ref solve of 0.3–10 s after the run; a study that does not
    read it need not wait for it).

    ``shape_every=K`` records the shape descriptors every K steps (and at the start) in
    ``OUT/shapes.csv`` and in the result's ``shapes`` (a transient shows as a label that comes
    and goes); ``monitor(backend, row)`` (Python only) is then called with each row.

    The run's choices become one :class:`fem_ade.engine.config.RunConfig` (or give ``config``, one
    built already, instead of them): every input is checked first (ModelError, nothing
    created): the numbers, the scene, the backend's options, the output folder, and the
    initial field (finite, with an inside and an outside). Then the folder is made
    (``fresh``: a new folder, as the CLI's default) and locked, and, with ``force``, the
    previous run's files in it are removed. ``dry_run``: check, then return a one-line
    description instead of running.
    """
    scene = _scene_argument(scene)
    if config is not None:
        if not isinstance(config, RunConfig):
            raise TypeError(f"config must be a fem_ade.engine.config.RunConfig, got "
                            f"{type(config).__name__}")
        given = _run_keywords_given(locals())
        if given:
            raise ModelError(f"give config or the run's keywords, not both: {', '.join(given)} "
                             "would be ignored (config.with_(...) changes a configuration)")
    if monitor is not None and not callable(monitor):
        raise TypeError(f"monitor must be callable (backend, row), got "
                        f"{type(monitor).__name__}")
    if config is None:
        if not is_real(perturb):  # None included: perturb has no "not given"
            raise ModelError(f"{option('perturb')} must be a number >= 0, got {perturb!r}")
        config = RunConfig.build(
            scene, backend=backend, n=n, dt=dt, steps=steps, until_steady=until_steady,
            max_steps=max_steps, every=every, ic=ic, perturb=perturb, seed=seed, scheme=scheme,
            constraints=constraints, adaptive=adaptive, accelerate=accelerate,
            checkpoint_every=checkpoint_every, save_every=save_every, shape_every=shape_every,
            render=render, sharp=sharp, backend_options=backend_options)
    scene, initial = _start_field(scene, phi0)
    config.check(scene, allow_underresolved=allow_underresolved)
    scene = scene_as_run(scene, config)
    out = check_out_dir(out, force=force) if out is not None else None
    be = build_backend(scene, config)  # checks the initial field, writes nothing
    if dry_run:
        info = be.info()
        grid = info.get("resolution", f"n = {config.n}")
        return (f"{scene.name} with the {config.backend} backend ({grid}, "
                f"{config.scheme} scheme, {config.constraints} constraints, "
                f"dt = {config.dt:g}, "
                + (f"{config.steps} steps" if config.steps is not None else
                   f"until steady (tol {config.until_steady:g}, at most {config.max_steps} "
                   "steps)")
                + (", momentum" if config.accelerate else "") + ")"
                + (f" into {out}" if out is not None else ""))
    if out is None:
        return _execute(out, scene, config, quiet=quiet, monitor=monitor, be=be)
    lock = prepare_out_dir(out, force=force, fresh=fresh)  # ours until the run ends
    try:
        if initial is not None:  # the start field is kept with the run
            write_fields(out / "initial.npz", initial)
            scene = scene.with_(ic=FieldIC(path=str((out / "initial.npz").resolve()),
                                           grid=initial.get("phi_grid", initial.get("phi"))))
        return _execute(out, scene, config, quiet=quiet, monitor=monitor, be=be)
    finally:
        lock.release()


def _start_field(scene, phi0) -> tuple:
    """(the scene starting from ``phi0``, the fields its run keeps in initial.npz), or
    (scene, None) without ``phi0``: a grid field (``phi``), or an axisymmetric run's (its
    grid ``phi_grid`` and its (r, z) nodes: such a run resumes from them)."""
    if phi0 is None:
        return scene, None
    if isinstance(phi0, (str, Path)):
        scene = scene.with_(ic=FieldIC(path=str(Path(phi0).resolve())))
        scene.ic.check(scene.dim)
        grid = scene.ic.values()  # kept with the run: it resumes if phi0 moves
        meridian = scene.ic.meridian()
        initial = {"phi": grid} if meridian is None else {"phi_grid": grid, **meridian}
    else:
        if np.iscomplexobj(phi0):
            raise ModelError("phi0 must be a real field, got complex values")
        initial = {"phi": check_grid_field(phi0, "phi0")}
        scene = scene.with_(ic=FieldIC(grid=initial["phi"]))
        scene.ic.check(scene.dim)
    return scene, initial


#: simulate's keywords that a RunConfig holds (with ``config=``, none may be given)
_RUN_KEYWORDS = ("backend", "n", "dt", "steps", "until_steady", "max_steps", "every", "ic",
                 "perturb", "seed", "scheme", "constraints", "adaptive", "accelerate",
                 "checkpoint_every", "save_every", "shape_every", "render", "sharp",
                 "backend_options")


def _run_keywords_given(values: dict) -> list[str]:
    """The run keywords of a simulate call that differ from their defaults."""
    import inspect

    defaults = {k: p.default for k, p in inspect.signature(simulate).parameters.items()}
    return [k for k in _RUN_KEYWORDS if values[k] is not defaults[k]
            and values[k] != defaults[k]]


def scene_as_run(scene: Scene, config: RunConfig) -> Scene:
    """The scene as ``config`` runs it, as run.json records it: its grid the run's (points
    per axis, so that the backend's default n for it is ``config.n``) and, with
    ``ic="seeded"``, its initial shape the seeded one (:mod:`fem_ade.scenes.seeds`)."""
    changes = {}
    nodes = backend_class(config.backend, **config.backend_options).nodes_per_axis(
        config.n, **config.backend_options)
    if nodes is not None and nodes != scene.n:
        changes["n"] = nodes
    if config.ic == "seeded" and not scene.ic.is_field:
        from fem_ade.scenes.seeds import seeded_shape

        changes["ic"] = seeded_shape(scene.name)
    return scene.with_(**changes) if changes else scene


def _scene_argument(scene) -> Scene:
    """``scene`` of the Python API: a Scene, or the name of a catalogue scene or a TOML file
    (as on the command line); TypeError for anything else."""
    if isinstance(scene, Scene):
        return scene
    if isinstance(scene, (str, Path)):
        from fem_ade.scenes.catalogue import resolve_scene

        return resolve_scene(str(scene))
    raise TypeError(f"scene must be a Scene or a scene name, got {type(scene).__name__}")


def build_backend(scene: Scene, config: RunConfig, state: dict | None = None) -> Backend:
    """The run's backend (its initial field checked: finite, with an inside), or from a
    checkpoint's ``state``."""
    c0 = time.process_time()
    be = make_backend(config.backend, scene, n=config.n, ic=config.ic,
                      perturb=config.perturb, seed=config.seed, scheme=config.scheme,
                      constraints=config.constraints, start_state=state,
                      **config.backend_options)
    be.setup_cpu_s = time.process_time() - c0  # the set-up's CPU time (summary.json)
    phi = be.fields()["phi"]
    if not np.all(np.isfinite(phi)):
        raise ModelError("the initial field is not finite" if state is None else
                         "the checkpoint's field is not finite")
    if state is None and np.count_nonzero(phi > 0) < 2**scene.dim:
        raise ModelError(f"the initial field has no inside (phi > 0 at fewer than "
                         f"{2**scene.dim} nodes): the scene's shape is smaller than the grid "
                         f"resolves, or does not fit its box (L = {scene.params.L})")
    if state is None and np.count_nonzero(phi < 0) < 2**scene.dim:
        raise ModelError(f"the initial field has no outside (phi < 0 at fewer than "
                         f"{2**scene.dim} nodes): the scene's shape covers its whole box "
                         f"(L = {scene.params.L}), so there is no membrane")
    return be


def default_out(scene_name: str, backend: str) -> Path:
    """A new folder name under runs/: the scene, the backend, the time and a random suffix
    (two runs started in the same second never share one; the folder is made fresh)."""
    import secrets

    stamp = time.strftime("%Y%m%d-%H%M%S")
    return Path("runs") / f"{scene_name}-{backend}-{stamp}-{secrets.token_hex(2)}"


@limit_threads
def resume(out: str | Path, *, steps: int | None = None, quiet: bool = True,
           with_config: bool = False):
    """Continue the run in ``out`` from its checkpoint up to step ``steps`` (default: as before).

    The continued run is bit for bit the uninterrupted one. The folder is locked first
    (:class:`fem_ade.store.lock.FolderBusy` if another process holds it), then everything read is
    checked before anything is written (ModelError, nothing changed): run.json with the
    checks of a new run (scene, backend and its options, the loop's numbers), the checkpoint
    (readable, complete, finite, its step within the run, of this very run: scene, backend,
    resolution, options, scheme, constraints and parameters) and history.csv.
    ``with_config``: return (result, scene, config).
    """
    from fem_ade.store.lock import FolderLock

    out = Path(out)
    missing = [name for name in ("run.json", "checkpoint.npz") if not (out / name).is_file()]
    if missing:
        raise ModelError(f"cannot resume {out}: it has no {' and no '.join(missing)} "
                         "(run with --checkpoint-every K, or interrupt with Ctrl-C)")
    lock = FolderLock(out).acquire()
    try:
        scene, config, state, ls = _check_resumable(out, steps)
        try:
            be = build_backend(scene, config, state)
        except (ValueError, TypeError, KeyError) as err:  # ModelError is a ValueError too
            if isinstance(err, ModelError):
                raise ModelError(f"cannot resume {out}: {err}") from None
            raise ModelError(f"cannot resume {out}: the checkpoint's state does not fit this "
                             f"run ({type(err).__name__}: {err})") from None
        result = _execute(out, scene, config, quiet=quiet, start=(state, ls), be=be)
    finally:
        lock.release()
    return (result, scene, config) if with_config else result


def read_run(out: str | Path, doing: str = "read") -> tuple[Scene, RunConfig]:
    """(scene, configuration) of a run folder's run.json; ModelError (one line, "cannot
    DOING OUT: ...") if it is missing or not a run's."""
    out = Path(out)
    try:
        data = read_json(out / "run.json")
        if not isinstance(data, dict) or "scene" not in data:
            raise KeyError("scene")
        scene = scene_from_mapping(data["scene"], where=str(out / "run.json"))
        config = RunConfig.from_mapping({k: v for k, v in data.items() if k != "scene"})
    except ModelError as err:
        raise ModelError(f"cannot {doing} {out}: {err}") from None
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as err:
        raise ModelError(f"cannot {doing} {out}: run.json is not a run's ({err!r})") from None
    return scene, config


def _check_resumable(out: Path, steps: int | None):
    """(scene, config, state, loop state) of a run folder to resume, every piece checked as
    a new run's would be; ModelError (one line) for the first that is not right."""
    scene, config = read_run(out, "resume")
    try:
        config.check(scene, allow_underresolved=True)
        if steps is not None:  # --steps N: continue to step N (checked as a new run's)
            config = config.continued_to(steps)
    except (ModelError, TypeError, ValueError) as err:
        raise ModelError(f"cannot resume {out}: run.json: {err}") from None
    state, ls, identity, digests = read_checkpoint(out)
    if identity is None or "config" not in identity or digests is None:
        raise ModelError(f"cannot resume {out}: its checkpoint.npz carries no checksums (an "
                         "older fem_ade wrote it): start the run again")
    if isinstance(identity.get("config"), dict):  # a checkpoint of an older RUN_FORMAT
        identity = {**identity, "config": upgraded(identity["config"])}
    difference = identity_difference(identity, run_identity(scene, config))
    if difference:
        raise ModelError(f"cannot resume {out}: its checkpoint.npz belongs to another run than "
                         f"run.json's ({difference}); a resume continues that very run")
    if digests.get("state") != state_digest(state, ls):
        raise ModelError(f"cannot resume {out}: the checkpoint's state does not match its "
                         "checksum (changed after it was written)")
    if not (isinstance(ls.k, int) and ls.k >= 0):
        raise ModelError(f"cannot resume {out}: the checkpoint's step is {ls.k!r}, not an "
                         "integer >= 0")
    if not (is_real(ls.t) and ls.t >= 0 and is_real(ls.dt) and ls.dt > 0):
        raise ModelError(f"cannot resume {out}: the checkpoint's time or time step is not "
                         f"usable (t = {ls.t!r}, dt = {ls.dt!r})")
    if config.total_steps < ls.k:
        raise ModelError(f"the checkpoint is at step {ls.k}, past --steps {config.total_steps}")
    check_history(out / "history.csv", ls.k)
    if digests.get("history") != history_digest(out / "history.csv", ls.k):
        raise ModelError(f"cannot resume {out}: history.csv up to step {ls.k} is not the one "
                         "its checkpoint was written after (rows changed, missing or added)")
    return scene, config, state, ls


#: the run.json fields a resume may change: how far it goes, how often it writes a
#: checkpoint, whether it draws or compares with the sharp membrane — none changes the
#: trajectory or a file already written
RESUMABLE_CHANGES = ("steps", "max_steps", "checkpoint_every", "render", "sharp")


def run_identity(scene: Scene, config: RunConfig) -> dict:
    """What a checkpoint must match to be resumed: the scene as run and every field of the
    configuration but :data:`RESUMABLE_CHANGES` (as JSON would store them)."""
    config_map = {k: v for k, v in config.to_mapping().items() if k not in RESUMABLE_CHANGES}
    return json.loads(json.dumps({"scene": scene_to_mapping(scene), "config": config_map},
                                 sort_keys=True, default=str))


def planned_identity(scene, options: dict) -> dict:
    """The :func:`run_identity` of the run ``simulate(scene, **options)`` would make (its
    configuration built as simulate builds it, nothing run or written): what
    :func:`fem_ade.engine.jobs.ensure` compares with an ended folder's. ModelError or TypeError for
    options simulate would refuse."""
    scene = _scene_argument(scene)
    config = RunConfig.build(scene, **{k: options[k] for k in _RUN_KEYWORDS if k in options})
    return run_identity(scene_as_run(scene, config), config)


def folder_identity(out: str | Path) -> dict:
    """The :func:`run_identity` of the run a folder's run.json records; ModelError (one
    line) if it has none or it is not a run's."""
    return run_identity(*read_run(out))


def identity_difference(stored: dict, current: dict, where: str = "") -> str | None:
    """The first field where two identities differ, as 'FIELD: A in the checkpoint, B in
    run.json', or None."""
    if isinstance(stored, dict) and isinstance(current, dict):
        for key in sorted(set(stored) | set(current)):
            d = identity_difference(stored.get(key), current.get(key),
                                    f"{where}.{key}" if where else key)
            if d:
                return d
        return None
    if stored != current:
        name = where.replace("config.", "", 1)

        def short(x):
            text = json.dumps(x, default=str)
            return text if len(text) <= 60 else text[:57] + "..."

        return f"{name}: {short(stored)} in the checkpoint, {short(current)} in run.json"
    return None


def state_digest(state: dict, ls: LoopState) -> str:
    """SHA-256 of a checkpoint's backend state (names, dtypes, shapes, bytes), its loop state
    and the momentum anchor: a resume refuses a checkpoint changed after it was written."""
    import hashlib

    h = hashlib.sha256()
    for prefix, arrays in (("state", state), ("anchor", ls.anchor or {})):
        for name in sorted(arrays):
            a = np.ascontiguousarray(arrays[name])
            h.update(f"{prefix}/{name}/{a.dtype.str}/{a.shape};".encode())
            h.update(a.tobytes())
    h.update(json.dumps(ls.to_json(), sort_keys=True, default=str).encode())
    return h.hexdigest()


# ---------------------------------------------------------------------------------------
# the run folder
# ---------------------------------------------------------------------------------------
def write_checkpoint(out: Path, backend: Backend, ls: LoopState, identity: dict) -> None:
    """OUT/checkpoint.npz: the backend's state and the loop's (with momentum, its previous
    iterate), whose run it is, and the checksums of the state and of history.csv up to its
    step (a resume checks both), atomically."""
    state = backend.state()
    arrays = {f"state__{k}": v for k, v in state.items()}
    arrays.update({f"anchor__{k}": v for k, v in (ls.anchor or {}).items()})
    digests = {"state": state_digest(state, ls),
               "history": history_digest(out / "history.csv", ls.k)}
    write_fields(out / "checkpoint.npz", arrays, loop=json.dumps(ls.to_json()),
                 identity=json.dumps(identity), digests=json.dumps(digests))


def read_checkpoint(out: Path) -> tuple[dict, LoopState, dict | None, dict | None]:
    """(backend state, loop state, identity, checksums) of OUT/checkpoint.npz; ModelError if
    it is unreadable, incomplete or not finite."""
    path = out / "checkpoint.npz"
    try:
        with np.load(path) as z:
            def part(prefix):
                return {k[len(prefix):]: np.array(z[k]) for k in z.files
                        if k.startswith(prefix)}

            state, anchor = part("state__"), part("anchor__")
            ls = LoopState(**json.loads(str(z["loop"])), anchor=anchor or None)
            identity = json.loads(str(z["identity"])) if "identity" in z.files else None
            digests = json.loads(str(z["digests"])) if "digests" in z.files else None
    except Exception as err:  # noqa: BLE001 (numpy raises many kinds for a broken file)
        raise ModelError(f"cannot resume {out}: checkpoint.npz is unreadable or incomplete "
                         f"({type(err).__name__}: {err})") from None
    if not state:
        raise ModelError(f"cannot resume {out}: checkpoint.npz holds no state")
    for name, value in {**state, **anchor}.items():
        if np.issubdtype(value.dtype, np.number) and not np.all(np.isfinite(value)):
            raise ModelError(f"cannot resume {out}: the checkpoint's {name} is not finite")
    return state, ls, identity, digests


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


def _execute(out: Path | None, scene: Scene, config: RunConfig, *, quiet: bool, be: Backend,
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

    def checkpoint(ls):
        with critical():
            write_checkpoint(out, be, ls, identity)

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
