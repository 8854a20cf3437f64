"""Direct solves of the Hessian and the stability of axisymmetric states in each azimuthal
mode m (fem_ade.backends.fem.direct, fem_ade.backends.fem.modes, fem_ade.campaigns.stability;
docs/model.md §13):
the same Newton iterates and eigenvalues as the iterative path, the mode operator against
Bessel modes, a sphere's multiplets, the blocks against a 3D eigen-solve, the zero modes
taken out, the inertia's count, the command line."""

import json
import math
import platform
import sys

import numpy as np
import pytest

from fem_ade.backends.base import make_backend
from fem_ade.backends.fem import modes as M
from fem_ade.backends.fem.newton import NewtonSystem, kkt_solve, linearize, solve_steady
from fem_ade.campaigns.branch import main as branch_main
from fem_ade.campaigns.stability import axisymmetric, cartesian, load_state
from fem_ade.campaigns.stability import main as stability_main
from fem_ade.scenes.catalogue import vesicle_scene

#: the prolate with ADE (κ̄/κ = 1.4, Δa₀ = 1.2): the blocks and the 3D spectrum carry the ADE
#: force's coefficients and its rank-one term
ADE = {"kbar": 1.4, "da0": 1.2}
BRANCH = ["vesicle", "--branch", "prolate", "--eps", "0.04", "--R0", "0.2", "--param", "v",
          "--from", "0.85", "--to", "0.84", "--step", "0.01", "--quiet", "--modes", "4",
          "--kbar", str(ADE["kbar"]), "--da0", str(ADE["da0"])]


@pytest.fixture(scope="module")
def prolate(tmp_path_factory):
    """A prolate branch with ADE at ε = 0.04 (v 0.85 → 0.84), its first point's backend."""
    out = tmp_path_factory.mktemp("modes") / "prolate"
    assert branch_main([*BRANCH, "--out", str(out)]) == 0
    be, _ = load_state(out / "points" / "0000")
    return out, be


def _backend(eps=0.05, v=0.9, branch="prolate", R0=0.2, **ade):
    scene = vesicle_scene(v=v, branch=branch, eps=eps, R0=R0, **ade)
    from fem_ade.backends.fem.axisym import default_nodes

    return make_backend("fem", scene, n=default_nodes(eps, 1.0, 8), geometry="axisymmetric",
                        scheme="stabilized", constraints="exact", dt=scene.dt)


def test_direct_newton_gives_the_iterative_iterates():
    """Newton with the sparse LU of the mixed Hessian (the default in 2D) gives the iterates
    of Newton–MINRES solved to 1e-12: φ to 1e-10 after each of three iterations."""
    a, b = _backend(), _backend()
    for be in (a, b):
        be.phi = be.phi + 0.02 * np.cos(3 * be.space.doflocs[1])  # away from steady
        be._set(be.phi, None)
    for _ in range(3):
        ra = solve_steady(a, max_iterations=1, linear="direct")
        rb = solve_steady(b, max_iterations=1, linear="minres", inner_tol=1e-12)
        assert ra.iterations == rb.iterations
        scale = np.max(np.abs(a.phi))
        assert np.max(np.abs(a.phi - b.phi)) <= 1e-10 * scale
        assert ra.E == pytest.approx(rb.E, rel=1e-12)


