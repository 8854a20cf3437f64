"""Parameter sweeps on Dask (fem_ade.campaigns.sweep): the file, the points, a run on a
LocalCluster of
two processes, its skip of finished points, a failed point, the table's columns, and a sweep
killed twice that ends with the table of an uninterrupted one."""

from __future__ import annotations

import csv
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fem_ade.campaigns.sweep import main, run_sweep
from fem_ade.campaigns.sweep_file import load_sweep
from fem_ade.campaigns.sweep_points import COLUMNS, read_sweep_table
from fem_ade.model.params import ModelError

ROOT = Path(__file__).resolve().parents[1]
#: spheres seeded at v < 1 need no sharp solve: the quickest vesicle points
SWEEP = """
name = "t"
base = "vesicle"
seeds = ["sphere"]
[scene]
eps = 0.08
[axes]
v = {axes}
[run]
recipe = "steady"
backend = "spectral"
n = 16
max_steps = {steps}
constraints = "exact"
checkpoint_every = 5
"""


def _file(tmp_path, axes="[0.8, 0.9]", steps=12, name="s.toml") -> Path:
    path = tmp_path / name
    path.write_text(SWEEP.format(axes=axes, steps=steps))
    return path


def _table(path: Path) -> list[dict]:
    with open(path) as fh:
        return list(csv.DictReader(fh))


def test_sweep_file_and_points(tmp_path):
    """Axes as lists and as {start, stop, num}; one point per value and seed, named by its
    parameters; bad files refused in one line."""
    path = tmp_path / "a.toml"
    path.write_text('base = "vesicle"\nseeds = ["prolate", "oblate"]\n[scene]\neps = 0.06\n'
                    '[axes]\nv = {start = 0.7, stop = 0.9, num = 3}\nkbar = [0.0]\n'
                    '[run]\nn = 24\nsteps = 2\n')
    sweep = load_sweep(path)
    names = [p.name for p in sweep.points()]
    assert sweep.axes["v"] == [0.7, 0.8, 0.9] and len(names) == 6
    assert names[0] == "v=0.7_kbar=0_seed=prolate" and names[-1] == "v=0.9_kbar=0_seed=oblate"
    for text, match in [("[axes]\nv = []\n", "non-empty"), ("colour = 1\n", "unknown key"),
                        ("[run]\nsolver = 1\n", "unknown run option"),
                        ("[run]\nn = 1.5\n", "run.n must be"),
                        ("[scene]\nv = 1.5\n", "vesicle v must be")]:
        path.write_text(text)
        with pytest.raises(ModelError, match=match):
            load_sweep(path)


def test_sweep_runs_skips_and_records_a_failure(tmp_path, capsys):
    """On a LocalCluster of two processes: every point runs to its end, the table has its
    columns and one row per point; a point that fails when it is built (its seed does not
    fit the box at that R₀) is recorded as failed with its reason and does not stop the
    rest; run again, nothing runs twice. (A value no point can take — v = 1.2 — is refused
    before anything runs: ``test_bad_sweeps_are_one_line_before_anything_runs``.)"""
    path = _file(tmp_path, axes="[0.8, 0.9]")
    path.write_text(path.read_text().replace("[axes]\n", "[axes]\nR0 = [0.2, 0.45]\n"))
    sweep = load_sweep(path)
    out = tmp_path / "out"
    rows = run_sweep(sweep, out, workers=2, quiet=True)
    table = _table(out / "sweep.csv")
    assert list(table[0]) == ["point", "R0", "v", *COLUMNS]
    assert [r["point"] for r in table] == ["R0=0.2_v=0.8_seed=sphere", "R0=0.2_v=0.9_seed=sphere",
                                           "R0=0.45_v=0.8_seed=sphere",
                                           "R0=0.45_v=0.9_seed=sphere"]
    good, bad = table[:2], table[2:]
    for r in good:
        assert r["status"] == "max_steps" and r["steps"] == "12" and r["components"] == "1"
        assert float(r["E"]) > 0 and r["label"]
    for r in bad:
        assert r["status"] == "failed" and "does not fit the box" in r["reason"], r
    assert rows[2]["status"] == "failed"
    stamps = {p: (out / "points" / p / "summary.json").stat().st_mtime_ns
              for p in ("R0=0.2_v=0.8_seed=sphere", "R0=0.2_v=0.9_seed=sphere")}
    again = run_sweep(sweep, out, workers=2, quiet=True)
    assert [r["status"] for r in again] == [r["status"] for r in rows]
    assert stamps == {p: (out / "points" / p / "summary.json").stat().st_mtime_ns
                      for p in stamps}, "a finished point ran again"
    assert _table(out / "sweep.csv") == table
    back = read_sweep_table(out / "sweep.csv")  # the table alone gives the rows back
    for r, b in zip(rows, back, strict=True):
        assert b["point"] == r["point"] and b["status"] == r["status"]
        assert b.get("E") == pytest.approx(r.get("E"), rel=1e-9) if r.get("E") else True
        assert b["v"] == r["v"]
    again = run_sweep(sweep, out, workers=2, quiet=True, retry_failed=True)  # fails again
    assert again[2]["status"] == "failed" and "task_s" in again[2]
    (out / "sweep.csv").unlink()
    assert main([str(path), "--out", str(out), "--report-only"]) == 0
    assert _table(out / "sweep.csv") == table and (out / "phase-diagram.png").is_file()


