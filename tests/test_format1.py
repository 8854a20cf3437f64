"""Folders written before ``n`` meant nodes per axis at every layer still resume.

tests/data/format1 holds three folders made by fem_ade at commit 476926f, whose run.json and
branch.json (no ``format`` key: format 1) count the FEM's ``n`` in cells of order p:

- ``run3d``: ``discocyte --n 16 --order 2 --allow-underresolved --steps 10 --every 5
  --checkpoint-every 5 --no-render --no-sharp`` (run.json: n = 8 cells);
- ``runaxi``: ``vesicle --geometry axisymmetric --eps 0.05 --R0 0.2 --v 0.9 --branch prolate
  --steps 10 --every 5 --checkpoint-every 5 --no-render --no-sharp`` (order 8, n = 8 cells);
- ``branch``: ``fem_ade.branch vesicle --branch prolate --eps 0.05 --R0 0.2 --param v --from
  0.95 --to 0.93 --step 0.02`` (branch.json: n = 8 cells, no order written; its pictures
  left out).

Each is continued by today's code and compared with the same run made from scratch today
(the timing columns aside; to 1e-9 relative, since the folders' first rows were computed on
another machine).
"""

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from fem_ade.campaigns.branch import main as branch_main
from fem_ade.cli.run import main as run_main
from fem_ade.engine.runs import read_run, resume
from fem_ade.model.params import ModelError

DATA = Path(__file__).resolve().parent / "data" / "format1"
COMMON = ["--steps", "20", "--every", "5", "--checkpoint-every", "5", "--no-render",
          "--no-sharp", "--quiet"]
RUNS = {
    "run3d": ["discocyte", "--n", "16", "--order", "2", "--allow-underresolved"],
    "runaxi": ["vesicle", "--geometry", "axisymmetric", "--eps", "0.05", "--R0", "0.2",
               "--v", "0.9", "--branch", "prolate"],
}
BRANCH = ["vesicle", "--branch", "prolate", "--eps", "0.05", "--R0", "0.2", "--param", "v",
          "--from", "0.95", "--step", "0.02", "--quiet"]
#: what a point's row may differ in from the same point made today: its timings, and its
#: Newton iterations (the folder's points were corrected to |dp| < 1e-9, today's to 1e-7:
#: one iteration fewer where the last moved p by 1e-9, the state the same to the tolerance
#: checked below)
UNCOMPARED = ("seconds", "newton_s", "stability_s", "solve_s", "newton")


def table(path):
    with open(path) as fh:
        return [{k: v for k, v in r.items() if k not in UNCOMPARED} for r in csv.DictReader(fh)]


def assert_same_rows(a, b):
    assert len(a) == len(b) and [list(r) for r in a] == [list(r) for r in b]
    for ra, rb in zip(a, b, strict=True):
        for key in ra:
            try:
                x, y = float(ra[key]), float(rb[key])
            except ValueError:
                assert ra[key] == rb[key], key
                continue
            assert x == pytest.approx(y, rel=1e-9, abs=1e-12), (key, ra["step" if "step" in
                                                                     ra else "v"])


@pytest.mark.parametrize("name", list(RUNS))
def test_a_format1_run_resumes_as_a_new_run(name, tmp_path):
    """A format-1 run folder (n in cells) continues to the history of the same run made
    today; its summary then says n in nodes per axis."""
    old = tmp_path / "old"
    shutil.copytree(DATA / name, old)
    assert "format" not in json.loads((old / "run.json").read_text())
    scene, config = read_run(old)
    assert config.n == {"run3d": 16, "runaxi": 64}[name]  # 8 cells of order 2 or 8
    resume(old, steps=20)
    assert run_main([*RUNS[name], *COMMON, "--out", str(tmp_path / "new")]) == 0
    assert_same_rows(table(old / "history.csv"), table(tmp_path / "new" / "history.csv"))
    new = json.loads((tmp_path / "new" / "run.json").read_text())
    assert new["format"] == 2 and new["n"] == config.n
    assert json.loads((old / "summary.json").read_text())["n"] == config.n


def test_format1_is_told_by_the_missing_key(tmp_path):
    """Control: the same run.json marked format 2 reads its n = 8 as nodes — 4 cells of
    order 2, another run than its checkpoint's — and the resume refuses it."""
    old = tmp_path / "old"
    shutil.copytree(DATA / "run3d", old)
    run = json.loads((old / "run.json").read_text())
    (old / "run.json").write_text(json.dumps({**run, "format": 2}))
    assert read_run(old)[1].n == 8
    with pytest.raises(ModelError, match="belongs to another run"):
        resume(old, steps=20)


def test_a_format1_branch_resumes_as_a_new_branch(tmp_path):
    """A format-1 branch folder (n = 8 cells, no order written) goes on to v = 0.89 with the
    points the same branch made today has; its points' stability reads it."""
    from fem_ade.campaigns.branch_folder import read_identity
    from fem_ade.campaigns.stability import main as stability_main

    old = tmp_path / "old"
    shutil.copytree(DATA / "branch", old)
    assert read_identity(old)["n"] == 64
    assert branch_main([*BRANCH, "--to", "0.89", "--out", str(old)]) == 0
    assert branch_main([*BRANCH, "--to", "0.89", "--out", str(tmp_path / "new")]) == 0
    rows = table(old / "branch.csv")
    assert len(rows) == 4
    assert_same_rows(rows, table(tmp_path / "new" / "branch.csv"))
    assert json.loads((old / "ended.json").read_text())["why"] == "reached v = 0.89"
    assert stability_main([str(old / "points" / "0001"), "--json"]) == 0
    with np.load(old / "points" / "0000" / "final.npz") as z:
        assert z["phi"].size > 0