def test_a_factorization_is_of_its_own_parameters():
    """The bordered solve answers the system of the linearization it was made for: after
    Δa₀ moves (the ADE term's force, so the Hessian), a new linearization's solve has a
    residual of round-off in the matrix-free Hessian, while the solve of the factorization
    from before the move leaves a residual of the change's size."""
    from fem_ade.campaigns.branch import set_parameter

    be = _backend(kbar=1.4, da0=1.2)
    solve_steady(be)
    sys_ = NewtonSystem(be)
    old = linearize(sys_, be.phi)
    rhs = np.concatenate([old.grad + np.sin(be.space.doflocs[1]), [0.0, 0.0, 0.0]])
    x_old, _ = kkt_solve(sys_, old, rhs)
    be.stepper.params = be.params = set_parameter(be.params, "da0", 1.3)  # the ADE force
    new = linearize(sys_, be.phi)
    x, _ = kkt_solve(sys_, new, rhs)
    N = be.phi.size
    step = sys_.step

    def apply(lin, x):
        v, nu = x[:N], x[N:]
        top = (step.hessian_vector(lin.phi, lin.mu, lin.Kphi, v)
               + step.constraint_hessian_vector(lin.phi, lin.Kphi, v, *lin.lam[:2])
               + sum(n * c for n, c in zip(nu, lin.C, strict=True)))
        return np.concatenate([top, [c @ v for c in lin.C]])

    def residual(lin, x):
        return np.linalg.norm(apply(lin, x) - rhs) / np.linalg.norm(rhs)

    assert residual(new, x) < 1e-8
    assert residual(new, x_old) > 1e3 * residual(new, x)
    assert new.bordered is not old.bordered


#: the test extra installs MKL here (pyproject.toml's marker): there PARDISO must be found
MKL_EXPECTED = sys.platform == "linux" and platform.machine() == "x86_64"


def _pardiso_or_skip():
    from fem_ade.backends.fem import pardiso

    if not pardiso.available():
        assert not MKL_EXPECTED, "the test extra installs mkl on Linux x86-64: mkl_rt not found"
        pytest.skip("MKL is not installed")


@pytest.mark.parametrize("below", [0, 2])
def test_the_sparse_codes_agree(prolate, below):
    """PARDISO's L D Lᵀ and SuperLU's L U of the bordered H − σP of the prolate's m = 0
    block (σ below its lowest eigenvalue, or between its second and third) solve alike to
    1e-9 and count the same eigenvalues below σ (the inertia), with no pivot perturbed."""
    from fem_ade.backends.fem.direct import count_below

    _pardiso_or_skip()
    _, be = prolate
    sys_ = NewtonSystem(be)
    lin = linearize(sys_, be.phi.copy())
    block = M.mode_block(sys_, lin, 0)
    values = M.lowest(sys_, lin, 0, k=3).eigenvalues
    shift = -1e-6 if below == 0 else 0.5 * (values[1] + values[2])
    b = np.sin(3 * be.space.doflocs[1]) * be.space.weights
    out = {}
    for code in ("pardiso", "superlu"):
        with pytest.MonkeyPatch.context() as mp:
            mp.setenv("FEM_ADE_SPARSE", code)
            F, B = M.block_factor(sys_, block, shift)
        assert F.factor.code == code
        out[code] = (B.solve(b)[0], count_below(F, B))
    (xp, np_), (xs, ns) = out["pardiso"], out["superlu"]
    assert np.linalg.norm(xp - xs) <= 1e-9 * np.linalg.norm(xs)
    assert np_ == ns == below


def test_a_perturbed_pivot_is_not_kept():
    """Where PARDISO has to perturb a pivot (an exact 0 in this order) its factorization is
    inexact: the matrix goes to SuperLU instead, which refuses it as singular, as before."""
    import scipy.sparse as sp

    from fem_ade.backends.fem import pardiso
    from fem_ade.backends.fem.direct import Factorization

    _pardiso_or_skip()
    A = sp.csr_matrix(np.diag([1.0, 0.0, -1.0]))
    with pytest.raises(pardiso.Perturbed):
        pardiso.LDL(A)
    with pytest.raises(RuntimeError, match="singular"):
        Factorization(A, np.arange(3), code="pardiso")
    F = Factorization(sp.csr_matrix(np.diag([1.0, 1e-12, -1.0])), np.arange(3), code="pardiso")
    assert F.code == "pardiso" and F.negative == 1


