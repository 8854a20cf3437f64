"""Shape descriptors (fem_ade.analysis.shape) on analytic phase fields φ = tanh(s/(√2ε)), 64³ grid.

s is the signed distance (exact for spheres and the torus, first-order for ellipsoids);
stars are unions (max of s) of ellipsoids.
"""

import math

import numpy as np
import pytest

from fem_ade.analysis.shape import describe
from fem_ade.analysis.surface import euler_characteristic, extract_surface

N, L, EPS = 64, 1.0, 0.025
C = (0.5, 0.5, 0.5)


def _grid(n=N):
    x = np.arange(n) * (L / n)
    return np.stack(np.meshgrid(x, x, x, indexing="ij"))


X = _grid()


def profile(s, eps=EPS):
    return np.tanh(s / (math.sqrt(2.0) * eps))


def sphere(c, R):
    return R - np.sqrt(sum((X[i] - c[i]) ** 2 for i in range(3)))


def ellipsoid(c, axes, angle=0.0):
    """Approximate signed distance (1 − q)·q/|∇q| of an ellipsoid, rotated about z."""
    d = np.stack([X[i] - c[i] for i in range(3)])
    ca, sa = math.cos(angle), math.sin(angle)
    d = np.stack([ca * d[0] + sa * d[1], -sa * d[0] + ca * d[1], d[2]])
    a = np.asarray(axes, dtype=float).reshape(3, 1, 1, 1)
    q = np.sqrt(np.sum(d**2 / a**2, axis=0))
    g = np.sqrt(np.sum(d**2 / a**4, axis=0))
    return np.where(q < 1e-9, a.min(), (1.0 - q) * q / np.maximum(g, 1e-12))


def torus(R=0.28, r=0.1):
    rho = np.sqrt((X[0] - 0.5) ** 2 + (X[1] - 0.5) ** 2)
    return r - np.sqrt((rho - R) ** 2 + (X[2] - 0.5) ** 2)


def three_star():
    arms = [ellipsoid((0.5 + 0.18 * math.cos(t), 0.5 + 0.18 * math.sin(t), 0.5),
                      (0.2, 0.09, 0.09), angle=t) for t in (0.1, 0.1 + 2 * math.pi / 3,
                                                            0.1 + 4 * math.pi / 3)]
    return np.max(arms, axis=0)


def six_star():
    return np.max([ellipsoid(C, ax) for ax in
                   [(0.38, 0.09, 0.09), (0.09, 0.38, 0.09), (0.09, 0.09, 0.38)]], axis=0)


@pytest.fixture(scope="module")
def sphere_desc():
    return describe(profile(sphere(C, 0.25)), L)


def test_sphere(sphere_desc):
    d = sphere_desc
    assert d["components"] == 1 and d["genus"] == [0] and d["nested"] is False
    assert d["arms"] == 1  # convention: a body without arms has one lobe
    assert d["sources"] == {"V": "sharp", "A": "sharp", "dA": "sharp"}
    R = 0.25
    assert d["sharp"]["A"] == pytest.approx(4 * math.pi * R**2, rel=5e-3)
    assert d["sharp"]["V"] == pytest.approx(4 * math.pi * R**3 / 3, rel=5e-3)
    assert d["sharp"]["mean_curvature_integral"] == pytest.approx(4 * math.pi * R, rel=5e-3)
    assert d["reduced_volume"] == pytest.approx(1.0, abs=5e-3)
    assert d["reduced_area_difference"] == pytest.approx(1.0, abs=5e-3)
    assert d["shift"] == [0, 0, 0]


def test_given_values_are_used():
    R, D = 0.25, 2 * EPS / 3
    d = describe(profile(sphere(C, R)), L, V=4 * math.pi * R**3 / 3 * 1.1,
                 A=4 * math.pi * R**2, dA=8 * math.pi * D * R, D=D)
    assert d["sources"] == {"V": "given", "A": "given", "dA": "given"}
    assert d["reduced_volume"] == pytest.approx(1.1, rel=1e-12)
    assert d["reduced_area_difference"] == pytest.approx(1.0, rel=1e-12)


def test_prolate_ellipsoid_has_one_lobe():
    d = describe(profile(ellipsoid(C, (0.36, 0.12, 0.12))), L)
    assert (d["components"], d["genus"], d["arms"]) == (1, [0], 1)
    assert d["reduced_volume"] < 0.85


def test_torus():
    d = describe(profile(torus()), L)
    assert d["components"] == 1 and d["genus"] == [1] and d["nested"] is False
    assert d["arms"] == 1


def test_two_separate_spheres():
    s = np.maximum(sphere((0.27, 0.5, 0.5), 0.17), sphere((0.73, 0.5, 0.5), 0.17))
    d = describe(profile(s), L)
    assert d["components"] == 2 and d["genus"] == [0, 0] and d["nested"] is False
    assert d["inside_of"] == [None, None]
    assert d["reduced_volume"] == pytest.approx(1 / math.sqrt(2), abs=5e-3)


