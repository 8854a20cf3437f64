"""fem_ade.engine.jobs.ensure: the one way a study, a sweep or a branch makes a run's result exist —
start, skip when finished, resume after a kill, start from another run's end, record a
failure with its reason, report or wait for a busy folder."""

import json

import numpy as np
import pytest

from fem_ade.engine.jobs import ensure, failure_record, status_of
from fem_ade.model.params import ModelError
from fem_ade.scenes.catalogue import PAPER_SCENES
from fem_ade.store.lock import FolderBusy
from fem_ade.store.output import read_history
from fem_ade.store.status import Status

SCENE = PAPER_SCENES["discocyte"]
OPTIONS = {"backend": "spectral", "n": 16, "every": 5, "render": False,
           "allow_underresolved": True}


def test_a_run_starts_then_is_skipped(tmp_path):
    folder = tmp_path / "a"
    first = ensure(folder, SCENE, options=dict(OPTIONS, steps=10))
    assert first.ran and first.ok and first.status == Status.COMPLETED
    assert first.summary["steps"] == 10
    stamp = (folder / "summary.json").stat().st_mtime_ns
    again = ensure(folder, SCENE, options=dict(OPTIONS, steps=10))
    assert not again.ran and again.summary == first.summary
    assert (folder / "summary.json").stat().st_mtime_ns == stamp


def test_an_ended_folder_of_another_run_is_not_its_result(tmp_path):
    """An ended folder answers only for the run it holds: another scene or other options
    (the backend's n, the scheme) give ``failed`` with the field that differs, run nothing and
    change nothing; the same run is still skipped (issue 40: ensure returned the torus's
    folder for the discocyte, ran = False, status completed)."""
    folder = tmp_path / "a"
    first = ensure(folder, SCENE, options=dict(OPTIONS, steps=10))
    files = {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}
    for scene, options, field in ((PAPER_SCENES["torus"], dict(OPTIONS, steps=10), "dt"),
                                  (SCENE, dict(OPTIONS, steps=10, n=24), "n"),
                                  (SCENE, dict(OPTIONS, steps=10, scheme="stabilized"),
                                   "scheme")):
        other = ensure(folder, scene, options=options)
        assert other.status == Status.FAILED and not other.ran and not other.ok
        assert "holds another run" in other.reason and field in other.reason
        assert not failure_record(folder).exists()
    assert {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()} == files
    assert ensure(folder, SCENE, options=dict(OPTIONS, steps=10)).summary == first.summary


def test_a_killed_run_is_resumed_to_the_uninterrupted_one(tmp_path):
    whole = ensure(tmp_path / "whole", SCENE, options=dict(OPTIONS, steps=20))

    def kill(backend, row):
        if row["step"] >= 10:
            raise KeyboardInterrupt

    part, killing = tmp_path / "part", dict(OPTIONS, steps=20, monitor=kill, shape_every=5)
    cut = ensure(part, SCENE, options=killing)  # the monitor sees a shape row every 5 steps
    assert cut.status == Status.INTERRUPTED and not cut.ok and cut.summary["steps"] == 10
    done = ensure(part, SCENE, options=killing)
    assert done.ran and done.status == Status.COMPLETED and done.summary["steps"] == 20
    with np.load(tmp_path / "whole" / "final.npz") as a, np.load(part / "final.npz") as b:
        assert np.array_equal(a["phi"], b["phi"])
    assert done.summary["final"]["E"] == whole.summary["final"]["E"]


def test_an_interrupted_folder_of_another_run_is_not_resumed(tmp_path):
    """An interrupted folder is resumed only as the run it holds: asked for with another n,
    ensure gives ``failed`` naming n, runs nothing and changes no file; asked for as itself,
    it resumes (the last stop's note: ensure resumed whatever an interrupted folder held)."""
    def kill(backend, row):
        if row["step"] >= 10:
            raise KeyboardInterrupt

    folder, killing = tmp_path / "a", dict(OPTIONS, steps=20, monitor=kill, shape_every=5)
    assert ensure(folder, SCENE, options=killing).status == Status.INTERRUPTED
    files = {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}
    other = ensure(folder, SCENE, options=dict(killing, n=24), restart=True)
    assert other.status == Status.FAILED and not other.ran
    assert "holds another run" in other.reason and "n" in other.reason
    assert {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()} == files
    assert not failure_record(folder).exists()
    done = ensure(folder, SCENE, options=killing)
    assert done.ran and done.status == Status.COMPLETED and done.summary["steps"] == 20


def test_a_run_from_another_runs_end(tmp_path):
    first = ensure(tmp_path / "first", SCENE, options=dict(OPTIONS, steps=10)).summary
    then = ensure(tmp_path / "then", SCENE, options=dict(OPTIONS, steps=5),
                  after=tmp_path / "first")
    assert then.ok
    start = read_history(tmp_path / "then" / "history.csv")["E"][0]
    assert start == pytest.approx(first["final"]["E"], rel=1e-12)
    fresh = read_history(tmp_path / "first" / "history.csv")["E"][0]
    assert abs(start - fresh) > 1e-6 * abs(fresh)  # not the scene's own start


def test_a_failure_is_recorded_with_its_reason_and_tried_again(tmp_path):
    folder = tmp_path / "bad"

    def bad_scene():
        raise ModelError("R0 does not fit the box")

    failed = ensure(folder, bad_scene, options=OPTIONS)
    assert failed.status == Status.FAILED and "does not fit the box" in failed.reason
    record = json.loads(failure_record(folder).read_text())
    assert "does not fit the box" in record["reason"]
    kept = ensure(folder, SCENE, options=dict(OPTIONS, steps=5), retry_failed=False)
    assert kept.status == Status.FAILED and not kept.ran and "does not fit" in kept.reason
    with pytest.raises(ModelError, match="does not fit the box"):
        kept.check()
    done = ensure(folder, SCENE, options=dict(OPTIONS, steps=5))
    assert done.ok and not failure_record(folder).exists()


def test_a_busy_folder_is_reported_or_waited_for(tmp_path, monkeypatch):
    monkeypatch.setattr("fem_ade.engine.jobs.WAIT_POLL_S", 0.01)
    calls = []

    def make(folder):
        calls.append(1)
        if len(calls) < 3:
            raise FolderBusy(f"{folder} is held by pid 1")
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "summary.json").write_text(json.dumps({"status": "completed"}))

    busy = ensure(tmp_path / "b", make=make)
    assert busy.status == Status.BUSY and "held by pid 1" in busy.reason
    waited = ensure(tmp_path / "b", make=make, wait=True)
    assert waited.ok and len(calls) == 3 and status_of(tmp_path / "b") == Status.COMPLETED


def test_a_job_is_a_scene_or_a_make_function(tmp_path):
    with pytest.raises(TypeError):
        ensure(tmp_path / "x")
    with pytest.raises(TypeError):
        ensure(tmp_path / "x", SCENE, make=lambda f: None)
