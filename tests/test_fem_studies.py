"""The FEM studies run in their quick mode (they are importable and quiet on import)."""

import importlib.util
from pathlib import Path

import pytest

STUDIES = Path(__file__).resolve().parents[1] / "studies"


def _load(name):
    spec = importlib.util.spec_from_file_location(name, STUDIES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_bench_quick(capsys):
    _load("bench_fem").main(["--quick"])
    out = capsys.readouterr().out
    assert "setup and step" in out and "peak memory" in out


@pytest.mark.slow
def test_convergence_quick():
    rates = _load("convergence_fem").main(["--quick"])
    assert min(rates["ellipse-2d"]["Q1"][q] for q in ("E", "V", "A")) > 1.7
    assert min(rates["ellipse-2d"]["Q2"][q] for q in ("E", "V", "A")) > 3.0
