"""Everything the project writes: history.csv, summary.json, final.npz (and the output folder).

Backends never write files; the run folder (:mod:`fem_ade.engine.execute`) hands rows and fields to
the writers here.
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
import os
import platform
import stat
from importlib import metadata
from pathlib import Path

import numpy as np

from fem_ade.model.params import ModelError

PACKAGES = ("fem_ade", "numpy", "scipy", "scikit-fem", "pyamg", "meshio", "pyvista", "matplotlib")


#: the files a run writes into its folder (``--force`` removes these, and nothing else)
RUN_FILES = ("run.json", "history.csv", "summary.json", "final.npz", "checkpoint.npz",
             "phi.xdmf", "phi.h5", "shape.png", "history.png", "shapes.csv", "initial.npz")
RUN_GLOBS = ("phi-[0-9]*.h5", "phi-from-*.xdmf", "phi-from-*.h5", "*.tmp", "*.tmp.npz",
             "*.tmp.png", "*.tmp.h5")


def series_files(folder: Path) -> list[Path]:
    """The files of a run's ParaView series in ``folder`` (its index, mesh and steps)."""
    folder = Path(folder)
    found = [folder / n for n in ("phi.xdmf", "phi.h5") if (folder / n).exists()]
    return found + sorted(folder.glob("phi-[0-9]*.h5")) + sorted(folder.glob("phi-from-*"))


def run_files(folder: Path) -> list[Path]:
    """The files of a run that exist in ``folder``."""
    found = [folder / name for name in RUN_FILES if (folder / name).exists()]
    for pattern in RUN_GLOBS:
        found += sorted(folder.glob(pattern))
    return found


def not_files(folder: Path) -> list[str]:
    """The names of a run's files in ``folder`` that exist and are not regular files (a file
    that vanishes while this looks — another run's atomic write — is not one of them)."""
    odd = []
    for p in run_files(folder):
        try:
            if not stat.S_ISREG(p.stat().st_mode):
                odd.append(p.name)
        except FileNotFoundError:
            pass
    return odd


def contents(path: Path) -> list[Path]:
    """What a folder holds, without the lock and owner files of :mod:`fem_ade.store.lock`."""
    from fem_ade.store.lock import HIDDEN

    return [p for p in Path(path).iterdir() if p.name not in HIDDEN]


def check_path_name(path: Path, what: str = "--out") -> None:
    """ModelError for a path no file system here takes: a name longer than NAME_MAX, a path
    longer than PATH_MAX, a NUL byte."""
    text = str(path)
    if "\0" in text:
        raise ModelError(f"{what}: the path contains a NUL byte")
    try:
        name_max = os.pathconf(".", "PC_NAME_MAX")
        path_max = os.pathconf(".", "PC_PATH_MAX")
    except (OSError, ValueError, AttributeError):
        name_max, path_max = 255, 4096
    long = [part for part in Path(path).parts if len(os.fsencode(part)) > name_max]
    if long:
        raise ModelError(f"{what}: a folder name of {len(os.fsencode(long[0]))} bytes is longer "
                         f"than this file system takes ({name_max})")
    if len(os.fsencode(os.path.abspath(text))) >= path_max:
        raise ModelError(f"{what}: the path is longer than this system takes ({path_max} bytes)")


def check_out_dir(path: str | Path, *, force: bool = False) -> Path:
    """Check that ``path`` can take a run, creating and changing nothing (ModelError): an
    existing folder must be empty (or, with ``force``, hold a run whose files are files), a
    new one must be creatable in a writable folder."""
    text = str(path)
    if not text.strip():
        raise ModelError("--out needs a folder name")
    path = Path(path)
    check_path_name(path)
    if path.exists() and not path.is_dir():
        raise ModelError(f"--out {path} exists and is not a folder")
    if path.is_dir():
        if contents(path) and not force:
            raise ModelError(
                f"output folder {path} exists and is not empty; use --force or another --out")
        odd = not_files(path)
        if odd:
            raise ModelError(f"--out {path}: {', '.join(odd)} should be files of a run but are "
                             "not; remove them first")
        if not os.access(path, os.W_OK | os.X_OK):
            raise ModelError(f"--out {path} is not writable")
        return path
    check_creatable(path)
    return path


