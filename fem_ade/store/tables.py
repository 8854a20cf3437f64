"""Tables: a campaign's rows as one CSV file (a sweep's sweep.csv, a branch's branch.csv) —
written whole and atomically, read back with numbers as the numbers they were written from.
The one reader and writer of both; what the columns are is each campaign's."""

from __future__ import annotations

import csv
import os
from pathlib import Path

from fem_ade.store.output import csv_cell, parse_cell


def write_table(path: str | Path, columns: list[str], rows: list[dict]) -> None:
    """``rows`` (dicts; a missing or None cell is empty) under ``columns``, each cell by
    :func:`fem_ade.store.output.csv_cell`, into ``path`` through ``path.tmp`` and a rename:
    a reader sees the old table or the new one, never half of one."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(columns)
        for r in rows:
            w.writerow([csv_cell(r.get(k)) for k in columns])
    os.replace(tmp, path)


def read_table(path: str | Path, *, text: tuple[str, ...] = (), empty=None) -> list[dict]:
    """The rows of a table: each cell the int or float it was written from
    (:func:`fem_ade.store.output.parse_cell`) or, empty, ``empty``; the ``text`` columns as
    written."""
    with open(path, newline="") as fh:
        return [{k: (v if k in text else empty if v == "" else parse_cell(v))
                 for k, v in r.items()} for r in csv.DictReader(fh)]
