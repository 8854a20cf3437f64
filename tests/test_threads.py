"""Threads set once, on purpose (fem_ade.backends.threads): one BLAS thread during a run unless
FEM_ADE_BLAS_THREADS says otherwise, in numpy's library and scipy's both."""

import pytest
from threadpoolctl import threadpool_info

from fem_ade.backends.threads import blas_threads, limit_threads, limited
from fem_ade.model.params import ModelError


def _blas_threads() -> set[int]:
    """The threads of each BLAS loaded, less MKL in its sequential layer (loaded by the
    PARDISO solves, fem_ade.backends.fem.pardiso: one thread whatever the limit)."""
    return {lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"
            and lib.get("threading_layer") != "sequential"}


def test_a_run_uses_one_blas_thread_by_default(monkeypatch):
    import scipy.linalg  # noqa: F401 (both libraries loaded)
    from threadpoolctl import threadpool_limits

    monkeypatch.delenv("FEM_ADE_BLAS_THREADS", raising=False)
    assert blas_threads() == 1

    @limit_threads
    def inside():
        return _blas_threads()

    with threadpool_limits(limits=2, user_api="blas"):  # as if the library chose 2
        assert _blas_threads() == {2}
        with limited():
            assert _blas_threads() == {1}
        assert inside() == {1}
        assert _blas_threads() == {2}  # and back after the run


def test_the_environment_chooses_the_blas_threads(monkeypatch):
    before = _blas_threads()
    monkeypatch.setenv("FEM_ADE_BLAS_THREADS", "all")
    assert blas_threads() is None
    with limited():
        assert _blas_threads() == before
    monkeypatch.setenv("FEM_ADE_BLAS_THREADS", "2")
    assert blas_threads() == 2
    for bad in ("0", "-1", "two", ""):
        monkeypatch.setenv("FEM_ADE_BLAS_THREADS", bad)
        with pytest.raises(ModelError, match="FEM_ADE_BLAS_THREADS"):
            blas_threads()
