"""Branch switching into 3D (issue 44; fem_ade.campaigns.switch): the softest mode of a block
as a field, the switched start φ + δψ cos mθ, the 3D run folder it makes, the command line's
refusals."""

import json
import math

import numpy as np
import pytest

from fem_ade.backends.fem.modes import lowest, lowest_mode, mode_block
from fem_ade.backends.fem.newton import NewtonSystem, linearize
from fem_ade.campaigns.branch import main as branch_main
from fem_ade.campaigns.stability import load_state
from fem_ade.campaigns.switch import start_fields
from fem_ade.cli.switch import main as switch_main
from fem_ade.model.params import ModelError
from fem_ade.scenes.fields import load_meridian_field, meridian_values

#: the oblate at ε = 0.04, R₀ = 0.25 down from v = 0.85: its block m = 2 is unstable at the
#: first four points and crosses zero near v = 0.80 (one m = 2 bifurcation)
OBLATE = ["vesicle", "--branch", "oblate", "--eps", "0.04", "--R0", "0.25", "--param", "v",
          "--from", "0.85", "--to", "0.80", "--step", "0.01", "--quiet", "--modes", "3"]


@pytest.fixture(scope="module")
def oblate(tmp_path_factory):
    out = tmp_path_factory.mktemp("switch") / "oblate"
    assert branch_main([*OBLATE, "--out", str(out)]) == 0
    bifs = json.loads((out / "bifurcations.json").read_text())["bifurcations"]
    assert [b["m"] for b in bifs] == [2], bifs
    return out


def test_the_softest_mode_is_the_blocks_lowest(oblate):
    """lowest_mode's (λ, ψ): λ is lowest's first eigenvalue, ψ solves H_m ψ = λ P_m ψ on the
    block's free nodes (to 1e-6 of |H_m ψ|), vanishes on the axis (m ≥ 1) and is scaled to
    max ψ = 1."""
    be, _ = load_state(oblate / "points" / "0000")
    sys_ = NewtonSystem(be)
    lin = linearize(sys_, be.phi)
    lam, psi = lowest_mode(sys_, lin, 2)
    res = lowest(sys_, lin, 2, k=2)
    assert lam < 0 and res.unstable == 1
    assert lam == pytest.approx(res.eigenvalues[0], rel=1e-8)
    block = mode_block(sys_, lin, 2)
    x = psi[block.free]
    Hx, Px = block.H(x), block.P(x)
    # H_m ψ − λP_m ψ lies in the span of the zero modes' borders (none for m = 2)
    assert np.linalg.norm(Hx - lam * Px) <= 1e-6 * np.linalg.norm(Hx)
    r = be.space.doflocs[0]
    assert np.all(psi[r == 0] == 0.0)
    assert np.max(np.abs(psi)) == pytest.approx(1.0) and np.max(psi) == pytest.approx(1.0)


def test_the_start_is_the_state_plus_its_mode(oblate, tmp_path):
    """The start field at 3D points on a circle about the axis: the revolved state plus
    δψ(r, z) cos 2θ, and an (r, z) file without the mode gives the state alone."""
    params, fields, lam = start_fields(oblate / "points" / "0000", 2, delta=0.05, grid=16)
    assert lam < 0 and fields["phi_grid"].shape == (16, 16, 16)
    ax, ay = fields["axis"]
    theta = np.linspace(0, 2 * np.pi, 9)[:-1]
    r0, z0 = 0.2, float(np.median(fields["points"][1]))
    pts = np.stack([ax + r0 * np.cos(theta), ay + r0 * np.sin(theta), np.full(8, z0)])
    bare = {k: fields[k] for k in ("axis", "points", "phi")}
    base, switched = meridian_values(bare, pts), meridian_values(fields, pts)
    assert np.ptp(base) < 1e-12  # axisymmetric
    angle = 2 * (theta - float(fields["azimuthal_phase"]))
    assert float(fields["azimuthal_phase"]) == pytest.approx(np.pi / 8)
    mode = (switched - base) / np.cos(angle)
    inside = np.abs(np.cos(angle)) > 0.5
    assert np.ptp(mode[inside]) < 1e-9 and abs(mode[inside][0]) > 1e-3
    path = tmp_path / "start.npz"
    np.savez(path, **fields)
    kept = load_meridian_field(path)
    assert kept["azimuthal_m"] == 2 and np.array_equal(kept["azimuthal_psi"],
                                                       fields["azimuthal_psi"])
    np.savez(path, **{**fields, "azimuthal_m": np.array(0.5)})
    with pytest.raises(ModelError, match="integer m >= 1"):
        load_meridian_field(path)