def test_sweep_command_line(tmp_path, capsys):
    """The command line: a bad file exits 2 with one line; --report-only rebuilds the table
    and the phase diagram without running."""
    bad = tmp_path / "bad.toml"
    bad.write_text("[axes]\nv = 3\n")
    assert main([str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "error: axes.v" in capsys.readouterr().err
    path = _file(tmp_path)
    assert main([str(path), "--out", str(tmp_path / "o"), "--report-only"]) == 2
    assert "holds no sweep" in capsys.readouterr().err
    assert main([str(path), "--out", str(tmp_path / "o"), "--workers", "0"]) == 2


def _finished(csv_path: Path) -> int:
    try:
        return sum(r["status"] in ("steady", "max_steps") for r in _table(csv_path))
    except (OSError, KeyError):
        return 0


def test_sweep_killed_twice_ends_with_the_uninterrupted_table(tmp_path):
    """The command line killed twice while its points run — SIGTERM (a scheduler's kill),
    then SIGINT to one started with SIGINT ignored (it could not be stopped) — each time one
    line and exit 130, then run to the end: the table is the one of a sweep never
    interrupted (each resumed run bit for bit its uninterrupted self)."""
    path = _file(tmp_path, axes="[0.8, 0.85, 0.9, 0.95]", steps=150)
    cmd = [sys.executable, "-m", "fem_ade.sweep", str(path), "--workers", "2", "--quiet"]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    whole = tmp_path / "whole"
    subprocess.run([*cmd, "--out", str(whole)], check=True, env=env, timeout=600,
                   capture_output=True)
    out = tmp_path / "killed"
    for sig in (signal.SIGTERM, signal.SIGINT):  # the second started with SIGINT ignored, as
        def ignore_sigint():                     # a background job of a script is
            signal.signal(signal.SIGINT, signal.SIG_IGN)

        proc = subprocess.Popen([*cmd, "--out", str(out)], env=env, stdout=subprocess.DEVNULL,
                                stderr=subprocess.PIPE, text=True,
                                preexec_fn=ignore_sigint if sig == signal.SIGINT else None)
        t0 = time.time()
        started = _finished(out / "sweep.csv")
        # kill once a run has checkpointed since this start (mid-run), or a point finished
        while time.time() < t0 + 300 and proc.poll() is None:
            if any(p.stat().st_mtime > t0 for p in (out / "points").glob("*/checkpoint.npz")) \
                    or _finished(out / "sweep.csv") > started:
                break
            time.sleep(0.05)
        proc.send_signal(sig)
        err = proc.communicate(timeout=120)[1]
        assert proc.returncode == 130 and "interrupted" in err, (proc.returncode, err)
        assert len(err.strip().splitlines()) == 1, err  # (a resource tracker warned after it)
    done = subprocess.run([*cmd, "--out", str(out)], env=env, timeout=600,
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert _table(out / "sweep.csv") == _table(whole / "sweep.csv")
    assert {r["status"] for r in _table(out / "sweep.csv")} == {"steady"}


def test_slurm_config(tmp_path, monkeypatch):
    """The dask-jobqueue settings for Slurm make the job script a site needs: 2 workers of 1
    thread per job, the threads pinned, the environment activated (nothing submitted)."""
    import importlib.util

    pytest.importorskip("dask_jobqueue")
    monkeypatch.chdir(tmp_path)
    spec = importlib.util.spec_from_file_location(
        "slurm_cluster", ROOT / "studies" / "sweeps" / "slurm_cluster.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    script = module.main(["--print-script"])
    for line in ("#SBATCH --cpus-per-task=2", "#SBATCH -t 04:00:00", "#SBATCH --mem=8G",
                 "source .venv/bin/activate", "FEM_ADE_FFT_WORKERS=1", "--nthreads 1",
                 "--nworkers 2", "distributed.cli.dask_worker",
                 "DASK_CONFIG=studies/sweeps/dask"):
        assert line in script, line


def test_sweep_point_in_the_axisymmetric_geometry(tmp_path):
    """``geometry = "axisymmetric"`` in [run] runs a point on the FEM's (r, z) half-plane
    (docs/model.md §11): its run folder says so, its row has the end state."""
    from fem_ade.campaigns.sweep_points import run_point

    text = SWEEP.format(axes="[0.9]", steps=30).replace('backend = "spectral"\nn = 16',
                                                       'backend = "fem"\ngeometry = '
                                                       '"axisymmetric"')
    path = tmp_path / "axi.toml"
    path.write_text(text)
    (point,) = load_sweep(path).points()
    assert point.options(point.scene())["backend_options"] == {"geometry": "axisymmetric"}
    r = run_point(point, str(tmp_path / "out"))
    assert r["status"] == "max_steps" and r["components"] == 1 and r["label"] == "sphere"
    import json

    info = json.loads((tmp_path / "out" / "points" / point.name / "summary.json").read_text())
    assert info["backend_info"]["geometry"] == "axisymmetric"


def test_a_point_is_its_parameters_not_its_name(tmp_path, capsys):
    """Change the sweep's fixed ε and run it again into the same folder: it is refused with
    one line naming the difference (the old table is not shown under the new file), also
    with --report-only; --rerun-changed runs the changed points anew."""
    path = _file(tmp_path, axes="[0.9]", steps=6)
    out = tmp_path / "out"
    assert main([str(path), "--out", str(out), "--workers", "1", "--quiet"]) == 0
    first = _table(out / "sweep.csv")
    path.write_text(path.read_text().replace("eps = 0.08", "eps = 0.1"))
    capsys.readouterr()
    for extra in ([], ["--report-only"]):
        assert main([str(path), "--out", str(out), "--workers", "1", "--quiet", *extra]) == 2
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and "fixed.eps: 0.08 when it ran, 0.1 now" \
            in err, err
    assert _table(out / "sweep.csv") == first
    assert main([str(path), "--out", str(out), "--workers", "1", "--quiet",
                 "--rerun-changed"]) == 0
    again = _table(out / "sweep.csv")
    assert again[0]["status"] == "max_steps" and again[0]["E"] != first[0]["E"]


def test_point_names_never_collide(tmp_path):
    """Values that print alike get names that differ; a value or a seed listed twice, or a
    seed that is no plain name, is refused before anything runs."""
    sweep = load_sweep(_file(tmp_path, axes="[0.9, 0.9000001]"))
    names = [p.name for p in sweep.points()]
    assert len(set(names)) == 2, names
    for axes, match in (("[0.9, 0.9]", "lists a value twice"),):
        with pytest.raises(ModelError, match=match):
            load_sweep(_file(tmp_path, axes=axes))
    for seeds, match in (('["sphere", "sphere"]', "a seed twice"),
                         ('["a/b"]', "plain name")):
        path = _file(tmp_path)
        path.write_text(path.read_text().replace('seeds = ["sphere"]', f"seeds = {seeds}"))
        with pytest.raises(ModelError, match=match):
            load_sweep(path)


def _bad_file(tmp_path, change):
    path = _file(tmp_path, axes="[0.9]", steps=4)
    path.write_text(change(path.read_text()))
    return path


#: (what is wrong, how the sweep file changes or the extra arguments, a word of the message)
BAD_SWEEPS = [
    ("branch as an axis", lambda t: t.replace("v = [0.9]", "branch = ['prolate']"),
     "not a parameter"),
    ("v fixed and swept", lambda t: t.replace("eps = 0.08", "eps = 0.08\nv = 0.8"),
     "both fixed"),
    ("a word in an axis", lambda t: t.replace("[0.9]", "[0.9, 'x']"), "vesicle v must be"),
    ("num not an integer", lambda t: t.replace("[0.9]", "{start = 0.8, stop = 0.9, num = 2.5}"),
     "integer"),
    ("n below the least", lambda t: t.replace("n = 16", "n = -5"), "n must be"),
    ("an unknown backend", lambda t: t.replace('"spectral"', '"bogus"'), "backend"),
    ("an unknown recipe", lambda t: t.replace('recipe = "steady"', 'recipe = "bogus"'),
     "recipe"),
    ("order 0", lambda t: t.replace('backend = "spectral"\nn = 16',
                                    'backend = "fem"\nn = 16\nbackend_options = {order = 0}'),
     "order"),
    ("max_steps 0", lambda t: t.replace("max_steps = 4", "max_steps = 0"), "max-steps"),
    ("a listed point without a name", lambda t: t + "[[points]]\nseed = 'sphere'\n",
     "needs a name"),
    ("a listed point named twice", lambda t: t + "[[points]]\nname = 'a'\n" * 2,
     "already in the sweep"),
    ("a listed point named as a grid point", lambda t: t + "[[points]]\nname = 'v=0.9_seed="
     "sphere'\n", "already in the sweep"),
    ("after a point below", lambda t: t + "[[points]]\nname = 'a'\nafter = 'b'\n"
     "[[points]]\nname = 'b'\n", "names no point before it"),
    ("after itself", lambda t: t + "[[points]]\nname = 'a'\nafter = 'a'\n",
     "names no point before it"),
    ("a listed point's unknown key", lambda t: t + "[[points]]\nname = 'a'\nstart = 'x'\n",
     "unknown key"),
    ("a listed point's unknown seed", lambda t: t + "[[points]]\nname = 'a'\nseed = 'pear'\n",
     "not one of the sweep's seeds"),
    ("a listed point's bad run option", lambda t: t + "[[points]]\nname = 'a'\n"
     "run = {n = 'x'}\n", "run.n must be"),
    ("a listed point's unresolved run", lambda t: t + "[[points]]\nname = 'a'\n"
     "run = {n = 6}\n", "point a:"),
    ("a listed point's bad parameter", lambda t: t + "[[points]]\nname = 'a'\n"
     "scene = {eps = -1}\n", "point a:"),
]


#: a branch sweep: each point a prolate followed in v (issue 32), two sizes
BRANCH_SWEEP = """
name = "b"
base = "vesicle"
seeds = ["prolate"]
[scene]
eps = 0.05
[axes]
R0 = [0.18, 0.2]
[branch]
param = "v"
from = 0.95
to = 0.92
step = 0.02
"""
#: its mistakes: (what is wrong, the change, a word of the message)
BAD_BRANCH_SWEEPS = [
    ("the parameter swept", lambda t: t.replace("R0 = [0.18, 0.2]", "v = [0.9]"), "cannot be"),
    ("a run option", lambda t: t + '[run]\nrecipe = "steady"\n', "takes only"),
    ("an unknown key", lambda t: t.replace("step = 0.02", "stride = 0.02"), "unknown key"),
    ("no end", lambda t: t.replace("to = 0.92\n", ""), "needs to"),
    ("folds below 0", lambda t: t + "folds = -1\n", "--folds"),
    ("a step too long", lambda t: t.replace("step = 0.02", "step = 0.5"), "--step"),
    ("a word as the end", lambda t: t.replace("to = 0.92", 'to = "low"'), "branch.to"),
    ("an unknown parameter", lambda t: t.replace('param = "v"', 'param = "R0"'), "--param"),
    ("stability not true or false", lambda t: t + 'stability = "no"\n', "true or false"),
    # checked before anything runs (issue 40: these failed on the workers, exit 0)
    ("too few nodes", lambda t: t + '[run]\nn = 10\n', "n"),
    ("order 0", lambda t: t + '[run]\nbackend_options = {order = 0}\n', "--order"),
    ("an unknown option", lambda t: t + '[run]\nbackend_options = {stride = 2}\n', "stride"),
    ("the Cartesian geometry",
     lambda t: t + '[run]\nbackend_options = {geometry = "cartesian"}\n', "axisymmetric"),
]


def test_a_sweep_of_branches(tmp_path, capsys):
    """With [branch] each point is a branch followed by continuation: its folder is the
    branch folder, its row the last point (steps = its points, end = its v), and run again
    the sweep skips it; another [branch] end is another point (refused, as a changed run)."""
    path = tmp_path / "b.toml"
    path.write_text(BRANCH_SWEEP)
    out = tmp_path / "out"
    assert main([str(path), "--out", str(out), "--workers", "1", "--quiet"]) == 0
    rows = _table(out / "sweep.csv")
    assert [r["status"] for r in rows] == ["completed"] * 2
    for r in rows:
        branch = _table(out / "points" / r["point"] / "branch.csv")
        assert int(r["steps"]) == len(branch) >= 2
        assert r["end"] == branch[-1]["v"] and r["e"] == branch[-1]["e"]
        assert float(r["end"]) <= 0.92
    assert rows[0]["e"] != rows[1]["e"]  # two sizes: two branches
    capsys.readouterr()
    assert main([str(path), "--out", str(out), "--workers", "1"]) == 0
    assert "2 done, 0 to run" in capsys.readouterr().out
    assert _table(out / "sweep.csv") == rows
    path.write_text(BRANCH_SWEEP.replace("to = 0.92", "to = 0.9"))
    assert main([str(path), "--out", str(out), "--workers", "1", "--quiet"]) == 2
    assert "other settings" in capsys.readouterr().err


#: listed branches: one point on the grid, one listed with its own size and end
LISTED_BRANCHES = BRANCH_SWEEP.replace("R0 = [0.18, 0.2]", "R0 = [0.2]") + """
[[points]]
name = "small"
scene = {R0 = 0.18}
branch = {to = 0.93, step = 0.01}
"""
#: a listed branch point's mistakes: (what is wrong, the change, a word of the message)
BAD_LISTED_BRANCHES = [
    ("a start from another point", lambda t: t + 'after = "R0=0.2_seed=prolate"\n',
     "starts from its seed"),
    ("the parameter in its scene", lambda t: t.replace("{R0 = 0.18}", "{R0 = 0.18, v = 0.9}"),
     "branch's parameter"),
    ("its own parameter", lambda t: t.replace("{to = 0.93", '{param = "da0", to = 0.93'),
     "unknown key"),
    ("a step too long for its ends", lambda t: t.replace("step = 0.01}", "step = 0.05}"),
     "point small: --step"),
    ("a run option", lambda t: t + 'run = {recipe = "steady"}\n', "takes only"),
    ("a 3D scene of no axis under the vesicle's [scene]", lambda t: t + 'base = "three-arm"\n',
     "point small"),
]


def test_a_sweep_listed_in_code_is_the_sweep_file_s(tmp_path):
    """fem_ade.campaigns.sweep_file.listed_sweep (the studies' sweeps built from their plans)
    makes the points a sweep file listing the same tables makes: the same names and identities, runs
    and branches alike; and it checks them as load_sweep does."""
    from fem_ade.campaigns.sweep_file import listed_sweep

    path = tmp_path / "l.toml"
    path.write_text('name = "b"\nseeds = ["prolate"]\n[branch]\nparam = "v"\nfrom = 0.95\n'
                    'to = 0.92\n[[points]]\nname = "small"\nscene = {R0 = 0.18, eps = 0.05}\n'
                    'branch = {to = 0.93, step = 0.01}\n')
    from_file = load_sweep(path).points()
    made = listed_sweep("b", [{"name": "small", "seed": "prolate",
                               "scene": {"R0": 0.18, "eps": 0.05},
                               "branch": {**from_file[0].branch}}])
    assert [p.identity() for p in made.points()] == [p.identity() for p in from_file]
    runs = listed_sweep("r", [{"name": "a", "scene": {"v": 0.9, "eps": 0.08},
                               "seed": "prolate", "run": {"recipe": "steady"}},
                              {"name": "b", "after": "a", "seed": "prolate",
                               "scene": {"v": 0.9, "eps": 0.04}}])
    assert [(p.name, p.after) for p in runs.points()] == [("a", None), ("b", "a")]
    with pytest.raises(ModelError, match="recipe"):
        listed_sweep("r", [{"name": "a", "seed": "prolate", "run": {"recipe": "nope"}}])


def test_a_vesicle_branch_in_da0_is_checked_at_its_start(tmp_path):
    """A vesicle sweep of branches in Δa₀: each point's vesicle is checked with Δa₀ at the
    branch's start (it was checked without it, and refused as κ̄ without Δa₀)."""
    path = tmp_path / "b.toml"
    path.write_text(BRANCH_SWEEP.replace("eps = 0.05", "eps = 0.05\nkbar = 1.4\nv = 0.85")
                    .replace('param = "v"', 'param = "da0"').replace("from = 0.95", "from = 1.04")
                    .replace("to = 0.92", "to = 1.1"))
    sweep = load_sweep(path)
    assert [p.branch["from"] for p in sweep.points()] == [1.04, 1.04]
    assert "stability" not in sweep.points()[0].identity()["branch"]  # (old folders stay)
    path.write_text(path.read_text() + "stability = false\n")
    assert load_sweep(path).points()[0].branch["stability"] is False
    path.write_text(path.read_text().replace("stability = false\n", ""))
    path.write_text(path.read_text().replace("kbar = 1.4", "kbar = -1.0"))
    with pytest.raises(ModelError, match="kbar"):
        load_sweep(path)


def test_listed_branches(tmp_path):
    """A branch sweep's listed point follows its own branch: its size from its scene, its
    ends and step over [branch]'s (its branch.json records them), beside the grid's."""
    path = tmp_path / "b.toml"
    path.write_text(LISTED_BRANCHES)
    out = tmp_path / "out"
    assert main([str(path), "--out", str(out), "--workers", "1", "--quiet"]) == 0
    rows = {r["point"]: r for r in _table(out / "sweep.csv")}
    assert set(rows) == {"R0=0.2_seed=prolate", "small"}
    small = _table(out / "points" / "small" / "branch.csv")
    record = json.loads((out / "points" / "small" / "branch.json").read_text())
    assert (record["from"], record["step"]) == (0.95, 0.01)
    assert record["params"]["beta"] == pytest.approx(4 * math.pi * 0.18**2)  # area 4πR₀²
    assert float(small[0]["v"]) == pytest.approx(0.95, abs=1e-9)
    assert float(rows["small"]["end"]) <= 0.93 < float(small[-2]["v"])
    assert int(rows["small"]["steps"]) == len(small)
    assert float(rows["R0=0.2_seed=prolate"]["end"]) <= 0.92


#: each mistake with the branch sweep it is made in (a grid, or listed branches)
BAD_BRANCH_CASES = [(BRANCH_SWEEP, c) for c in BAD_BRANCH_SWEEPS] + \
    [(LISTED_BRANCHES, c) for c in BAD_LISTED_BRANCHES]


@pytest.mark.parametrize("sweep, case", BAD_BRANCH_CASES,
                         ids=[("listed: " if t is LISTED_BRANCHES else "") + c[0]
                              for t, c in BAD_BRANCH_CASES])
def test_bad_branch_sweeps_are_one_line(tmp_path, capsys, sweep, case):
    _, change, word = case
    path = tmp_path / "b.toml"
    path.write_text(change(sweep))
    out = tmp_path / "out"
    code = main([str(path), "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and word in err, err
    assert not out.exists(), "a refused sweep wrote something"


@pytest.mark.parametrize("case", BAD_SWEEPS, ids=[c[0] for c in BAD_SWEEPS])
def test_bad_sweeps_are_one_line_before_anything_runs(tmp_path, capsys, case):
    _, change, word = case
    out = tmp_path / "out"
    code = main([str(_bad_file(tmp_path, change)), "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and word in err, err
    assert not out.exists(), "a refused sweep wrote something"


@pytest.mark.parametrize("case", ["a file", "/dev/null", "read-only", "unrelated folder",
                                  "a run folder", "empty --out", "empty --scheduler",
                                  "refused address", "unknown scheme", "garbage file",
                                  "empty file"])
def test_bad_places_are_one_line_and_write_nothing(tmp_path, capsys, case):
    path = _file(tmp_path, axes="[0.9]", steps=4)
    out, extra = tmp_path / "out", []
    if case == "a file":
        out.write_text("x")
    elif case == "/dev/null":
        out = Path("/dev/null")
    elif case == "read-only":
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        out = ro / "sweep"
        if os.access(ro, os.W_OK):  # root writes anywhere: nothing to refuse
            pytest.skip("running as root: a read-only folder is writable")
    elif case == "unrelated folder":
        out.mkdir()
        (out / "notes.txt").write_text("mine")
    elif case == "a run folder":
        out.mkdir()
        (out / "run.json").write_text("{}")
    elif case == "empty --out":
        out = Path("")
    else:
        sched = {"empty --scheduler": "", "refused address": "tcp://127.0.0.1:9",
                 "unknown scheme": "bogus://host:1"}.get(case)
        if sched is None:
            sched = tmp_path / "sched.json"
            sched.write_text("not json" if case == "garbage file" else "")
        extra = ["--scheduler", str(sched)]
    before = sorted(p.name for p in tmp_path.iterdir())
    code = main([str(path), "--out", str(out), "--quiet", *extra])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_report_only_over_damaged_folders(tmp_path, capsys):
    """A point folder whose summary.json is damaged reads as "damaged" in the table, not a
    traceback."""
    path = _file(tmp_path, axes="[0.9]", steps=4)
    out = tmp_path / "out"
    assert main([str(path), "--out", str(out), "--workers", "1", "--quiet"]) == 0
    (point,) = (out / "points").glob("*/summary.json")
    point.write_text('{"final": 3}')
    assert main([str(path), "--out", str(out), "--report-only"]) == 1
    (row,) = _table(out / "sweep.csv")
    assert row["status"] == "damaged" and "summary.json" in row["reason"]


#: a chain of listed points: a from the seed, b from a's end, c from b's at another ε
CHAIN = """
name = "chain"
base = "vesicle"
seeds = ["sphere"]
[scene]
eps = 0.08
v = 0.9
[run]
recipe = "steady"
backend = "spectral"
n = 16
max_steps = 12
constraints = "exact"
checkpoint_every = 5
[[points]]
name = "a"
[[points]]
name = "b"
after = "a"
run = {max_steps = 6}
[[points]]
name = "c"
scene = {eps = 0.07}
after = "b"
"""


def _first_E(folder: Path) -> float:
    return float(_table(folder / "history.csv")[0]["E"])


def _last_E(folder: Path) -> float:
    return float(_table(folder / "history.csv")[-1]["E"])


def test_listed_points_start_from_each_others_end(tmp_path, capsys):
    path, out = tmp_path / "chain.toml", tmp_path / "out"
    path.write_text(CHAIN)
    assert [p.name for p in load_sweep(path).points()] == ["a", "b", "c"]
    assert main([str(path), "--out", str(out), "--quiet"]) == 0
    rows = read_sweep_table(out / "sweep.csv")
    assert [(r["point"], r["after"], r["eps"]) for r in rows] == [
        ("a", "", None), ("b", "a", None), ("c", "b", 0.07)]
    assert [r["status"] for r in rows] == ["max_steps"] * 3
    pts = out / "points"
    assert _first_E(pts / "b") == pytest.approx(_last_E(pts / "a"), rel=1e-12)
    assert _first_E(pts / "c") != pytest.approx(_first_E(pts / "a"), rel=1e-3)
    assert not (out / "phase-diagram.png").exists()  # no key that every point sets
    capsys.readouterr()
    assert main([str(path), "--out", str(out)]) == 0  # again: nothing runs
    assert "3 points, 3 done, 0 to run" in capsys.readouterr().out
    # a at other settings: a refused, and b and c with it (each is where it starts from)
    from fem_ade.campaigns.sweep_points import changed

    other = load_sweep(_write(tmp_path / "other.toml",
                              CHAIN.replace("max_steps = 12", "max_steps = 11")))
    assert all(changed(p, out) for p in other.points()), "b, c not changed with their start"


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_a_point_after_a_failed_one_fails_with_the_reason(tmp_path):
    """a failed (its record, as a sweep writes it): b is recorded as failed, with a's
    status named, and c after b too; nothing of theirs runs."""
    from fem_ade.engine.jobs import record_failure
    from fem_ade.store.output import write_json_atomic

    sweep = load_sweep(_write(tmp_path / "chain.toml", CHAIN))
    out = tmp_path / "out"
    a = sweep.points()[0]
    write_json_atomic(out / "sweep.json", {"name": "chain"}, make_folder=True)  # (a sweep's)
    write_json_atomic(out / "points" / "a.point.json", a.identity(), make_folder=True)
    record_failure(out / "points" / "a", "ModelError: made to fail")
    rows = run_sweep(sweep, out, workers=1, quiet=True)
    assert [r["status"] for r in rows] == ["failed"] * 3
    assert "its start a ended failed" in rows[1]["reason"]
    assert "its start b ended failed" in rows[2]["reason"]
    assert not (out / "points" / "b").exists() and not (out / "points" / "c").exists()


def test_a_point_waits_while_its_start_has_not_ended(tmp_path):
    """b's start a has not ended (not run yet, or a checkpoint another process holds): b is
    ``busy`` (the driver asks again later) and nothing of b's is written."""
    from fem_ade.campaigns.sweep_points import run_point

    b = load_sweep(_write(tmp_path / "chain.toml", CHAIN)).points()[1]
    r = run_point(b, str(tmp_path))
    assert r["status"] == "busy" and r["reason"] == "waits for a to end"
    assert not (tmp_path / "points").exists()


def test_a_point_runs_only_after_the_end_it_asks_for(tmp_path, capsys):
    """b asks for a steady start (``when``); a ends at max_steps: b is skipped with the
    reason (not failed, not run), the sweep ends with exit code 0; c after b fails."""
    text = CHAIN.replace('after = "a"\n', 'after = "a"\nwhen = ["steady"]\n')
    path, out = _write(tmp_path / "w.toml", text), tmp_path / "out"
    assert main([str(path), "--out", str(out), "--quiet"]) == 0
    assert "1 failed, 1 skipped" in capsys.readouterr().out
    rows = {r["point"]: r for r in read_sweep_table(out / "sweep.csv")}
    assert rows["a"]["status"] == "max_steps" and rows["b"]["status"] == "skipped"
    assert rows["b"]["reason"] == "not run: its start a ended max_steps; it runs after steady"
    assert rows["c"]["status"] == "failed" and "its start b was skipped" in rows["c"]["reason"]
    assert not (out / "points" / "b").exists()
    bad = _write(tmp_path / "bad.toml", text.replace('when = ["steady"]', 'when = ["busy"]'))
    assert main([str(bad), "--out", str(tmp_path / "o2"), "--quiet"]) == 2
    assert "when must be a list of the statuses" in capsys.readouterr().err


def _worker_environ(key: str):
    return os.environ.get(key)


def test_sweep_workers_keep_the_dynamic_mmap_threshold():
    """A sweep's LocalCluster starts its workers without Dask's MALLOC_TRIM_THRESHOLD_ (it
    made an axisymmetric point 4x slower); a LocalCluster with Dask's defaults, the control,
    sets it."""
    from dask.distributed import Client, LocalCluster

    from fem_ade.campaigns.sweep import connect

    os.environ.pop("MALLOC_TRIM_THRESHOLD_", None)  # (a nanny sets it in its own process too)
    client, cluster = connect(None, 1)
    try:
        assert client.submit(_worker_environ, "MALLOC_TRIM_THRESHOLD_").result() is None
    finally:
        client.close()
        cluster.close()
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                      dashboard_address=":0", silence_logs=40) as control, Client(control) as c:
        assert c.submit(_worker_environ, "MALLOC_TRIM_THRESHOLD_").result() == "65536"
    os.environ.pop("MALLOC_TRIM_THRESHOLD_", None)


def test_a_listed_point_with_a_scene_of_its_own(tmp_path, capsys):
    """A listed point's base may be a scene's table (what scene_to_mapping makes of a scene
    built in code): it runs as that scene does (the same end as the named scene's point);
    a table that is no scene is one line before anything runs."""
    from fem_ade.campaigns.sweep_file import Sweep, check_sweep
    from fem_ade.scenes.catalogue import get_scene, scene_to_mapping

    own = scene_to_mapping(get_scene("discocyte"))
    run = {"backend": "spectral", "n": 16, "steps": 4, "render": False,
           "allow_underresolved": True}
    sweep = Sweep("own", "discocyte", {}, {}, [0], {}, listed=[
        {"name": "named", "base": "discocyte", "seed": 0, "scene": {}, "run": run,
         "after": None},
        {"name": "table", "base": own, "seed": 0, "scene": {}, "run": run, "after": None}])
    check_sweep(sweep)
    rows = {r["point"]: r for r in run_sweep(sweep, tmp_path / "out", workers=1, quiet=True)}
    assert rows["table"]["status"] == "completed" and rows["table"]["E"] == rows["named"]["E"]
    bad = _write(tmp_path / "bad.toml", 'name = "b"\nbase = "discocyte"\nseeds = [0]\n'
                 '[[points]]\nname = "x"\nbase = {params = {eps = -1}}\n')
    assert main([str(bad), "--out", str(tmp_path / "o"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "[[points]] x: base" in err, err


def test_the_check_before_anything_runs_solves_no_sharp_seed(monkeypatch):
    """A vesicle sweep's check builds its points' scenes without their sharp seeds (a solve
    of 0.3–10 s each: minimal.toml's first point, the prolate at v = 0.5, took 20 s before any
    point ran); the seed is solved where the point runs. The committed sweep files load with
    the sharp solver made to fail."""
    import fem_ade.analysis.sharp
    from fem_ade.scenes.catalogue import vesicle_scene

    def no_solve(*args):
        raise AssertionError(f"a sharp solve in the check: {args}")

    monkeypatch.setattr(fem_ade.analysis.sharp, "solve_cached", no_solve)
    for name in ("minimal", "ade", "eps_ladder"):
        assert load_sweep(ROOT / "studies" / "sweeps" / f"{name}.toml").points()
    with pytest.raises(AssertionError, match="a sharp solve"):  # a scene to run has its seed
        vesicle_scene(v=0.9, branch="prolate")
    checked = vesicle_scene(v=0.9, branch="prolate", sharp_seed=False)
    assert "standing in for the sharp seed" in checked.description


def test_a_local_cluster_only_for_points_to_run(tmp_path, monkeypatch):
    """A local cluster has no more workers than points to run, and a sweep whose points
    have all ended starts none: its table again, the same."""
    import fem_ade.campaigns.sweep

    asked = []
    connect = fem_ade.campaigns.sweep.connect
    monkeypatch.setattr(fem_ade.campaigns.sweep, "connect",
                        lambda scheduler, workers: asked.append(workers) or connect(scheduler,
                                                                                   workers))
    sweep = load_sweep(_file(tmp_path, axes="[0.9]", steps=2))
    out = tmp_path / "out"
    rows = run_sweep(sweep, out, workers=2, quiet=True)
    assert asked == [1] and rows[0]["status"] == "max_steps"
    table = _table(out / "sweep.csv")
    again = run_sweep(sweep, out, workers=2, quiet=True)
    assert asked == [1] and again[0]["E"] == rows[0]["E"]
    assert _table(out / "sweep.csv") == table


def test_one_table_reader_for_sweeps_and_branches(tmp_path):
    """fem_ade.store.tables is the one CSV writer and reader of sweep.csv and branch.csv: a
    row comes back with its numbers as numbers, its text columns as text, an empty cell as
    the caller's ``empty``; the file is replaced whole."""
    from fem_ade.store.tables import read_table, write_table

    path = tmp_path / "t.csv"
    rows = [{"point": "007", "v": 0.85, "steps": 12, "label": "", "x": None}]
    write_table(path, ["point", "v", "steps", "label", "x"], rows)
    assert path.read_text().splitlines() == ["point,v,steps,label,x", "007,0.85,12,,"]
    assert read_table(path, text=("point", "label")) == [
        {"point": "007", "v": 0.85, "steps": 12, "label": "", "x": None}]
    assert read_table(path, empty="") == [
        {"point": 7, "v": 0.85, "steps": 12, "label": "", "x": ""}]
    assert not (tmp_path / "t.csv.tmp").exists()
