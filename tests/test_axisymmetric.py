"""The axisymmetric geometry of the FEM (docs/model.md §11): the axis' quadrature, the sphere
values of model §8, h-convergence at rate 2p, agreement with the 3D backends, the domain's
size, which scenes it takes, and a run through the command line (folder, picture, resume)."""

import json
import math

import numpy as np
import pytest

from fem_ade.backends.base import make_backend
from fem_ade.backends.fem import gll
from fem_ade.backends.fem.axisym import AxisymmetricFEMBackend, graded_vertices
from fem_ade.backends.fem.tensor import BoundedAxis, TensorSpace
from fem_ade.engine.runs import recipe, resume, simulate
from fem_ade.model.params import ModelError
from fem_ade.scenes.catalogue import get_scene, sphere_values, vesicle_scene


# ---------------------------------------------------------------------------------------------
# the axis
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("p", [1, 2, 3, 5, 8])
def test_gauss_lobatto_jacobi_rule(p):
    """∫₋₁¹ f(1 + ξ) dξ exact for degree ≤ 2p − 1, not 2p; positive weights, ξ = ±1 nodes."""
    xi, rho = gll.jacobi_points_weights(p)
    assert xi[0] == -1.0 and xi[-1] == 1.0 and (rho > 0).all()

    def exact(k):  # ∫ ξᵏ (1 + ξ) dξ
        return sum((1 - (-1) ** (j + 1)) / (j + 1) for j in (k, k + 1))

    for k in range(2 * p):
        assert np.sum(rho * xi**k) == pytest.approx(exact(k), abs=1e-13)
    assert abs(np.sum(rho * xi ** (2 * p)) - exact(2 * p)) > 1e-6


def radial_laplacian_error(order: int, cells: int = 5) -> float:
    """max |μ + 4| over the nodes that are not on the outer edge, μ = W⁻¹K(r²) the discrete
    −(1/r)(r u′)′ of u = r² (exactly −4; the outer edge carries the natural BC's flux)."""
    ax = BoundedAxis(np.linspace(0.0, 1.0, cells + 1), order, radial=True)
    mu = ax.laplacian @ ax.nodes**2
    return float(np.max(np.abs(mu[:-1] + 4.0)))


def test_axis_quadrature_and_a_deliberate_error_in_it(monkeypatch):
    """With GLJ(0, 1) in the cell at the axis, −Δ(r²) = −4 at every node, the axis' included
    (p ≥ 2: the rule integrates the degree p + 1 of v·r exactly); the measure ∫ rᵏ 2πr dr too.
    An axis cell integrated with the GLL rule times r, its zero weight at r = 0 nudged to a
    positive one (the naive repair of the singular mass), fails both."""
    for p in (2, 4, 8):
        assert radial_laplacian_error(p) < 1e-9
        ax = BoundedAxis(np.linspace(0.0, 1.0, 4), p, radial=True)
        for k in range(2 * p - 1):
            assert np.sum(ax.weights * ax.nodes**k) == pytest.approx(2 * np.pi / (k + 2),
                                                                     rel=1e-12)

    def naive(p):  # the GLL rule of f·r on the axis cell, r = (1 + ξ)/2·h: weights w(1 + ξ)
        xi, w = gll.points_weights(p)
        rho = w * (1.0 + xi)
        rho = np.where(rho == 0.0, 1e-3 * rho.max(), rho)
        return xi, rho

    monkeypatch.setattr(gll, "jacobi_points_weights", naive)
    assert radial_laplacian_error(4) > 1e-3
    ax = BoundedAxis(np.linspace(0.0, 1.0, 4), 4, radial=True)
    assert abs(np.sum(ax.weights) - np.pi) > 1e-6  # the area of the unit disc