def test_the_sparse_code_is_chosen_by_its_variable(monkeypatch):
    """FEM_ADE_SPARSE chooses the code; auto is PARDISO where MKL is, an unknown name is
    refused with the names."""
    from fem_ade.backends.fem import pardiso
    from fem_ade.backends.fem.direct import sparse_code
    from fem_ade.model.params import ModelError

    monkeypatch.setenv("FEM_ADE_SPARSE", "superlu")
    assert sparse_code() == "superlu"
    monkeypatch.setenv("FEM_ADE_SPARSE", "auto")
    assert sparse_code() == ("pardiso" if pardiso.available() else "superlu")
    monkeypatch.setenv("FEM_ADE_SPARSE", "umfpack")
    with pytest.raises(ModelError, match="superlu, pardiso"):
        sparse_code()


def _laplacian(n: int, shift: float):
    """The 2D 5-point Laplacian on an n × n grid less ``shift`` (indefinite for a shift
    between its eigenvalues)."""
    import scipy.sparse as sp

    T = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(n, n))
    return sp.csr_matrix(sp.kronsum(T, T) - shift * sp.identity(n * n))


def test_an_analysis_is_reused_only_by_a_dead_factorization_of_its_pattern():
    """PARDISO's analysis of a pattern is kept when its factorization is collected and used
    again for a matrix of that pattern: the factorization so made solves and counts exactly
    as a fresh one; a live factorization keeps its own (the next one is analysed anew and
    the first still solves its own matrix); another pattern is analysed anew."""
    import scipy.sparse as sp

    from fem_ade.backends.fem import pardiso

    _pardiso_or_skip()
    pardiso.clear_pool()
    A1, A2 = _laplacian(30, 0.3), _laplacian(30, 0.9)
    b = np.linspace(-1.0, 2.0, 900)
    fresh = pardiso.LDL(A2)
    x_fresh, negative = fresh.solve(b), fresh.negative
    del fresh
    pardiso.clear_pool()
    first = pardiso.LDL(A1)
    second = pardiso.LDL(A2)  # the first alive: a handle of its own
    assert not first.reused and not second.reused
    assert np.allclose(A1 @ first.solve(b), b, atol=1e-10)
    del first, second
    reused = pardiso.LDL(A2)
    assert reused.reused
    assert np.array_equal(reused.solve(b), x_fresh) and reused.negative == negative > 0
    other = pardiso.LDL(sp.diags([-1.0, 2.5, -1.0], [-1, 0, 1], shape=(900, 900)))  # 1D
    assert not other.reused
    pardiso.clear_pool()


def test_the_upper_triangle_stores_every_diagonal_entry():
    """PARDISO's form of a symmetric matrix: its upper triangle by rows, sorted, with a
    diagonal entry stored even where it is 0 (an unstored one is an error there)."""
    import scipy.sparse as sp

    from fem_ade.backends.fem.pardiso import upper

    A = sp.csr_matrix(np.array([[0.0, 2.0, 0.0], [2.0, 3.0, 1.0], [0.0, 1.0, 0.0]]))
    U = upper(A)
    assert U.has_sorted_indices and U.indices.dtype == np.int32
    assert [list(U.indices[U.indptr[i]:U.indptr[i + 1]]) for i in range(3)] == [[0, 1], [1, 2], [2]]
    assert np.array_equal(U.toarray(), np.triu(A.toarray()))


def test_the_m0_block_equals_the_iterative_eigensolve(prolate):
    """The m = 0 block by shift-invert on the LU equals ARPACK's regular mode on the
    projected operator (the path before) to 1e-8 relative, the four lowest."""
    _, be = prolate
    direct = axisymmetric(be, (0,), 4).modes[0]
    iterative = cartesian(be, 4).eigenvalues
    assert np.max(np.abs(np.asarray(direct) / np.asarray(iterative) - 1)) < 1e-8


def test_a_3d_count_is_all_the_unstable_directions_or_says_it_is_not(prolate):
    """cartesian() asked for one eigenvalue, with a threshold between the third and the
    fourth lowest, makes the solve again with 2k until one is above it: the count is 3 and
    complete (before, a count equal to k was silently a lower bound: the starfish on the
    whole box had 4 of 4). With every eigenvalue below the threshold it stops at ``most``
    and says the count is a lower bound."""
    _, be = prolate
    four = cartesian(be, 4).eigenvalues
    between = 0.5 * (four[2] + four[3])
    grown = cartesian(be, 1, below=between)
    assert grown.unstable_3d == 3 and grown.complete and len(grown.eigenvalues) == 4
    assert np.allclose(grown.eigenvalues, four, rtol=1e-8)
    capped = cartesian(be, 1, below=1e9, most=2)
    assert capped.unstable_3d == 2 and not capped.complete
    assert capped.as_json()["complete"] is False