def test_a_switch_is_an_ordinary_run_folder(oblate, tmp_path, capsys):
    """python -m fem_ade.switch writes a 3D run folder that says where it came from, keeps
    its start (with the mode) and resumes."""
    from fem_ade.cli.run import main as run_main

    out = tmp_path / "switched"
    assert switch_main([str(oblate), "--out", str(out), "--n", "32", "--max-steps", "30",
                        "--checkpoint-every", "10", "--quiet"]) == 0
    assert "bifurcation 0 (m = 2, point 0003" in capsys.readouterr().out
    run = json.loads((out / "run.json").read_text())
    origin = json.loads(run["scene"]["description"].split(": ", 1)[1])
    assert origin["m"] == 2 and origin["point"] == "0003" and origin["eigenvalue"] < 0
    assert run["scene"]["dim"] == 3
    with np.load(out / "initial.npz") as z:
        assert float(z["azimuthal_m"]) == 2 and z["azimuthal_psi"].shape == z["phi"].shape
    summary = json.loads((out / "summary.json").read_text())
    assert summary["steps"] == 30 and math.isfinite(summary["final"]["E"])
    assert run_main(["--resume", str(out), "--steps", "40", "--quiet"]) == 0
    assert json.loads((out / "summary.json").read_text())["steps"] == 40


