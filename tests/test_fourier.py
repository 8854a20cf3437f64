"""The Fourier–(r, z) geometry (fem_ade.backends.fem.fourier; docs/model.md §13): an
axisymmetric field has the (r, z) energy, one cosine has the azimuthal block's Hessian, the
modes go and come back, Newton with an amplitude pin finds a steady state with that amplitude,
and a kick in a stable mode goes back to the axisymmetric state."""

import numpy as np
import pytest

from fem_ade.backends.fem.fourier import FourierNewtonSystem, FourierSpace, FourierState
from fem_ade.backends.fem.modes import lowest_mode, mode_block
from fem_ade.backends.fem.newton import NewtonSystem, linearize, solve_steady
from fem_ade.campaigns.branch import main as branch_main
from fem_ade.campaigns.stability import load_state
from fem_ade.model.params import ModelError


@pytest.fixture(scope="module")
def oblate_line(tmp_path_factory):
    """The oblate at ε = 0.04, R₀ = 0.25, v = 0.85 and 0.84: a branch folder."""
    out = tmp_path_factory.mktemp("fourier") / "oblate"
    assert branch_main(["vesicle", "--branch", "oblate", "--eps", "0.04", "--R0", "0.25",
                        "--param", "v", "--from", "0.85", "--to", "0.84", "--step", "0.01",
                        "--quiet", "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def oblate(oblate_line):
    """The oblate at ε = 0.04, v = 0.85, R₀ = 0.25: one negative eigenvalue in block m = 2,
    none in m = 4 (tests/test_modes.py)."""
    be, _ = load_state(oblate_line / "points" / "0000")
    return be


def _fields(space, phi):
    mu = space.laplacian(phi)
    return mu, space.weights * mu


def test_an_axisymmetric_field_has_the_rz_energy(oblate):
    """φ(r, z) on the Fourier space: E, V, A, ΔA of the (r, z) geometry (to round-off), and
    the gradient's θ-sum is the (r, z) gradient's (to 1e-9 of its largest entry; measured
    2.4e-10: the DCT's round-off on a θ-constant field, times m² and 1/r² next to the axis)."""
    st = FourierState.of(oblate, 2, 4)
    three = st.stepper.diagnostics(st.phi, *_fields(st.space, st.phi))
    two = oblate.stepper.diagnostics(oblate.phi, *_fields(oblate.space, oblate.phi))
    for k in ("E", "V", "A", "dA"):
        assert three[k] == pytest.approx(two[k], rel=1e-12), k
    g3 = st.stepper.gradient(st.phi, *_fields(st.space, st.phi))
    g2 = oblate.stepper.gradient(oblate.phi, *_fields(oblate.space, oblate.phi))
    s = st.space
    off = g3[s.na:].reshape(s.n_theta, s.no).sum(axis=0)  # the θ-sum of the nodal weights
    assert np.allclose(g3[:s.na], g2[s.axis], rtol=0, atol=1e-9 * np.abs(g2).max())
    assert np.allclose(off, g2[s.off], rtol=0, atol=1e-9 * np.abs(g2).max())


@pytest.mark.parametrize("m0, j", [(2, 1), (2, 2), (3, 1)])
def test_one_cosine_has_the_blocks_hessian(oblate, m0, j):
    """v = ψ(r, z) cos(j m₀ θ): vᵀ H_L v on the Fourier space is ½ ψᵀ H_m ψ of the (r, z)
    block m = j m₀ (the θ-mean of cos² is ½), for a random ψ off the axis."""
    sys2 = NewtonSystem(oblate)
    lin2 = linearize(sys2, oblate.phi)
    m = j * m0
    block = mode_block(sys2, lin2, m)
    psi = np.zeros(oblate.space.n_dofs)
    psi[block.free] = np.random.default_rng(m).standard_normal(block.size)
    st = FourierState.of(oblate, m0, 4)
    v = st.space.from_modes({j: psi})
    sys3 = FourierNewtonSystem(st)
    lin3 = linearize(sys3, st.phi)
    step = st.stepper
    Hv = step.hessian_vector(lin3.phi, lin3.mu, lin3.Kphi, v) + step.constraint_hessian_vector(
        lin3.phi, lin3.Kphi, v, lin3.lam[0], lin3.lam[1])
    assert v @ Hv == pytest.approx(0.5 * psi[block.free] @ block.H(psi[block.free]), rel=1e-10)


def test_the_modes_go_and_come_back(oblate):
    """from_modes then modes is the identity on cosines below n_θ (ψ off the axis for j ≥ 1),
    and a cosine at or above n_θ is refused."""
    space = FourierSpace(oblate.space, 2, 5)
    rng = np.random.default_rng(0)
    r = oblate.space.doflocs[0]
    given = {j: rng.standard_normal(r.size) * (r > 0 if j else 1) for j in range(5)}
    back = space.modes(space.from_modes(given))
    assert max(np.abs(back[j] - given[j]).max() for j in range(5)) < 1e-13
    with pytest.raises(ModelError, match="mode j = 5"):
        space.from_modes({5: given[1]})


def test_a_pinned_cosine_is_a_steady_state_at_its_amplitude(oblate):
    """The oblate (unstable in m = 2) kicked along its m = 2 eigenvector, the kick's amplitude
    pinned: Newton converges, keeps the amplitude, and the result is lower than the oblate."""
    sys2 = NewtonSystem(oblate)
    _, psi = lowest_mode(sys2, linearize(sys2, oblate.phi), 2)
    st = FourierState.of(oblate, 2, 4, {1: 0.2 * psi})
    P = st.space.from_modes({1: psi})
    pin = st.space.weights * P
    before = float(pin @ st.phi)
    sys3 = FourierNewtonSystem(st, pins=[pin])
    res = solve_steady(st, system=sys3)
    assert res.converged
    assert float(pin @ st.phi) == pytest.approx(before, rel=1e-10)
    E0 = oblate.stepper.diagnostics(oblate.phi, *_fields(oblate.space, oblate.phi))["E"]
    assert res.E < E0
    assert max(sys3.gmres_iterations) < 100


def test_a_kick_in_a_stable_mode_goes_back(oblate):
    """The oblate kicked by 0.1 ψ cos 4θ (block m = 4 is stable), no pin: Newton goes back to
    the axisymmetric state — the cosines below 1e-6 (measured 1.05e-7: Newton stops on the
    energy's decrement, 1e-12 of E), E the (r, z) one."""
    st = FourierState.of(oblate, 2, 4)
    r = oblate.space.doflocs[0]
    bump = np.exp(-((r - r.max() / 2) ** 2) / 0.01) * (r > 0)
    st.phi = st.space.from_modes({0: oblate.phi, 2: 0.1 * bump})
    res = solve_steady(st, system=FourierNewtonSystem(st))
    assert res.converged
    A = st.space.modes(st.phi)
    assert np.abs(A[1:]).max() < 1e-6
    E0 = oblate.stepper.diagnostics(oblate.phi, *_fields(oblate.space, oblate.phi))["E"]
    assert res.E == pytest.approx(E0, rel=1e-10)


def test_the_spectrum_of_an_axisymmetric_field_is_the_blocks(oblate):
    """fourier.lowest on the oblate as a field of the m₀ = 2 space: its five eigenvalues
    nearest −1e-3 are the union of the (r, z) blocks m = 0, 2, 4 (measured: −4.5837e-4 and
    4.6567e-3 of m = 2, 6.4736e-3 of m = 0, 8.4680e-3 of m = 4, 2.2239e-2 of m = 2), to
    1e-6 relative: the stability this space gives a non-axisymmetric state is the blocks'
    where it is axisymmetric."""
    from fem_ade.backends.fem.fourier import lowest
    from fem_ade.backends.fem.modes import lowest as block_lowest

    sys2 = NewtonSystem(oblate)
    lin2 = linearize(sys2, oblate.phi)
    union = sorted(x for m in (0, 2, 4, 6) for x in block_lowest(sys2, lin2, m, k=3).eigenvalues)
    found = lowest(FourierState.of(oblate, 2, 4), k=5, sigma=-1e-3)
    assert found[0] < 0
    assert np.allclose(found, union[:5], rtol=1e-6, atol=0)


def test_the_parameter_as_an_unknown_lands_where_the_secant_does(oblate_line):
    """At amplitude 0.1 of the m = 2 branch in v, from the oblate at v = 0.84 (the branch
    is born at 0.7993): Newton with v an unknown of the bordered system (its pin's
    multiplier zero to round-off) and the secant on that multiplier (to its P_TOL in v) find
    the same v and e, and each state is steady at the v it reports. (From v = 0.85 the
    bordered Newton, which has no line search, strays and its GMRES stalls: the secant
    takes over there.)"""
    from fem_ade.campaigns.fourier_branch import P_TOL, AmplitudeBranch

    be, _ = load_state(oblate_line / "points" / "0001")
    sys2 = NewtonSystem(be)
    _, psi = lowest_mode(sys2, linearize(sys2, be.phi), 2)
    rows = {}
    for method in ("bordered", "secant"):
        br = AmplitudeBranch(be, psi, m0=2, param="v", n_theta=4, method=method)
        rows[method] = row = br.point(0.1)
        assert row["method"] == method and row["n_theta"] == 4
        assert br.amplitude(br.state.phi) == pytest.approx(0.1, rel=1e-10)
        lin = linearize(br.system, br.state.phi)
        assert np.abs(lin.grad).max() < 1e-7 * np.abs(br.system.gradient(br.state.phi)).max()
    b, s = rows["bordered"], rows["secant"]
    assert abs(b["lam_pin"]) < 1e-7 < abs(s["lam_pin"])  # measured: 7.5e-12, 5.7e-6 (10 solves)
    assert b["solves"] == 2 < s["solves"]
    assert b["v"] == pytest.approx(s["v"], abs=10 * P_TOL)
    assert b["e"] == pytest.approx(s["e"], abs=1e-6)  # de/dv · the secant's error in v


def test_the_branch_refuses_an_unknown_method(oblate):
    from fem_ade.campaigns.fourier_branch import AmplitudeBranch

    with pytest.raises(ModelError, match="method is one of"):
        AmplitudeBranch(oblate, np.zeros(oblate.space.n_dofs), m0=2, method="arclength")


def test_the_predictors_weights_are_exact_on_a_parabola():
    """The branch's predictor (the parabola through its last three points) reproduces a
    quadratic, and its weights sum to one."""
    from fem_ade.campaigns.fourier_branch import _lagrange

    nodes = [0.2, 0.4, 0.7]
    w = _lagrange(nodes, 1.0)
    assert w.sum() == pytest.approx(1.0, abs=1e-14)
    assert float(w @ [3 - x + 2 * x * x for x in nodes]) == pytest.approx(4.0, abs=1e-13)
    assert _lagrange([0.4, 0.7], 1.0) == pytest.approx([-1.0, 2.0])


def test_the_predictor_moves_an_interface_instead_of_blending_two():
    """_extrapolate gives back each field at its own weight (to round-off; |φ| > 1 in the
    bulk included), and the line through two tanh profiles at x₀ = 0, 0.1 puts the third at
    0.2 to round-off, where the blend in φ is off by O(1) of its shift over ε."""
    from fem_ade.campaigns.fourier_branch import _extrapolate, _lagrange

    x = np.linspace(-1, 1, 401)
    eps = 0.05
    prof = [np.tanh((x - s) / eps) for s in (0.0, 0.1, 0.2)]
    prof[0][:3] = -1.0 - 1e-4  # an overshoot in the bulk
    for i in range(2):
        assert np.allclose(_extrapolate(prof[:2], np.eye(2)[i]), prof[i], rtol=0, atol=1e-12)
    w = _lagrange([0.0, 0.1], 0.2)
    assert np.abs(_extrapolate(prof[:2], w) - prof[2])[3:].max() < 1e-6
    assert np.abs(w[0] * prof[0] + w[1] * prof[1] - prof[2]).max() > 0.5


def test_the_coarse_functions_of_an_axisymmetric_field(oblate):
    """fourier_shape_functions on the oblate as a field of the m₀ = 2 space, degree 2: 6
    polynomials × 4 cosines × 2 axes; the constant's j = 0, ∂_z function is the translation
    along z (to round-off), and each j ≥ 1 function has cosine j only (the field is
    θ-constant, so p ∂ₐφ is too)."""
    from fem_ade.backends.fem.coarse import fourier_shape_functions
    from fem_ade.backends.fem.fourier import translation

    st = FourierState.of(oblate, 2, 4)
    Z = fourier_shape_functions(st.space, st.phi, st.params.eps, degree=2)
    assert Z.shape == (6 * 4 * 2, st.space.n_dofs)
    t = translation(st.space, st.phi)
    assert np.abs(Z[1] - t).max() < 1e-12 * np.abs(t).max()
    for row in range(8):  # the constant polynomial: cosine j = row // 2, axis row % 2
        A = st.space.modes(Z[row])
        others = np.delete(A, row // 2, axis=0)
        assert np.abs(others).max() < 1e-12 * np.abs(A).max(), row


def test_the_coarse_step_solves_the_same_system_in_fewer_iterations(oblate):
    """The oblate kicked by 1.0 ψ cos 2θ, its amplitude pinned, solved by Newton (with the
    coarse step); there, one bordered solve with the θ-mean blocks alone (degree 0) and with
    the coarse step of degree 4: the same solution (measured: to 2e-10 relative) in at most
    half the GMRES iterations (measured 49 and 18)."""
    from fem_ade.backends.fem.fourier import KKTSolver

    sys2 = NewtonSystem(oblate)
    _, psi = lowest_mode(sys2, linearize(sys2, oblate.phi), 2)
    st = FourierState.of(oblate, 2, 4, {1: psi})
    pin = st.space.weights * st.space.from_modes({1: psi})
    sys3 = FourierNewtonSystem(st, pins=[pin])
    assert solve_steady(st, system=sys3, quiet=True).converged
    lin = linearize(sys3, st.phi)
    b = st.space.weights * st.space.from_modes({0: oblate.phi, 2: psi})
    alone, coarse = KKTSolver(sys3, lin, degree=0), KKTSolver(sys3, lin, degree=4)
    x0, x4 = alone.solve(b)[0], coarse.solve(b)[0]
    assert np.linalg.norm(x4 - x0) < 1e-7 * np.linalg.norm(x0)
    assert coarse.iterations[0] <= alone.iterations[0] / 2


def test_a_coarse_step_is_kept_while_the_field_stays_near(oblate):
    """The Newton system keeps its coarse step for a linearization within REUSE of the φ it
    was made at (node by node) and makes a new one beyond it; the kept one, made at another
    state, still gives the solution of the θ-mean blocks alone (to 1e-7 relative)."""
    from fem_ade.backends.fem.fourier import REUSE, KKTSolver

    sys2 = NewtonSystem(oblate)
    _, psi = lowest_mode(sys2, linearize(sys2, oblate.phi), 2)
    st = FourierState.of(oblate, 2, 4, {1: 0.5 * psi})
    sys3 = FourierNewtonSystem(st, pins=[st.space.weights * st.space.from_modes({1: psi})])
    first = sys3.factor(linearize(sys3, st.phi)).coarse
    near = linearize(sys3, st.phi + 0.5 * REUSE * np.sin(7 * st.space.doflocs[1]))
    kept = sys3.factor(near)
    assert kept.coarse is first
    b = st.space.weights * st.space.from_modes({0: oblate.phi, 2: psi})
    x0 = KKTSolver(sys3, near, degree=0).solve(b)[0]
    assert np.linalg.norm(kept.solve(b)[0] - x0) < 1e-7 * np.linalg.norm(x0)
    far = linearize(sys3, st.phi + 2 * REUSE * np.sin(7 * st.space.doflocs[1]))
    assert sys3.factor(far).coarse is not first


def test_a_point_at_a_held_parameter_reads_on_from_the_amplitudes(oblate_line, tmp_path):
    """Three points of the m = 2 branch by amplitude, then one with v held at the third's
    value and the amplitude free (natural continuation): its start is the third point's
    field exactly (the predictor's weights are 0, 0, 1), which is steady without the pin,
    so Newton takes no step and the point is the third (its amplitude and e); the three are
    read back from the folder, not made again. Held values that are not monotone are
    refused."""
    from fem_ade.campaigns.fourier_branch import follow

    be, _ = load_state(oblate_line / "points" / "0001")
    sys2 = NewtonSystem(be)
    _, psi = lowest_mode(sys2, linearize(sys2, be.phi), 2)
    amplitudes = (0.1, 0.15, 0.2)
    pts = follow(be, psi, amplitudes, tmp_path, m0=2, param="v")
    assert [x["method"] for x in pts] == ["bordered"] * 3
    made = (tmp_path / "0002.json").stat().st_mtime_ns
    more = follow(be, psi, amplitudes, tmp_path, m0=2, param="v", held=(pts[2]["v"],))
    assert (tmp_path / "0002.json").stat().st_mtime_ns == made  # read back
    held = more[3]
    assert held["method"] == "held" and held["solves"] == 0 and held["lam_pin"] is None
    assert held["v"] == pts[2]["v"]
    assert held["amplitude"] == pytest.approx(0.2, rel=1e-9)
    assert held["e"] == pytest.approx(pts[2]["e"], abs=1e-12)
    with pytest.raises(ModelError, match="monotone"):
        follow(be, psi, amplitudes, tmp_path, m0=2, param="v", held=(0.8, 0.81, 0.8))