def test_nested_spheres():
    s = np.minimum(sphere(C, 0.35), -sphere(C, 0.2))  # a shell: φ > 0 between the spheres
    d = describe(profile(s), L)
    assert d["components"] == 2 and d["genus"] == [0, 0] and d["nested"] is True
    assert d["inside_of"] == [None, 0]  # the inner (smaller) sphere lies in the outer one
    V = 4 * math.pi / 3 * (0.35**3 - 0.2**3)
    assert d["sharp"]["V"] == pytest.approx(V, rel=1e-2)


@pytest.mark.parametrize("star, arms", [(three_star, 3), (six_star, 6)])
def test_stars(star, arms):
    d = describe(profile(star()), L)
    assert d["components"] == 1 and d["genus"] == [0] and d["nested"] is False
    assert d["arms"] == arms


def test_surface_is_closed_without_seam_across_the_boundary():
    """A sphere across the periodic boundary is re-centred and closed (χ = 2, no open edge)."""
    phi = np.roll(profile(sphere(C, 0.25)), (30, -20, 7), axis=(0, 1, 2))
    S = extract_surface(phi, L)
    assert S.n_components == 1 and S.wraps == [False]
    assert euler_characteristic(S.tri) == 2
    d = describe(phi, L, surface=S)
    assert d["genus"] == [0] and d["arms"] == 1
    assert d["reduced_volume"] == pytest.approx(1.0, abs=5e-3)


def test_surface_winding_round_the_box():
    """A cylinder spanning the periodic box closes into a torus on the 3-torus."""
    phi = profile(0.2 - np.sqrt((X[0] - 0.5) ** 2 + (X[1] - 0.5) ** 2))
    d = describe(phi, L)
    assert d["components"] == 1 and d["wraps"] == [True] and d["genus"] == [1]
    assert d["sharp"]["A"] == pytest.approx(2 * math.pi * 0.2 * L, rel=5e-3)


def test_no_surface():
    d = describe(-np.ones((16, 16, 16)), L)
    assert d["components"] == 0 and d["genus"] == [] and d["arms"] == 0


# --- the body's geometry and the label (issue 10's verdicts) ------------------------------
def _classified(ic, n=48, eps=0.02):
    import math

    from fem_ade.analysis.shape import describe

    x = np.arange(n) / n
    s, _ = ic.level(np.stack(np.meshgrid(x, x, x, indexing="ij")), 1.0)
    return describe(np.tanh(s / (math.sqrt(2) * eps)), 1.0)


def _shapes():
    from fem_ade.scenes.initial import (
        Capsule,
        Discocyte,
        Ellipsoid,
        Sphere,
        Spheres,
        Starfish,
        Torus,
    )

    c = (0.5, 0.5, 0.5)
    return {
        "sphere": Sphere(c, 0.25),
        "prolate": Ellipsoid(c, (0.1, 0.1, 0.2), 0.25, 0.25),
        "oblate": Ellipsoid(c, (0.2, 0.2, 0.07), 0.25, 0.25),
        "discocyte": Discocyte(c, 0.6),
        "torus": Torus(c, 0.25, 0.1),
        "gourd": Spheres(((0.5, 0.5, 0.4), (0.5, 0.5, 0.6)), (0.14, 0.14)),
        "chain": Spheres(((0.5, 0.5, 0.3), (0.5, 0.5, 0.5), (0.5, 0.5, 0.7)), (0.12,) * 3),
        "cylinder": Capsule(c, (0, 0, 1), 0.5, 0.08),
        "starfish-3": Starfish(c, 3, 0.35, 0.06, 0.1),
        "starfish-6": Starfish(c, 6, 0.35, 0.06, 0.1, plane=False),
        "nested": Spheres((c, c), (0.35, 0.2), (1, -1)),
        "2 vesicles": Spheres(((0.5, 0.5, 0.25), (0.5, 0.5, 0.75)), (0.12, 0.12)),
    }


@pytest.mark.parametrize("label", list(_shapes()))
def test_classify_names_each_kind_of_shape(label):
    d = _classified(_shapes()[label])
    print(label, "->", d["label"], d["body"])
    assert d["label"] == label


#: the shapes of _shapes() that are surfaces of revolution about z
ROUND = ("sphere", "prolate", "oblate", "discocyte", "torus", "gourd", "chain", "cylinder",
         "nested", "2 vesicles")


@pytest.mark.parametrize("label", ROUND)
def test_one_classifier_for_both_geometries(label):
    """The same shape, described in 3D (its φ = 0 surface) and in the axisymmetric geometry
    (its φ = 0 meridians, order 8 at 2.5 nodes per ε), gets the same label from the one
    decision tree (fem_ade.analysis.shape.classify) — issue 41: the two geometries had two
    trees that had drifted apart."""
    from fem_ade.backends.base import make_backend
    from fem_ade.backends.fem.axisym import default_nodes
    from fem_ade.model.params import Params
    from fem_ade.scenes.catalogue import Scene

    ic = _shapes()[label]
    params = Params(eps=0.02, alpha=0.05, beta=0.8)
    scene = Scene(label, params, 1e-7, ic, n=48)
    be = make_backend("fem", scene, n=default_nodes(0.02, 1.0, 8), order=8,
                      geometry="axisymmetric")
    shape, _ = be.describe_final(be.diagnostics())
    assert _classified(ic)["label"] == label
    assert shape["label"] == label, shape
