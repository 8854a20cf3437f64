"""``--linalg petsc`` under MPI: 1 and 2 ranks give the serial pyamg path's history (to the
solver tolerance), for the paper's scheme, the stabilized one and exact constraints; a
checkpoint resumes bit for bit under MPI; without petsc4py the option is one line, exit 2.

Skipped (with the reason) where petsc4py, mpi4py or mpirun are missing; CI installs them
(``scripts/install-petsc.sh``).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from fem_ade.store.output import read_history

try:
    import mpi4py  # noqa: F401
    import petsc4py  # noqa: F401

    HAVE_PETSC = True
except ImportError:
    HAVE_PETSC = False
MPIRUN = shutil.which("mpirun") or shutil.which("mpiexec")
#: CI sets FEM_ADE_REQUIRE_MPI once it has installed PETSc: then a missing piece fails
REQUIRED = bool(os.environ.get("FEM_ADE_REQUIRE_MPI"))
needs_mpi = pytest.mark.skipif(not (HAVE_PETSC and MPIRUN) and not REQUIRED,
                               reason="petsc4py, mpi4py and mpirun (scripts/install-petsc.sh)")
#: tight PCG tolerances, so that the serial and distributed solves agree far below 1e-9
RTOL = "1e-11"
#: the paper's scheme at 32³ with 1 and 2 ranks; the others smaller, 2 ranks (order 1 but
#: for order-3: the assembled matrices the ranks share)
CASES = {
    "paper": ["--order", "1", "--n", "32", "--steps", "20"],
    "stabilized": ["--order", "1", "--n", "24", "--allow-underresolved", "--steps", "10",
                   "--scheme", "stabilized", "--dt", "5e-5"],
    "exact": ["--order", "1", "--n", "24", "--allow-underresolved", "--steps", "10",
              "--scheme", "stabilized", "--dt", "5e-5", "--constraints", "exact"],
    "order-3": ["--order", "3", "--n", "24", "--allow-underresolved", "--steps", "10",
                "--scheme", "stabilized", "--dt", "5e-5", "--constraints", "exact"],
}


def _env():
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMP_NUM_THREADS="1", OMPI_MCA_rmaps_base_oversubscribe="1")
    env.pop("PETSC_OPTIONS", None)
    return env


def run(args, ranks: int | None, out, *, check=True):
    """The CLI, serially (ranks None) or under mpirun with ``--linalg petsc``."""
    cmd = [sys.executable, "-m", "fem_ade.run", *map(str, args), "--out", str(out),
           "--quiet", "--no-render"]
    if ranks is not None:
        cmd = [MPIRUN, "-n", str(ranks), *cmd, "--linalg", "petsc"]
    r = subprocess.run(cmd, capture_output=True, text=True, env=_env(), timeout=600)
    if check:
        assert r.returncode == 0, (r.stdout[-2000:], r.stderr[-3000:])
    return r


def history(out):
    h = read_history(out / "history.csv")
    return {k: np.asarray(h[k]) for k in ("step", "E", "V", "A", "dA")}


@needs_mpi
@pytest.mark.parametrize("case", list(CASES))
def test_ranks_agree_with_the_serial_path(case, tmp_path):
    base = ["discocyte", "--every", "5", "--rtol", RTOL, *CASES[case]]
    run([*base, "--solver", "amg"], None, tmp_path / "serial")
    serial = history(tmp_path / "serial")
    for ranks in ((1, 2) if case == "paper" else (2,)):
        run(base, ranks, tmp_path / f"mpi{ranks}")
        h = history(tmp_path / f"mpi{ranks}")
        assert np.array_equal(h["step"], serial["step"])
        for q in ("E", "V", "A", "dA"):
            rel = np.max(np.abs(h[q] - serial[q]) / np.abs(serial[q]))
            print(f"{case}, {ranks} rank(s): max relative difference in {q}: {rel:.1e}")
            assert rel <= 1e-9, (case, ranks, q, rel)
    assert not list(tmp_path.glob("mpi*/checkpoint*"))  # no stray files of other ranks


@needs_mpi
def test_resume_is_bit_identical_under_mpi(tmp_path):
    base = ["discocyte", "--order", "1", "--n", "16", "--allow-underresolved", "--every", "2",
            "--scheme", "stabilized", "--dt", "5e-5", "--constraints", "exact"]
    run([*base, "--steps", "10"], 2, tmp_path / "whole")
    run([*base, "--steps", "6", "--checkpoint-every", "6"], 2, tmp_path / "parts")
    r = subprocess.run([MPIRUN, "-n", "2", sys.executable, "-m", "fem_ade.run", "--resume",
                        str(tmp_path / "parts"), "--steps", "10", "--quiet"],
                       capture_output=True, text=True, env=_env(), timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    a, b = history(tmp_path / "whole"), history(tmp_path / "parts")
    for q in a:
        assert np.array_equal(a[q], b[q]), q
    fa = np.load(tmp_path / "whole" / "final.npz")["phi"]
    fb = np.load(tmp_path / "parts" / "final.npz")["phi"]
    assert np.array_equal(fa, fb)


@needs_mpi
def test_bad_input_under_mpi_is_one_line(tmp_path):
    r = run(["discocyte", "--order", "1", "--n", "32", "--steps", "2", "--solver", "fft"], 2,
            tmp_path / "x",
            check=False)
    assert r.returncode == 2, (r.returncode, r.stderr[-2000:])
    assert r.stderr.count("fem_ade.run: error: --linalg petsc solves by PCG") == 1
    assert not (tmp_path / "x").exists()


def test_petsc_missing_is_one_line(tmp_path, monkeypatch):
    """Without petsc4py (hidden here when installed), ``--linalg petsc`` is exit 2 with how
    to install it, and nothing is written."""
    code = ("import sys; sys.modules['petsc4py'] = None; sys.modules['mpi4py'] = None; "
            "from fem_ade.cli.run import main; sys.exit(main(sys.argv[1:]))")
    out = tmp_path / "x"
    r = subprocess.run([sys.executable, "-c", code, "discocyte", "--n", "32", "--steps", "2",
                        "--linalg", "petsc", "--out", str(out)], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and "scripts/install-petsc.sh" in r.stderr, r.stderr
    assert not out.exists()


def test_many_ranks_without_petsc_linalg_are_refused(tmp_path):
    """Under mpirun, a serial backend would run the whole job on every rank: refused."""
    env = dict(os.environ, OMPI_COMM_WORLD_RANK="0", OMPI_COMM_WORLD_SIZE="2")
    r = subprocess.run([sys.executable, "-m", "fem_ade.run", "discocyte", "--n", "32",
                        "--steps", "2", "--out", str(tmp_path / "x")], capture_output=True,
                       text=True, env=env, timeout=120)
    assert r.returncode == 2 and "--linalg petsc" in r.stderr, r.stderr
    assert not (tmp_path / "x").exists()

