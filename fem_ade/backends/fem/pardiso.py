"""MKL's PARDISO as the symmetric indefinite LDLᵀ of the direct solves (docs/model.md §13),
through its documented C interface (``pardiso``) in the runtime library ``mkl_rt`` of the
``mkl`` wheel (the ``fast`` and ``test`` extras, Linux on x86-64).

Why PARDISO. The mixed Hessian of :mod:`fem_ade.backends.fem.direct` is symmetric and
indefinite. SuperLU factors it as L U (both triangles: twice the entries and the flops of
L D Lᵀ). PARDISO factors it as L D Lᵀ in supernodes, with Bunch–Kaufman pivots inside each
supernode (1 × 1 and 2 × 2: the signs of D are the inertia, Sylvester, iparm(22), iparm(23)).
Measured on the mixed Hessian of the prolate at ε = 0.005 (132530 unknowns, ordered by the
project's nested dissection, one thread): SuperLU 1.05–1.08 s to factor, 3.0e7 entries,
0.058 s a solve; PARDISO 0.12 s of analysis and 0.40 s to factor, 1.6e7 entries, 0.053 s a
solve (0.017 s each of six right sides at once), the same residual (8e-8 against 1e-7),
solutions 5e-10 apart, the same inertia.

Why not pypardiso (the Python wrapper on PyPI): its public ``factorize`` repeats the
analysis (METIS, 0.9–1.9 s measured there, more than the factorization itself) at every
call, and its options are PARDISO's defaults (METIS, matching, two refinement steps: a
solve 0.11 s). Here the nodes come in the project's own order (iparm(5) = 1 with the
identity: the matrix is permuted before), with no scaling or matching and no iterative
refinement, one PARDISO handle per live factorization.

One analysis per sparsity pattern. PARDISO's analysis (phase 11: the supernodes of the
given order, 0.12 s of the 0.52 s above) depends on the pattern only, and a branch factors
one pattern again and again (each Newton iteration; each azimuthal block m ≥ 1 has the same
one). When a factorization is collected its handle keeps its analysis, its factor released
(phase 0), in a small pool (:data:`POOL`), and a later matrix of the same pattern (its
indices compared entry by entry) is factored on it by phase 22 alone. A handle is only
reused once its factorization is gone, so no live factor is ever overwritten.

A pivot PARDISO had to perturb (iparm(14) > 0; in the cases probed an exact zero, while
pivots of 1e-12 and 1e-20 beside 1 were kept) makes the factorization inexact and its
inertia unreliable: :class:`LDL` raises :class:`Perturbed` then, and the caller factors the
matrix by SuperLU instead, which refuses a singular one as it did before PARDISO.

MKL runs sequentially here (its threading layer set to SEQUENTIAL before any other call):
the project runs one BLAS thread per process by default and a Dask sweep one process per
core (:mod:`fem_ade.backends.threads`), and MKL's OpenMP runtime beside OpenBLAS's threads
is what that avoids.
"""

from __future__ import annotations

import ctypes
import functools
import glob
import os
import sys
import threading
import weakref

import numpy as np
import scipy.sparse as sp

#: where ``mkl_rt`` is looked for when this variable is not set: the environment's lib
#: folder (where the ``mkl`` wheel puts it), then the system's library path
LIBRARY_ENV = "FEM_ADE_MKL_RT"
#: MKL's iparm (0-based here): 0 own values; 4 the user's order; 7 refinement steps; 9 the
#: pivot perturbation 1e-8 (the default of symmetric matrices); 10, 12 no scaling and no
#: matching; 17 report the factor's entries; 20 Bunch–Kaufman pivots; 34 0-based indices
IPARM = {0: 1, 4: 1, 7: 0, 9: 8, 10: 0, 12: 0, 17: -1, 20: 1, 34: 1}
#: analysed handles kept for reuse, their factors released (module docstring): the most
#: recent; a branch point uses two patterns (the axis free for m = 0 and Newton, not for m ≥ 1)
#: and holds at most two factors of one at a time (a Newton iterate's beside the next's)
POOL = 4
#: PARDISO's real symmetric indefinite matrix type
SYMMETRIC_INDEFINITE = -2
_INT = ctypes.POINTER(ctypes.c_int32)
#: error codes of pardiso (MKL's reference)
ERRORS = {-1: "input inconsistent", -2: "not enough memory", -3: "reordering problem",
          -4: "zero pivot, numerical factorization or iterative refinement problem",
          -5: "unclassified (internal) error", -6: "reordering failed",
          -7: "diagonal matrix is singular", -8: "32-bit integer overflow",
          -9: "not enough memory for the out-of-core solver", -10: "error opening OOC files",
          -11: "read/write error with OOC files", -12: "pardiso_64 called from a 32-bit library"}


