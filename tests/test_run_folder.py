"""A run folder belongs to one process (issue 22): locked for the whole life of a run or a
resume, crash-consistent, and never trusted on resume without the checks of a new run.

Concurrency uses real subprocesses; a full disk is a patched write that raises ENOSPC (a
tmpfs needs privileges CI may not have); SIGKILL is real.
"""

from __future__ import annotations

import errno
import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from fem_ade.store import output
from fem_ade.store.lock import LOCK_NAME, OWNER_NAME
from fem_ade.store.output import read_history
from fem_ade.store.xdmf import read_series

#: a run of a few seconds (long enough to meet a second process), and a short one
LONG = ["discocyte", "--n", "24", "--allow-underresolved", "--steps", "600", "--every", "10",
        "--quiet", "--no-render", "--checkpoint-every", "50", "--save-every", "100"]
SHORT = ["discocyte", "--n", "16", "--allow-underresolved", "--every", "5", "--quiet",
         "--no-render"]


def start(args, **kw) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "fem_ade.run", *map(str, args)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)


def wait_for(predicate, timeout=60.0, what="a condition"):
    t0 = time.monotonic()
    while not predicate():
        if time.monotonic() - t0 > timeout:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.02)


def snapshot(folder: Path) -> dict:
    """Every file under ``folder`` (but the lock file) with its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != LOCK_NAME}


def one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def same_run(a: Path, b: Path) -> None:
    """Bit for bit: every history column but timings, the field, the series' times."""
    ha, hb = read_history(a / "history.csv"), read_history(b / "history.csv")
    assert list(ha) == list(hb)
    for column in ha:
        if not column.endswith("_s"):
            assert np.array_equal(ha[column], hb[column]), column
    assert np.array_equal(np.load(a / "final.npz")["phi"], np.load(b / "final.npz")["phi"])
    ta = [t for t, _ in read_series(a / "phi.xdmf")[2]]
    tb = [t for t, _ in read_series(b / "phi.xdmf")[2]]
    assert ta == tb


# --- ownership ------------------------------------------------------------------------------
def test_a_file_that_vanishes_while_looked_at_is_not_odd(tmp_path, monkeypatch):
    """The owner's atomic write (checkpoint.tmp.npz renamed away) may happen between the listing
    of a folder and the look at each file: such a file is gone, not 'not a file' (CI once
    refused a second run for that instead of naming the owner); a folder in a file's place is
    odd."""
    (tmp_path / "checkpoint.npz").mkdir()
    listed = output.run_files(tmp_path)
    monkeypatch.setattr(output, "run_files",
                        lambda folder: [*listed, folder / "checkpoint.tmp.npz"])
    assert output.not_files(tmp_path) == ["checkpoint.npz"]


def test_second_run_on_the_same_folder_is_refused(tmp_path):
    """Two runs with the same --out: the second exits 2 with one line naming the owner; the
    folder ends as the first run's, whole (not a mix of both)."""
    out = tmp_path / "R"
    first = start([*LONG, "--out", out])
    wait_for(lambda: (out / OWNER_NAME).is_file(), what="the first run's lock")
    second = subprocess.run([sys.executable, "-m", "fem_ade.run", *SHORT, "--steps", "5",
                             "--out", out, "--force"], capture_output=True, text=True,
                            timeout=120)
    assert second.returncode == 2
    line = one_line(second.stderr)
    assert "in use by another run" in line and f"pid {first.pid}" in line, line
    _, err = first.communicate(timeout=300)
    assert first.returncode == 0, err
    summary = json.loads((out / "summary.json").read_text())
    run = json.loads((out / "run.json").read_text())
    assert summary["n"] == run["n"] == 24 and summary["steps"] == 600  # nodes per axis
    h = read_history(out / "history.csv")
    assert np.array_equal(h["step"], np.arange(0, 601, 10))
    assert not (out / OWNER_NAME).exists()  # released at the end


