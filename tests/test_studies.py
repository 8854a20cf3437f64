"""Every study script runs in its quick mode, found by glob (no hand-kept list).

The FEM benchmark and convergence studies have their own checks in test_fem_studies.py;
here each remaining study's quick mode must run and write its result file.
"""

import importlib.util
from pathlib import Path

import pytest

STUDIES = Path(__file__).resolve().parents[1] / "studies"
CHECKED_ELSEWHERE = {"bench_fem", "convergence_fem"}
SCRIPTS = sorted(p for p in STUDIES.glob("*.py") if p.stem not in CHECKED_ELSEWHERE)


def _load(path):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("path", SCRIPTS, ids=[p.stem for p in SCRIPTS])
def test_study_quick_mode(path, tmp_path, capsys):
    module = _load(path)
    assert capsys.readouterr().out == "", "a study must be quiet on import"
    if path.stem == "readme_figure":
        module.main(["--steps", "2", "--n", "26", "--out", str(tmp_path)])
    else:
        module.main(["--quick", "--out", str(tmp_path)])
    written = [p for p in tmp_path.rglob("*") if p.is_file()]
    assert written, f"{path.name} --quick wrote nothing"