class Perturbed(ArithmeticError):
    """PARDISO perturbed a pivot: the factorization is not exact (module docstring)."""


def _candidates() -> list[str]:
    own = os.environ.get(LIBRARY_ENV)
    if own:
        return [own]
    found = sorted(glob.glob(os.path.join(sys.prefix, "lib", "libmkl_rt.so*")), key=len)
    return found + ["libmkl_rt.so.2", "libmkl_rt.so"]


@functools.lru_cache(maxsize=1)
def library():
    """MKL's runtime library with ``pardiso`` typed and the threading layer sequential, or
    None where it is not installed (or ``FEM_ADE_MKL_RT`` names no loadable library)."""
    for path in _candidates():
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        lib.MKL_Set_Threading_Layer.argtypes = [ctypes.c_int]
        lib.MKL_Set_Threading_Layer(1)  # MKL_THREADING_SEQUENTIAL
        lib.pardiso.argtypes = [ctypes.POINTER(ctypes.c_int64), _INT, _INT, _INT, _INT, _INT,
                                ctypes.c_void_p, _INT, _INT, _INT, _INT, _INT, _INT,
                                ctypes.c_void_p, ctypes.c_void_p, _INT]
        lib.pardiso.restype = None
        return lib
    return None


def available() -> bool:
    return library() is not None


class _Handle:
    """A PARDISO handle with its options, the identity order and the pattern it analysed."""

    def __init__(self, lib, U: sp.csr_matrix):
        self.lib, self.n = lib, U.shape[0]
        self.pt = np.zeros(64, dtype=np.int64)
        self.iparm = np.zeros(64, dtype=np.int32)
        for k, v in IPARM.items():
            self.iparm[k] = v
        self.perm = np.arange(self.n, dtype=np.int32)
        self.indptr, self.indices = U.indptr, U.indices
        self.sound = False  # its (analysis and) factorization returned without an error

    def of(self, U: sp.csr_matrix) -> bool:
        """Whether this handle analysed the pattern of ``U``."""
        return (self.n == U.shape[0] and np.array_equal(self.indptr, U.indptr)
                and np.array_equal(self.indices, U.indices))

    def call(self, phase: int, U=None, b=None):
        """One call of pardiso on this handle (x for the solve phase with ``b``, else None)."""
        nrhs = 1 if b is None or b.ndim == 1 else b.shape[1]
        rhs = np.zeros(self.n) if b is None else np.asfortranarray(b, dtype=float)
        x = np.zeros_like(rhs)
        err = ctypes.c_int32(0)

        def i32(v):
            return ctypes.byref(ctypes.c_int32(v))

        self.lib.pardiso(self.pt.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)), i32(1), i32(1),
                         i32(SYMMETRIC_INDEFINITE), i32(phase), i32(self.n),
                         None if U is None else U.data.ctypes.data,
                         None if U is None else U.indptr.ctypes.data_as(_INT),
                         None if U is None else U.indices.ctypes.data_as(_INT),
                         self.perm.ctypes.data_as(_INT), i32(nrhs),
                         self.iparm.ctypes.data_as(_INT), i32(0), rhs.ctypes.data,
                         x.ctypes.data, ctypes.byref(err))
        if err.value:
            message = f"PARDISO (phase {phase}): {ERRORS.get(err.value, 'error')} ({err.value})"
            if err.value == -2:
                raise MemoryError(message)
            raise ArithmeticError(message)
        return x if b is not None else None

    def release(self):
        """All of the handle's memory freed (phase −1)."""
        if self.pt.any():
            self.call(-1)