def test_two_resumes_at_once(tmp_path, cli):
    """Two resumes of one folder: one continues to the end, the other exits 2; the history
    is the uninterrupted run's."""
    out, whole = tmp_path / "R", tmp_path / "W"
    assert cli([*LONG, "--steps", "50", "--out", out]).returncode == 0
    a = start(["--resume", out, "--steps", "600", "--quiet"])
    wait_for(lambda: (out / OWNER_NAME).is_file(), what="the resume's lock")
    b = subprocess.run([sys.executable, "-m", "fem_ade.run", "--resume", str(out), "--steps",
                        "600", "--quiet"], capture_output=True, text=True, timeout=120)
    assert b.returncode == 2 and "in use by another run" in one_line(b.stderr)
    _, err = a.communicate(timeout=300)
    assert a.returncode == 0, err
    assert cli([*LONG, "--out", whole]).returncode == 0
    same_run(whole, out)


def test_stale_lock_of_a_killed_run_is_taken_over(tmp_path, cli):
    """SIGKILL leaves the lock and owner files; the lock is free (the OS released it): a
    resume takes it and the run ends as the uninterrupted one."""
    out, whole = tmp_path / "R", tmp_path / "W"
    p = start([*LONG, "--out", out])
    wait_for(lambda: (out / "checkpoint.npz").is_file(), what="a checkpoint")
    p.send_signal(signal.SIGKILL)
    p.wait(timeout=60)
    assert (out / OWNER_NAME).is_file()  # the dead owner's note
    r = cli(["--resume", out, "--quiet"])
    assert r.returncode == 0, r.stderr
    assert cli([*LONG, "--out", whole]).returncode == 0
    same_run(whole, out)
    assert not (out / OWNER_NAME).exists()


# --- resume checks everything before it writes ----------------------------------------------
def _edit_json(path: Path, **changes):
    data = json.loads(path.read_text())
    data.update(changes)
    path.write_text(json.dumps(data))


def _edit_checkpoint(path: Path, **loop):
    with np.load(path) as z:
        arrays = {k: np.array(z[k]) for k in z.files}
    state = json.loads(str(arrays["loop"]))
    state.update(loop)
    arrays["loop"] = np.array(json.dumps(state))
    with open(path, "wb") as f:
        np.savez(f, **arrays)


def _edit_state(path: Path, phi):
    with np.load(path) as z:
        arrays = {k: np.array(z[k]) for k in z.files}
    arrays["state__phi"] = phi
    with open(path, "wb") as f:
        np.savez(f, **arrays)


BROKEN = {
    "every 0": lambda d: _edit_json(d / "run.json", every=0),
    "dt -1": lambda d: _edit_json(d / "run.json", dt=-1.0),
    "steps as text": lambda d: _edit_json(d / "run.json", steps="30"),
    "unknown option": lambda d: _edit_json(d / "run.json", backend_options={"nope": 1}),
    "no backend": lambda d: _edit_json(d / "run.json", backend=None),
    "checkpoint step -5": lambda d: _edit_checkpoint(d / "checkpoint.npz", k=-5),
    "checkpoint dt 0": lambda d: _edit_checkpoint(d / "checkpoint.npz", dt=0.0),
    "state of text": lambda d: _edit_state(d / "checkpoint.npz", np.array(["a", "b"])),
    "state of another size": lambda d: _edit_state(d / "checkpoint.npz", np.zeros(7)),
    "history missing": lambda d: (d / "history.csv").unlink(),
    "history garbage": lambda d: (d / "history.csv").write_text("\x00\x01 not a csv\n1,2\n"),
    "history row garbage": lambda d: (d / "history.csv").write_text(
        (d / "history.csv").read_text().replace("\n10,", "\nten,", 1)),
}


