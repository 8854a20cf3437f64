"""A branch's folder (:mod:`fem_ade.campaigns.branch` follows the branch into it):
``branch.json`` (the branch's identity), ``points/NNNN/`` (each point's φ and row, with their
checksums), ``branch.csv`` (the table) and ``ended.json`` (why the branch ended).

``points/NNNN/`` holds ``final.npz`` (φ and its points) and ``summary.json`` (the point's
parameter, E and its parts, V, A, ΔA, e = (W + G)/W_sphere, the φ = 0 surface's v and Δa,
the label, the lowest eigenvalues and the unstable count, Newton's iterations). ``branch.json``
says what the branch is: a resumed one must be the same; its --to may differ, on the same
side of --from (the branch goes on to it). Killed and started again with the same command, a
branch goes on from its last points — only from points it can vouch for
(:func:`load_points`): each point's summary.json carries its ``integrity`` (the checksum of
the branch's identity, its index, the checksums of its φ and its row), and a gap, a
stranger, a copy, an edit or a folder without branch.json stops the resume with one line.

``branch.json``'s identity is read in the current format whichever fem_ade wrote it
(:func:`upgraded_identity`): the one place that knows how older branch folders counted
``n`` (the stability of a branch point, :mod:`fem_ade.campaigns.stability`, reads one).

Why a module of its own: what is on disk, and whether it can be trusted, is read without
the solver — by a sweep of branches (:func:`row_digest` of a branch point's last row), the
stability of a saved point and the studies — and changes with the folder's format, not
with the numerics (:mod:`fem_ade.campaigns.continuation`).
"""

from __future__ import annotations

import json
import math
import os
import zipfile
from pathlib import Path

import numpy as np

from fem_ade.backends.fem.axisym import DEFAULT_ORDER
from fem_ade.engine.config import RUN_FORMAT
from fem_ade.model.params import HISTORY_COLUMNS, ModelError, is_int

#: the table's columns: a point's energies and functionals are the history's columns
#: (:data:`fem_ade.model.params.HISTORY_COLUMNS` after step and t)
COLUMNS = ("point", "e", *HISTORY_COLUMNS[2:], "v_surface", "da_surface", "unstable",
           "lowest_eigenvalue", "label", "fold", "newton", "seconds", "newton_s", "stability_s")


# ---------------------------------------------------------------------------------------------
# branch.json: the branch's identity
# ---------------------------------------------------------------------------------------------
def upgraded_identity(stored):
    """A branch.json's identity as the current code writes it: one made before ``format``
    (:data:`fem_ade.engine.config.RUN_FORMAT`) counted ``n`` in cells of order p, n·p
    nodes per L. What is no identity is returned as it is."""
    if not isinstance(stored, dict) or not isinstance(stored.get("options"), dict):
        return stored
    order = stored["options"].get("order", DEFAULT_ORDER)
    if "format" not in stored and is_int(stored.get("n"), 1) and is_int(order, 1):
        stored = {**stored, "n": stored["n"] * order, "format": RUN_FORMAT}
    return stored


def read_identity(folder: str | Path) -> dict:
    """The identity of the branch in ``folder`` (its branch.json, :func:`upgraded_identity`);
    OSError or ValueError where it has none readable."""
    return upgraded_identity(json.loads((Path(folder) / "branch.json").read_text()))


def same_identity(stored, identity: dict) -> bool:
    """Whether a branch.json's identity is ``identity`` (a branch as the current code
    writes it): equal once upgraded, where a folder made before a backend option's default
    was written out (``order``) counts as having that default."""
    stored = upgraded_identity(stored)
    if stored == identity:
        return True
    if not isinstance(stored, dict) or not isinstance(stored.get("options"), dict):
        return False
    filled = {**stored, "options": {"order": DEFAULT_ORDER, **stored["options"]}}
    return filled == identity


def check_out(out) -> Path:
    """``--out`` as a path a branch folder can be made in (ModelError, one line)."""
    from fem_ade.store.output import check_creatable, check_path_name

    if not isinstance(out, (str, Path)) or str(out).strip() in ("", "."):
        raise ModelError("--out needs a folder name (a new folder, or the branch's own)")
    out = Path(out)
    check_path_name(out)
    if out.exists() and not out.is_dir():
        raise ModelError(f"--out {out} exists and is not a folder")
    if out.exists():
        if not os.access(out, os.W_OK | os.X_OK):
            raise ModelError(f"--out {out} is not writable")
    else:
        check_creatable(out)
    return out


