"""Pictures without a display (fem_ade.plots.render): shape.png and history.png of a run folder."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from fem_ade.plots.history import render_history
from fem_ade.plots.render import main
from fem_ade.plots.shapes import render_shape

PNG = b"\x89PNG\r\n\x1a\n"


def _headless_env(**extra):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env.update(extra)
    return env


def _run(module, *args, env=None):
    return subprocess.run([sys.executable, "-m", module, *map(str, args)], capture_output=True,
                          text=True, timeout=300, env=env or _headless_env())


def _png_size(path):
    assert path.is_file() and path.stat().st_size > 10_000
    assert path.read_bytes()[:8] == PNG
    with Image.open(path) as im:
        return im.size


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("render") / "sphere"
    r = _run("fem_ade.run", "sphere", "--n", 24, "--steps", 10, "--every", 5, "--out", out,
             "--quiet", "--no-render", "--backend", "spectral", "--allow-underresolved")
    assert r.returncode == 0, r.stderr
    return out


def test_cli_renders_a_run_folder_without_display(run_dir):
    r = _run("fem_ade.render", run_dir)
    assert r.returncode == 0, r.stderr
    assert _png_size(run_dir / "shape.png") == (1200, 600)
    _png_size(run_dir / "history.png")
    assert "1 component, genus 0, arms = 1" in r.stdout


def test_cli_view_and_size(run_dir, tmp_path):
    assert main([str(run_dir), "--view", "30", "60", "--size", "800", "400",
                 "--engine", "matplotlib"]) == 0
    assert _png_size(run_dir / "shape.png") == (800, 400)


@pytest.mark.parametrize("what", ["no-folder", "no-final", "mesh-field", "bad-summary"])
def test_cli_bad_input(run_dir, tmp_path, what):
    out = tmp_path / "run"
    if what != "no-folder":
        out.mkdir()
        for name in ("summary.json", "history.csv", "final.npz"):
            (out / name).write_bytes((run_dir / name).read_bytes())
    if what == "no-final":
        (out / "final.npz").unlink()
    elif what == "mesh-field":
        np.savez(out / "final.npz", phi=np.zeros(125), x=np.zeros((125, 3)))
    elif what == "bad-summary":
        (out / "summary.json").write_text(json.dumps({"scene": "x"}))
    r = _run("fem_ade.render", out)
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("fem_ade.render: error:")
    assert not (out / "shape.png").exists()


def test_render_shape_both_engines(tmp_path):
    n = 32
    x = np.arange(n) / n
    X = np.meshgrid(x, x, x, indexing="ij")
    r = np.sqrt(sum((Xi - 0.5) ** 2 for Xi in X))
    phi = np.tanh((0.3 - r) / (np.sqrt(2) * 0.04))
    for engine in ("auto", "matplotlib"):
        path = render_shape(phi, 1.0, tmp_path / f"{engine}.png", title="sphere",
                            engine=engine, size=(900, 450))
        assert _png_size(path) == (900, 450)


def test_shape_picture_shows_the_membrane_and_its_section(tmp_path):
    """What the 3D view shows: the membrane in its colour, and — VTK — the section y = ½ as
    one whole dark curve across it (flush with the surface it showed as broken "seams"):
    a torus cut by y = ½ in two circles; the dark pixels of the left panel form long runs."""
    from fem_ade.plots.shapes import COLOURS, choose_engine

    n = 48
    x = np.arange(n) / n
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    rho = np.sqrt((X - 0.5) ** 2 + (Y - 0.5) ** 2)
    phi = np.tanh((0.1 - np.sqrt((rho - 0.25) ** 2 + (Z - 0.5) ** 2)) / (np.sqrt(2) * 0.03))
    path = render_shape(phi, 1.0, tmp_path / "torus.png", title="torus", size=(900, 450))
    with Image.open(path) as im:
        left = np.asarray(im.convert("RGB"))[60:, :430].astype(int)
    membrane = np.array([int(COLOURS[0][i:i + 2], 16) for i in (1, 3, 5)])
    near = np.abs(left - membrane).sum(axis=2) < 120
    shaded = (left[..., 0] > left[..., 2] + 40)  # warm: the membrane, lit or shaded
    print(f"membrane-coloured {near.mean():.3f}, warm {shaded.mean():.3f} of the left panel")
    assert shaded.mean() > 0.05
    if choose_engine("auto") == "vtk":
        dark = left.sum(axis=2) < 150
        rows = np.flatnonzero(dark.any(axis=1))
        print(f"dark pixels {dark.sum()}, over {len(rows)} rows")
        assert dark.sum() > 300 and len(rows) > 60  # two curves across the tube, whole


def test_render_history_computes_penalties(tmp_path):
    csv = tmp_path / "history.csv"
    t = np.linspace(0, 1e-5, 6)
    rows = ["step,t,E,W,G,V,A,dA"] + [
        f"{k},{tk!r},{30 - k},{25 - k},{0.1 * (k + 1)},{0.1 + 0.01 * k},{1 - 0.02 * k},0.2"
        for k, tk in enumerate(t.tolist())]
    csv.write_text("\n".join(rows) + "\n")
    from fem_ade.model.params import Params

    p = Params(eps=0.04, alpha=0.1, beta=1.0, delta_A0=0.25)
    path = render_history(csv, tmp_path / "history.png", p)
    _png_size(path)
    path = render_history(csv, tmp_path / "h2.png", p.with_(delta_A0=0.0, effects={"bending"}))
    _png_size(path)


def test_run_writes_series_pictures_and_shape(cli, tmp_path):
    """Issue 5 'done when': a sphere run writes the XDMF series, both PNGs, and its shape."""
    from fem_ade.store.xdmf import read_series

    out = tmp_path / "D"
    r = cli(["sphere", "--n", "24", "--allow-underresolved", "--steps", "20", "--every", "5",
             "--save-every", "10", "--out", out, "--quiet", "--backend", "spectral"])
    assert r.returncode == 0, r.stderr
    assert "1 component(s), genus 0" in r.stdout
    for name in ("phi.xdmf", "shape.png", "history.png", "summary.json"):
        assert (out / name).stat().st_size > 0, name
    shape = json.loads((out / "summary.json").read_text())["shape"]
    assert shape["components"] == 1 and shape["genus"] == [0] and not shape["nested"]
    assert abs(shape["reduced_volume"] - 1) < 0.01
    points, cells, steps = read_series(out / "phi.xdmf")
    assert [t for t, _ in steps] == pytest.approx([0.0, 5e-6, 1e-5])
    assert all(set(d) == {"phi"} for _, d in steps)
    assert len(points) == 25**3  # n = 24, periodic images closed

    r = cli(["sphere", "--steps", "2", "--no-render", "--out", tmp_path / "E", "--quiet",
             "--backend", "spectral"])
    assert r.returncode == 0 and not (tmp_path / "E" / "shape.png").exists()


@pytest.mark.slow
def test_default_fem_run_writes_the_series_and_pictures(cli, tmp_path):
    """Issue 5 'done when', exactly as written: `run sphere --steps 20 --out D` (FEM default,
    n = 48; the default suite runs the same at n = 24: test_fem_run_writes_...)."""
    import json

    from fem_ade.store.xdmf import read_series

    out = tmp_path / "D"
    r = cli(["sphere", "--steps", "20", "--out", out, "--quiet"])
    assert r.returncode == 0, r.stderr
    for name in ("phi.xdmf", "shape.png", "history.png"):
        assert (out / name).stat().st_size > 0, name
    shape = json.loads((out / "summary.json").read_text())["shape"]
    assert shape["components"] == 1 and shape["genus"] == [0]
    _, _, steps = read_series(out / "phi.xdmf")
    assert [round(t, 12) for t, _ in steps] == [0.0, 1e-5]
    assert all(set(d) == {"phi", "mu"} for _, d in steps)


def test_fem_run_writes_the_series_and_pictures(cli, tmp_path):
    """A FEM run writes φ and μ to its series (first and last state), both PNGs and its shape."""
    from fem_ade.store.xdmf import read_series

    out = tmp_path / "D"
    r = cli(["sphere", "--n", "24", "--allow-underresolved", "--steps", "6", "--out", out,
             "--quiet"])
    assert r.returncode == 0, r.stderr
    for name in ("phi.xdmf", "shape.png", "history.png"):
        assert (out / name).stat().st_size > 0, name
    assert _png_size(out / "shape.png") == (1200, 600)
    shape = json.loads((out / "summary.json").read_text())["shape"]
    assert shape["components"] == 1 and shape["genus"] == [0]
    assert abs(shape["reduced_volume"] - 1) < 0.02
    points, _, steps = read_series(out / "phi.xdmf")
    assert [round(t, 12) for t, _ in steps] == [0.0, 3e-6]
    assert all(set(d) == {"phi", "mu"} for _, d in steps)
    assert len(points) == 25**3