@pytest.mark.parametrize("case", list(BROKEN))
def test_resume_checks_everything_before_writing(tmp_path, cli, case):
    out = tmp_path / "R"
    r = cli([*SHORT, "--steps", "20", "--checkpoint-every", "20", "--out", out])
    assert r.returncode == 0, r.stderr
    BROKEN[case](out)
    before = snapshot(out)
    r = cli(["--resume", out, "--steps", "30", "--quiet"])
    assert r.returncode == 2, (case, r.stdout, r.stderr)
    assert "cannot resume" in one_line(r.stderr) or "checkpoint" in r.stderr, r.stderr
    assert snapshot(out) == before, f"{case}: the failed resume changed the folder"


def test_history_row_cut_short_by_a_crash_is_dropped(tmp_path, cli):
    """A last history row cut short (a kill in the middle of a write) is dropped on resume."""
    out, whole = tmp_path / "R", tmp_path / "W"
    assert cli([*SHORT, "--steps", "20", "--checkpoint-every", "10", "--out", out]
               ).returncode == 0
    with open(out / "history.csv", "a") as f:
        f.write("25,1.2e-05,60.1")  # no newline: cut short
    assert cli(["--resume", out, "--steps", "30", "--quiet"]).returncode == 0
    assert cli([*SHORT, "--steps", "30", "--out", whole]).returncode == 0
    same_run(whole, out)


def test_phi0_run_resumes_after_its_start_moved(tmp_path, cli):
    """A --phi0 run keeps its start field in its own folder (initial.npz)."""
    src, out, whole = tmp_path / "S", tmp_path / "R", tmp_path / "W"
    assert cli([*SHORT, "--steps", "5", "--out", src]).returncode == 0
    assert cli([*SHORT, "--steps", "10", "--checkpoint-every", "10", "--phi0", src, "--out",
                out]).returncode == 0
    assert cli([*SHORT, "--steps", "20", "--phi0", src, "--out", whole]).returncode == 0
    src.rename(tmp_path / "moved")
    r = cli(["--resume", out, "--steps", "20", "--quiet"])
    assert r.returncode == 0, r.stderr
    same_run(whole, out)
    assert (out / "initial.npz").is_file()


def test_phi0_run_folder_moves_and_still_resumes(tmp_path, cli):
    """A run records its own start relative to its folder: the folder moved elsewhere
    resumes bit for bit (its run.json names ``initial.npz``, no absolute path)."""
    src, out, whole = tmp_path / "S", tmp_path / "R", tmp_path / "W"
    assert cli([*SHORT, "--steps", "5", "--out", src]).returncode == 0
    assert cli([*SHORT, "--steps", "10", "--checkpoint-every", "10", "--phi0", src, "--out",
                out]).returncode == 0
    assert cli([*SHORT, "--steps", "20", "--phi0", src, "--out", whole]).returncode == 0
    assert json.loads((out / "run.json").read_text())["scene"]["ic"]["path"] == "initial.npz"
    moved = tmp_path / "elsewhere" / "R2"
    moved.parent.mkdir()
    out.rename(moved)
    r = cli(["--resume", moved, "--steps", "20", "--quiet"])
    assert r.returncode == 0, r.stderr
    same_run(whole, moved)