@pytest.mark.parametrize("m", [0, 1, 2, 3, 5])
def test_the_mode_laplacian_on_bessel_modes(m):
    """W⁻¹K_m applied to J_m(kr)cos(πz) (natural ends: J_m'(kR) = 0) is (k² + π²) times it
    at every node, the axis' neighbours included (the exact GLJ rule of ∫ψχ/r², whose node
    on the axis carries ψ'(0)χ'(0): without it m = 1 errs by 3 at the first node)."""
    import scipy.sparse as sp
    import scipy.special as ss
    from scipy.optimize import brentq

    from fem_ade.backends.fem.tensor import BoundedAxis, TensorSpace

    R, Z, p, cells = 0.5, 1.0, 8, 6
    space = TensorSpace([BoundedAxis(np.linspace(0, R, cells + 1), p, radial=True),
                         BoundedAxis(np.linspace(0, Z, cells + 1), p)], p)
    grid = np.linspace(0.5, 30, 3000)
    vals = ss.jvp(m, grid * R)
    i = next(i for i in range(len(grid) - 1) if vals[i] * vals[i + 1] < 0)
    k = brentq(lambda x: ss.jvp(m, x * R), grid[i], grid[i + 1])
    r, z = space.doflocs
    psi = ss.jv(m, k * r) * np.cos(np.pi * z / Z)
    Km = space.assembled_stiffness()
    if m:
        Km = Km + m * m * M.radial_inverse_square(space)
    free = np.arange(r.size) if m == 0 else np.flatnonzero(r > 0)
    Km = sp.csr_matrix(Km)[free][:, free]
    mu = (Km @ psi[free]) / space.weights[free]
    lam = k * k + (np.pi / Z) ** 2
    assert np.max(np.abs(mu - lam * psi[free])) < 1e-7 * lam * np.max(np.abs(psi))


def _sphere():
    """A steady sphere (ε = 0.02, R₀ = 0.25, order 8 at 2.5 nodes per ε) at the V and A of
    its tanh seed: its tension makes l = 2 and 3 unstable (l(l + 1)κ_H/R² = 90, 181 against
    its −λ_A = 310), which spreads the multiplets apart."""
    be = _backend(eps=0.02, v=1.0, branch="sphere", R0=0.25)
    d = be.diagnostics()
    be.stepper.params = be.params = be.params.with_(alpha=d["V"], beta=d["A"])
    assert solve_steady(be, max_iterations=60).converged
    sys_ = NewtonSystem(be)
    return sys_, linearize(sys_, be.phi)


def _multiplets_hold(sys_, lin) -> bool:
    """Each eigenvalue of angular order l appears in the blocks m = 0 … l (module
    docstring): l = 3 the lowest of blocks 0–3 and absent from 4; l = 2 the second of
    blocks 0–2 and absent from 3; each to 1 %."""
    low = {m: M.lowest(sys_, lin, m, k=3).eigenvalues for m in range(5)}
    l3, l2 = low[0][0], low[0][1]

    def near(x, y):
        return abs(x / y - 1) < 0.01

    return (all(near(low[m][0], l3) for m in range(4)) and not near(low[4][0], l3)
            and all(near(low[m][1], l2) for m in range(3))
            and not any(near(x, l2) for x in low[3]))


def test_a_spheres_modes_are_its_multiplets(monkeypatch):
    """Check (a): on a steady sphere the blocks' eigenvalues are the spherical harmonics'
    multiplets (measured: to 0.3 % at this resolution), and a deliberate error in the
    m²/r² term (m²/2) breaks them (the l = 2 one in block 1 by 27 %)."""
    sys_, lin = _sphere()
    assert _multiplets_hold(sys_, lin)
    right = M.radial_inverse_square
    monkeypatch.setattr(M, "radial_inverse_square", lambda space: 0.5 * right(space))
    assert not _multiplets_hold(sys_, lin)


