"""Newton's method for steady states (fem_ade.backends.fem.newton): the exact Hessian-vector
product of
every term, quadratic convergence, and the same steady state as the gradient flow's."""

import numpy as np
import pytest

from fem_ade.backends.base import make_backend
from fem_ade.backends.fem.newton import solve_steady
from fem_ade.engine.loop import run_loop
from fem_ade.engine.runs import recipe
from fem_ade.scenes.catalogue import get_scene, vesicle_scene

CASES = {
    "axisymmetric, ADE, exact": (lambda: vesicle_scene(v=0.85, branch="prolate", eps=0.04,
                                                       kbar=1.4, da0=1.3),
                                 {"geometry": "axisymmetric", "n": 96}, "exact"),
    "3D p = 2, paper scene, penalties": (lambda: get_scene("torus"), {"order": 2, "n": 16},
                                         "penalty"),
    "3D p = 1, spontaneous curvature": (lambda: get_scene("discocyte").with_(
        C=1.5, effects=frozenset({"bending", "ade", "volume", "area",
                                  "spontaneous_curvature"})), {"n": 12}, "exact"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_hessian_vector_product_is_the_gradients_derivative(case):
    make_scene, options, constraints = CASES[case]
    be = make_backend("fem", make_scene(), scheme="stabilized", constraints=constraints,
                      dt=1e-6, **options)
    st, phi = be.stepper, be.phi
    v = np.random.default_rng(1).standard_normal(phi.size) * 0.1

    def grad(p):
        mu = be.space.laplacian(p)
        return st.gradient(p, mu, be.w * mu)

    h = 1e-6
    fd = (grad(phi + h * v) - grad(phi - h * v)) / (2 * h)
    Hv = st.hessian_vector(phi, be.mu, be.Kphi, v)
    assert np.linalg.norm(Hv - fd) < 1e-7 * np.linalg.norm(fd)

    def constraints_gradient(p):
        mu = be.space.laplacian(p)
        return 0.7 * st.volume_gradient(p) - 0.3 * st.area_gradient(p, be.w * mu)

    fd = (constraints_gradient(phi + h * v) - constraints_gradient(phi - h * v)) / (2 * h)
    Hv = st.constraint_hessian_vector(phi, be.Kphi, v, 0.7, -0.3)
    assert np.linalg.norm(Hv - fd) < 1e-7 * np.linalg.norm(fd)


def test_newton_converges_quadratically_to_the_flows_steady_state():
    """From the flow's early stop (1e-4 per step) Newton reaches the steady state the flow
    reaches at 1e-12, E equal to 1e-8; its decrements fall quadratically at the end."""
    scene = vesicle_scene(v=0.8, branch="oblate", eps=0.04)
    kw = recipe("steady", scene)

    def flow(tol):
        be = make_backend("fem", scene, n=80, geometry="axisymmetric", scheme="stabilized",
                          constraints="exact")
        res = run_loop(be, dt=kw["dt"], until_steady=tol, max_steps=20000, every=10,
                       accelerate=True)
        return be, res

    be, early = flow(1e-4)
    _, steady = flow(1e-12)
    result = solve_steady(be)
    assert result.converged and result.iterations <= 8, result
    assert result.E == pytest.approx(steady.final["E"], rel=1e-8)
    assert early.final["E"] - result.E > 1e-7 * result.E  # the early stop was not there
    d = result.decrement
    assert len(d) >= 3 and d[-1] < 1e-12, d  # measured: 2.1e-6, 5.7e-11, 1.1e-19
    assert np.log(d[-1]) / np.log(d[-2]) > 1.7, d  # the order of convergence: ≈ 2
    assert be.diagnostics()["E"] == pytest.approx(result.E, rel=1e-13)


def test_bordered_solve_meets_its_tolerance_with_the_right_side_in_the_constraint_rows():
    """A branch's tangent: the bordered system's right side only in the constraint rows
    (∂F/∂v). The M-norm of the true residual is below 1e-8 of the right side's — the test
    scipy's minres does not make (its backward error stopped it after 2 iterations here)."""
    from fem_ade.backends.fem.newton import NewtonSystem, kkt_solve, linearize

    scene = vesicle_scene(v=0.9, branch="prolate", eps=0.02)
    be = make_backend("fem", scene, n=128, geometry="axisymmetric", scheme="stabilized",
                      constraints="exact")
    run_loop(be, dt=recipe("steady", scene)["dt"], steps=50, every=10)
    sys_ = NewtonSystem(be, "minres")  # (the direct solve of 2D spaces: test_modes.py)
    lin = linearize(sys_, be.phi)
    N, m = be.phi.size, len(lin.C)
    rhs = np.zeros(N + m)
    rhs[N] = -0.07  # −∂(V − α)/∂v
    x, its = kkt_solve(sys_, lin, rhs, inner_tol=1e-8)
    v, nu = x[:N], x[N:]
    st = sys_.step
    top = (st.hessian_vector(lin.phi, lin.mu, lin.Kphi, v)
           + st.constraint_hessian_vector(lin.phi, lin.Kphi, v, lin.lam[0], lin.lam[1])
           + sum(nj * cj for nj, cj in zip(nu, lin.C, strict=True)))
    r = rhs - np.concatenate([top, [float(np.dot(c, v)) for c in lin.C]])
    S = np.array([[np.dot(ci, sys_.P_inverse(cj)) for cj in lin.C] for ci in lin.C])

    def m_norm(y):
        return np.sqrt(np.dot(y[:N], sys_.P_inverse(y[:N])) + y[N:] @ np.linalg.solve(S, y[N:]))

    assert its > 2
    assert m_norm(r) < 2e-8 * m_norm(rhs), (its, m_norm(r) / m_norm(rhs))


def test_a_step_that_climbs_is_taken_downhill(monkeypatch):
    """Where the Newton step climbs (∇Lᵀδφ > 0: negative curvature along it, met at a saddle
    a flow crept to — the stomatocyte at v = 0.6, eps = 0.005) solve_steady takes it the other
    way instead of giving up. Here the first step is made to climb by reversing it."""
    import fem_ade.backends.fem.newton as newton

    scene = vesicle_scene(v=0.8, branch="oblate", eps=0.04)
    be = make_backend("fem", scene, n=80, geometry="axisymmetric", scheme="stabilized",
                      constraints="exact")
    run_loop(be, dt=recipe("steady", scene)["dt"], until_steady=1e-4, max_steps=20000,
             every=10, accelerate=True)
    start = be.phi.copy()
    reference = solve_steady(be)
    be._set(start, None)
    real, calls = newton.kkt_solve, []

    def climbing(sys_, lin, rhs, inner_tol=1e-8):
        x, its = real(sys_, lin, rhs, inner_tol)
        calls.append(its)
        return (-x if len(calls) == 1 else x), its

    monkeypatch.setattr(newton, "kkt_solve", climbing)
    result = solve_steady(be)
    assert len(calls) > 1 and result.converged, result.message
    assert result.E == pytest.approx(reference.E, rel=1e-10)


def _tilted_prolate():
    """A 3D prolate with ADE whose axis is along none of the mesh's (0.45, 0.3, 0.84) and
    whose centre is off the nodes, relaxed by the flow to a change of 1e-6 per step (32³
    nodes of order 4, ε = 0.04)."""
    import dataclasses

    scene = vesicle_scene(v=0.85, branch="prolate", eps=0.04, R0=0.18, kbar=1.4, da0=1.2)
    axis = np.array([0.45, 0.3, 0.84]) / np.linalg.norm([0.45, 0.3, 0.84])
    scene = scene.with_(ic=dataclasses.replace(scene.ic, axis=tuple(axis),
                                               centre=(0.5123, 0.4871, 0.5057)))
    be = make_backend("fem", scene, n=32, order=4, scheme="stabilized", constraints="exact",
                      dt=100 * scene.dt)
    run_loop(be, dt=100 * scene.dt, until_steady=1e-6, max_steps=3000, every=10,
             accelerate=True)
    return be


def _centroid(be):
    inside = be.space.weights * (be.phi + 1.0)
    return np.array([np.sum(inside * x) / np.sum(inside) for x in be.space.doflocs])


@pytest.mark.parametrize("pinned", [True, False])
def test_3d_pins_keep_the_rigid_motions_where_they_were(pinned, monkeypatch):
    """In 3D Newton's corrections are held P-orthogonal to the starting state's rigid
    motions (NewtonSystem._translations; uᵀPu = 1 each, so a pin's value moves by s when
    the shape moves by s·u): from a tilted, off-centre prolate the steady state keeps each
    pin's value to 1.2e-7 and its centroid to 6e-6 of L (measured), where without the pins
    (the control) Newton slides along the mesh-pinned motions — the pins' values by up to
    0.86, the centroid by 8.7e-4 — to another orientation of lower E, in one more
    iteration."""
    from fem_ade.backends.fem.newton import NewtonSystem

    be = _tilted_prolate()
    pins = NewtonSystem(be).translations
    assert len(pins) == 6  # no axis of symmetry on this mesh
    if not pinned:
        monkeypatch.setattr(NewtonSystem, "_translations", lambda self: [])
    c0, t0 = _centroid(be), np.array([p @ be.phi for p in pins])
    result = solve_steady(be, max_iterations=40)
    assert result.converged
    moved = np.abs(_centroid(be) - c0).max()
    slid = np.abs(np.array([p @ be.phi for p in pins]) - t0).max()
    if pinned:
        assert moved < 5e-5 and slid < 1e-5
    else:
        assert moved > 2e-4 and slid > 0.1


def test_a_3d_continuation_step_keeps_the_pins_and_lands_on_a_steady_state():
    """One pseudo-arclength step in v of the tilted prolate in 3D (the axisymmetric
    branches' Continuation on the 3D tensor FEM, its pins among the constraints): v moves
    along the tangent, the new point is steady (Newton from it: at most one iteration, E
    moved by 7.6e-10, measured) and the pins' values stay (the tangent and the corrections
    are P-orthogonal to the rigid motions)."""
    from fem_ade.campaigns.continuation import Continuation

    be = _tilted_prolate()
    assert solve_steady(be).converged
    cont = Continuation(be, "v")
    pins = cont.sys.translations
    phi0, v0 = be.phi.copy(), cont.p
    t0 = np.array([p @ phi0 for p in pins])
    tangent = cont.tangent(phi0)
    (phi1, v1, _), ds = cont.advance([(phi0, v0)], tangent, 0.01, 1e-4)
    assert ds == 0.01 and v1 - v0 == pytest.approx(ds * tangent[1], rel=0.05)
    assert np.abs(np.array([p @ phi1 for p in pins]) - t0).max() < 1e-7
    E1 = be.stepper.diagnostics(phi1, *cont.sys.fields(phi1))["E"]
    be._set(phi1, None)
    check = solve_steady(be)
    assert check.converged and check.iterations <= 1
    assert check.E == pytest.approx(E1, rel=1e-8)


@pytest.fixture(scope="module")
def tilted():
    be = _tilted_prolate()
    return be, be.phi.copy()


def test_the_coarse_space_changes_the_iterations_not_the_iterates(tilted):
    """MINRES preconditioned by P and the coarse space of shape modes
    (fem_ade.backends.fem.coarse) against P alone, from the same tilted prolate, every
    inner solve to 1e-12: the same Newton iterates — the same iterations, decrements equal
    to 1e-6 where they are above round-off, the final φ to 1e-10 and E to 1e-13 — in at
    most half the MINRES iterations (measured: 3 solves of 151–155 iterations against 42
    each, one coarse space made and kept for all three; φ equal to 2e-15, the decrements to
    2e-10)."""
    be, phi0 = tilted
    runs = {}
    for linear in ("minres", "coarse"):
        be._set(phi0.copy(), None)
        runs[linear] = (solve_steady(be, linear=linear, inner_tol=1e-12), be.phi.copy())
    (plain, phi_p), (coarse, phi_c) = runs["minres"], runs["coarse"]
    assert plain.converged and coarse.converged
    assert coarse.iterations == plain.iterations
    big = [i for i, d in enumerate(plain.decrement) if d > 1e-15]
    assert len(big) >= 2
    assert np.allclose([coarse.decrement[i] for i in big], [plain.decrement[i] for i in big],
                       rtol=1e-6, atol=0)
    assert np.abs(phi_c - phi_p).max() < 1e-10
    assert coarse.E == pytest.approx(plain.E, rel=1e-13)
    assert sum(coarse.krylov) <= 0.5 * sum(plain.krylov), (coarse.krylov, plain.krylov)


def test_a_coarse_space_from_another_state_is_still_a_preconditioner(tilted):
    """M⁻¹ = P⁻¹ + Vᵀ diag(1/|θ| − 1) V is symmetric positive definite whatever V: a coarse
    space made at another state (here the flow's state moved by 0.02 along a smooth field)
    leaves the bordered solve's answer as P alone gives it (to the solves' 1e-10) and only
    its iterations change (measured: 137 with P alone, 114 with that space, 36 with the
    state's own); a solve that needs more than REBUILD times the first one's
    iterations marks the space stale, and the next solve makes a new one."""
    from fem_ade.backends.fem import coarse as coarse_mod
    from fem_ade.backends.fem.newton import NewtonSystem, kkt_solve, linearize

    be, phi0 = tilted
    X = be.space.doflocs
    moved = phi0 + 0.02 * np.sin(2 * np.pi * X[0]) * np.cos(2 * np.pi * X[2])
    sys_ = NewtonSystem(be, "coarse")
    lin = linearize(sys_, phi0)
    rhs = -np.concatenate([lin.grad, lin.violation])
    plain = NewtonSystem(be, "minres")
    x0, its0 = kkt_solve(plain, linearize(plain, phi0), rhs, inner_tol=1e-10)
    other = coarse_mod.CoarseSpace(sys_, linearize(sys_, moved))
    sys_.coarse = other
    x, its = kkt_solve(sys_, lin, rhs, inner_tol=1e-10)
    assert sys_.coarse is other and other.solves == 1
    assert np.abs(x - x0).max() <= 1e-8 * np.abs(x0).max()
    assert its < its0
    rng = np.random.default_rng(1)
    u, v = rng.standard_normal((2, phi0.size))

    def M(y):
        return sys_.P_inverse(y) + other.apply(y)

    assert M(u) @ v == pytest.approx(u @ M(v), rel=1e-10)
    assert np.all(other.d > 0) and u @ M(u) > u @ sys_.P_inverse(u) > 0
    other.record(int(coarse_mod.REBUILD * other.first) + 1)
    assert other.stale
    kkt_solve(sys_, lin, rhs, inner_tol=1e-10)
    assert sys_.coarse is not other and sys_.coarse.solves == 1


def test_the_coarse_spaces_hessian_of_a_stack_is_the_hessian_vector_product(tilted):
    """coarse.hessian (H on a stack, from the Hessian's coefficients: what the smoothing and
    the Ritz values use) equals hessian_vector + constraint_hessian_vector column by column,
    at the tilted prolate's multipliers (to 1e-12 of the largest entry)."""
    from fem_ade.backends.fem.coarse import hessian
    from fem_ade.backends.fem.newton import NewtonSystem, linearize

    be, phi0 = tilted
    sys_ = NewtonSystem(be)
    lin = linearize(sys_, phi0)
    co = sys_.step.hessian_coefficients(lin.phi, lin.mu, lin.Kphi, lin.lam[0], lin.lam[1])
    z = np.random.default_rng(2).standard_normal((3, phi0.size))
    got = hessian(be.space, sys_.bulk()[2], co, z)
    st = sys_.step
    for zi, gi in zip(z, got, strict=True):
        want = (st.hessian_vector(lin.phi, lin.mu, lin.Kphi, zi)
                + st.constraint_hessian_vector(lin.phi, lin.Kphi, zi, lin.lam[0], lin.lam[1]))
        assert np.abs(gi - want).max() <= 1e-12 * np.abs(want).max()
    assert lin.lam[0] != 0.0 and lin.lam[1] != 0.0  # the constraints' part is in it


def test_auto_adds_the_coarse_space_from_its_size(tilted, monkeypatch):
    """linear="auto" adds the coarse space from COARSE_FROM nodes (where it pays), not at
    32³; "coarse" and "minres" choose whatever the size; the axisymmetric geometry solves
    directly."""
    import fem_ade.backends.fem.newton as newton

    be, _ = tilted
    assert be.phi.size < newton.COARSE_FROM
    assert not newton.NewtonSystem(be).uses_coarse
    assert newton.NewtonSystem(be, "coarse").uses_coarse
    monkeypatch.setattr(newton, "COARSE_FROM", be.phi.size)
    assert newton.NewtonSystem(be).uses_coarse
    assert not newton.NewtonSystem(be, "minres").uses_coarse
    axi = make_backend("fem", vesicle_scene(v=0.9, branch="prolate", eps=0.04), n=48,
                       geometry="axisymmetric", constraints="exact")
    sys_ = newton.NewtonSystem(axi)
    assert sys_.direct and not sys_.uses_coarse