_pool: list[_Handle] = []
_pool_lock = threading.RLock()  # (reentrant: a collection inside may give a handle back)


def _take(lib, U: sp.csr_matrix) -> _Handle | None:
    """A pooled handle that analysed the pattern of ``U``, out of the pool, or None."""
    with _pool_lock:
        for i, handle in enumerate(_pool):
            if handle.lib is lib and handle.of(U):
                return _pool.pop(i)
    return None


def _give_back(handle: _Handle) -> None:
    """A collected factorization's handle: its factor released and its analysis pooled, or
    all of it released where its last call failed or the pool is full (the oldest goes)."""
    if not handle.sound:
        handle.release()
        return
    handle.call(0)  # the factor's memory (matrix number 1), the analysis kept
    with _pool_lock:
        _pool.append(handle)
        while len(_pool) > POOL:
            _pool.pop(0).release()


def clear_pool() -> None:
    """Every pooled handle released (memory back; the next factorization analyses again)."""
    with _pool_lock:
        while _pool:
            _pool.pop().release()


def upper(A: sp.spmatrix) -> sp.csr_matrix:
    """The upper triangle of a symmetric matrix in CSR with 32-bit indices, sorted, every
    diagonal entry stored (PARDISO's form of a symmetric matrix)."""
    L = sp.csc_matrix(A)  # its lower triangle by columns is the upper one by rows (A = Aᵀ)
    L.sort_indices()
    n = L.shape[0]
    column = np.repeat(np.arange(n), np.diff(L.indptr))
    keep = L.indices >= column
    counts = np.bincount(column[keep], minlength=n)
    indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)
    U = sp.csr_matrix((L.data[keep], L.indices[keep].astype(np.int32), indptr), shape=L.shape)
    if np.count_nonzero(L.indices == column) == n:  # every diagonal entry stored
        return U
    # a diagonal entry not stored: stored as an explicit 0 (COO keeps it; no entry is pruned)
    U = U.tocoo()
    rows = np.concatenate([U.row, np.arange(n)])
    cols = np.concatenate([U.col, np.arange(n)])
    vals = np.concatenate([U.data, np.zeros(n)])
    U = sp.csr_matrix((vals, (rows, cols)), shape=(n, n))
    U.sum_duplicates()
    U.indptr, U.indices = U.indptr.astype(np.int32), U.indices.astype(np.int32)
    return U


class LDL:
    """A symmetric matrix, already in its fill-reducing order, factored by PARDISO as
    L D Lᵀ (module docstring): ``solve(b)``, ``negative`` (its negative eigenvalues),
    ``fill`` (the factor's entries). Raises :class:`Perturbed` where a pivot was perturbed."""

    def __init__(self, A: sp.spmatrix):
        lib = library()
        if lib is None:
            raise RuntimeError("MKL's runtime library (mkl_rt) is not installed: pip install mkl")
        self.U = upper(A)
        handle = _take(lib, self.U)
        self.reused = handle is not None  # the analysis of a pattern seen before
        handle = handle or _Handle(lib, self.U)
        self._handle = handle
        weakref.finalize(self, _give_back, handle)
        handle.sound = False
        handle.call(22 if self.reused else 12, self.U)  # (analysis and) factorization
        handle.sound = True
        if handle.iparm[13] > 0:
            raise Perturbed(f"PARDISO perturbed {int(handle.iparm[13])} pivots")

    @property
    def negative(self) -> int:
        """The count of negative eigenvalues (the inertia of L D Lᵀ)."""
        return int(self._handle.iparm[22])

    @property
    def fill(self) -> int:
        return int(self._handle.iparm[17])

    def solve(self, b: np.ndarray) -> np.ndarray:
        """A⁻¹b for b of shape (n,) or (n, k)."""
        b = np.asarray(b, dtype=float)
        return np.ascontiguousarray(self._handle.call(33, self.U, b))