def _oblate(tmp_path, modes: int):
    """The oblate at ε = 0.04, v = 0.85, R₀ = 0.25 (its m = 2 block has one negative
    eigenvalue): the first point of a branch with ``modes``, its backend."""
    out = tmp_path / "oblate"
    assert branch_main(["vesicle", "--branch", "oblate", "--eps", "0.04", "--R0", "0.25",
                        "--param", "v", "--from", "0.85", "--to", "0.84", "--step", "0.01",
                        "--quiet", "--modes", str(modes), "--out", str(out)]) == 0
    be, _ = load_state(out / "points" / "0000")
    return be


def _revolve(ax, scene):
    """An axisymmetric state revolved into 3D (order 8, 64³ nodes: the same spacing as the
    axisymmetric mesh's fine zone at ε = 0.04) and made steady there by Newton."""
    be = make_backend("fem", scene, n=64, order=8, scheme="stabilized", constraints="exact",
                      dt=1e-6)
    be.stepper.params = be.params = ax.params
    X, Y, Z = be.space.doflocs
    ar, az = ax.space.axes
    r = np.minimum(np.hypot(X - ax.axis[0], Y - ax.axis[1]), ar.nodes[-1])
    Phi = ax.phi.reshape(ax.space.shape)
    rows = ar.interpolation(r) @ Phi
    phi = np.einsum("ij,ij->i", rows, az.interpolation(Z).toarray())
    be._set(phi, None)
    assert solve_steady(be, max_iterations=10).converged
    return be


@pytest.fixture(scope="module")
def revolved(prolate):
    """The prolate's first point revolved into 3D and made steady there."""
    return _revolve(prolate[1], vesicle_scene(v=0.85, branch="prolate", eps=0.04, R0=0.2,
                                              **ADE))


def test_the_blocks_are_the_3d_spectrum(prolate, revolved):
    """Check (b), with ADE: the six lowest eigenvalues of the 3D constrained Hessian (its
    rigid motions taken out) are the union of the blocks' (m ≥ 1 twice: cos and sin) to 1e-3
    relative (measured: 2.3e-5 on the eight lowest; 2e-4 on the twelve lowest without ADE).
    The ADE's rank-one term moves block 0's six lowest by at most 2e-4 here (measured with
    it dropped), so this checks the ADE force's coefficients more than that term."""
    _, ax = prolate
    blocks = axisymmetric(ax, range(6), 6)
    union = sorted(x for m, vals in blocks.modes.items()
                   for x in (list(vals) if m == 0 else 2 * list(vals)))[:6]
    three = cartesian(revolved, 6, tol=1e-7).eigenvalues
    assert np.max(np.abs(np.asarray(three) / np.asarray(union) - 1)) < 1e-3


@pytest.mark.slow
def test_the_oblates_saddle_is_one_in_3d(tmp_path):
    """Check (b) where a block is unstable: the oblate at ε = 0.04, v = 0.85 (R₀ = 0.25) has
    one negative eigenvalue in block m = 2 and none in the others; revolved into 3D and made
    steady there by Newton (a saddle: Newton does not need a minimum), the 3D constrained
    Hessian has exactly two negative eigenvalues, the m = 2 one's pair (cos 2θ and sin 2θ),
    and its next four are the blocks' to 1e-3 (measured: 1.6e-4). The pair is split by the
    cubic mesh, which tells cos 2θ (along its axes) from sin 2θ (along its diagonals):
    measured −4.602e-4 and −4.579e-4 against the block's −4.584e-4, their mean 0.14 % off."""
    ax = _oblate(tmp_path, modes=0)
    blocks = axisymmetric(ax, range(6), 6)
    assert blocks.unstable == {0: 0, 1: 0, 2: 1, 3: 0, 4: 0, 5: 0}
    union = sorted(x for m, vals in blocks.modes.items()
                   for x in (list(vals) if m == 0 else 2 * list(vals)))[:6]
    three = cartesian(_revolve(ax, vesicle_scene(v=0.85, branch="oblate", eps=0.04, R0=0.25)),
                      6, tol=1e-7)
    assert three.unstable_3d == 2 and np.all(np.asarray(three.eigenvalues[:2]) < 0)
    ratio = np.asarray(three.eigenvalues) / np.asarray(union) - 1
    assert np.max(np.abs(ratio[2:])) < 1e-3 and np.max(np.abs(ratio[:2])) < 1e-2
    assert abs(np.mean(ratio[:2])) < 3e-3