def test_radial_stiffness_symmetric_and_eigenbasis():
    """K_r symmetric with constants in its kernel (natural ends); the step's eigenbasis
    diagonalizes W and K of the (r, z) space."""
    from fem_ade.backends.fem.solve import Eigenbasis

    ar = BoundedAxis(graded_vertices(0.0, 1.0, 0.1, 0.4, 0.05), 4, radial=True)
    az = BoundedAxis(np.linspace(-0.5, 0.7, 9), 4)
    for ax in (ar, az):
        K = ax.stiffness.toarray()
        assert np.allclose(K, K.T, atol=1e-12 * abs(K).max())
        assert np.allclose(K @ np.ones(ax.size), 0.0, atol=1e-10 * abs(K).max())
    space = TensorSpace([ar, az], 4)
    basis = Eigenbasis(space)
    x = np.random.default_rng(1).standard_normal(space.n_dofs)
    # V diag(1/(1 + λ)) Vᵀ (W + K) x = x
    y = basis.apply((space.weights * x + (space.K @ x))[None], 1.0 / (1.0 + basis.lam))[0]
    assert np.allclose(y, x, atol=1e-9 * np.abs(x).max())


# ---------------------------------------------------------------------------------------------
# model §8 and convergence
# ---------------------------------------------------------------------------------------------
def sphere_scene(eps):
    sv = sphere_values(0.25, eps, 2 * eps / 3)
    return get_scene("sphere").with_(eps=eps, D=2 * eps / 3, alpha=sv["V"], beta=sv["A"],
                                     delta_A0=sv["dA"]), sv


def test_sphere_values_of_model_section_8():
    """The equilibrium sphere's V, A, ΔA and W to 1e-6 (ε = 0.02, R = 0.25: the formulas'
    exponentially small terms are 1e-8 there; at ε = 0.04 they are 1.7e-5 in V)."""
    scene, sv = sphere_scene(0.02)
    be = make_backend("fem", scene, n=200, order=8, geometry="axisymmetric", mesh="uniform",
                      dt=5e-7)
    d = be.diagnostics()
    for key in ("V", "A", "dA", "W"):
        assert d[key] == pytest.approx(sv[key], rel=1e-6), key


@pytest.mark.parametrize("order", [1, 2, 3])
def test_h_convergence_at_rate_2p(order):
    """The area of the resolved sphere field converges at rate 2p in h (uniform meshes)."""
    scene, sv = sphere_scene(0.02)
    ns = [order * int(m * 4 / order) for m in (64, 96, 128)]  # nodes per L: whole cells
    err = []
    for n in ns:
        be = make_backend("fem", scene, n=n, order=order, geometry="axisymmetric",
                          mesh="uniform", dt=5e-7)
        err.append(abs(be.diagnostics()["A"] / sv["A"] - 1))
    rates = [math.log(err[i] / err[i + 1]) / math.log(ns[i + 1] / ns[i]) for i in range(2)]
    assert all(abs(r - 2 * order) < 0.3 for r in rates), rates


# ---------------------------------------------------------------------------------------------
# against the 3D backends, the domain's size
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def prolate_ade():
    """The prolate at v = 0.9 with ADE (κ̄/κ = 1.4, Δa₀ = 1.1), ε = 0.04, localized volume."""
    return vesicle_scene(v=0.9, branch="prolate", eps=0.04, kbar=1.4, da0=1.1)


def steady(scene, **kw):
    """The steady state, without the comparison with the sharp membrane (none reads it)."""
    run = {**recipe("steady", scene), "until_steady": 1e-11}
    return simulate(scene, **run, render=False, sharp=False, **kw)


@pytest.fixture(scope="module")
def axi_steady(prolate_ade):
    return steady(prolate_ade, backend="fem", n=104,
                  backend_options={"geometry": "axisymmetric", "order": 8})


KEYS = ("E", "W", "G", "V", "A", "dA")


def test_agrees_with_the_3d_spectral_reference_at_steady_state(prolate_ade, axi_steady):
    """Same scene, same ε, both to a steady state: E, W, G, V, A, ΔA within 1e-4 (measured:
    E 3e-8, G 3e-6 at n = 64; the difference is discretization only)."""
    ref = steady(prolate_ade, backend="spectral", n=48)
    for key in KEYS:
        assert axi_steady.final[key] == pytest.approx(ref.final[key], rel=1e-4), key
    from fem_ade.analysis.sharp import BRANCH_OF_LABEL

    assert BRANCH_OF_LABEL[axi_steady.shape["label"]] == "prolate"
    # the φ = 0 surface: contoured exactly on the meridian, by marching cubes on the 3D grid
    assert axi_steady.shape["reduced_volume"] == pytest.approx(ref.shape["reduced_volume"],
                                                                abs=3e-3)