def lock_folder(out: Path):
    """``out`` made (with its parents) and locked for this process: its
    :class:`fem_ade.store.lock.FolderLock`, acquired; ModelError (one line) where it cannot
    be made or locked."""
    from fem_ade.store.lock import FolderLock

    try:
        out.mkdir(parents=True, exist_ok=True)
        return FolderLock(out).acquire()
    except OSError as err:
        raise ModelError(f"--out {out}: cannot make or lock it ({err.strerror or err})") from None


def open_folder(out: Path, identity: dict) -> dict:
    """The branch folder ``out`` (locked) made this branch's: a new or empty one gets its
    branch.json, one with this branch's is gone on with; ModelError (one line) for a folder
    of another branch, one whose branch.json is not a branch's, or one that holds files but
    no branch.json (a run folder; a branch whose record was removed, whose points could be
    of any model). Returns the identity as branch.json holds it."""
    from fem_ade.store.output import contents, write_json_atomic

    recorded = out / "branch.json"
    if recorded.exists() or recorded.is_symlink():
        try:
            stored = json.loads(recorded.read_text())
        except (OSError, ValueError) as err:
            raise ModelError(f"{recorded} is not a branch's record ({type(err).__name__}): "
                             "give another --out") from None
        if not same_identity(stored, identity):
            from fem_ade.engine.runs import identity_difference

            why = identity_difference(stored, identity) if isinstance(stored, dict) else None
            why = "" if why is None else " (" + why.replace("in the checkpoint", "there").replace(
                "in run.json", "now") + ")"
            raise ModelError(f"{out} holds another branch{why}: give another --out")
        return stored
    if contents(out):
        raise ModelError(f"{out} holds files but no branch.json: it is no branch folder (a "
                         "run's, or a branch whose record was removed, so its points could "
                         "be of any model); give a new or empty --out")
    write_json_atomic(recorded, identity)
    return identity


# ---------------------------------------------------------------------------------------------
# the points
# ---------------------------------------------------------------------------------------------
def _digest(text: bytes) -> str:
    import hashlib

    return hashlib.sha256(text).hexdigest()


def identity_digest(identity: dict) -> str:
    """The branch's identity (branch.json) as a checksum: what ties each point to it."""
    return _digest(json.dumps(identity, sort_keys=True).encode())


def field_digest(phi: np.ndarray) -> str:
    """A point's φ as a checksum (its float64 values, little-endian)."""
    return _digest(np.ascontiguousarray(phi, dtype="<f8").tobytes())


#: a row's keys that are not the point's own: the checksum's record, and the fold, which
#: its neighbours decide (:func:`fem_ade.campaigns.branch_analysis.mark_folds`)
DERIVED = ("integrity", "fold")


def row_digest(row: dict) -> str:
    """A point's row as a checksum: its values as summary.json stores them, without
    :data:`DERIVED`."""
    from fem_ade.store.output import jsonable

    plain = {k: v for k, v in row.items() if k not in DERIVED}
    return _digest(json.dumps(jsonable(plain), sort_keys=True).encode())


def save_point(out: Path, k: int, be, row: dict, branch: str) -> dict:
    """Point ``k`` in ``points/NNNN/``: final.npz (φ), then summary.json (its row and its
    ``integrity``: the branch's :func:`identity_digest`, the index, φ's and the row's
    checksums — the summary is written last, so a point cut short has none); the row as
    saved."""
    from fem_ade.store.output import jsonable, write_fields, write_json_atomic

    folder = out / "points" / f"{k:04d}"
    folder.mkdir(parents=True, exist_ok=True)
    fields = be.fields()
    write_fields(folder / "final.npz", fields)
    row = json.loads(json.dumps(jsonable({k_: v for k_, v in row.items()
                                          if k_ not in DERIVED})))
    row["integrity"] = {"branch": branch, "index": k, "phi": field_digest(fields["phi"]),
                        "row": row_digest(row)}
    write_json_atomic(folder / "summary.json", row)
    return row


