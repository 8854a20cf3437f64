"""The command line end to end, and every bad input of the foundation issue (exit code 2)."""

import json

import numpy as np
import pytest

from fem_ade.store.output import read_history

COLUMNS = ["step", "t", "E", "W", "G", "V", "A", "dA"]


def test_cli_end_to_end(cli, tmp_path):
    out = tmp_path / "D"
    r = cli(["discocyte", "--backend", "spectral", "--n", "32", "--steps", "100", "--every", "50",
             "--out", out, "--no-render"])
    assert r.returncode == 0, r.stderr
    assert "completed 100 steps" in r.stdout
    h = read_history(out / "history.csv")
    assert list(h)[:8] == COLUMNS
    assert list(h["step"]) == [0, 50, 100]
    assert np.allclose(h["t"], h["step"] * 5e-7)
    summary = json.loads((out / "summary.json").read_text())
    for key in ("scene", "parameters", "backend", "n", "dt", "steps", "status", "final",
                "wall_s", "versions"):
        assert key in summary, key
    assert summary["status"] == "completed" and summary["steps"] == 100
    assert summary["final"]["E"] == pytest.approx(h["E"][-1], rel=1e-14)
    final = np.load(out / "final.npz")
    assert final["phi"].shape == (32, 32, 32) and int(final["step"]) == 100


def test_cli_list(cli):
    r = cli(["--list"])
    assert r.returncode == 0
    for name in ("discocyte", "torus", "nested", "six-arm", "sphere", "sphere-bending"):
        assert name in r.stdout
    assert "Fig. 9" in r.stdout
    # every paper scene has a gallery line: a verdict from fem_ade/verdicts.json or "not run"
    from fem_ade.cli.run import gallery_verdicts
    from fem_ade.scenes.catalogue import PAPER_SCENES

    assert r.stdout.count("gallery: ") == len(PAPER_SCENES)
    verdicts = gallery_verdicts()
    for name, entry in verdicts.items():
        assert name in PAPER_SCENES and entry["headline"] in r.stdout


@pytest.mark.parametrize("extra, expect", [
    ([], "stabilized scheme, exact constraints, dt = 2e-05, until steady (tol 1e-09, at most "
         "20000 steps), momentum"),
    (["--steps", "7"], "stabilized scheme, exact constraints, dt = 2e-05, 7 steps, momentum"),
    (["--scheme", "paper", "--dt", "1e-7", "--until-steady", "1e-6"],
     "paper scheme, exact constraints, dt = 1e-07, until steady (tol 1e-06, at most 20000"),
])
def test_recipe_sets_defaults_that_options_override(cli, extra, expect):
    r = cli(["torus", "--recipe", "steady", "--n", "36", "--dry-run", *extra])
    assert r.returncode == 0, r.stderr
    assert expect in r.stdout, r.stdout


def test_until_steady_stops(cli, tmp_path):
    out = tmp_path / "S"
    r = cli(["sphere", "--n", "32", "--until-steady", "1e-4", "--every", "5", "--out", out,
             "--quiet", "--backend", "spectral", "--no-render"])
    assert r.returncode == 0, r.stderr
    s = json.loads((out / "summary.json").read_text())
    assert s["status"] == "steady" and s["steps"] == 5


def test_printed_ic_diverges_cleanly_on_the_spectral_grid(cli, tmp_path):
    """The printed discocyte IC (A = 4.5 β) at its paper Δt: the spectral backend stops at
    step 3 with exit 3 and the diagnosis; no non-finite row, the last finite state saved."""
    out = tmp_path / "P"
    r = cli(["discocyte", "--ic", "printed", "--n", "32", "--steps", "100", "--every", "1",
             "--out", out, "--quiet", "--backend", "spectral", "--no-render"])
    assert r.returncode == 3, r.stdout + r.stderr
    assert "explicit area penalty" in r.stderr and "diverged at step" in r.stderr
    h = read_history(out / "history.csv")
    assert all(np.all(np.isfinite(v)) for v in h.values())
    final = np.load(out / "final.npz")
    assert np.all(np.isfinite(final["phi"])) and str(final["status"]) == "diverged"
    assert json.loads((out / "summary.json").read_text())["status"] == "diverged"


def test_printed_ic_diverges_cleanly_on_the_fem_mesh(cli, tmp_path):
    """The same case on the FEM (p = 1, n = 24): it diverges too (measured: at step 19 —
    every resolved discretization does, the spectral one at step 3, p = 2 and 4 within 6
    steps; only the earlier 27-point Q1 stencil outlived it on coarse grids), and stops the
    same clean way: exit 3, the diagnosis, finite rows, the last finite state saved."""
    out = tmp_path / "P"
    r = cli(["discocyte", "--ic", "printed", "--order", "1", "--n", "24",
             "--allow-underresolved", "--steps",
             "100", "--every", "1", "--out", out, "--quiet", "--no-render"])
    assert r.returncode == 3, r.stdout + r.stderr
    assert "explicit area penalty" in r.stderr and "diverged at step" in r.stderr
    h = read_history(out / "history.csv")
    assert all(np.all(np.isfinite(v)) for v in h.values())
    assert 5 < len(h["step"]) < 100
    final = np.load(out / "final.npz")
    assert np.all(np.isfinite(final["phi"])) and str(final["status"]) == "diverged"


