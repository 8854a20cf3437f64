"""Everything the project writes: history.csv, summary.json, final.npz (and the output folder).

Backends never write files; the run folder (:mod:`fem_ade.runs`) hands rows and fields to the
writers here.
"""

from __future__ import annotations

import csv
import json
import math
import os
import platform
from importlib import metadata
from pathlib import Path

import numpy as np

from .model import ModelError

PACKAGES = ("fem_ade", "numpy", "scipy", "scikit-fem", "pyamg", "meshio", "pyvista", "matplotlib")


#: the files a run writes into its folder (``--force`` removes these, and nothing else)
RUN_FILES = ("run.json", "history.csv", "summary.json", "final.npz", "checkpoint.npz",
             "phi.xdmf", "phi.h5", "shape.png", "history.png", "shapes.csv", "initial.npz")
RUN_GLOBS = ("phi-from-*.xdmf", "phi-from-*.h5", "*.tmp", "*.tmp.npz", "*.tmp.png")


def run_files(folder: Path) -> list[Path]:
    """The files of a run that exist in ``folder``."""
    found = [folder / name for name in RUN_FILES if (folder / name).exists()]
    for pattern in RUN_GLOBS:
        found += sorted(folder.glob(pattern))
    return found


def check_out_dir(path: str | Path, *, force: bool = False) -> Path:
    """Check that ``path`` can take a run, creating and changing nothing (ModelError): an
    existing folder must be empty (or, with ``force``, hold a run whose files are files), a
    new one must be creatable in a writable folder."""
    text = str(path)
    if not text.strip():
        raise ModelError("--out needs a folder name")
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ModelError(f"--out {path} exists and is not a folder")
    if path.is_dir():
        if any(path.iterdir()) and not force:
            raise ModelError(
                f"output folder {path} exists and is not empty; use --force or another --out")
        odd = [p.name for p in run_files(path) if not p.is_file()]
        if odd:
            raise ModelError(f"--out {path}: {', '.join(odd)} should be files of a run but are "
                             "not; remove them first")
        if not os.access(path, os.W_OK | os.X_OK):
            raise ModelError(f"--out {path} is not writable")
        return path
    parent = path.parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise ModelError(f"--out {path}: {parent} is not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ModelError(f"--out {path}: cannot create it, {parent} is not writable")
    return path


def prepare_out_dir(path: Path, *, force: bool = False, fresh: bool = False) -> None:
    """Create the run folder (``fresh``: it must not exist yet: a default folder is never
    shared) and prove it writable; with ``force``, remove the previous run's files (and
    nothing else). ModelError, with anything created here removed again, if that fails."""
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
    if force:
        for p in run_files(path):
            p.unlink()


def package_versions() -> dict:
    versions = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    return versions


class HistoryWriter:
    """history.csv: one row per recorded step, flushed at once so nothing is lost on failure."""

    def __init__(self, path: str | Path, columns: tuple[str, ...], *, append: bool = False):
        self.columns = columns
        self._file = open(path, "a" if append else "w", newline="")  # noqa: SIM115
        self._csv = csv.writer(self._file)
        if not append:
            self._csv.writerow(columns)
        self._file.flush()

    def write(self, row: dict) -> None:
        out = []
        for c in self.columns:
            v = row.get(c, 0)
            if isinstance(v, (float, np.floating)):
                out.append(repr(float(v)))
            else:
                out.append(str(v))
        self._csv.writerow(out)
        self._file.flush()

    def close(self) -> None:
        self._file.close()


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, set, frozenset)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating, float)):
        f = float(obj)
        return f if math.isfinite(f) else None
    if isinstance(obj, Path):
        return str(obj)
    return obj


def write_json_atomic(path: str | Path, data: dict) -> None:
    path = Path(path)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(_jsonable(data), indent=2) + "\n")
    os.replace(tmp, path)


def write_fields(path: str | Path, fields: dict, **meta) -> None:
    """final.npz (or last_good.npz): the backend's fields plus scalar metadata; atomic."""
    path = Path(path)
    tmp = path.with_name(path.stem + ".tmp.npz")
    arrays = {k: np.asarray(v) for k, v in fields.items()}
    arrays.update({k: np.asarray(v) for k, v in meta.items()})
    np.savez_compressed(tmp, **arrays)
    os.replace(tmp, path)


def read_history(path: str | Path) -> dict[str, np.ndarray]:
    """history.csv as a dict of column arrays."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header, body = rows[0], rows[1:]
    return {c: np.array([float(r[i]) for r in body]) for i, c in enumerate(header)}


def truncate_csv(path: str | Path, last_step: int) -> list[dict[str, str]]:
    """Drop the rows of a per-step CSV file (first column: step) after ``last_step``, before
    a resumed run appends to it; return the rows kept, as dicts of strings."""
    path = Path(path)
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    keep = rows[:1] + [r for r in rows[1:] if int(r[0]) <= last_step]
    tmp = path.with_suffix(".csv.tmp")
    with open(tmp, "w", newline="") as f:
        csv.writer(f).writerows(keep)
    os.replace(tmp, path)
    return [dict(zip(rows[0], r, strict=True)) for r in keep[1:]]


def truncate_history(path: str | Path, last_step: int) -> list[dict]:
    """:func:`truncate_csv` for history.csv: the rows kept, as dicts of floats."""
    return [{c: float(v) for c, v in r.items()} for r in truncate_csv(path, last_step)]


def read_json(path: str | Path) -> dict:
    return json.loads(Path(path).read_text())