def test_the_zero_modes_are_taken_out(prolate, monkeypatch):
    """Check (c): without the rigid motions taken out, block 0 has one and block 1 two
    eigenvalues far below the lowest shape mode (the translations and the tilt, pinned by
    the mesh); taken out, no eigenvalue is within 1e-3 of the lowest shape mode of zero."""
    _, be = prolate
    sys_ = NewtonSystem(be)
    lin = linearize(sys_, be.phi)
    with_ = {m: M.lowest(sys_, lin, m, k=3).eigenvalues for m in (0, 1)}
    monkeypatch.setattr(M, "zero_modes", lambda space, phi, m: [])
    without = {m: M.lowest(sys_, lin, m, k=3).eigenvalues for m in (0, 1)}
    for m, count in ((0, 1), (1, 2)):
        shape = with_[m][0]
        assert np.all(np.abs(with_[m]) > 1e-3 * shape)
        assert np.sum(np.abs(without[m]) < 1e-2 * shape) == count
        assert without[m][count] == pytest.approx(shape, rel=1e-2)


def test_the_inertia_counts_what_the_eigensolve_finds(tmp_path):
    """The count below the threshold from the LU's inertia equals the number of computed
    eigenvalues below it, on an oblate at ε = 0.04 whose m = 2 block has one (v = 0.85)."""
    be = _oblate(tmp_path, modes=3)
    from fem_ade.campaigns.stability import threshold

    result = axisymmetric(be, range(4), 3)
    for m in range(4):
        assert result.unstable[m] == int(np.sum(result.modes[m] < threshold(be.params)))
    assert result.unstable[2] == 1 and result.unstable_3d == 2


def test_a_shift_near_the_lowest_changes_no_eigenvalue(tmp_path, monkeypatch):
    """A block's Lanczos started at NEAR · ``near`` gives the eigenvalues and counts of the
    shift at σ: with ``near`` the lowest itself (the shift used where the inertia counts none
    below it), twice it (an eigenvalue below the shift tried: back to σ) and half of it; the
    oblate's m = 2 block has a negative one (the shift tried is above it)."""
    be = _oblate(tmp_path, modes=3)
    plain = axisymmetric(be, range(4), 3)
    shifts = []
    lanczos = M._lanczos
    monkeypatch.setattr(M, "_lanczos", lambda block, B, shift, k, which, *a, **kw: (
        which == "LA" and shifts.append((block.m, shift)),
        lanczos(block, B, shift, k, which, *a, **kw))[1])
    for scale in (1.0, 2.0, 0.5):
        near = {m: scale * plain.lowest(m) for m in plain.modes}
        shifts.clear()
        again = axisymmetric(be, range(4), 3, near=near)
        assert again.unstable == plain.unstable
        for m in range(4):
            np.testing.assert_allclose(again.modes[m], plain.modes[m], rtol=1e-8)
        if scale != 2.0:
            assert (3, M.NEAR * near[3]) in shifts  # the shift tried was kept
        assert all(s < plain.lowest(m) for m, s in shifts)  # the lowest above the shift