def check_creatable(path: Path, what: str = "--out") -> None:
    """ModelError (one line) unless ``path`` can be made: its nearest existing ancestor a
    writable folder."""
    parent = Path(path).parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise ModelError(f"{what} {path}: {parent} is not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ModelError(f"{what} {path}: cannot create it, {parent} is not writable")


def prepare_out_dir(path: Path, *, force: bool = False, fresh: bool = False):
    """Create the run folder (``fresh``: it must not exist yet: a default folder is never
    shared), prove it writable and take its lock (:class:`fem_ade.store.lock.FolderLock`, returned:
    the caller holds it for the whole run); under the lock, check again that it is empty
    (another process may have written there since :func:`check_out_dir`) or, with
    ``force``, remove the previous run's files (and nothing else). ModelError — FolderBusy
    when another run holds it — with anything created here removed again, if that fails."""
    from fem_ade.store.lock import FolderLock

    created = []
    try:
        for folder in reversed([path, *path.parents]):
            if not folder.exists():
                folder.mkdir()
                created.append(folder)
        if fresh and not created:
            raise ModelError(f"output folder {path} appeared meanwhile; run again")
        probe = path / f".write-test-{os.getpid()}"
        probe.write_text("")
        probe.unlink()
    except OSError as err:
        for folder in reversed(created):
            try:
                folder.rmdir()
            except OSError:
                pass
        raise ModelError(f"--out {path}: cannot write there ({err.strerror or err})") from None
    lock = FolderLock(path)
    try:
        lock.acquire()
    except ModelError:
        for folder in reversed(created):
            try:
                folder.rmdir()
            except OSError:
                pass
        raise
    try:
        if force:
            odd = not_files(path)
            if odd:
                raise ModelError(f"--out {path}: {', '.join(odd)} should be files of a run but "
                                 "are not; remove them first")
            for p in run_files(path):
                p.unlink()
        elif contents(path):
            raise ModelError(f"output folder {path} is not empty any more (another process "
                             "wrote there); use --force or another --out")
    except (ModelError, OSError) as err:
        lock.release()
        if isinstance(err, OSError):
            raise ModelError(f"--out {path}: cannot clean it ({err.strerror or err})") from None
        raise
    return lock


def package_versions() -> dict:
    versions = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    return versions


class HistoryWriter:
    """history.csv: one row per recorded step, flushed at once so nothing is lost on failure,
    each row written whole (a signal waits for it: :func:`fem_ade.store.interrupt.critical`)."""

    def __init__(self, path: str | Path, columns: tuple[str, ...], *, append: bool = False):
        self.columns = columns
        self._file = open(path, "a" if append else "w", newline="")  # noqa: SIM115
        self._csv = csv.writer(self._file)
        if not append:
            self._csv.writerow(columns)
        self._file.flush()

    def write(self, row: dict) -> None:
        from fem_ade.store.interrupt import critical

        out = []
        for c in self.columns:
            v = row.get(c, 0)
            if isinstance(v, (float, np.floating)):
                out.append(repr(float(v)))
            else:
                out.append(str(v))
        with critical():
            self._csv.writerow(out)
            self._file.flush()

    def close(self) -> None:
        self._file.close()


def jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, set, frozenset)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating, float)):
        f = float(obj)
        return f if math.isfinite(f) else None
    if isinstance(obj, Path):
        return str(obj)
    return obj


def write_json_atomic(path: str | Path, data: dict, indent: int | None = 2,
                      make_folder: bool = False) -> None:
    """``data`` as JSON in ``path``, whole or not at all (written, then renamed);
    ``indent=None``: on one line without spaces (the studies' large caches);
    ``make_folder``: its folder made first if it is missing."""
    path = Path(path)
    if make_folder:
        path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    separators = (",", ":") if indent is None else None
    tmp.write_text(json.dumps(jsonable(data), indent=indent, separators=separators) + "\n")
    os.replace(tmp, path)


