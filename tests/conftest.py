"""Shared fixtures: seeded randomness, floating-point errors as exceptions, the CLI helper."""

import os
import sys

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture(scope="session", autouse=True)
def _one_blas_thread_per_worker():
    """One BLAS thread in each test process, as every run has (fem_ade.backends.threads):
    two pytest workers share two cores, and the tests that call the solvers directly (3D
    Newton, the eigen-solves) would otherwise run two threads each and oversubscribe them —
    measured: tests/test_newton.py on two workers in 56 s, and in 272 s once."""
    from fem_ade.backends.threads import limited

    with limited():
        yield


@pytest.fixture(autouse=True)
def _seed():
    np.random.seed(0)


@pytest.fixture(autouse=True)
def _floating_point_errors_raise():
    """Overflow, division by zero and invalid operations raise FloatingPointError (py-pde's
    habit): a NaN the code does not expect fails the test where it is made. The time loop
    catches it as a divergence (exit code 3). Underflow (e.g. tanh far from the membrane) is
    harmless and stays silent."""
    with np.errstate(all="raise", under="ignore"):
        yield


def run_cli(args, cwd=None, env=None):
    """Run ``python -m fem_ade.run ARGS``; return the CompletedProcess (text mode)."""
    import subprocess

    return subprocess.run([sys.executable, "-m", "fem_ade.run", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, timeout=600,
                          env=None if env is None else {**os.environ, **env})


@pytest.fixture
def cli():
    return run_cli
