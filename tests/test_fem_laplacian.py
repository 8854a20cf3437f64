"""The periodic spectral-element Laplacian: GLL nodes and weights, the matrix-free tensor K equal
to scikit-fem's assembly with the GLL rule, the constants as its kernel, the first eigenvalue
4π² at rate 2p, and interpolation exact to the element's order."""

import numpy as np
import pytest

from fem_ade.backends.fem import gll
from fem_ade.backends.fem import mesh as fm
from fem_ade.backends.fem.assemble import AssembledSpace
from fem_ade.backends.fem.solve import Eigenbasis
from fem_ade.backends.fem.tensor import TensorSpace


@pytest.mark.parametrize("p", [1, 2, 3, 5, 8, 12])
def test_gll_rule(p):
    """p + 1 points integrate polynomials of degree 2p − 1 exactly, not 2p; the derivative
    matrix differentiates degree p exactly."""
    xi, w = gll.points_weights(p)
    assert xi[0] == -1.0 and xi[-1] == 1.0 and np.all(np.diff(xi) > 0)
    for k in range(2 * p):
        exact = 0.0 if k % 2 else 2.0 / (k + 1)
        assert abs(w @ xi**k - exact) < 1e-13, k
    assert abs(w @ xi ** (2 * p) - 2.0 / (2 * p + 1)) > 1e-9
    D = gll.derivative_matrix(p)
    assert np.abs(D @ xi**p - p * xi ** (p - 1)).max() < 1e-10 * p**2


def _matching(a, b, L=1.0):
    """Permutation q with b[:, j] ≡ a[:, q[j]] modulo the period."""
    def key(x):
        return tuple(np.round((x % L) / L * 1e6).astype(np.int64) % 1_000_000)
    index = {key(a[:, i]): i for i in range(a.shape[1])}
    return np.array([index[key(b[:, j])] for j in range(b.shape[1])])


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("kind", ["uniform", "graded"])
def test_tensor_space_equals_skfem_with_gll_rule(dim, order, kind):
    """The Kronecker-sum K = Σ K₁ ⊗ W ⊗ W and W = ⊗ w are scikit-fem's assembly of (∇u, ∇v)
    and (u, v) with the tensor GLL rule on the same mesh; its mass comes out diagonal."""
    mesh = fm.uniform(dim, 4) if kind == "uniform" else fm.graded(dim, 4)
    tensor = TensorSpace(mesh.axes, order)
    ref = AssembledSpace(mesh, order)
    q = _matching(tensor.doflocs, ref.doflocs)
    assert np.abs(tensor.weights[q] - ref.weights).max() < 1e-15
    K = tensor.assembled_stiffness()
    assert abs(K[q][:, q] - ref.K).max() < 1e-12


@pytest.mark.parametrize("order", [1, 2, 4, 8])
def test_matrix_free_equals_assembled(order):
    """K @ x by sum factorization (dense 1D products along each axis) = the assembled K,
    also for a stack of vectors and on a graded mesh; μ = W⁻¹Kx."""
    mesh = fm.graded(3, 3)
    space = TensorSpace(mesh.axes, order)
    x = np.random.default_rng(1).standard_normal((2, space.n_dofs))
    K = space.assembled_stiffness()
    for v in x:
        assert np.abs(space.K @ v - K @ v).max() < 1e-11 * np.abs(K @ v).max()
    stacked = space.laplacian(x)
    assert np.abs(stacked[1] - (K @ x[1]) / space.weights).max() < 1e-9 * np.abs(stacked).max()
    assert np.allclose(space.K.diagonal(), K.diagonal())


@pytest.mark.parametrize("dim,order,n", [(2, 1, 6), (2, 3, 3), (3, 1, 4), (3, 2, 3), (3, 6, 3)])
def test_kernel_is_constants(dim, order, n):
    """One zero eigenvalue of W⁻¹K (the constants), the next one positive."""
    space = TensorSpace(fm.graded(dim, n).axes, order)
    lam = np.sort(Eigenbasis(space, fourier=False).lam.ravel())
    assert abs(lam[0]) < 1e-9 and lam[1] > 1.0, lam[:3]
    assert np.allclose(space.laplacian(np.ones(space.n_dofs)), 0.0, atol=1e-9)


