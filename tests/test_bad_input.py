"""Bad input never costs a user data (issue 11): one line on stderr and exit 2 with nothing
written; a diverged run keeps its last good state; a checkpoint resumes only its own run;
signals at any moment end with one line and exit 130.

Most cases run the CLI in-process (``fem_ade.cli.run.main``); the fuzz test checks inputs with
``--dry-run`` (validated, not run) so that it takes seconds.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from fem_ade.cli import run

SMALL = ["--n", "16", "--allow-underresolved", "--quiet", "--no-render"]


def cli(args, capsys) -> tuple[int, str, str]:
    """``python -m fem_ade.run ARGS`` in-process: (exit code, stdout, stderr)."""
    try:
        code = run.main([str(a) for a in args])
    except SystemExit as err:  # argparse's own errors
        code = err.code
    out = capsys.readouterr()
    return code, out.out, out.err


def files_under(path: Path) -> list[str]:
    return sorted(str(p.relative_to(path)) for p in path.rglob("*")) if path.exists() else []


def assert_refused(code, err, where: Path, match: str = ""):
    assert code == 2, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert match.lower() in err.lower(), err
    assert files_under(where) == [], files_under(where)


# --- CLI numbers and flags -------------------------------------------------------------------
BAD_ARGS = [
    (["--perturb", "0.1", "--seed", "-1"], "seed"),
    (["--mesh", "graded:abc"], "graded"),
    (["--n", "1500", "--backend", "spectral"], "memory"),
    (["--n", "1500"], "memory"),
    (["--steps", "-5"], "steps"),
    (["--every", "0"], "every"),
    (["--every", "-1"], "every"),
    (["--until-steady", "1e-6", "--max-steps", "-1"], "max-steps"),
    (["--steps", "5", "--max-steps", "10"], "max-steps"),
    (["--checkpoint-every", "0"], "checkpoint-every"),
    (["--save-every", "-1"], "save-every"),
    (["--shape-every", "0"], "shape-every"),
    (["--perturb", "nan"], "perturb"),
    (["--perturb", "inf"], "perturb"),
    (["--dt", "nan"], "time step"),
    (["--until-steady", "nan"], "until-steady"),
    (["--step", "5"], "unrecognized"),  # no abbreviations
    (["--ic", "seeded"], "no seeded"),  # ellipse-2d has no seed
]


@pytest.mark.parametrize("args, match", BAD_ARGS, ids=[" ".join(a) for a, _ in BAD_ARGS])
def test_bad_cli_input_writes_nothing(tmp_path, capsys, args, match):
    scene = "ellipse-2d" if "--ic" in args else "discocyte"
    code, _, err = cli([scene, *SMALL, "--out", tmp_path / "out", *args], capsys)
    assert_refused(code, err, tmp_path, match)


@pytest.mark.parametrize("out, match", [
    ("/proc/fem_ade_x", "cannot"), ("FILE/sub", "not a folder"), ("", "folder name")])
def test_unusable_output_folders(tmp_path, capsys, out, match):
    (tmp_path / "FILE").write_text("a file")
    out = out.replace("FILE", str(tmp_path / "FILE"))
    code, _, err = cli(["discocyte", *SMALL, "--steps", "2", "--out", out], capsys)
    assert code == 2 and match in err and len(err.strip().splitlines()) == 1, err
    assert files_under(tmp_path) == ["FILE"]


def test_force_refuses_a_folder_where_a_run_file_should_be(tmp_path, capsys):
    out = tmp_path / "out"
    (out / "final.npz").mkdir(parents=True)
    code, _, err = cli(["discocyte", *SMALL, "--steps", "2", "--out", out, "--force"], capsys)
    assert code == 2 and "final.npz" in err
    assert files_under(tmp_path) == ["out", "out/final.npz"]


def test_force_removes_the_old_run_and_nothing_else(tmp_path, capsys):
    out = tmp_path / "out"
    base = ["discocyte", "--backend", "spectral", *SMALL, "--out", out]
    assert cli([*base, "--steps", "4", "--checkpoint-every", "2"], capsys)[0] == 0
    (out / "notes.txt").write_text("mine")
    assert (out / "checkpoint.npz").is_file()
    assert cli([*base, "--steps", "2", "--force"], capsys)[0] == 0
    assert not (out / "checkpoint.npz").exists(), "a stale checkpoint was kept"
    assert (out / "notes.txt").read_text() == "mine"
    assert json.loads((out / "summary.json").read_text())["steps"] == 2


def test_default_output_folders_are_unique(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for _ in range(2):
        assert cli(["sphere", "--backend", "spectral", *SMALL, "--steps", "1"], capsys)[0] == 0
    runs = sorted((tmp_path / "runs").iterdir())
    assert len(runs) == 2 and runs[0] != runs[1]


# --- scene files -----------------------------------------------------------------------------
TOML = [
    ("dim = 1", "dim"), ("dim = 4", "dim"), ("steps = -3", "steps"),
    ('name = "../../escaped"', "plain file name"),
    ("[params]\nalpha = 5.0", "box"), ("[params]\nbeta = 1e300", "beta"),
    ("[params]\nL = 1e-3", "box"), ("[params]\neps = nan", "eps"),
    ("[params]\nalpha = 0.2\nbeta = 0.1", "reduced volume"),
    ("[params]\nM1 = -1.0", "M1"), ("[params]\nkappa_bar = inf", "kappa_bar"),
    ('[params]\nvolume_functional = "bulk"', "volume functional"),
    ("[ic]\nkind = 'sphere'\ncentre = [nan, 0.5, 0.5]\nradius = 0.2", "finite"),
    ("[ic]\nkind = 'sphere'\ncentre = [0.5, 0.5, 0.5]\nradius = -0.2", "positive"),
    ("[ic]\nkind = 'ellipsoid'\ncentre = [0.5, 0.5, 0.5]\naxes = [0.1, 0.0, 0.1]\nc = 0.1",
     "positive"),
    ("[ic]\nkind = 'ellipsoid'\ncentre = [0.5, 0.5, 0.5]\naxes = [0.1, -0.1, 0.1]\nc = 0.1",
     "positive"),
    ("[ic]\nkind = 'torus'\ncentre = [0.5, 0.5, 0.5]\nR = 0.1\nr = 0.2", "r < R"),
    ("[ic]\nkind = 'sphere'\ncentre = [0.5, 0.5, 0.5]\nradius = 1e-4", "no inside"),
    ("[ic]\nkind = 'cube'", "ic.kind"), ("[ic]\nkind = 'sphere'\ncentre = [0.5]", "needs"),
    ("eps = [", "malformed"),
]


@pytest.mark.parametrize("body, match", TOML, ids=[b.split("\n")[-1] for b, _ in TOML])
def test_bad_scene_files_write_nothing(tmp_path, capsys, body, match):
    f = tmp_path / "scene.toml"
    f.write_text(f'base = "discocyte"\n{body}\n')
    code, _, err = cli([f, "--backend", "spectral", *SMALL, "--steps", "2", "--out",
                        tmp_path / "out"], capsys)
    assert code == 2 and match.lower() in err.lower(), err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert files_under(tmp_path) == ["scene.toml"]


def test_scene_file_that_is_a_folder_or_unreadable(tmp_path, capsys):
    folder = tmp_path / "s.toml"
    folder.mkdir()
    code, _, err = cli([folder, *SMALL, "--out", tmp_path / "o"], capsys)
    assert code == 2 and "is a folder" in err
    code, _, err = cli(["/proc/self/mem", *SMALL, "--out", tmp_path / "o"], capsys)
    assert code == 2 and "cannot read" in err
    assert files_under(tmp_path) == ["s.toml"]


def test_mesh_file_sets_the_resolution(tmp_path, capsys):
    mesh = Path(__file__).resolve().parents[1] / "meshes" / "box12_uniform.vtu"
    code, _, err = cli(["discocyte", "--mesh", mesh, "--n", "32", "--out", tmp_path / "o"],
                       capsys)
    assert code == 2 and "--n does not apply" in err
    code, _, err = cli(["discocyte", "--mesh", mesh, "--out", tmp_path / "o"], capsys)
    assert code == 2 and "too coarse" in err  # its own spacing, 1/12 > eps
    (tmp_path / "bad.vtu").write_text("garbage")
    code, _, err = cli(["discocyte", "--mesh", tmp_path / "bad.vtu", "--out", tmp_path / "o"],
                       capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert files_under(tmp_path) == ["bad.vtu"]


# --- resume ----------------------------------------------------------------------------------
@pytest.fixture
def checkpointed(tmp_path, capsys):
    out = tmp_path / "run"
    code, _, err = cli(["discocyte", "--backend", "spectral", *SMALL, "--steps", "4",
                        "--checkpoint-every", "2", "--out", out], capsys)
    assert code == 0, err
    return out


def _snapshot(folder: Path) -> dict:
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}


BROKEN = {
    "truncated": lambda f: f.write_bytes(f.read_bytes()[: len(f.read_bytes()) // 2]),
    "empty": lambda f: f.write_bytes(b""),
    "random": lambda f: f.write_bytes(np.random.default_rng(1).bytes(3000)),
    "no loop": lambda f: np.savez(f, state__phi_hat=np.zeros((16, 16, 9), complex)),
    "not finite": lambda f: _rewrite(f, lambda z: {**z, "state__phi_hat": z["state__phi_hat"]
                                                   * np.nan}),
}


def _rewrite(path, change):
    with np.load(path) as z:
        data = change({k: np.array(z[k]) for k in z.files})
    np.savez(path, **data)
    if not str(path).endswith(".npz"):
        Path(str(path) + ".npz").replace(path)


@pytest.mark.parametrize("kind", list(BROKEN))
def test_broken_checkpoints_are_refused(checkpointed, capsys, kind):
    BROKEN[kind](checkpointed / "checkpoint.npz")
    before = _snapshot(checkpointed)
    code, _, err = cli(["--resume", checkpointed, "--steps", "8", "--quiet"], capsys)
    assert code == 2 and "cannot resume" in err and len(err.strip().splitlines()) == 1, err
    assert _snapshot(checkpointed) == before, "a refused resume changed the folder"


@pytest.mark.parametrize("change", ["other scene", "other n", "other backend"])
def test_a_checkpoint_resumes_only_its_own_run(tmp_path, capsys, checkpointed, change):
    other = tmp_path / "other"
    args = {"other scene": ["sphere", "--backend", "spectral"],
            "other n": ["discocyte", "--backend", "spectral", "--n", "20"],
            "other backend": ["discocyte", "--backend", "fem"]}[change]
    code, _, err = cli([*args, *SMALL[2:], *(["--n", "16"] if "--n" not in args else []),
                        "--allow-underresolved", "--steps", "2", "--checkpoint-every", "2",
                        "--out", other], capsys)
    assert code == 0, err
    shutil.copy(other / "checkpoint.npz", checkpointed / "checkpoint.npz")
    before = _snapshot(checkpointed)
    code, _, err = cli(["--resume", checkpointed, "--steps", "8", "--quiet"], capsys)
    assert code == 2 and "belongs to another run" in err, err
    assert _snapshot(checkpointed) == before


@pytest.mark.parametrize("content", ["", "{", "[]", '{"scene": 3}'])
def test_malformed_run_json_is_refused(checkpointed, capsys, content):
    (checkpointed / "run.json").write_text(content)
    code, _, err = cli(["--resume", checkpointed, "--quiet"], capsys)
    assert code == 2 and "cannot resume" in err and len(err.strip().splitlines()) == 1, err


@pytest.mark.parametrize("option", [["--n", "32"], ["--dt", "1e-7"], ["--backend", "fem"],
                                    ["--order", "2"], ["--out", "x"], ["--every", "3"]])
def test_resume_refuses_options_it_cannot_honour(checkpointed, capsys, option):
    code, _, err = cli(["--resume", checkpointed, *option], capsys)
    assert code == 2 and option[0] in err, err


# --- states and pictures ---------------------------------------------------------------------
def test_a_diverged_run_keeps_its_last_good_state_and_says_so(tmp_path, capsys):
    out = tmp_path / "D"
    code, _, err = cli(["discocyte", "--backend", "spectral", "--n", "32", "--ic", "printed",
                        "--steps", "50", "--every", "1", "--out", out, "--quiet"], capsys)
    assert code == 3, err
    assert np.all(np.isfinite(np.load(out / "final.npz")["phi"]))
    assert (out / "shape.png").is_file()
    from fem_ade.plots.render import run_label

    summary = json.loads((out / "summary.json").read_text())
    assert "DIVERGED" in run_label(summary, 32)


def test_interrupt_while_drawing_leaves_a_consistent_folder(tmp_path, capsys, monkeypatch):
    import fem_ade.plots.render

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(fem_ade.plots.render, "draw_run", interrupted)
    out = tmp_path / "I"
    code, _, err = cli(["sphere", "--backend", "spectral", "--n", "16", "--allow-underresolved",
                        "--steps", "2", "--out", out, "--quiet"], capsys)
    assert code == 130 and err.strip() == "fem_ade.run: interrupted"
    names = files_under(out)
    assert "summary.json" in names and "final.npz" in names
    assert not [n for n in names if ".tmp" in n], names


def test_signal_during_set_up_is_one_line(tmp_path):
    """SIGINT while the FEM's AMG hierarchy is built (64³ with --solver amg: seconds; the
    default exact solve sets up in 0.1 s): one line, exit 130."""
    out = tmp_path / "S"
    proc = subprocess.Popen([sys.executable, "-m", "fem_ade.run", "discocyte", "--n", "64",
                             "--solver", "amg", "--steps", "5", "--out", str(out), "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(2.0)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and len(err.strip().splitlines()) <= 2, err
    if out.exists():  # started: a consistent folder (no half-written files)
        assert not [p for p in out.iterdir() if ".tmp" in p.name]


# --- the fuzz test ---------------------------------------------------------------------------
NUMBERS = st.one_of(
    st.sampled_from(["nan", "inf", "-inf", "0", "-1", "1e300", "-1e300", "1e-300", "abc", "",
                     "1e-7", "3", "17", "0.5", "2.5e-6", "1_000"]),
    st.integers(-10, 10**6).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr))
CLI_OPTIONS = ["--n", "--dt", "--steps", "--every", "--perturb", "--seed", "--until-steady",
               "--checkpoint-every", "--save-every", "--shape-every", "--order", "--max-steps"]
TOML_VALUES = st.one_of(
    st.sampled_from(["nan", "inf", "-inf", "0", "-1", "1e300", "0.0", '"x"', "[]", "true",
                     "[0.5, 0.5]", "[0.5, 0.5, 0.5]", "[nan, 0.5, 0.5]", "1e-300"]),
    st.floats(allow_nan=False, allow_infinity=False, min_value=-10, max_value=10).map(repr))
TOML_KEYS = ["params.eps", "params.alpha", "params.beta", "params.delta_A0", "params.kappa",
             "params.kappa_bar", "params.C", "params.D", "params.M1", "params.M2",
             "params.A0", "params.L", "ic.radius", "ic.centre", "n", "dt", "steps", "dim"]


def _check(code, err, where: Path) -> None:
    assert code in (0, 2), (code, err)
    assert "Traceback" not in err, err
    if code == 2:
        assert len(err.strip().splitlines()) == 1, err
    assert files_under(where) == [], "a dry run wrote something"


@settings(max_examples=int(os.environ.get("FUZZ_EXAMPLES", 60)), deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(option=st.sampled_from(CLI_OPTIONS), value=NUMBERS)
def test_fuzz_cli_numbers(tmp_path_factory, capsys, option, value):
    where = tmp_path_factory.mktemp("fuzz")
    args = ["discocyte", "--backend", "fem", "--n", "16", "--allow-underresolved",
            "--out", where / "out", "--dry-run"]
    if option == "--max-steps":
        args += ["--until-steady", "1e-6"]
    code, _, err = cli([*args, f"{option}={value}"], capsys)
    _check(code, err, where)


@settings(max_examples=int(os.environ.get("FUZZ_EXAMPLES", 60)), deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(key=st.sampled_from(TOML_KEYS), value=TOML_VALUES)
def test_fuzz_scene_files(tmp_path_factory, capsys, key, value):
    where = tmp_path_factory.mktemp("fuzz")
    table, _, field = key.rpartition(".")
    body = f"[{table}]\n{field} = {value}\n" if table else f"{field} = {value}\n"
    if table == "ic":
        body = "[ic]\nkind = 'sphere'\ncentre = [0.5, 0.5, 0.5]\nradius = 0.2\n" + body.replace(
            "[ic]\n", "")
        body = _dedupe(body)
    scene = where / "scene.toml"
    scene.write_text(f'base = "discocyte"\n{body}')
    code, _, err = cli([scene, "--backend", "spectral", "--n", "16", "--allow-underresolved",
                        "--out", where / "out", "--dry-run"], capsys)
    assert code in (0, 2) and "Traceback" not in err, (body, err)
    if code == 2:
        assert len(err.strip().splitlines()) == 1, err
    assert files_under(where) == ["scene.toml"]


def _affordable(option: str, value: str) -> bool:
    """A valid but huge --steps or --n is a real run of minutes to hours, not bad input: the
    run fuzz keeps to what finishes in seconds (invalid values of every size stay in)."""
    try:
        x = float(value.replace("_", ""))
    except ValueError:
        return True
    limit = {"--steps": 2000, "--max-steps": 2000, "--n": 64}.get(option)
    return limit is None or not (math.isfinite(x) and x > limit)


def _dedupe(body: str) -> str:
    """Keep the last assignment of each key of a TOML table (the fuzzed one wins)."""
    lines, seen = body.splitlines(), {}
    for i, line in enumerate(lines):
        if "=" in line:
            seen[line.split("=")[0].strip()] = i
    return "\n".join(line for i, line in enumerate(lines)
                     if "=" not in line or seen[line.split("=")[0].strip()] == i) + "\n"


@pytest.mark.slow
@settings(max_examples=500, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(option=st.sampled_from(CLI_OPTIONS[:8]), value=NUMBERS)
def test_fuzz_cli_runs(tmp_path_factory, capsys, option, value):
    """With real (tiny) runs: exit 0, 2 or 3; exit 2 writes nothing; exit 3 only from a run
    whose start was finite (its first history row)."""
    assume(_affordable(option, value))
    where = tmp_path_factory.mktemp("fuzz")
    out = where / "out"
    args = ["sphere", "--backend", "spectral", "--n", "8", "--allow-underresolved", "--steps",
            "2", "--every", "1", "--quiet", "--no-render", "--out", out]
    code, _, err = cli([*args, f"{option}={value}"], capsys)
    assert code in (0, 2, 3) and "Traceback" not in err, (code, err)
    if code == 2:
        assert len(err.strip().splitlines()) == 1 and files_under(where) == [], err
    if code == 3:
        first = (out / "history.csv").read_text().splitlines()[1].split(",")
        assert all(math.isfinite(float(v)) for v in first)


# --- issue 31: what ended in a traceback, ran on without a word or did not end ------------
def _mesh_variant(tmp_path, kind):
    import meshio

    m = meshio.read(Path(__file__).resolve().parents[1] / "meshes" / "box12_uniform.vtu")
    points, cells = m.points.copy(), m.cells[0].data.copy()
    if kind == "index out of range":
        cells[0, 0] = len(points) + 5
    elif kind == "duplicated cell":
        cells = np.vstack([cells, cells[:1]])
    elif kind == "shifted":
        points = points + 0.25
    path = tmp_path / f"{kind.replace(' ', '_')}.vtu"
    meshio.write(path, meshio.Mesh(points, [("hexahedron", cells)]))
    return path


@pytest.mark.parametrize("case", ["FEM_ADE_FFT_WORKERS=abc", "FEM_ADE_FFT_WORKERS=0",
                                  "FEM_ADE_BLAS_THREADS=0", "FEM_ADE_BLAS_THREADS=two",
                                  "rtol 1e-300", "index out of range", "duplicated cell",
                                  "shifted"])
def test_run_mistakes_are_one_line_and_write_nothing(tmp_path, capsys, monkeypatch, case):
    out = tmp_path / "out"
    args = ["discocyte", *SMALL, "--steps", "2", "--out", out]
    if case.startswith("FEM_ADE"):
        monkeypatch.setenv(*case.split("="))
        args += ["--backend", "spectral"]
    elif case == "rtol 1e-300":
        args += ["--solver", "jacobi", "--rtol", "1e-300"]
    else:
        args = ["discocyte", "--mesh", _mesh_variant(tmp_path, case), "--allow-underresolved",
                "--quiet", "--no-render", "--steps", "2", "--out", out]
    code, _, err = cli(args, capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert not out.exists()


@pytest.mark.parametrize("case", ["full device", "closed pipe", "deleted directory",
                                  "file-size limit"])
def test_run_environment_failures_are_one_line(tmp_path, case):
    """Output to a full device or a closed pipe after the run, a working directory that is
    gone, a file-size limit at the first phi.h5: one line on stderr, exit 2 or 3, no
    traceback (the run folder, where one was begun, keeps what it could)."""
    import resource

    cmd = [sys.executable, "-m", "fem_ade.run", "discocyte", "--backend", "spectral",
           "--n", "48", "--allow-underresolved", "--quiet", "--no-render", "--steps", "2",
           "--out", str(tmp_path / "out")]
    kwargs = {"stderr": subprocess.PIPE, "text": True, "timeout": 300}
    if case == "full device":
        if not Path("/dev/full").exists():
            pytest.skip("no /dev/full")
        with open("/dev/full", "w") as full:
            r = subprocess.run(cmd, stdout=full, **kwargs)
    elif case == "closed pipe":
        p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        p.stdout.close()  # nobody reads the report
        _, err = p.communicate(timeout=300)
        r = subprocess.CompletedProcess(cmd, p.returncode, None, err)
    elif case == "deleted directory":
        gone = tmp_path / "gone"
        gone.mkdir()
        r = subprocess.run(["/bin/sh", "-c", f"cd {gone} && rmdir {gone} && "
                            + " ".join(cmd[:-2] + ["--dry-run"])], stdout=subprocess.PIPE,
                           **kwargs)
    else:
        def limit():
            resource.setrlimit(resource.RLIMIT_FSIZE, (200_000, 200_000))
        r = subprocess.run(cmd, stdout=subprocess.PIPE, preexec_fn=limit, **kwargs)
    assert r.returncode in (2, 3) and "Traceback" not in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_api_mistakes(tmp_path):
    """The Python API: numpy integers are integers; config with the run's keywords, a dict as
    config, no scene, n = 0 and a negative dt are clear errors."""
    from fem_ade import get_scene, simulate
    from fem_ade.backends.base import make_backend
    from fem_ade.engine.config import RunConfig
    from fem_ade.engine.loop import run_loop
    from fem_ade.model.params import ModelError

    scene = get_scene("discocyte")
    r = simulate(scene, backend="spectral", n=np.int64(16), steps=np.int64(2),
                 allow_underresolved=True)
    assert r.status == "completed" and r.steps == 2
    config = RunConfig.build(scene, backend="spectral", n=16, steps=2)
    with pytest.raises(ModelError, match="not both: n, steps"):
        simulate(scene, config=config, n=64, steps=7)
    with pytest.raises(TypeError, match="RunConfig"):
        simulate(scene, config={})
    with pytest.raises(TypeError, match="Scene"):
        RunConfig.build(None)
    with pytest.raises(ModelError, match="positive integer"):
        make_backend("fem", scene, n=0)
    with pytest.raises(ModelError, match="dt must be"):
        run_loop(make_backend("spectral", scene, n=16), dt=-1, steps=2)


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
def test_a_signal_whose_exception_python_dropped_still_stops_the_run(monkeypatch, capsys):
    """A signal that comes while a finalizer runs (the set-up's garbage collection): Python
    prints "Exception ignored in ..." and drops the handler's KeyboardInterrupt — CI saw a
    SIGINT during the AMG set-up end as exit 0. The loop raises it before its next step:
    the run ends interrupted, at step 0."""
    import gc

    from fem_ade.engine.runs import simulate
    from fem_ade.scenes.catalogue import get_scene
    from fem_ade.store import interrupt

    class Finalized:
        def __del__(self):
            interrupt.handler(signal.SIGINT, None)

    Finalized()  # its __del__ raises in the handler; Python ignores it
    gc.collect()
    monkeypatch.setattr(sys, "unraisablehook", interrupt.unraisable)  # as the CLI installs
    capsys.readouterr()
    Finalized()  # again: the CLI's hook prints nothing of it
    gc.collect()
    assert capsys.readouterr().err == ""
    res = simulate(get_scene("discocyte"), backend="spectral", n=16, steps=5, render=False,
                   allow_underresolved=True)
    assert res.status == "interrupted" and res.steps == 0, res.message
    res = simulate(get_scene("discocyte"), backend="spectral", n=16, steps=5, render=False,
                   allow_underresolved=True)
    assert res.status == "completed"  # handled: the next run is not interrupted again