@pytest.mark.slow
def test_agrees_with_the_3d_fem_at_steady_state(prolate_ade, axi_steady):
    ref = steady(prolate_ade, backend="fem", n=64, backend_options={"order": 8})
    for key in KEYS:
        assert axi_steady.final[key] == pytest.approx(ref.final[key], rel=1e-4), key


def test_result_does_not_depend_on_the_domain(prolate_ade):
    """Once the natural edges are ≥ 9ε from the membrane, the steady state is that of an
    isolated vesicle: half as large again a domain changes E, W, V, A, ΔA by < 1e-7 (G, the
    square of ΔA − ΔA₀, 400 times as sensitive as ΔA, by < 1e-5). (The
    default domain, the box's cylinder, has the poles 4.5ε from its edges, like the 3D box
    from its images: both differ from the isolated vesicle's E by 3e-5, its G by 0.2 %.)"""
    runs = [steady(prolate_ade, backend="fem", n=104,
                   backend_options={"geometry": "axisymmetric", "order": 8, "domain": d})
            for d in ("0.8,-0.2,1.2", "1.1,-0.5,1.5")]
    for key in KEYS:
        tol = 1e-5 if key == "G" else 1e-7
        assert runs[0].final[key] == pytest.approx(runs[1].final[key], rel=tol), key


def test_torus_matches_the_3d_spectral_run():
    """A torus (a loop off the axis: genus 1) against the 3D reference at ε = 0.04."""
    from fem_ade.model.params import Params
    from fem_ade.scenes.catalogue import Scene
    from fem_ade.scenes.initial import Torus

    R, r, eps = 0.16, 0.16 / math.sqrt(2), 0.04  # its images 11ε apart in the box
    params = Params(eps=eps, alpha=2 * math.pi**2 * R * r * r, beta=4 * math.pi**2 * R * r,
                    effects=frozenset({"bending", "volume", "area"}),
                    volume_functional="localized")
    scene = Scene("clifford", params, 0.0075 * eps**3, Torus((0.5, 0.5, 0.5), R, r), n=48)
    axi = steady(scene, backend="fem", n=104, backend_options={"geometry": "axisymmetric",
                                                               "order": 8})
    ref = steady(scene, backend="spectral", n=48)
    assert axi.shape["label"] == "torus" and axi.shape["genus"] == [1]
    for key in ("E", "W", "V", "A"):
        assert axi.final[key] == pytest.approx(ref.final[key], rel=1e-4), key


# ---------------------------------------------------------------------------------------------
# scenes, options, the run folder
# ---------------------------------------------------------------------------------------------
def test_scenes_it_takes_and_refuses():
    for name in ("torus", "discocyte", "nested", "sphere", "chain"):
        AxisymmetricFEMBackend.check(get_scene(name), n=128, dt=1e-6, scheme="stabilized",
                                     constraints="exact", geometry="axisymmetric")
    with pytest.raises(ModelError, match="2D"):
        AxisymmetricFEMBackend.check(get_scene("ellipse-2d"), n=128, dt=1e-6,
                                     scheme="stabilized", constraints="exact",
                                     geometry="axisymmetric")
    with pytest.raises(ModelError, match="not a surface of revolution"):  # seeded: arms
        make_backend("fem", get_scene("three-arm"), n=128, dt=1e-7, ic="seeded",
                     geometry="axisymmetric")
    with pytest.raises(ModelError, match="reaches the edge"):  # the domain cuts the membrane
        make_backend("fem", get_scene("sphere"), n=128, dt=1e-6, geometry="axisymmetric",
                     domain="0.2,0,1")
    for bad, match in (({"domain": "1,2"}, "three numbers"), ({"domain": "-1,0,1"}, "R > 0"),
                       ({"mesh": "graded:x"}, "margin"), ({"mesh": "foo.msh"}, "uniform or"),
                       ({"solver": "fft"}, "fdm"), ({"linalg": "petsc"}, "one process")):
        with pytest.raises(ModelError, match=match):
            AxisymmetricFEMBackend.check(get_scene("sphere"), n=128, dt=1e-6,
                                         scheme="stabilized", constraints="exact",
                                         geometry="axisymmetric", **bad)