# --- crashes and signals --------------------------------------------------------------------
def test_sigkill_keeps_the_series_and_resumes_bit_for_bit(tmp_path, cli):
    """SIGKILL at any moment: the series' index lists whole files only (the steps saved so
    far stay readable); the resume rebuilds it and the run ends as the uninterrupted one."""
    out, whole = tmp_path / "R", tmp_path / "W"
    p = start([*LONG, "--save-every", "20", "--out", out])
    wait_for(lambda: len(list(out.glob("phi-*.h5"))) >= 6, what="saved steps")
    p.send_signal(signal.SIGKILL)
    p.wait(timeout=60)
    _, _, steps = read_series(out / "phi.xdmf")  # readable as it was left
    assert len(steps) >= 5
    assert cli(["--resume", out, "--quiet"]).returncode == 0
    assert cli([*LONG, "--save-every", "20", "--out", whole]).returncode == 0
    same_run(whole, out)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_mid_run_is_one_line_and_130(tmp_path, sig):
    """TERM or INT during the loop: exit 130, one line on stderr (what happened and how to
    continue); SIGINT even when the process was started with SIGINT ignored (a background
    job of a non-interactive shell, a pytest-xdist worker)."""
    out = tmp_path / "R"
    p = start([*LONG, "--out", out],
              preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    wait_for(lambda: (out / "history.csv").is_file() and
             len((out / "history.csv").read_text().splitlines()) > 5, what="the loop")
    p.send_signal(sig)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 130, err
    line = one_line(err)
    assert "interrupted at step" in line and "--resume" in line, line
    assert json.loads((out / "summary.json").read_text())["status"] == "interrupted"


def test_signal_in_the_final_write_waits_for_it(tmp_path, monkeypatch):
    """A signal that arrives while the run's last files are written is held until they are
    whole, then ends the run with exit 130 (it used to end with 0)."""
    from fem_ade.cli.run import main
    from fem_ade.engine import execute as execute_mod
    from fem_ade.store import interrupt

    finish = execute_mod._finish

    def finish_with_a_signal(*args, **kwargs):
        interrupt.handler(signal.SIGTERM, None)  # as if TERM came now
        return finish(*args, **kwargs)

    monkeypatch.setattr(execute_mod, "_finish", finish_with_a_signal)
    monkeypatch.setattr(signal, "signal", lambda *a: None)  # keep pytest's own handlers
    out = tmp_path / "R"
    code = main([*SHORT, "--steps", "4", "--out", str(out)])
    assert code == 130
    assert json.loads((out / "summary.json").read_text())["status"] == "completed"
    assert np.load(out / "final.npz")["phi"].size > 0


def test_results_are_written_before_the_analysis(tmp_path, monkeypatch, capsys):
    """What the run computed (final.npz, summary.json with its final diagnostics) is written
    before the shape analysis, the sharp comparison and the pictures; a failure there (a
    MemoryError while VTK is imported, say) is reported and leaves them: exit 0, summary's
    ``analysis`` says why."""
    from fem_ade.backends.base import BackendBase
    from fem_ade.cli.run import main

    seen = {}

    def fails(self, final, grid=None):
        seen["files"] = sorted(p.name for p in out.iterdir())
        seen["summary"] = json.loads((out / "summary.json").read_text())
        raise MemoryError("no memory for VTK")

    monkeypatch.setattr(BackendBase, "describe_final", fails)
    monkeypatch.setattr(signal, "signal", lambda *a: None)
    out = tmp_path / "R"
    with pytest.warns(UserWarning, match="shape analysis failed"):
        code = main([*SHORT, "--steps", "4", "--out", str(out)])
    assert code == 0
    assert {"final.npz", "summary.json", "history.csv"} <= set(seen["files"])
    assert seen["summary"]["analysis"] == "pending" and seen["summary"]["final"]["E"] > 0
    s = json.loads((out / "summary.json").read_text())
    assert s["analysis"].startswith("failed: MemoryError") and s["shape"] is None
    assert s["final"] == seen["summary"]["final"] and np.load(out / "final.npz")["phi"].size


# --- resources ------------------------------------------------------------------------------
def test_disk_full_mid_run_keeps_the_last_checkpoint(tmp_path, monkeypatch, capsys):
    """ENOSPC while the history is written after step 30 (a checkpoint at 20): one line,
    exit 3, the checkpoint at step 20 kept — and the run resumes from it."""
    from fem_ade.cli.run import main
    from fem_ade.store import output

    write = output.HistoryWriter.write

    def full_after_30(self, row):
        if row["step"] > 30:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self._file.name))
        return write(self, row)

    monkeypatch.setattr(output.HistoryWriter, "write", full_after_30)
    monkeypatch.setattr(signal, "signal", lambda *a: None)
    out = tmp_path / "R"
    code = main([*SHORT, "--steps", "40", "--checkpoint-every", "20", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 3
    line = one_line(err)
    assert "No space left on device" in line and "checkpoint (step 20) is kept" in line, line
    monkeypatch.setattr(output.HistoryWriter, "write", write)
    assert main(["--resume", str(out), "--quiet"]) == 0


def test_disk_full_on_a_real_small_file_system(tmp_path):
    """A 300 kB tmpfs (where this machine lets root mount one; skipped elsewhere): exit 3,
    one line naming the error, no temporary file left behind."""
    mount = tmp_path / "small"
    mount.mkdir()
    made = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=300k", "tmpfs", str(mount)],
                          capture_output=True)
    if made.returncode != 0:
        pytest.skip("cannot mount a tmpfs here (needs root and the privilege)")
    try:
        r = subprocess.run([sys.executable, "-m", "fem_ade.run", *SHORT, "--n", "24",
                            "--steps", "200", "--every", "1", "--checkpoint-every", "20",
                            "--out", str(mount / "R")], capture_output=True, text=True,
                           timeout=300)
        assert r.returncode == 3, r.stderr
        assert "No space left on device" in one_line(r.stderr)
        assert not list((mount / "R").glob("*.tmp*"))
    finally:
        subprocess.run(["umount", str(mount)], capture_output=True)


# --- the Python API checks its arguments before any work ------------------------------------
def test_api_arguments(tmp_path):
    from fem_ade import simulate
    from fem_ade.model.params import ModelError

    out = tmp_path / "R"
    r = simulate("sphere", n=16, steps=2, allow_underresolved=True, render=False)
    assert r.status == "completed"  # a scene by name, as on the command line
    with pytest.raises(ModelError, match=r"^perturb \(--perturb\) must be a number"):
        simulate("sphere", n=16, steps=2, perturb=None, out=out)
    with pytest.raises(ModelError, match="real field"):
        simulate("sphere", n=16, steps=2, phi0=np.ones((16,) * 3, complex), out=out)
    with pytest.raises(TypeError, match="monitor must be callable"):
        simulate("sphere", n=16, steps=2, monitor=3, out=out)
    with pytest.raises(TypeError, match="scene must be a Scene"):
        simulate(3.5, out=out)
    with pytest.raises(ModelError, match=r"^steps \(--steps\) must be an integer >= 1"):
        simulate("sphere", n=16, steps=0, allow_underresolved=True, out=out)
    assert not out.exists()


def test_one_run_configuration(tmp_path, cli):
    """The command line and the API build the same RunConfig; run.json is it (with the scene
    as run) and reads back to it; a run.json that lacks a choice is refused by name."""
    from fem_ade import simulate
    from fem_ade.engine.config import RunConfig
    from fem_ade.model.params import ModelError
    from fem_ade.scenes.catalogue import SCENES

    r = cli(["sphere", "--n", "16", "--steps", "3", "--allow-underresolved", "--no-render",
             "--dt", "2e-7", "--out", tmp_path / "cli"])
    assert r.returncode == 0, r.stderr
    simulate("sphere", n=16, steps=3, dt=2e-7, allow_underresolved=True, render=False,
             out=tmp_path / "api")
    cli_json = json.loads((tmp_path / "cli" / "run.json").read_text())
    api_json = json.loads((tmp_path / "api" / "run.json").read_text())
    assert cli_json == api_json
    config = RunConfig.from_mapping({k: v for k, v in cli_json.items() if k != "scene"})
    assert config == RunConfig.build(SCENES["sphere"], n=16, steps=3, dt=2e-7, render=False)
    assert config.to_mapping() == {k: v for k, v in cli_json.items() if k != "scene"}
    assert config.continued_to(9).steps == 9 and config.total_steps == 3
    del cli_json["seed"]
    with pytest.raises(ModelError, match="lacks seed"):
        RunConfig.from_mapping({k: v for k, v in cli_json.items() if k != "scene"})
    with pytest.raises(ModelError, match="--dt must be a positive number"):
        RunConfig.build(SCENES["sphere"], dt=-1.0, adaptive=True)
    # the scene as run: a seeded FEM run of order 2 on 16 nodes records the torus it started
    # from and its 16 points per axis, whose default n is the run's again
    from fem_ade.scenes.catalogue import scene_from_mapping

    simulate("torus", backend="fem", n=16, steps=1, ic="seeded", allow_underresolved=True,
             render=False, backend_options={"order": 2}, out=tmp_path / "seeded")
    run = json.loads((tmp_path / "seeded" / "run.json").read_text())
    assert run["scene"]["ic"]["kind"] == "torus" and run["scene"]["n"] == 16
    recorded = scene_from_mapping(run["scene"])
    assert RunConfig.build(recorded, backend="fem", backend_options={"order": 2}).n == 16


# --- the randomized fault test ----------------------------------------------------------------
@pytest.mark.slow
def test_random_kills_resume_bit_for_bit(tmp_path, cli):
    """Runs killed at random moments — SIGKILL or SIGTERM, at set-up, mid-run, in a
    checkpoint, in the final write — and resumed (or, killed before their first checkpoint,
    started again with --force) until they finish: each ends bit for bit as the
    uninterrupted run. FAULT_KILLS kills in all (default 200)."""
    kills = int(os.environ.get("FAULT_KILLS", 200))
    rng = random.Random(12345)
    args = [*SHORT, "--steps", "300", "--checkpoint-every", "7", "--save-every", "9"]
    whole = tmp_path / "W"
    assert cli([*args, "--out", whole]).returncode == 0
    done, compared = 0, 0
    while done < kills:
        out = tmp_path / f"R{compared}"
        p = start([*args, "--out", out])
        for _ in range(rng.randint(1, 8)):
            time.sleep(rng.uniform(0.05, 1.2))
            if p.poll() is not None:
                break
            p.send_signal(rng.choice([signal.SIGKILL, signal.SIGTERM]))
            p.wait(timeout=120)
            done += 1
            if (out / "checkpoint.npz").is_file():
                p = start(["--resume", out, "--quiet"])
            else:  # killed before its first checkpoint: start it again
                p = start([*args, "--out", out, "--force"])
        _, err = p.communicate(timeout=300)
        assert p.returncode == 0, err
        assert json.loads((out / "summary.json").read_text())["steps"] == 300
        same_run(whole, out)
        compared += 1
    print(f"{done} kills over {compared} runs, each resumed to the uninterrupted result")


def test_a_signal_right_after_a_step_keeps_its_row(tmp_path, monkeypatch):
    """A signal between a step and its bookkeeping (its count, time, history row and
    checkpoint) waits for them: the run stops at that step with its row written, and the
    resumed run ends with the uninterrupted history. The random-kill test once lost the row of
    step 60 so (a SIGTERM there: the checkpoint at 60 without its row)."""
    from fem_ade.engine import loop
    from fem_ade.engine.runs import resume, simulate
    from fem_ade.scenes.catalogue import get_scene
    from fem_ade.store import interrupt

    kw = dict(backend="spectral", n=16, steps=20, every=5, checkpoint_every=7, render=False,
              allow_underresolved=True)
    whole = simulate(get_scene("discocyte"), out=tmp_path / "W", **kw)
    accepted = loop.FixedStep.accepted

    def signal_after_step_10(self, backend, ls, good, diag):
        accepted(self, backend, ls, good, diag)
        if ls.k == 10:
            interrupt.handler(signal.SIGTERM, None)  # as if SIGTERM came here

    monkeypatch.setattr(loop.FixedStep, "accepted", signal_after_step_10)
    cut = simulate(get_scene("discocyte"), out=tmp_path / "R", **kw)
    assert cut.status == "interrupted" and cut.steps == 10
    assert list(read_history(tmp_path / "R" / "history.csv")["step"]) == [0, 5, 10]
    monkeypatch.setattr(loop.FixedStep, "accepted", accepted)
    done = resume(tmp_path / "R", quiet=True)
    assert done.status == whole.status and done.final == whole.final
    same_run(tmp_path / "W", tmp_path / "R")
