"""Checkpoint and restart: a resumed run equals the uninterrupted one bit for bit (issue 4)."""

import json
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from fem_ade.store.output import read_history


def _same_run(a, b):
    """Bit for bit: every history column but wall-clock timings (``*_s``), and the field."""
    ha, hb = read_history(a / "history.csv"), read_history(b / "history.csv")
    assert list(ha) == list(hb)
    for column in ha:
        if not column.endswith("_s"):
            assert np.array_equal(ha[column], hb[column]), column
    fa, fb = np.load(a / "final.npz"), np.load(b / "final.npz")
    assert np.array_equal(fa["phi"], fb["phi"])


@pytest.mark.parametrize("backend, constraints", [
    ("spectral", "penalty"), ("fem", "penalty"), ("spectral", "exact"), ("fem", "exact"),
    ("fem-fft", "exact")])
def test_resume_is_bit_identical(cli, tmp_path, backend, constraints):
    """Exact constraints resume in the middle of their targets' ramp (17 steps); the FEM's
    direct Fourier path (``fft``) keeps φ̂ as its state."""
    solver = ["--solver", "fft", "--order", "1"] if backend == "fem-fft" else []
    common = ["discocyte", "--backend", backend.split("-")[0], *solver, "--n", "16", "--every",
              "5", "--quiet", "--allow-underresolved", "--constraints", constraints,
              "--no-render"]
    whole, part = tmp_path / "whole", tmp_path / "part"
    assert cli([*common, "--steps", "30", "--out", whole]).returncode == 0
    r = cli([*common, "--steps", "10", "--checkpoint-every", "10", "--out", part])
    assert r.returncode == 0, r.stderr
    r = cli(["--resume", part, "--steps", "30", "--quiet"])
    assert r.returncode == 0, r.stderr
    _same_run(whole, part)
    assert json.loads((part / "summary.json").read_text())["steps"] == 30


@pytest.mark.parametrize("backend", ["spectral", "fem"])
def test_resume_with_momentum(cli, tmp_path, backend):
    """--accelerate: the checkpoint holds the momentum (t_k and the previous iterate)."""
    common = ["discocyte", "--n", "16", "--every", "5", "--quiet", "--allow-underresolved",
              "--scheme", "stabilized", "--dt", "5e-5", "--accelerate", "--backend", backend,
              "--constraints", "exact", "--no-render"]
    whole, part = tmp_path / "whole", tmp_path / "part"
    assert cli([*common, "--steps", "40", "--out", whole]).returncode == 0
    r = cli([*common, "--steps", "25", "--checkpoint-every", "25", "--out", part])
    assert r.returncode == 0, r.stderr
    assert cli(["--resume", part, "--steps", "40", "--quiet"]).returncode == 0
    _same_run(whole, part)


def test_resume_with_adaptive_dt_and_stabilized_scheme(cli, tmp_path):
    common = ["discocyte", "--n", "16", "--every", "5", "--quiet", "--allow-underresolved",
              "--scheme", "stabilized", "--dt", "5e-6", "--adaptive", "--backend", "spectral",
              "--no-render"]
    whole, part = tmp_path / "whole", tmp_path / "part"
    assert cli([*common, "--steps", "40", "--out", whole]).returncode == 0
    assert cli([*common, "--steps", "20", "--checkpoint-every", "10", "--out", part]
               ).returncode == 0
    assert cli(["--resume", part, "--steps", "40", "--quiet"]).returncode == 0
    _same_run(whole, part)


def test_resume_drops_rows_recorded_after_the_checkpoint(cli, tmp_path):
    """A run killed after its last checkpoint (SIGTERM, a lost machine) has history and shape
    rows past the checkpoint's step: the resumed run records those steps again, once."""
    common = ["discocyte", "--n", "16", "--every", "5", "--shape-every", "5", "--quiet",
              "--allow-underresolved", "--backend", "spectral", "--no-render"]
    whole, part = tmp_path / "whole", tmp_path / "part"
    assert cli([*common, "--steps", "30", "--out", whole]).returncode == 0
    r = cli([*common, "--steps", "10", "--checkpoint-every", "10", "--out", part])
    assert r.returncode == 0, r.stderr
    for name in ("history.csv", "shapes.csv"):  # what steps 11-15 left before the kill
        rows = (part / name).read_text().splitlines()
        (part / name).write_text("\n".join([*rows, "15" + rows[-1][rows[-1].index(","):]])
                                 + "\n")
    assert cli(["--resume", part, "--steps", "30", "--quiet"]).returncode == 0
    _same_run(whole, part)
    steps = [int(line.split(",")[0]) for line in
             (part / "shapes.csv").read_text().splitlines()[1:]]
    assert steps == [0, 5, 10, 15, 20, 25, 30]
    assert (part / "shapes.csv").read_text() == (whole / "shapes.csv").read_text()


def test_sigint_writes_a_checkpoint_and_resumes(cli, tmp_path):
    out, whole = tmp_path / "int", tmp_path / "whole"
    args = ["discocyte", "--n", "24", "--steps", "4000", "--every", "10", "--quiet",
            "--backend", "spectral", "--no-render", "--allow-underresolved"]
    proc = subprocess.Popen([sys.executable, "-m", "fem_ade.run", *args, "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 60
    while time.time() < deadline:
        h = out / "history.csv"
        if h.exists() and len(h.read_text().splitlines()) > 5:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stdout + stderr
    assert "interrupted at step" in stderr and f"--resume {out}" in stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted"
    k = summary["steps"]
    assert 0 < k < 4000
    total = k + 20
    r = cli(["--resume", out, "--steps", total, "--quiet"])
    assert r.returncode == 0, r.stderr
    resumed = json.loads((out / "summary.json").read_text())
    # the seconds count both sittings: the first's (to its checkpoint at the interrupt) and
    # the resume's 20 steps (the resume's alone would be below the first's k ≥ 50 steps)
    assert resumed["wall_s"] > summary["wall_s"] and resumed["cpu_s"] > 0.9 * summary["cpu_s"]
    r = cli([*args[:1], "--n", "24", "--steps", total, "--every", "10", "--quiet",
             "--backend", "spectral", "--no-render", "--allow-underresolved", "--out", whole])
    assert r.returncode == 0, r.stderr
    _same_run(whole, out)


def test_resume_errors(cli, tmp_path):
    r = cli(["--resume", tmp_path / "nothing"])
    assert r.returncode == 2 and "cannot resume" in r.stderr
    r = cli(["discocyte", "--resume", tmp_path])
    assert r.returncode == 2