def test_graded_mesh_and_the_default_resolution():
    x = graded_vertices(0.0, 1.0, 0.3, 0.5, 0.01)
    h = np.diff(x)
    assert x[0] == 0.0 and x[-1] == 1.0 and np.all(h > 0)
    fine = (x[:-1] >= 0.3 - 1e-12) & (x[1:] <= 0.5 + 1e-12)
    assert np.allclose(h[fine], 0.01) and h.max() <= 12 * 0.01 * 1.0001
    assert np.all(h[1:] / h[:-1] < 1.31) and np.all(h[:-1] / h[1:] < 1.31)
    scene = vesicle_scene(v=0.8, eps=0.01)
    n = AxisymmetricFEMBackend.default_n(scene)
    from fem_ade.backends.fem.axisym import DEFAULT_ORDER, NODES_PER_EPS

    assert 0.01 * n >= NODES_PER_EPS - 1e-9 and n % DEFAULT_ORDER == 0


def test_cli_run_folder_picture_and_resume(tmp_path, cli):
    """The vesicle family through the command line: a steady state (the family's default
    recipe), its verdict and sharp comparison, the run folder (summary, final.npz with the
    (r, z) field, XDMF of the half-plane, shape.png, drawn again identically from the files),
    and a resume that continues the interrupted run to the identical end."""
    out = tmp_path / "run"
    args = ["vesicle", "--v", "0.9", "--branch", "oblate", "--eps", "0.05", "--geometry",
            "axisymmetric", "--out", out, "--every", "5"]
    r = cli(args)
    assert r.returncode == 0, r.stderr
    assert "seeded on the oblate branch" in r.stdout and "sharp oblate at v" in r.stdout
    s = json.loads((out / "summary.json").read_text())
    assert s["backend_info"]["geometry"] == "axisymmetric" and s["status"] == "steady"
    assert s["shape"]["geometry"] == "axisymmetric" and s["verdict"]["same"]
    with np.load(out / "final.npz") as z:
        assert z["points"].shape[0] == 2 and z["phi"].shape == (z["points"].shape[1],)
        assert z["phi_grid"].ndim == 3
    assert (out / "shape.png").stat().st_size > 10_000 and (out / "phi.xdmf").is_file()
    # the picture again from the folder's files (python -m fem_ade.render): the same bytes
    from fem_ade.plots.render import render_run

    picture = (out / "shape.png").read_bytes()
    render_run(out, quiet=True)
    assert (out / "shape.png").read_bytes() == picture
    # stopped at step 20 with a checkpoint, resumed: the uninterrupted end (--no-sharp: no
    # comparison with the sharp oblate, a solve of 5 s at each end's own v)
    part = tmp_path / "part"
    r = cli([*args[:-4], "--out", part, "--every", "5", "--steps", "20",
             "--checkpoint-every", "10", "--no-render", "--no-sharp"])
    assert r.returncode == 0, r.stderr
    assert "sharp oblate at v" not in r.stdout and "seeded on the oblate branch" in r.stdout
    assert json.loads((part / "summary.json").read_text())["sharp_reference"] is None
    whole = tmp_path / "whole"
    r = cli([*args[:-4], "--out", whole, "--every", "5", "--steps", "30", "--no-render",
             "--no-sharp"])
    assert r.returncode == 0, r.stderr
    res = resume(part, steps=30)
    with np.load(whole / "final.npz") as z:
        assert np.array_equal(res.final_grid, z["phi_grid"])
    assert res.final == json.loads((whole / "summary.json").read_text())["final"]


def test_cli_refuses_a_scene_that_is_not_a_surface_of_revolution(tmp_path, cli):
    r = cli(["three-arm", "--ic", "seeded", "--geometry", "axisymmetric", "--out",
             tmp_path / "x"])
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "surface of revolution" in r.stderr and not (tmp_path / "x").exists()
    r = cli(["torus", "--domain", "0.5,0,1", "--out", tmp_path / "y"])
    assert r.returncode == 2 and "axisymmetric" in r.stderr


