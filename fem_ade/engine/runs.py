"""Runs with an output folder: the Python API behind the command line.

:func:`simulate` checks every input and builds the backend; :func:`resume` checks a run
folder's run.json and checkpoint and rebuilds the backend from it. Either then hands the
backend to :func:`fem_ade.engine.execute.execute`, which drives it with
:func:`fem_ade.engine.loop.run_loop` and writes the run folder. Nothing here knows which backend
it runs: backend-specific options are checked by the backend's own
:meth:`~fem_ade.backends.base.Backend.check` and passed through unread.

This module is what a caller uses: the checks of a run's inputs, the backend built from them,
a recipe's options, a folder's run.json read back (:func:`read_run`), and the identity of a run
still to be made or of a folder's run (:func:`planned_identity`, :func:`folder_identity`,
which read a run as :func:`simulate` and :func:`read_run` do). What a run folder holds is
documented in :mod:`fem_ade.engine.execute`, which writes it. The folder's internals stand
below this module, and neither imports it: :mod:`fem_ade.engine.folder` holds a run's
identity, the checksums and the checkpoint file, and :mod:`fem_ade.engine.execute` the run
written while and after the loop runs.
"""

from __future__ import annotations

import inspect
import time
from dataclasses import fields as dataclass_fields
from pathlib import Path

import numpy as np

from fem_ade.backends.base import Backend, backend_class, make_backend
from fem_ade.backends.threads import limit_threads
from fem_ade.engine.config import RunConfig, option, upgraded
from fem_ade.engine.execute import execute
from fem_ade.engine.folder import identity_difference, read_checkpoint, run_identity, state_digest
from fem_ade.engine.loop import RunResult
from fem_ade.model.params import ModelError, is_real
from fem_ade.scenes.catalogue import Scene, scene_from_mapping
from fem_ade.scenes.fields import check_grid_field
from fem_ade.scenes.initial import FieldIC
from fem_ade.store.output import (
    check_history,
    check_out_dir,
    history_digest,
    prepare_out_dir,
    read_json,
    write_fields,
)

#: the start field a run keeps in its folder, recorded in run.json relative to the folder
#: (a moved folder still reads and resumes)
KEPT_START = "initial.npz"


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
    fresh: bool = False,
    config: RunConfig | None = None,
) -> RunResult:
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
    previous run's files in it are removed. :func:`plan` checks the same and says what
    would run.
    """
    scene, config, initial, out, be = _prepare(locals())
    if out is None:
        return execute(out, scene, config, quiet=quiet, monitor=monitor, be=be)
    lock = prepare_out_dir(out, force=force, fresh=fresh)  # ours until the run ends
    try:
        if initial is not None:  # the start field is kept with the run
            write_fields(out / KEPT_START, initial)
            scene = scene.with_(ic=FieldIC(path=KEPT_START, base=str(out.resolve()),
                                           grid=initial.get("phi_grid", initial.get("phi"))))
        return execute(out, scene, config, quiet=quiet, monitor=monitor, be=be)
    finally:
        lock.release()


def plan(scene, **options) -> str:
    """What ``simulate(scene, **options)`` would run, in one line — every input checked as
    :func:`simulate` checks it (ModelError, TypeError), the backend built, nothing written
    (``python -m fem_ade.run --dry-run``)."""
    defaults = _simulate_defaults()
    unknown = sorted((set(options) - set(defaults)) | ({"scene"} & set(options)))
    if unknown:
        raise TypeError(f"plan() takes simulate's keywords; not {', '.join(unknown)}")
    scene, config, _, out, be = _prepare({**defaults, **options, "scene": scene})
    grid = be.info().get("resolution", f"n = {config.n}")
    return (f"{scene.name} with the {config.backend} backend ({grid}, "
            f"{config.scheme} scheme, {config.constraints} constraints, "
            f"dt = {config.dt:g}, "
            + (f"{config.steps} steps" if config.steps is not None else
               f"until steady (tol {config.until_steady:g}, at most {config.max_steps} "
               "steps)")
            + (", momentum" if config.accelerate else "") + ")"
            + (f" into {out}" if out is not None else ""))


def _prepare(values: dict):
    """(scene as run, configuration, the start field to keep, the output folder, the
    backend) of a :func:`simulate` call's keyword ``values``: everything checked (ModelError,
    TypeError), nothing written."""
    scene, config, monitor = _scene_argument(values["scene"]), values["config"], values["monitor"]
    if config is not None:
        if not isinstance(config, RunConfig):
            raise TypeError(f"config must be a fem_ade.engine.config.RunConfig, got "
                            f"{type(config).__name__}")
        given = _run_keywords_given(values)
        if given:
            raise ModelError(f"give config or the run's keywords, not both: {', '.join(given)} "
                             "would be ignored (config.with_(...) changes a configuration)")
    if monitor is not None and not callable(monitor):
        raise TypeError(f"monitor must be callable (backend, row), got "
                        f"{type(monitor).__name__}")
    if config is None:
        if not is_real(values["perturb"]):  # None included: perturb has no "not given"
            raise ModelError(f"{option('perturb')} must be a number >= 0, got "
                             f"{values['perturb']!r}")
        config = RunConfig.build(scene, **{k: values[k] for k in _RUN_KEYWORDS})
    scene, initial = _start_field(scene, values["phi0"])
    config.check(scene, allow_underresolved=values["allow_underresolved"])
    scene = scene_as_run(scene, config)
    out = values["out"]
    out = check_out_dir(out, force=values["force"]) if out is not None else None
    be = build_backend(scene, config)  # checks the initial field, writes nothing
    return scene, config, initial, out, be


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


#: simulate's keywords that a RunConfig holds, its fields (with ``config=``, none may be
#: given)
_RUN_KEYWORDS = tuple(f.name for f in dataclass_fields(RunConfig))


def _simulate_defaults() -> dict:
    """simulate's keywords and their defaults (``scene``: no default)."""
    return {k: p.default for k, p in inspect.signature(simulate).parameters.items()}


def _run_keywords_given(values: dict) -> list[str]:
    """The run keywords of a simulate call that differ from their defaults."""
    defaults = _simulate_defaults()
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
        result = execute(out, scene, config, quiet=quiet, start=(state, ls), be=be)
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
        own = (data["scene"].get("ic") or {}).get("path") == KEPT_START  # the folder's
        scene = scene_from_mapping(data["scene"], where=str(out / "run.json"),
                                   files=str(out.resolve()) if own else "")
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

