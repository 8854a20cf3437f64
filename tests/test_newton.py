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
