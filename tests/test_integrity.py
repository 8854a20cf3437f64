"""A resume is a continuation of exactly that run (issue 31): every run.json field that
changes the trajectory or the files is part of the checkpoint's identity, and the checkpoint
carries checksums of its state and of history.csv up to its step. Each tampering below was
resumed silently before (or deleted saved files); each is refused now with one line, the
folder untouched."""

from __future__ import annotations

import csv
import json
import shutil

import numpy as np
import pytest

from fem_ade.cli.run import main

RUN = ["discocyte", "--backend", "spectral", "--n", "16", "--allow-underresolved", "--every",
       "5", "--quiet", "--no-render", "--save-every", "5"]


def snapshot(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()
            and not p.name.startswith(".fem_ade")}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """A run interrupted at step 15 (its checkpoint; series steps 0, 5, 10, 15) and a copy of
    the same run checkpointed at step 20."""
    import signal

    base = tmp_path_factory.mktemp("integrity")
    old = signal.getsignal(signal.SIGINT)
    try:
        assert main([*RUN, "--steps", "15", "--checkpoint-every", "15",
                     "--out", str(base / "at15")]) == 0
        assert main([*RUN, "--steps", "20", "--checkpoint-every", "20",
                     "--out", str(base / "at20")]) == 0
    finally:
        signal.signal(signal.SIGINT, old)
    return base


def edit_json(path, change):
    data = json.loads(path.read_text())
    change(data)
    path.write_text(json.dumps(data))


def edit_checkpoint(path, change):
    with np.load(path) as z:
        data = {k: np.array(z[k]) for k in z.files}
    change(data)
    np.savez(path, **data)
    written = path.with_name(path.name + ".npz")
    if written.exists():
        written.replace(path)


def edit_loop(key, value):
    def change(data):
        loop = json.loads(str(data["loop"]))
        loop[key] = value
        data["loop"] = np.array(json.dumps(loop))
    return change


def edit_history(change):
    def apply(folder):
        path = folder / "history.csv"
        with open(path, newline="") as f:
            rows = list(csv.reader(f))
        rows = change(rows)
        with open(path, "w", newline="") as f:
            csv.writer(f).writerows(rows)
    return apply


def _swap(rows):
    rows[1], rows[2] = rows[2], rows[1]
    return rows


def _alter(rows):
    rows[2][2] = repr(float(rows[2][2]) * (1 + 1e-9))
    return rows


TAMPER = {
    # run.json: what a resume would have continued differently (or deleted files for)
    "accelerate": lambda f: edit_json(f / "run.json", lambda d: d.update(accelerate=True)),
    "adaptive": lambda f: edit_json(f / "run.json", lambda d: d.update(
        adaptive={"dt_min": 1e-9, "dt_max": 1e-6})),
    "every": lambda f: edit_json(f / "run.json", lambda d: d.update(every=3)),
    "save_every": lambda f: edit_json(f / "run.json", lambda d: d.update(save_every=7)),
    "scene's ic": lambda f: edit_json(f / "run.json", lambda d: d["scene"]["ic"].update(
        c_consistent=0.13)),
    # the checkpoint
    "step edited": lambda f: edit_checkpoint(f / "checkpoint.npz", edit_loop("k", 10)),
    "dt edited": lambda f: edit_checkpoint(f / "checkpoint.npz", edit_loop("dt", 4e-7)),
    "t edited": lambda f: edit_checkpoint(f / "checkpoint.npz", edit_loop("t", 1e-5)),
    "phi off by 1e-12": lambda f: edit_checkpoint(
        f / "checkpoint.npz", lambda d: d.update(state__phi_hat=d["state__phi_hat"]
                                                 * (1 + 1e-12))),
    "phi as float32": lambda f: edit_checkpoint(
        f / "checkpoint.npz", lambda d: d.update(
            state__phi_hat=d["state__phi_hat"].astype(np.complex64))),
    "a later checkpoint": lambda f: shutil.copy(f.parent / "runs" / "at20" / "checkpoint.npz",
                                                f / "checkpoint.npz"),
    # history.csv up to the checkpoint's step
    "history row deleted": edit_history(lambda rows: rows[:2] + rows[3:]),
    "history row duplicated": edit_history(lambda rows: rows[:3] + rows[2:]),
    "history rows swapped": edit_history(_swap),
    "history value altered": edit_history(_alter),
}


@pytest.mark.parametrize("kind", list(TAMPER))
def test_a_tampered_run_is_not_resumed(runs, tmp_path, capsys, kind):
    folder = tmp_path / "at15"
    shutil.copytree(runs / "at15", folder)
    (tmp_path / "runs").symlink_to(runs)
    TAMPER[kind](folder)
    before = snapshot(folder)
    code = main(["--resume", str(folder), "--steps", "25", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert "cannot resume" in err, err
    assert snapshot(folder) == before, "a refused resume changed the folder"


def test_an_untouched_run_resumes_and_may_change_only_how_far_it_goes(runs, tmp_path):
    """The control: the same folder untouched resumes; so does one whose run.json changes
    only what a resume may change (steps, max_steps, checkpoint_every, render)."""
    folder = tmp_path / "at15"
    shutil.copytree(runs / "at15", folder)
    edit_json(folder / "run.json", lambda d: d.update(checkpoint_every=4, render=False))
    assert main(["--resume", str(folder), "--steps", "20", "--quiet"]) == 0
    with np.load(folder / "final.npz") as a, np.load(runs / "at20" / "final.npz") as b:
        assert np.array_equal(a["phi"], b["phi"])
    assert sorted(p.name for p in folder.glob("phi-*.h5")) == [
        f"phi-{k:08d}.h5" for k in (0, 5, 10, 15, 20)]