def load_points(out: Path, branch: str | None = None, size: int | None = None,
                param: str | None = None) -> list[tuple[dict, np.ndarray]]:
    """The saved points of a branch folder, in order: (row, φ). Each is checked against the
    branch (``branch``: its :func:`identity_digest`) — its index, its φ's and its row's
    checksums, its φ's length (``size``); the folders must be 0000, 0001, … without a gap
    or a stranger. Only the last may be cut short (final.npz without summary.json: a kill
    between the two), and is left out. ModelError (one line) for anything else: a resume
    never continues from points it cannot vouch for. Points written before the checksums
    (no ``integrity``) are taken as they are, in their order."""
    points = out / "points"
    if not points.exists():
        return []
    if not points.is_dir():
        raise ModelError(f"{points} is not a folder: {out} is not a branch folder this "
                         "command can continue")
    names = sorted(p.name for p in points.iterdir())
    strangers = [n for n in names if not (len(n) == 4 and n.isdigit()
                                          and (points / n).is_dir())]
    if strangers:
        raise ModelError(f"{points} holds {strangers[0]!r}, which is no point of a branch: "
                         "remove it, or give another --out")
    found = []
    for k, name in enumerate(names):
        where = points / name
        if name != f"{k:04d}":
            raise ModelError(f"{points}: point {k:04d} is missing (next is {name}): the "
                             f"branch's points have a gap; remove the points from {name} "
                             "on to go on from the last whole one, or give another --out")
        summary = where / "summary.json"
        if not summary.exists() and k == len(names) - 1:
            break  # cut short by a kill: made again
        try:
            row = json.loads(summary.read_text())
            with np.load(where / "final.npz") as z:
                phi = np.array(z["phi"], dtype=float)
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as err:
            raise ModelError(f"{where} is not a whole point ({type(err).__name__}: "
                             f"{str(err)[:80]}): remove it and the points after it, or give "
                             "another --out") from None
        _check_point(where, k, row, phi, branch, size, param)
        found.append((row, phi))
    return found


def _check_point(where: Path, k: int, row, phi: np.ndarray, branch, size, param) -> None:
    """ModelError (one line) where a saved point is not point ``k`` of this branch."""
    def refuse(why):
        raise ModelError(f"{where}: {why}; a resume continues only from its own branch's "
                         "points: remove this point and those after it, or give another --out")

    if not isinstance(row, dict):
        refuse("its summary.json is not a table")
    for key in (param, "e", "s", "theta") if param else ():
        value = row.get(key, 0.0 if key in ("s", "theta") else None)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not \
                math.isfinite(value):
            refuse(f"its {key} is {value!r}, not a number")
    if phi.ndim != 1 or (size is not None and phi.size != size) or not np.all(
            np.isfinite(phi)):
        refuse(f"its final.npz holds no finite field of this branch's {size} nodes")
    record = row.get("integrity")
    if record is None:  # written before the checksums
        return
    if not isinstance(record, dict):
        refuse("its integrity record is not a table")
    if branch is not None and record.get("branch") != branch:
        refuse("it belongs to another branch (its integrity record names another)")
    if record.get("index") != k:
        refuse(f"it is point {record.get('index')!r} of its branch, not {k}")
    if record.get("phi") != field_digest(phi):
        refuse("its final.npz is not the field the point was saved with (changed or "
               "replaced)")
    if record.get("row") != row_digest(row):
        refuse("its summary.json was changed after the point was saved")


def mode_columns(rows: list[dict]) -> list[str]:
    """The azimuthal modes' columns of a branch's rows: lowest_m0 … lowest_mM, unstable_3d
    (none for a branch without modes)."""
    modes = sorted({int(k[len("lowest_m"):]) for r in rows for k in r
                    if k.startswith("lowest_m")})
    return [f"lowest_m{m}" for m in modes] + (["unstable_3d"] if modes else [])


def write_branch_table(out: Path, name: str, rows: list[dict]) -> None:
    """A branch's rows as its branch.csv (:func:`fem_ade.store.tables.write_table`): the
    point's number, the parameter ``name``, :data:`COLUMNS` and the modes' columns."""
    from fem_ade.store.tables import write_table

    cols = ["point", name, *COLUMNS[1:], *mode_columns(rows)]
    write_table(out / "branch.csv", cols, [{**r, "point": k} for k, r in enumerate(rows)])


def read_branch_table(out: Path) -> list[dict]:
    """A branch folder's branch.csv (:func:`write_branch_table`) as rows, numbers as the
    ints and floats they were written from ('' where a cell is empty: no fold, no
    stability)."""
    from fem_ade.store.tables import read_table

    return read_table(out / "branch.csv", empty="")


def write_ended(out: Path, param: str, rows: list[dict], why: str) -> None:
    """``ended.json``: why the branch ended where it did (what the command printed last), its
    points and its last parameter, rewritten by each run that ends (a resume that goes on
    past an end says the new one)."""
    from fem_ade.store.output import write_json_atomic

    write_json_atomic(out / "ended.json", {"why": why, "points": len(rows),
                                           "param": param, "last": rows[-1][param]})