def test_a_switch_goes_on_in_its_own_folder(oblate, tmp_path, capsys):
    """The same switch into the same folder again: an ended run is returned as it is
    (nothing runs), one capped below a new --max-steps goes on from its checkpoint, bit for
    bit the run made at once; another switch (another δ) is refused in one line."""
    out, whole = tmp_path / "switched", tmp_path / "whole"
    common = [str(oblate), "--n", "32", "--checkpoint-every", "10", "--quiet"]
    assert switch_main([*common, "--out", str(out), "--max-steps", "20"]) == 0
    first = (out / "summary.json").read_text()
    assert switch_main([*common, "--out", str(out), "--max-steps", "20"]) == 0
    assert (out / "summary.json").read_text() == first  # not run again
    assert switch_main([*common, "--out", str(out), "--max-steps", "30"]) == 0
    assert switch_main([*common, "--out", str(whole), "--max-steps", "30"]) == 0
    capsys.readouterr()
    went_on, made = (json.loads((f / "summary.json").read_text()) for f in (out, whole))
    assert went_on["steps"] == made["steps"] == 30
    assert went_on["final"] == made["final"]
    assert switch_main([*common, "--out", str(out), "--max-steps", "30", "--delta",
                        "0.2"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "holds another run (scene.description" in err, err


@pytest.mark.parametrize("args, message", [
    (["--bifurcation", "3"], "has bifurcations 0 … 0, not 3"),
    (["--point", "4"], "has no negative eigenvalue"),
    (["--delta", "2"], "delta is the start's max"),
    (["--mode", "2"], "a mode m >= 1 is taken at a point"),
    # --follow's (a failed first point leaves no folder behind either)
    (["--follow", "0"], "a positive integer"),
    (["--follow", "2", "--step", "2"], "amplitude per step, in (0, 1]"),
    (["--follow", "2", "--delta", "0.2"], "are the flow's"),
    (["--step", "0.2"], "go with --follow"),
    (["--follow", "2", "--mode", "2"], "a mode m >= 1 is taken at a point"),
    (["--follow", "2", "--n", "32", "--order", "4"], "no first point at v = "),
    # the octant's
    (["--geometry", "octant", "--mode", "3", "--point", "0"], "for even m only"),
    (["--geometry", "octant", "--backend", "spectral"], "the octant geometry is the FEM's"),
    (["--follow", "2", "--geometry", "octant", "--mode", "3", "--point", "0"],
     "for even m only"),
])
def test_refusals_are_one_line(oblate, tmp_path, capsys, args, message):
    out = tmp_path / "never"
    assert switch_main([str(oblate), "--out", str(out), "--quiet", *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err, err
    assert not out.exists()


def test_an_octant_switch_is_an_ordinary_run_folder(oblate, tmp_path, capsys):
    """--geometry octant: the 3D run on the mirror-symmetric eighth of the box (order 8 by
    default), started along cos 2θ (the phase the mirrors keep), a run folder that resumes;
    its grid is the whole box's, unfolded."""
    from fem_ade.cli.run import main as run_main

    out = tmp_path / "octant"
    assert switch_main([str(oblate), "--out", str(out), "--geometry", "octant", "--n", "32",
                        "--max-steps", "20", "--checkpoint-every", "10", "--quiet"]) == 0
    run = json.loads((out / "run.json").read_text())
    assert run["backend_options"] == {"order": 8, "geometry": "octant"}
    origin = json.loads(run["scene"]["description"].split(": ", 1)[1])
    assert origin["geometry"] == "octant" and origin["m"] == 2
    with np.load(out / "initial.npz") as z:
        assert float(z["azimuthal_phase"]) == 0.0
    assert run_main(["--resume", str(out), "--steps", "30", "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["steps"] == 30 and summary["backend_info"]["n_dofs"] == 17**3


def test_the_mirror_error_sees_a_body_off_centre():
    """mirror_error: 0 for a ball at the box's centre on the grid x_j = jL/m, the shift's
    jump for one moved by a node."""
    from fem_ade.campaigns.switch import mirror_error

    m = 32
    x = (np.arange(m) - m / 2) / m
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    ball = np.tanh((0.25 - np.sqrt(X**2 + Y**2 + Z**2)) / 0.03)
    assert mirror_error(ball) < 1e-12
    assert mirror_error(np.roll(ball, 1, axis=2)) > 0.5


def test_a_branch_without_its_points_is_refused(oblate, tmp_path, capsys):
    """A committed branch keeps its table, not its points: say so."""
    import shutil

    bare = tmp_path / "bare"
    bare.mkdir()
    for name in ("branch.json", "branch.csv", "bifurcations.json"):
        shutil.copy(oblate / name, bare / name)
    assert switch_main([str(bare), "--out", str(tmp_path / "x"), "--quiet"]) == 2
    assert "the branch's points are needed" in capsys.readouterr().err


def _newton_3d(params, fields, tmp_path, name):
    """Newton (with its pins) on 32³ nodes of order 4 from a 3D start's fields; the backend
    at the steady state and the result."""
    from fem_ade.backends.base import make_backend
    from fem_ade.backends.fem.newton import solve_steady
    from fem_ade.scenes.catalogue import Scene
    from fem_ade.scenes.initial import FieldIC

    path = tmp_path / f"{name}.npz"
    np.savez(path, **fields)
    scene = Scene(name=name, params=params, dt=1e-6, ic=FieldIC(path=str(path)), n=32, dim=3)
    be = make_backend("fem", scene, n=32, order=4, scheme="stabilized", constraints="exact",
                      dt=1e-6)
    return be, solve_steady(be, max_iterations=40)


def test_a_kick_along_a_stable_mode_returns_to_the_revolved_state(oblate, tmp_path):
    """The control of a switch: past its m = 2 bifurcation (v = 0.790, point 4) the oblate
    is stable in every block, and its start φ + δψ₃ cos 3(θ − π/12) (δ = 0.05, λ₃ > 0)
    goes back, by Newton in 3D (its pins keep where the start was), to the steady state
    Newton finds from the revolved oblate alone, moved by the kick's shift of the centroid:
    measured, E equal to 1.0e-8, the fields differ by 1.5e-3, of which all but 1.7e-4 is a
    translation of 5.6e-5 L in x and y (the pins' position; the cubic mesh makes E depend
    on it at 1e-8)."""
    from fem_ade.backends.fem.modes import rigid_motions

    point = oblate / "points" / "0004"
    params, kicked, lam = start_fields(point, 3, delta=0.05, grid=16)
    assert lam > 0
    plain = {k: v for k, v in kicked.items() if not k.startswith("azimuthal")}
    be_k, res_k = _newton_3d(params, kicked, tmp_path, "kicked")
    be_p, res_p = _newton_3d(params, plain, tmp_path, "plain")
    assert res_k.converged and res_p.converged
    assert res_k.E == pytest.approx(res_p.E, rel=1e-7)
    d = be_k.phi - be_p.phi
    motions = np.column_stack(rigid_motions(be_p, be_p.phi))
    a = np.linalg.lstsq(motions, d, rcond=None)[0]
    rest = np.abs(d - motions @ a).max()
    assert rest < 1e-3 and rest < np.abs(d).max() / 4  # mostly a rigid motion
    assert np.abs(a[:3]).max() < 1e-4  # a translation of ~5.6e-5 L


def _mirror(be, phi, perm):
    """φ at the nodes moved by ``perm`` (x, y about the axis; coordinates (3, N) → (3, N))."""
    X = np.asarray(be.space.doflocs)
    L = be.params.L
    key = {tuple(np.round(np.mod(p, L) / L * 4096).astype(int)): i for i, p in enumerate(X.T)}
    moved = np.mod(perm(X), L)
    index = [key[tuple(np.round(p / L * 4096).astype(int))] for p in moved.T]
    return phi[index]


def test_following_the_born_branch_in_3d(oblate, tmp_path, capsys):
    """--follow: the branch born at the m = 2 bifurcation, by continuation on the 3D FEM.
    Its first two points hold the mode's amplitude at 0.1 and 0.2; each point has the mode's
    symmetry — mirror planes through the axis along the mesh's x and y (cos 2θ is even in
    both) but not the quarter turn the revolved oblate has (cos 2θ changes sign) — and is a
    steady state; a second run goes on from the last point."""
    from fem_ade.campaigns.branch_folder import load_points, read_branch_table
    from fem_ade.campaigns.continuation import Continuation
    from fem_ade.campaigns.switch_branch import switched_start

    out = tmp_path / "d2"
    common = [str(oblate), "--follow", "2", "--n", "32", "--order", "8", "--quiet",
              "--out", str(out)]
    assert switch_main(common) == 0
    first = read_branch_table(out)
    assert [r["amplitude"] for r in first] == pytest.approx([0.1, 0.2], abs=1e-9)
    common[2] = "3"
    assert switch_main(common) == 0
    rows = read_branch_table(out)
    assert len(rows) == 3 and rows[:2] == first  # gone on from its points
    assert rows[2]["amplitude"] > 0.2 and json.loads((out / "ended.json").read_text())[
        "points"] == 3
    assert (out / "branch3d.png").is_file()
    _, be, psi = switched_start(oblate, 0, None, None, 32, 8)
    ax, ay = (float(a) for a in np.load(oblate / "points" / "0003" / "final.npz")["axis"])
    phi0 = be.phi.copy()

    def quarter(X):
        return np.stack([ax - (X[1] - ay), ay + (X[0] - ax), X[2]])

    def mirror_x(X):
        return np.stack([2 * ax - X[0], X[1], X[2]])

    def mirror_y(X):
        return np.stack([X[0], 2 * ay - X[1], X[2]])

    assert np.max(np.abs(_mirror(be, phi0, quarter) - phi0)) < 1e-9  # the control
    points = load_points(out)
    for _, phi in points:
        for move in (mirror_x, mirror_y):
            assert np.max(np.abs(_mirror(be, phi, move) - phi)) < 1e-8
        assert np.max(np.abs(_mirror(be, phi, quarter) - phi)) > 0.1
    row, phi = points[-1]
    be._set(phi, None)
    Continuation(be, "v").set_p(row["v"])  # the last point's parameters
    sys_ = NewtonSystem(be)
    lin = linearize(sys_, be.phi)
    assert np.max(np.abs(lin.violation[:2])) < 1e-10 * be.params.alpha
    assert np.linalg.norm(lin.grad) < 1e-5 * np.linalg.norm(sys_.gradient(be.phi))


def test_the_octant_follows_the_same_branch(oblate, tmp_path, capsys):
    """--follow --geometry octant: the m = 2 branch on the mirror-symmetric eighth of the box,
    without pins, has the box's points (v, e, the amplitude) on the same nodes (32 per L of
    order 8), and its stability line says it is the sector's."""
    from fem_ade.campaigns.branch_folder import read_branch_table

    rows = {}
    for geometry in ("cartesian", "octant"):
        out = tmp_path / geometry
        assert switch_main([str(oblate), "--follow", "2", "--n", "32", "--order", "8",
                            "--geometry", geometry, "--out", str(out),
                            *(["--stability"] if geometry == "octant" else [])]) == 0
        rows[geometry] = read_branch_table(out)
    said = capsys.readouterr().out
    assert "even in x, y and z (the octant's)" in said
    assert json.loads((tmp_path / "octant" / "branch.json").read_text())["geometry"] == "octant"
    for box, eighth in zip(rows["cartesian"], rows["octant"], strict=True):
        assert eighth["v"] == pytest.approx(box["v"], abs=1e-8)
        assert eighth["e"] == pytest.approx(box["e"], rel=1e-8)
        assert eighth["amplitude"] == pytest.approx(box["amplitude"], abs=1e-8)
        assert eighth["unstable_3d"] >= 1  # the branch leaves the oblate's saddle


def test_a_branch_in_da0_is_followed_in_da0(tmp_path, capsys):
    """The 3D branch is followed in the parameter of the branch it left: from the m = 2
    bifurcation of an ADE oblate followed in Δa₀ at v = 0.8 (κ̄/κ = 1.4, ε = 0.04), on the
    octant, its points keep v and move Δa₀ (branch.csv's column, ended.json's parameter, the
    line printed), hold the mode's amplitude at 0.1 and 0.2 and are steady states at their
    Δa₀."""
    from fem_ade.campaigns.branch_folder import load_points, read_branch_table
    from fem_ade.campaigns.continuation import Continuation
    from fem_ade.campaigns.switch_branch import switched_start

    axi = tmp_path / "oblate-da0"
    assert branch_main(["vesicle", "--branch", "oblate", "--eps", "0.04", "--R0", "0.25",
                        "--v", "0.8", "--kbar", "1.4", "--param", "da0", "--from", "0.85",
                        "--to", "1.15", "--step", "0.05", "--modes", "3", "--quiet",
                        "--out", str(axi)]) == 0
    bif = json.loads((axi / "bifurcations.json").read_text())["bifurcations"][0]
    assert bif["m"] == 2  # near Δa₀ = 1.066
    out = tmp_path / "d2"
    assert switch_main([str(axi), "--follow", "3", "--n", "32", "--order", "8",
                        "--geometry", "octant", "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "  da0 = " in said
    assert json.loads((out / "branch.json").read_text())["param"] == "da0"
    assert json.loads((out / "ended.json").read_text())["param"] == "da0"
    rows = read_branch_table(out)
    assert [r["amplitude"] for r in rows[:2]] == pytest.approx([0.1, 0.2], abs=1e-9)
    assert all(r["v"] == pytest.approx(0.8, abs=1e-12) for r in rows)
    da0 = [r["da0"] for r in rows]
    assert len(set(da0)) == 3 and all(abs(d - bif["da0"]) < 0.2 for d in da0)
    _, be, _ = switched_start(axi, 0, None, None, 32, 8, "octant")
    for row, phi in load_points(out):
        be._set(phi, None)
        Continuation(be, "da0").set_p(row["da0"])
        sys_ = NewtonSystem(be)
        lin = linearize(sys_, be.phi)
        assert np.linalg.norm(lin.grad) < 1e-5 * np.linalg.norm(sys_.gradient(be.phi))
