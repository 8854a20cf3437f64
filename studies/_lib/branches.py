"""Axisymmetric branch folders a study makes once (``python -m fem_ade.branch``) and reads."""

from __future__ import annotations

from pathlib import Path


def make_branch(out: Path, args: list[str]) -> Path | str:
    """A branch folder made once by ``python -m fem_ade.branch`` (kept: a second run reads
    it); ModelError's line where its seed is not the branch."""
    from fem_ade.campaigns.branch import main as branch_main

    if not (out / "branch.csv").is_file():
        import contextlib
        import io

        err = io.StringIO()
        with contextlib.redirect_stderr(err):
            code = branch_main([*args, "--quiet", "--out", str(out)])
        if code != 0:
            return err.getvalue().strip().removeprefix("fem_ade.branch: error: ")
    return out


def branch_rows(folder: Path) -> list[dict]:
    """A branch folder's branch.csv as rows of strings."""
    import csv

    with open(folder / "branch.csv") as f:
        return list(csv.DictReader(f))
