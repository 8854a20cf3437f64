"""The octant geometry (fem_ade.backends.fem.octant): a state with the mirrors x, y, z = L/2
on one eighth of the box is the periodic box's state — the same integrals, steps, Newton
steady state and picture — at an eighth of the unknowns; and its refusals."""

import numpy as np
import pytest

from fem_ade.backends.base import check_backend, make_backend
from fem_ade.backends.fem.newton import NewtonSystem, solve_steady
from fem_ade.backends.fem.octant import fold
from fem_ade.model.params import ModelError
from fem_ade.scenes.catalogue import get_scene, vesicle_scene

#: a prolate with its axis along z at the box's centre (mirror-symmetric in x, y and z)
SCENE = vesicle_scene(v=0.8, da0=1.2, kbar=1.4, eps=0.04, branch="prolate")
KW = dict(n=32, order=4, constraints="exact", scheme="stabilized", dt=SCENE.dt)


def _pair():
    return [make_backend("fem", SCENE, geometry=g, **KW) for g in ("cartesian", "octant")]


def test_the_octant_is_the_box_for_a_mirror_symmetric_state():
    """Its nodes are the box's on [L/2, L]³ and its weights count the mirror images, so V, A,
    ΔA, W, G and every step equal the box's to round-off (measured 3e-15 relative after 20
    steps); the unfolded grid is the box's grid."""
    box, octant = _pair()
    assert octant.space.n_dofs == 17**3 and box.space.n_dofs == 32**3
    for _ in range(20):
        box.step()
        octant.step()
    a, b = box.diagnostics(), octant.diagnostics()
    for key in ("E", "W", "G", "V", "A", "dA"):
        assert b[key] == pytest.approx(a[key], rel=1e-12), key
    assert np.max(np.abs(box.grid_phi() - octant.grid_phi())) < 1e-12


def test_newton_in_the_octant_needs_no_pins_and_finds_the_boxs_steady_state():
    """No rigid motion keeps the mirrors, so the octant's Newton has no pins; its steady
    state is the box's (with its pins) to 1e-9 in E."""
    box, octant = _pair()
    assert NewtonSystem(octant).translations == [] and len(NewtonSystem(box).translations) >= 5
    rb, ro = solve_steady(box, max_iterations=40), solve_steady(octant, max_iterations=40)
    assert rb.converged and ro.converged
    assert ro.E == pytest.approx(rb.E, rel=1e-9)


def test_fold_maps_the_box_onto_the_half_axis():
    x = np.array([0.0, 0.1, 0.3, 0.5, 0.7, 0.99, 1.2])
    assert np.allclose(fold(x, 0.5, 1.0), [1.0, 0.9, 0.7, 0.5, 0.7, 0.99, 0.8])


@pytest.mark.parametrize("scene, options, message", [
    (SCENE, dict(n=36, order=4), "needs a multiple of 2 x 4 nodes per L"),
    (SCENE, dict(n=32, order=4, mesh="graded"), "takes a uniform mesh"),
    (SCENE, dict(n=32, order=4, solver="amg"), "solved exactly"),
    ("ellipse-2d", dict(n=32, order=4), "the octant geometry is 3D"),
])
def test_refusals_are_one_line(scene, options, message):
    scene = get_scene(scene) if isinstance(scene, str) else scene
    with pytest.raises(ModelError, match=message) as err:
        check_backend("fem", scene, dt=scene.dt, geometry="octant", **options)
    assert "\n" not in str(err.value)


def test_the_octants_stability_says_it_is_a_sector():
    """An octant state's eigenvalues are those of the perturbations even in x, y and z: its
    JSON says so, a Cartesian state's does not."""
    from fem_ade.campaigns.stability import Stability

    assert Stability("octant", eigenvalues=[-1.0, 2.0], unstable_3d=1).as_json() == {
        "eigenvalues": [-1.0, 2.0], "unstable_3d": 1, "complete": True,
        "sector": "mirror-symmetric (octant)"}
    assert "sector" not in Stability("cartesian", eigenvalues=[1.0]).as_json()