def test_amg_solves_the_same_system_as_the_fast_diagonalization():
    """PCG with AMG on the low-order refined (r, z) operator (the check of the exact solve)
    and the fast diagonalization take the same steps: E to 1e-9 after 10 steps (measured
    6e-14 at rtol 1e-10)."""
    scene = vesicle_scene(v=0.9, branch="prolate", eps=0.04, kbar=1.4, da0=1.1)
    E = {}
    for solver in ("fdm", "amg"):
        be = make_backend("fem", scene, n=64, geometry="axisymmetric", solver=solver,
                          scheme="stabilized", constraints="exact", dt=4.8e-5,
                          **({"rtol": 1e-10} if solver == "amg" else {}))
        its = sum(be.step()["krylov_its"] for _ in range(10))
        assert (its > 0) == (solver == "amg")
        E[solver] = be.diagnostics()["E"]
    assert E["amg"] == pytest.approx(E["fdm"], rel=1e-9)


@pytest.mark.slow
def test_willmore_torus_in_the_sharp_limit():
    """The Clifford torus (bending only, exact V and A): e at ε = 0.02 and 0.01, extrapolated
    at second order, is π/2 to 0.1 % (the sharp-limit study: 1.57083 from ε ≤ 0.01)."""
    from fem_ade.analysis.sharp import reduced_energy
    from fem_ade.model.params import Params
    from fem_ade.scenes.catalogue import Scene
    from fem_ade.scenes.initial import Torus

    e = []
    for eps in (0.02, 0.01):
        R = 0.22
        r = R / math.sqrt(2)
        params = Params(eps=eps, alpha=2 * math.pi**2 * R * r * r,
                        beta=4 * math.pi**2 * R * r,
                        effects=frozenset({"bending", "volume", "area"}),
                        volume_functional="localized")
        scene = Scene("clifford", params, 0.0075 * eps**3, Torus((0.5, 0.5, 0.5), R, r),
                      n=64)
        e.append(reduced_energy(steady(scene, backend="fem",
                                       backend_options={"geometry": "axisymmetric"}).final))
    e0 = e[1] + (e[1] - e[0]) / 3.0
    assert e0 == pytest.approx(math.pi / 2, rel=1e-3), e


def test_a_run_starts_from_an_axisymmetric_runs_end(tmp_path):
    """``phi0`` = an axisymmetric run's folder: another axisymmetric run on the same nodes
    starts from its end (E equal to round-off), keeps its (r, z) field in initial.npz and
    resumes to the end of an uninterrupted run; a 3D run starts from its surface of
    revolution (E within the 3D grid's error)."""
    from fem_ade.store.output import read_history

    scene = vesicle_scene(v=0.9, branch="oblate", eps=0.05)
    kw = dict(backend="fem", backend_options={"geometry": "axisymmetric"}, every=5,
              render=False, quiet=True, constraints="exact", scheme="stabilized")
    simulate(scene, out=tmp_path / "a", steps=20, **kw)
    end = read_history(tmp_path / "a" / "history.csv")["E"][-1]
    simulate(scene, out=tmp_path / "part", steps=10, checkpoint_every=5, phi0=tmp_path / "a",
             **kw)
    assert read_history(tmp_path / "part" / "history.csv")["E"][0] == pytest.approx(end,
                                                                                  rel=1e-12)
    with np.load(tmp_path / "part" / "initial.npz") as z:
        assert {"phi_grid", "axis", "points", "phi"} <= set(z.files)
    whole = simulate(scene, out=tmp_path / "whole", steps=15, phi0=tmp_path / "a", **kw)
    assert resume(tmp_path / "part", steps=15, quiet=True).final == whole.final
    simulate(scene, out=tmp_path / "3d", steps=1, every=1, phi0=tmp_path / "a",
             backend="spectral", n=32, render=False, quiet=True)
    assert read_history(tmp_path / "3d" / "history.csv")["E"][0] == pytest.approx(end,
                                                                                rel=1e-3)