BAD = [
    (["nosuchscene"], "unknown scene"),
    (["discocyte", "--dt", "0"], "time step must be positive"),
    (["discocyte", "--dt=-1e-7"], "time step must be positive"),
    (["discocyte", "--dt", "1e-4"], "eps^3/kappa"),
    (["discocyte", "--n", "4"], "the FEM of order 4 needs at least 12 nodes per axis"),
    (["discocyte", "--n", "18"], "n (--n) = 18 nodes per axis is not a multiple of the order 4"),
    (["discocyte", "--backend", "spectral", "--n", "4"], "n must be"),
    (["two-spheres", "--n", "32"], "grid too coarse"),
    (["discocyte", "--steps", "ten"], "invalid int"),
    (["discocyte", "--backend", "lattice"], "invalid choice"),
    (["discocyte", "--backend", "spectral", "--order", "2"], "fem only"),
]


@pytest.mark.parametrize("args, match", BAD)
def test_bad_input(cli, tmp_path, args, match):
    out = tmp_path / "never"
    r = cli([*args, "--out", out])
    assert r.returncode == 2
    assert match in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not out.exists()


@pytest.mark.parametrize("params, match", [
    ("eps = -0.04", "eps must be"),
    ("eps = 0.0", "eps must be"),
    ("alpha = 0.0", "alpha must be positive"),
    ("beta = -1.0", "beta must be positive"),
    ("eps = [", "malformed TOML"),
])
def test_bad_scene_file(cli, tmp_path, params, match):
    f = tmp_path / "s.toml"
    f.write_text(f'base = "discocyte"\n[params]\n{params}\n')
    out = tmp_path / "never"
    r = cli([f, "--n", "32", "--out", out])
    assert r.returncode == 2 and match in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert not out.exists()


def test_existing_out_dir(cli, tmp_path):
    out = tmp_path / "full"
    out.mkdir()
    (out / "keep.txt").write_text("precious")
    r = cli(["sphere", "--n", "16", "--steps", "2", "--out", out, "--allow-underresolved",
             "--no-render"])
    assert r.returncode == 2 and "not empty" in r.stderr
    assert sorted(p.name for p in out.iterdir()) == ["keep.txt"]
    r = cli(["sphere", "--n", "16", "--steps", "2", "--out", out, "--allow-underresolved",
             "--force", "--quiet", "--no-render"])
    assert r.returncode == 0, r.stderr
    assert (out / "keep.txt").read_text() == "precious" and (out / "history.csv").exists()


def test_progress_toward_a_steady_state_tells_the_truth(cli, tmp_path):
    """Toward a steady state the bar follows the criterion (log10 of the energy change per
    step, from its first value to the tolerance), not the 20000-step cap: it ends at 100/100
    and shows the change; the pictures' time axis is the iteration (momentum)."""
    from fem_ade.plots.render import run_label

    out = tmp_path / "S"
    r = cli(["discocyte", "--recipe", "steady", "--order", "4", "--n", "16",
             "--allow-underresolved", "--out", out, "--no-render"])
    assert r.returncode == 0, r.stderr
    frames = r.stderr.replace("\r", "\n").splitlines()
    bars = [f for f in frames if "to steady" in f]
    assert bars and "100/100" in bars[-1] and "change=" in bars[-1], bars[-3:]
    assert not any("/20000" in f for f in frames)
    summary = json.loads((out / "summary.json").read_text())
    assert "iterations (momentum)" in run_label(summary, 16)


def test_plan_says_what_simulate_would_run(tmp_path):
    """The Python API's dry run: plan() takes simulate's keywords, checks them as simulate
    does, writes nothing and returns the CLI's line; simulate itself always runs (it returns
    a RunResult, never the line)."""
    import inspect

    import pytest

    from fem_ade.engine.runs import plan, simulate
    from fem_ade.model.params import ModelError

    out = tmp_path / "never"
    line = plan("sphere", backend="spectral", n=32, steps=3, out=out)
    assert line.startswith("sphere with the spectral backend") and "3 steps" in line
    assert line.endswith(f"into {out}") and not out.exists()
    with pytest.raises(ModelError, match="n must be"):
        plan("sphere", backend="spectral", n=4)
    with pytest.raises(TypeError, match="dry_run"):
        plan("sphere", dry_run=True)
    assert "dry_run" not in inspect.signature(simulate).parameters
