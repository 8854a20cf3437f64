"""The periodic FEM Laplacian (SPEC §5): Kronecker assembly = scikit-fem assembly, the kernel is
the constants, and the first nonzero eigenvalue 4π² converges at rate 2 (Q1) and 4 (Q2)."""

import numpy as np
import pytest
import scipy.linalg as sl

from fem_ade.fem import assemble as fa
from fem_ade.fem import mesh as fm


def _matching(a, b, L=1.0):
    """Permutation p with b[:, j] ≡ a[:, p[j]] modulo the period."""
    def key(x):
        return tuple(np.round((x % L) / L * 1e6).astype(np.int64) % 1_000_000)
    index = {key(a[:, i]): i for i in range(a.shape[1])}
    return np.array([index[key(b[:, j])] for j in range(b.shape[1])])


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("kind", ["uniform", "graded"])
def test_kronecker_equals_skfem(dim, order, kind):
    mesh = fm.uniform(dim, 4) if kind == "uniform" else fm.graded(dim, 4)
    kron = fa.operators(mesh, order, "kron")
    ref = fa.operators(mesh, order, "skfem")
    p = _matching(kron.doflocs, ref.doflocs)
    assert abs(kron.M[p][:, p] - ref.M).max() < 1e-14
    assert abs(kron.K[p][:, p] - ref.K).max() < 1e-12


@pytest.mark.parametrize("dim,order,n", [(2, 1, 6), (2, 2, 4), (3, 1, 4), (3, 2, 3)])
def test_kernel_is_constants(dim, order, n):
    ops = fa.operators(fm.graded(dim, n), order)
    lam, vec = sl.eigh(ops.K.toarray(), ops.M.toarray(), subset_by_index=[0, 1])
    assert abs(lam[0]) < 1e-9 and lam[1] > 1.0, lam
    v0 = vec[:, 0] / vec[0, 0]
    assert np.allclose(v0, 1.0, atol=1e-8)


def _first_eigenvalue(dim, order, n, lumped):
    """The smallest non-zero eigenvalue of K x = λ B x (shift-invert about −1)."""
    from scipy.sparse import diags
    from scipy.sparse.linalg import eigsh

    ops = fa.operators(fm.uniform(dim, n), order)
    B = diags(ops.weights).tocsc() if lumped else ops.M.tocsc()
    lam = eigsh(ops.K.tocsc(), k=2, M=B, sigma=-1.0, which="LM", return_eigenvectors=False)
    return float(np.max(lam))


@pytest.mark.parametrize("dim,order,ns,rate,tol", [
    (2, 1, (8, 16, 32), 2.0, 0.15),
    (2, 2, (4, 8, 16), 4.0, 0.3),
    (3, 1, (4, 6, 8), 2.0, 0.15),
    (3, 2, (3, 4, 5), 4.0, 0.4),
])
@pytest.mark.parametrize("lumped", [False, True])
def test_first_eigenvalue_rate(dim, order, ns, rate, tol, lumped):
    if lumped and dim == 3:
        pytest.skip("3D meshes this small are pre-asymptotic for the lumped eigenvalue")
    err = [abs(_first_eigenvalue(dim, order, n, lumped) - 4 * np.pi**2) for n in ns]
    observed = np.polyfit(np.log(1.0 / np.array(ns)), np.log(err), 1)[0]
    print(f"Q{order} {dim}D {'lumped' if lumped else 'consistent'}: errors {err}, "
          f"observed rate {observed:.2f}")
    assert abs(observed - rate) < tol, f"observed rate {observed:.2f}, expected {rate}"
