"""A run folder's identity and its checkpoint: what makes a checkpoint this very run's.

:func:`run_identity` is what a checkpoint must match to be resumed (the scene as run and every
field of the configuration but :data:`RESUMABLE_CHANGES`), :func:`identity_difference` names
the first field where two identities differ, and :func:`state_digest` is the checksum of a
checkpoint's state; :func:`write_checkpoint` and :func:`read_checkpoint` write and read
``checkpoint.npz``, which carries the state with all three.

Why a module of its own: both sides of a run folder use these, and they need nothing of
either. Writing a run (:mod:`fem_ade.engine.execute`) leaves a checkpoint every K steps; the
API (:mod:`fem_ade.engine.runs`) checks one before a resume, and
:func:`fem_ade.engine.jobs.ensure` asks whether a folder's run is the one it was asked for.
The identities of a run still to be made and of a folder's run.json
(:func:`fem_ade.engine.runs.planned_identity`, :func:`fem_ade.engine.runs.folder_identity`)
stay with the API, because they read a run as :func:`~fem_ade.engine.runs.simulate` and
:func:`~fem_ade.engine.runs.read_run` do.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from fem_ade.backends.base import Backend
from fem_ade.engine.config import RunConfig
from fem_ade.engine.loop import LoopState
from fem_ade.model.params import ModelError
from fem_ade.scenes.catalogue import Scene, scene_to_mapping
from fem_ade.store.output import history_digest, write_fields

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


def write_checkpoint(out: Path, backend: Backend, ls: LoopState, identity: dict,
                     spent: dict | None = None) -> None:
    """OUT/checkpoint.npz: the backend's state and the loop's (with momentum, its previous
    iterate), whose run it is, and the checksums of the state and of history.csv up to its
    step (a resume checks both), atomically. ``spent``: the loop's CPU and wall seconds up
    to this step, summed over the run's sittings (:func:`checkpoint_spent`; a record, not
    checksummed)."""
    state = backend.state()
    arrays = {f"state__{k}": v for k, v in state.items()}
    arrays.update({f"anchor__{k}": v for k, v in (ls.anchor or {}).items()})
    digests = {"state": state_digest(state, ls),
               "history": history_digest(out / "history.csv", ls.k)}
    write_fields(out / "checkpoint.npz", arrays, loop=json.dumps(ls.to_json()),
                 identity=json.dumps(identity), digests=json.dumps(digests),
                 spent=json.dumps(spent or {}))


def checkpoint_spent(out: Path) -> dict:
    """{"cpu_s", "wall_s"}: the loop's seconds up to OUT/checkpoint.npz's step over the
    sittings before it (what :func:`write_checkpoint` recorded); zeros for a checkpoint
    written before it recorded them, or none. A resumed run adds them to its own, so a
    run's summary.json counts every sitting (to the checkpoint each one left)."""
    zero = {"cpu_s": 0.0, "wall_s": 0.0}
    try:
        with np.load(out / "checkpoint.npz") as z:
            spent = json.loads(str(z["spent"])) if "spent" in z.files else {}
        return {k: float(spent.get(k, 0.0)) for k in zero}
    except (OSError, ValueError, KeyError, TypeError):
        return zero


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