def write_fields(path: str | Path, fields: dict, **meta) -> None:
    """final.npz (or last_good.npz): the backend's fields plus scalar metadata; atomic."""
    path = Path(path)
    tmp = path.with_name(path.stem + ".tmp.npz")
    arrays = {k: np.asarray(v) for k, v in fields.items()}
    arrays.update({k: np.asarray(v) for k, v in meta.items()})
    np.savez_compressed(tmp, **arrays)
    os.replace(tmp, path)


def csv_cell(value):
    """A value as a table's cell (branch.csv, sweep.csv): a float to 10 significant digits,
    None empty, anything else as it is."""
    if isinstance(value, float):
        return f"{value:.10g}"
    return "" if value is None else value


def parse_cell(text: str):
    """A CSV cell back as the int or float it was written from; text stays text ('' too)."""
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def read_history(path: str | Path) -> dict[str, np.ndarray]:
    """history.csv as a dict of column arrays."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header, body = rows[0], rows[1:]
    return {c: np.array([float(r[i]) for r in body]) for i, c in enumerate(header)}


def _step_of(row: list[str], width: int) -> int | None:
    """The step of a CSV row that is whole (``width`` cells, an integer first), else None."""
    if len(row) != width:
        return None
    try:
        return int(row[0])
    except ValueError:
        return None


def check_history(path: str | Path, last_step: int) -> None:
    """ModelError unless ``path`` is a run's history.csv that a resume from ``last_step`` can
    continue: readable, with its header, its rows whole up to that step (a last row cut short
    by a crash is dropped by :func:`truncate_csv`)."""
    from fem_ade.model.params import HISTORY_COLUMNS

    path = Path(path)
    try:
        with open(path, newline="") as f:
            rows = list(csv.reader(f))
    except FileNotFoundError:
        raise ModelError(f"cannot resume {path.parent}: its history.csv is missing") from None
    except (OSError, UnicodeDecodeError, csv.Error) as err:
        raise ModelError(f"cannot resume {path.parent}: history.csv is unreadable "
                         f"({err})") from None
    if not rows or tuple(rows[0][:len(HISTORY_COLUMNS)]) != HISTORY_COLUMNS:
        raise ModelError(f"cannot resume {path.parent}: history.csv has no header "
                         f"{','.join(HISTORY_COLUMNS)}")
    width = len(rows[0])
    for i, row in enumerate(rows[1:], start=2):
        step = _step_of(row, width)
        if step is None and i < len(rows):  # only the last row may be cut short
            raise ModelError(f"cannot resume {path.parent}: history.csv line {i} is not a "
                             "row of the run")
        if step is not None and step > last_step:
            break


def truncate_csv(path: str | Path, last_step: int) -> list[dict[str, str]]:
    """Drop the rows of a per-step CSV file (first column: step) after ``last_step``, and a
    last row cut short by a crash, before a resumed run appends to it (atomically); return
    the rows kept, as dicts of strings."""
    path = Path(path)
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    width = len(rows[0])
    keep = rows[:1] + [r for r in rows[1:] if (k := _step_of(r, width)) is not None
                       and k <= last_step]
    tmp = path.with_suffix(".csv.tmp")
    with open(tmp, "w", newline="") as f:
        csv.writer(f).writerows(keep)
    os.replace(tmp, path)
    return [dict(zip(rows[0], r, strict=True)) for r in keep[1:]]


def history_digest(path: str | Path, last_step: int) -> str:
    """SHA-256 of a per-step CSV file's header and whole rows up to ``last_step`` (what a
    checkpoint at that step was written after, and what a resume keeps)."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows:
        return hashlib.sha256(b"").hexdigest()
    width = len(rows[0])
    keep = rows[:1] + [r for r in rows[1:] if (k := _step_of(r, width)) is not None
                       and k <= last_step]
    return hashlib.sha256("\n".join(",".join(r) for r in keep).encode()).hexdigest()


def truncate_history(path: str | Path, last_step: int) -> list[dict]:
    """:func:`truncate_csv` for history.csv: the rows kept, as dicts of floats."""
    return [{c: float(v) for c, v in r.items()} for r in truncate_csv(path, last_step)]


def read_json(path: str | Path) -> dict:
    return json.loads(Path(path).read_text())
