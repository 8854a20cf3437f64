"""The command line every study starts from, and its threads.

Studies that time CPU seconds, or run two processes on two cores, pin BLAS (and the FFT)
to one thread before numpy is first imported: :func:`one_thread` is called at the top of
such a study, before its other imports.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path


def one_thread(fft: bool = True) -> None:
    """One BLAS thread per process (and one FFT worker, with ``fft``), unless the caller's
    environment says otherwise: CPU seconds then compare, and two workers share two cores."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    if fft:
        os.environ.setdefault("FEM_ADE_FFT_WORKERS", "1")


def study_parser(doc: str, out: Path | str | None, *, out_help: str | None = None,
                 quick: str | None = None, report_only: str | None = None,
                 workers: str | None = None, first_line: bool = False) -> argparse.ArgumentParser:
    """A study's parser with the options they share, in this order: ``--out`` (a Path,
    default ``out``; none where ``out`` is None), ``--quick``, ``--workers`` (default 2) and
    ``--report-only``, each only where its help is given ("" for none). The description is
    the docstring's first paragraph (its first line with ``first_line``)."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0] if first_line
                                 else doc.split("\n\n")[0])
    if out is not None:
        ap.add_argument("--out", type=Path, default=Path(out), help=out_help)
    if quick is not None:
        ap.add_argument("--quick", action="store_true", help=quick or None)
    if workers is not None:
        ap.add_argument("--workers", type=int, default=2, help=workers or None)
    if report_only is not None:
        ap.add_argument("--report-only", action="store_true", help=report_only or None)
    return ap


def results(args, name: str, compute) -> dict:
    """A study's result: ``OUT/NAME.json`` read back with ``--report-only``, else
    ``compute()`` written there (``_quick`` in its name with ``--quick``)."""
    import json

    suffix = "_quick" if getattr(args, "quick", False) else ""
    path = args.out / f"{name}{suffix}.json"
    if getattr(args, "report_only", False):
        return json.loads(path.read_text())
    result = compute()
    path.write_text(json.dumps(result, indent=1, allow_nan=False) + "\n")
    return result


def write_report(out: Path, stem: str, lines: list[str]) -> None:
    """``OUT/STEM.md``: the report's lines, then the hand-written ``OUT/STEM_notes.md``
    where there is one."""
    notes = out / f"{stem}_notes.md"
    if notes.is_file():
        lines = [*lines, "", notes.read_text().rstrip()]
    (out / f"{stem}.md").write_text("\n".join(lines) + "\n")