def test_branch_modes_and_bifurcations(tmp_path):
    """fem_ade.branch --modes: each point's lowest eigenvalue per mode and its 3D count in
    branch.csv, and the m = 2 bifurcation of the oblate at ε = 0.04 between v = 0.814 and
    0.778 in bifurcations.json (located where the eigenvalue crosses zero)."""
    import csv

    out = tmp_path / "oblate"
    assert branch_main(["vesicle", "--branch", "oblate", "--eps", "0.04", "--R0", "0.25",
                        "--param", "v", "--from", "0.85", "--to", "0.78", "--step", "0.02",
                        "--quiet", "--modes", "3", "--out", str(out)]) == 0
    with open(out / "branch.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert {"lowest_m0", "lowest_m3", "unstable_3d"} <= set(rows[0])
    assert rows[0]["unstable_3d"] == "2" and rows[-1]["unstable_3d"] == "0"
    found = json.loads((out / "bifurcations.json").read_text())["bifurcations"]
    assert [b["m"] for b in found] == [2] and found[0]["located"]
    assert 0.78 < found[0]["v"] < 0.814


def test_a_bifurcation_is_located_at_the_eigenvalues_zero():
    """The count is taken below a threshold, so it can change one interval before the
    eigenvalue's zero (the oblate's m = 2 at ε = 0.005: −5.0e-9 counted unstable below
    −4e-9, −5.7e-10 stable, the zero in the next interval); the bifurcation is placed at the
    zero there, not at the midpoint of the interval where the count changed. Where no
    neighbouring interval holds a zero, the midpoint, ``located`` False."""
    from fem_ade.campaigns.branch_analysis import bifurcations

    def row(v, lowest, count):
        return {"v": v, "s": 1.0 - v, "fold": "", "lowest_m2": lowest,
                "unstable_modes": {"0": 0, "2": count}}

    rows = [row(0.7554, -9.2e-9, 1), row(0.7527, -5.0e-9, 1), row(0.7500, -5.7e-10, 0),
            row(0.7472, 4.0e-9, 0)]
    (found,) = bifurcations(rows, "v")
    assert found["located"] and found["between"] == [2, 3] and found["unstable"] == [1, 0]
    assert found["v"] == pytest.approx(0.7500 - 5.7e-10 / 4.57e-9 * 0.0028)
    rows[1]["lowest_m2"] = -4.5e-9  # the zero in the interval itself
    rows[2]["lowest_m2"] = 1.0e-9
    (found,) = bifurcations(rows, "v")
    assert found["between"] == [1, 2] and found["v"] == pytest.approx(0.7527 - 4.5 / 5.5 * 0.0027)
    rows[2]["lowest_m2"] = rows[3]["lowest_m2"] = -1e-9  # no zero near: the midpoint
    (found,) = bifurcations(rows, "v")
    assert not found["located"] and found["v"] == pytest.approx(0.75135)
    rows[2]["unstable_modes"]["2"] = rows[3]["unstable_modes"]["2"] = 2  # 1 to 2: the midpoint
    (found,) = bifurcations(rows, "v")
    assert not found["located"] and found["unstable"] == [1, 2]


def test_the_stability_command(prolate, tmp_path, capsys):
    """python -m fem_ade.stability on a branch point: the modes, their counts, the 3D
    count, as JSON; a folder that is neither a run nor a point, and a run that is not
    steady, are one line and exit 2."""
    out, _ = prolate
    assert stability_main([str(out / "points" / "0000"), "--modes", "2", "--k", "2",
                           "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert set(data["modes"]) == {"0", "1", "2"} and all(len(v) == 2
                                                         for v in data["modes"].values())
    assert data["unstable_3d"] == 0 and math.isfinite(data["modes"]["1"][0])
    assert stability_main([str(tmp_path)]) == 2
    assert "neither a run folder" in capsys.readouterr().err
    from fem_ade.engine.runs import simulate

    run = tmp_path / "run"
    simulate(vesicle_scene(v=0.85, branch="prolate", eps=0.04, R0=0.2), steps=3,
             out=run, render=False, sharp=False,
             backend_options={"geometry": "axisymmetric"})
    assert stability_main([str(run)]) == 2
    err = capsys.readouterr().err
    assert "not a steady state" in err and len(err.strip().splitlines()) == 1
