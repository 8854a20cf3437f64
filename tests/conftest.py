"""Shared fixtures: small helpers to run scenes through the driver without the CLI."""

import os
import sys

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture(autouse=True)
def _seed():
    np.random.seed(0)


def run_cli(args, cwd=None):
    """Run ``python -m fem_ade.run ARGS``; return the CompletedProcess (text mode)."""
    import subprocess

    return subprocess.run([sys.executable, "-m", "fem_ade.run", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, timeout=600)


@pytest.fixture
def cli():
    return run_cli