@pytest.mark.parametrize("order,ns,rate", [(1, (8, 16, 32), 2.0), (2, (4, 8, 16), 4.0),
                                           (3, (3, 4, 6), 6.0), (4, (3, 4, 6), 8.0)])
def test_first_eigenvalue_rate(order, ns, rate):
    """The first non-zero eigenvalue of K x = λ W x converges to 4π² at rate 2p (measured
    1.99, 4.06, 6.03, 7.97): the GLL rule's under-integration of the mass costs no order."""
    err = []
    for n in ns:
        space = TensorSpace(fm.uniform(2, n).axes, order)
        lam = np.sort(Eigenbasis(space, fourier=False).lam.ravel())
        err.append(abs(lam[1] - 4 * np.pi**2))
    observed = np.polyfit(np.log(1.0 / np.array(ns)), np.log(err), 1)[0]
    print(f"p = {order}: errors {err}, observed rate {observed:.2f}")
    assert abs(observed - rate) < 0.15 * rate, f"observed rate {observed:.2f}, expected {rate}"


def test_fourier_and_dense_eigenbases_agree():
    """p = 1 on a uniform mesh: the FFT eigenbasis and the dense one give the same S⁻¹."""
    from fem_ade.backends.fem.solve import DiagonalizedSolver, StepMatrix

    space = TensorSpace(fm.uniform(3, 8).axes, 1)
    S = StepMatrix.of(dt=1e-5, kappa=1.0, eps=0.05)
    r = np.random.default_rng(2).standard_normal(space.n_dofs)
    x_fft = DiagonalizedSolver(Eigenbasis(space), S).solve([r])[0][0]
    x_fdm = DiagonalizedSolver(Eigenbasis(space, fourier=False), S).solve([r])[0][0]
    assert np.abs(x_fft - x_fdm).max() < 1e-10 * np.abs(x_fft).max()
    # and it is S⁻¹: S x = r
    Sx = S.a * space.weights * x_fft + space.K @ (S.c * x_fft + S.ke * space.laplacian(x_fft))
    assert np.abs(Sx - r).max() < 1e-9 * np.abs(r).max()


@pytest.mark.parametrize("order", [1, 3, 6])
def test_interpolation_is_exact_to_the_order(order):
    """The grid field of a tensor space is its own piecewise polynomial: exact for degree p
    per cell, on a graded mesh; a smooth field's error falls with p (measured 0.20, 5.5e-4,
    5.7e-8 at p = 1, 3, 6 on 8 cells)."""
    mesh = fm.graded(2, 8)
    space = TensorSpace(mesh.axes, order)
    x, y = space.doflocs
    u = np.sin(2 * np.pi * x) + np.cos(2 * np.pi * y)  # smooth: the interpolant is close
    pts = np.linspace(0.0, 1.0, 17, endpoint=False)
    values = space.interpolate_to([pts, pts])(u)
    X, Y = np.meshgrid(pts, pts, indexing="ij")
    exact = np.sin(2 * np.pi * X) + np.cos(2 * np.pi * Y)
    err = np.abs(values - exact).max()
    assert err < {1: 0.5, 3: 3e-3, 6: 2e-7}[order], err
    # a polynomial of degree p in each cell is reproduced to round-off: the nodal values of
    # the cell's own Lagrange polynomial
    ax = space.axes[0]
    cell = 1
    xi = 2.0 * (pts - ax.vertices[cell]) / ax.h[cell] - 1.0
    inside = (xi >= -1) & (xi <= 1)
    nodal = np.zeros(ax.size)
    nodal[ax.element_dofs[cell]] = gll.points_weights(order)[0] ** order
    got = ax.interpolation(pts[inside]) @ nodal
    assert np.abs(got - xi[inside] ** order).max() < 1e-12
