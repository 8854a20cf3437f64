"""Every study script runs in its quick mode and returns figures that make sense.

Studies are found by glob (no hand-kept list); each needs a ``check_<name>`` below that
asserts on what its ``main(["--quick", ...])`` returns (not only that files appear), so a
study without a check fails here.
"""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

STUDIES = Path(__file__).resolve().parents[1] / "studies"
SCRIPTS = sorted(STUDIES.glob("*.py"))
#: studies whose quick mode is too long for the default suite (they run with -m slow)
SLOW = {"convergence_fem"}


def _load(path):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def check_hard_cases(rows, out):
    """Each case runs with E_M never rising between records, stops with a diagnosis, or is
    refused as bad input."""
    assert rows
    for r in rows:
        if r["status"].startswith("completed"):
            assert "rose at 0 of" in r["detail"], r
        else:
            assert r["status"].startswith(("diverged", "refused")), r
            assert r["detail"], r


def check_cost_accuracy(results, out):
    """The FEM errors against the reference fall with n (the quick mode's n = 16–32 are
    pre-asymptotic for the spectral method: its error is not monotone there)."""
    for label in ("FEM Q1", "FEM Q2"):
        rows = results["rows"][label]
        errs = [r["err_E"] for r in rows]
        print(label, [(r["n"], f"{r['err_E']:.2e}", f"{r['wall_s']:.2f}s") for r in rows])
        assert all(math.isfinite(e) and e >= 0 for e in errs), label
        assert errs[-1] < errs[0], f"{label}: error did not fall with n: {errs}"


def check_constraints_study(cases, out):
    """Exact constraints hold V = α, A = β; penalties leave a gap that shrinks with M."""
    by = {c["variant"]: c for c in cases}
    assert set(by) == {"M1x", "M10x", "M100x", "exact"}
    exact = by["exact"]["final"]
    assert abs(exact["V"] / by["exact"]["alpha"] - 1) < 1e-8
    assert abs(exact["A"] / by["exact"]["beta"] - 1) < 1e-8
    gaps = [abs(by[v]["final"]["V"] / by[v]["alpha"] - 1) for v in ("M1x", "M10x", "M100x")]
    print("|V/alpha - 1| for M x1, x10, x100:", gaps)
    assert gaps[0] > gaps[1] > gaps[2]
    assert (out / "constraints.md").is_file()


def check_readme_figure(path, out):
    from PIL import Image

    with Image.open(path) as im:
        assert im.size == (1200, 600)
        assert np.asarray(im).std() > 10  # a picture, not a blank canvas


def check_bench(result, out):
    """Every figure is a finite number in bench_quick.json's format; iteration counts of the
    quick grids are bounded (nothing is timed: the machine's speed is not asserted)."""
    import json

    data = json.loads((out / "bench_quick.json").read_text())["figures"]
    assert data == result["figures"] and len(data) > 40
    for name, f in data.items():
        assert set(f) == {"value", "unit", "target", "op"}, name
        assert math.isfinite(f["value"]) and f["value"] > 0, (name, f)
        if name.endswith("PCG its (median)"):
            assert f["value"] <= 60, (name, f)
        if "(fft direct)" in name and name.endswith("(cpu)"):
            assert f["value"] < 10, (name, f)  # the direct path is no PCG loop


def check_gallery(result, out):
    """Every case ran, was analysed and has a verdict; the report and a montage exist."""
    verdicts = result["report"]["verdicts"]
    print(verdicts)
    assert len(verdicts) == len(result["results"]) >= 5
    assert all(isinstance(v, str) and v != "not run" for v in verdicts.values())
    kicked = [a for a in result["results"].values() if a["status"] == "steady"]
    assert kicked, "a quick steady run and its kick"
    text = (out / "gallery.md").read_text()
    assert "| discocyte (Fig. 1) | discocyte |" in text
    assert (out / "montage-spectral.png").is_file()


def check_convergence_fem(rates, out):
    assert min(rates["ellipse-2d"]["Q1"][q] for q in ("E", "V", "A")) > 1.7
    assert min(rates["ellipse-2d"]["Q2"][q] for q in ("E", "V", "A")) > 3.0


ARGS = {"readme_figure": ["--steps", "2", "--n", "26"]}


@pytest.mark.parametrize("path", [pytest.param(p, marks=pytest.mark.slow) if p.stem in SLOW
                                  else p for p in SCRIPTS], ids=[p.stem for p in SCRIPTS])
def test_study_quick_mode(path, tmp_path, capsys):
    module = _load(path)
    assert capsys.readouterr().out == "", "a study must be quiet on import"
    check = globals().get(f"check_{path.stem}")
    assert check is not None, f"add check_{path.stem} to tests/test_studies.py"
    args = ARGS.get(path.stem, ["--quick"])
    result = module.main([*args, "--out", str(tmp_path)])
    check(result, tmp_path)
