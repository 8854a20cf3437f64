"""Threads, set once and on purpose: how many the linear algebra (BLAS) and scipy's FFTs use.

* **BLAS** (numpy's and scipy's OpenBLAS/MKL): one thread by default during a run, a resume
  and a branch, axisymmetric or switched into 3D (:func:`limited`, applied by
  :func:`fem_ade.engine.runs.simulate`, :func:`fem_ade.engine.runs.resume`,
  :func:`fem_ade.campaigns.branch.follow` and
  :func:`fem_ade.campaigns.switch_branch.follow_switched`),
  ``FEM_ADE_BLAS_THREADS=N``
  for N, ``FEM_ADE_BLAS_THREADS=all`` for the library's own choice (all cores). Measured on
  this 2-core machine, ``discocyte --backend fem --order 4 --n 64 --steps 50`` (16 cells of
  order 4; the run command counted cells then): loop 1.8–1.9 s
  with one thread against 3.8–4.0 s with the library's default while two other processes ran
  (three tries each, alternating); alone, order 6 on 8 cells: 0.35 s against 0.44 s. The
  FEM's operators are small dense blocks (fast diagonalization, sum factorization): extra
  threads wait for cores more than they work, and a Dask sweep runs one process per core.
* **FFTs** (the spectral backend and the FEM's periodic fast-diagonalization solve):
  ``FEM_ADE_FFT_WORKERS`` (:func:`fft_workers`), all cores by default — the spectral runs
  moved far less with load than the FEM's BLAS did.

A value set by the environment the process started with (``OPENBLAS_NUM_THREADS``, …) is a
ceiling these limits stay under.
"""

from __future__ import annotations

import functools
import os
from contextlib import contextmanager

from fem_ade.model.params import ModelError

BLAS_ENV, FFT_ENV = "FEM_ADE_BLAS_THREADS", "FEM_ADE_FFT_WORKERS"


def blas_threads() -> int | None:
    """BLAS threads of a run: ``FEM_ADE_BLAS_THREADS`` (default 1; ``all``: None, the
    library's choice); ModelError for another value."""
    text = os.environ.get(BLAS_ENV, "1").strip()
    if text.lower() == "all":
        return None
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise ModelError(f"{BLAS_ENV} must be a positive integer or 'all', got {text!r}")
    return n


def fft_workers() -> int:
    """Threads of scipy's FFTs: ``FEM_ADE_FFT_WORKERS`` (e.g. 1 for a background job beside
    other work), else all cores (-1); ModelError for a value that is not -1 or a positive
    integer."""
    text = os.environ.get(FFT_ENV, "-1").strip()
    try:
        workers = int(text)
    except ValueError:
        workers = 0
    if workers == 0 or workers < -1:
        raise ModelError(f"{FFT_ENV} must be a positive integer (threads of the "
                         f"FFTs) or -1 (all cores), got {text!r}")
    return workers


@contextmanager
def limited():
    """BLAS limited to :func:`blas_threads` inside (numpy's and scipy's libraries both:
    scipy.linalg is loaded first, as threadpoolctl limits only the loaded ones)."""
    n = blas_threads()
    if n is None:
        yield
        return
    import scipy.linalg  # noqa: F401 (loads scipy's BLAS, so that the limit reaches it)
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=n, user_api="blas"):
        yield


def limit_threads(function):
    """``function`` run under :func:`limited`."""
    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        with limited():
            return function(*args, **kwargs)
    return wrapper
