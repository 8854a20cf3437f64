"""Branches by continuation (fem_ade.campaigns.branch): each point a steady state, the table and the
pictures, a branch resumed after it was stopped, and mistakes refused in one line."""

import csv
import json

import numpy as np
import pytest

from fem_ade.backends.base import make_backend
from fem_ade.backends.fem.newton import solve_steady
from fem_ade.campaigns.branch import get_parameter, main, set_parameter
from fem_ade.scenes.catalogue import vesicle_scene

ARGS = ["vesicle", "--branch", "prolate", "--eps", "0.05", "--R0", "0.2", "--param", "v",
        "--from", "0.95", "--to", "0.91", "--step", "0.02", "--quiet"]


def rows(folder):
    with open(folder / "branch.csv") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def branch(tmp_path_factory):
    out = tmp_path_factory.mktemp("branch") / "prolate"
    assert main([*ARGS, "--out", str(out)]) == 0
    return out


def test_a_branch_of_steady_states(branch):
    """From v = 0.95 down to 0.91: the prolate's e rises as v falls, every point stable
    (lowest eigenvalue > 0), the parameter reached, the table and pictures written."""
    table = rows(branch)
    v = [float(r["v"]) for r in table]
    e = [float(r["e"]) for r in table]
    assert v[0] == 0.95 and v[-1] <= 0.91 and len(table) >= 3
    assert all(a > b for a, b in zip(v, v[1:], strict=False))
    assert all(a < b for a, b in zip(e, e[1:], strict=False))
    assert all(r["unstable"] == "0" and float(r["lowest_eigenvalue"]) > 0 for r in table)
    assert (branch / "branch.png").is_file() and (branch / "shapes.png").is_file()
    ended = json.loads((branch / "ended.json").read_text())
    assert ended == {"why": "reached v = 0.91", "points": len(table), "param": "v",
                     "last": pytest.approx(v[-1], rel=1e-9)}  # (the table: 10 digits)


def test_each_point_is_a_steady_state(branch):
    """Newton from a saved point, at its parameter, does not move it: E to 1e-10."""
    scene = vesicle_scene(v=0.95, branch="prolate", eps=0.05, R0=0.2)
    n = json.loads((branch / "branch.json").read_text())["n"]
    be = make_backend("fem", scene, n=n, geometry="axisymmetric", scheme="stabilized",
                      constraints="exact")
    point = json.loads((branch / "points" / "0002" / "summary.json").read_text())
    params = set_parameter(be.params, "v", point["v"])
    be.stepper.params = be.params = params
    with np.load(branch / "points" / "0002" / "final.npz") as z:
        be._set(np.array(z["phi"]), None)
    result = solve_steady(be)
    assert result.converged and result.iterations <= 1
    assert result.E == pytest.approx(point["E"], rel=1e-10)
    assert get_parameter(params, "v") == pytest.approx(point["v"], rel=1e-12)


def test_a_branch_without_stability(branch, tmp_path):
    """--no-stability: the same points (v, e, E, label, Newton's iterations), the unstable
    count and lowest eigenvalue blank; it is another branch (its folder holds one with)."""
    out = tmp_path / "unchecked"
    assert main([*ARGS, "--no-stability", "--out", str(out)]) == 0
    keep = ("v", "e", "E", "W", "V", "A", "label", "newton")
    assert [{k: r[k] for k in keep} for r in rows(out)] == \
        [{k: r[k] for k in keep} for r in rows(branch)]
    assert all(r["unstable"] == "" and r["lowest_eigenvalue"] == "" for r in rows(out))
    assert json.loads((out / "branch.json").read_text())["stability"] is False
    assert "stability" not in json.loads((branch / "branch.json").read_text())
    assert main([*ARGS, "--out", str(branch)]) == 0  # the one with: as it was
    assert main([*ARGS, "--no-stability", "--out", str(branch)]) == 2


def test_a_stopped_branch_goes_on(branch, tmp_path):
    """The folder of a branch stopped after its second point, run again with the same
    command, ends with the table of the branch never stopped."""
    import shutil

    out = tmp_path / "stopped"
    shutil.copytree(branch, out)
    for folder in sorted((out / "points").iterdir())[2:]:
        shutil.rmtree(folder)
    assert main([*ARGS, "--out", str(out)]) == 0
    whole, again = rows(branch), rows(out)
    assert [r["v"] for r in again] == [r["v"] for r in whole]
    for a, b in zip(whole, again, strict=True):
        assert float(a["E"]) == pytest.approx(float(b["E"]), rel=1e-9)


def test_a_branch_goes_further_with_another_end(branch, tmp_path):
    """The same branch run again with a further --to keeps its points and goes on to it;
    one that asks for the other side of --from, or another step, is another branch."""
    import shutil

    out = tmp_path / "further"
    shutil.copytree(branch, out)
    args = list(ARGS)
    args[args.index("--to") + 1] = "0.85"
    assert main([*args, "--out", str(out)]) == 0
    whole, further = rows(branch), rows(out)
    assert [r["E"] for r in further[:len(whole)]] == [r["E"] for r in whole]
    assert float(further[-1]["v"]) <= 0.85 < float(whole[-1]["v"])
    ended = json.loads((out / "ended.json").read_text())  # the new end's, not the old's
    assert ended["why"] == "reached v = 0.85" and ended["points"] == len(further)
    for change in (["--to", "0.97"], ["--step", "0.01"]):
        args = list(ARGS)
        args[args.index(change[0]) + 1] = change[1]
        assert main([*args, "--out", str(out)]) == 2


def _files(folder):
    """Every file of a folder (the lock's files aside) and its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and not p.name.startswith(".fem_ade")}


def _edit_summary(key, value):
    def edit(out):
        path = out / "points" / "0002" / "summary.json"
        row = json.loads(path.read_text())
        if value is _DROP:
            del row[key]
        else:
            row[key] = value
        path.write_text(json.dumps(row))
    return edit


def _edit_field(change):
    def edit(out):
        path = out / "points" / "0002" / "final.npz"
        with np.load(path) as z:
            fields = {k: np.array(z[k]) for k in z.files}
        fields["phi"] = change(fields["phi"])
        np.savez(path, **fields)
    return edit


def _copy(a, b):
    def edit(out):
        import shutil

        target = b
        if b == "next":  # the point after the last
            target = f"points/{len(list((out / 'points').iterdir())):04d}"
        (shutil.copytree if (out / a).is_dir() else shutil.copy2)(out / a, out / target)
    return edit


def _remove(name):
    def edit(out):
        import shutil

        path = out / name
        shutil.rmtree(path) if path.is_dir() else path.unlink()
    return edit


def _write(name, data):
    def edit(out):
        path = out / name
        if path.is_dir():
            import shutil

            shutil.rmtree(path)
        elif path.exists():
            path.unlink()
        if data is _DIR:
            path.mkdir()
        else:
            path.write_bytes(data)
    return edit


_DROP, _DIR = object(), object()


@pytest.mark.parametrize("edit, word", [
    (_remove("points/0001"), "gap"),  # 0002 would be read as 0001, 0003 written over 0002
    (_copy("points/0001", "points/0009"), "gap"),  # a stray copy past the end
    (_copy("points/0000", "next"), "point 0 of its branch"),  # one more point, a copy
    (_copy("points/0000/final.npz", "points/0002/final.npz"), "final.npz"),
    (_edit_field(lambda phi: phi + 1e-3), "final.npz"),
    (_edit_field(lambda phi: np.where(np.arange(phi.size) == 7, np.nan, phi)), "finite"),
    (_edit_field(lambda phi: phi[:-5]), "finite field"),
    (_edit_summary("v", 0.932), "changed"), (_edit_summary("e", 1.0), "changed"),
    (_edit_summary("label", "torus"), "changed"), (_edit_summary("theta", 2.0), "changed"),
    (_edit_summary("v", "0.91"), "not a number"), (_edit_summary("v", _DROP), "not a number"),
    (_edit_summary("v", [0.91]), "not a number"),
    (_write("points/0002/summary.json", b"[1, 2]"), "not a table"),
    (_write("points/0002/summary.json", b"{"), "not a whole point"),
    (_write("points/0002/final.npz", b"PK\x03\x04 truncated"), "not a whole point"),
    (_write("points/0002/final.npz", b""), "not a whole point"),
    (_write("points/stray.txt", b"x"), "no point of a branch"),
    (_write("points/0001/summary.json", _DIR), "not a whole point"),
    (_remove("points/0001/summary.json"), "not a whole point"),  # only the last may lack it
    (_write("branch.json", b""), "not a branch's record"),
    (_write("branch.json", b"{no"), "not a branch's record"),
    (_write("branch.json", _DIR), "not a branch's record"),
    (_remove("branch.json"), "no branch.json"),
])
def test_a_resume_never_continues_from_points_it_cannot_vouch_for(branch, tmp_path, capsys,
                                                                   edit, word):
    """Issue 40: a branch folder is trusted only as far as its checksums go. A gap, a
    stranger, a copied or edited point, a field not the one saved, a branch.json that is not
    a branch's or is missing: the resume (here with a further --to) stops with one line and
    exit 2, and writes nothing — where the code before lost points (a removed 0001: 0002 read
    as 0001, the next point written over 0002) or continued from a copy or an edit."""
    import shutil

    out = tmp_path / "b"
    shutil.copytree(branch, out)
    edit(out)
    before = _files(out)
    args = list(ARGS)
    args[args.index("--to") + 1] = "0.87"
    code = main([*args, "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and word in err, err
    assert _files(out) == before


def test_a_branch_folder_without_its_record_is_not_gone_on_with_in_another_model(
        branch, tmp_path, capsys):
    """branch.json removed, then the command of another model (--C, --kbar --da0): the old
    points are not kept under it (the code before went on: one branch.csv, two models); a
    run folder is no branch folder either."""
    import shutil

    from fem_ade.engine.runs import simulate

    out = tmp_path / "b"
    shutil.copytree(branch, out)
    (out / "branch.json").unlink()
    for extra in (["--C", "0.5"], ["--kbar", "1", "--da0", "1.05"]):
        assert main([*ARGS, *extra, "--out", str(out)]) == 2
        assert "no branch.json" in capsys.readouterr().err
    run = tmp_path / "run"
    simulate("discocyte", backend="spectral", n=16, steps=2, out=run, render=False,
             allow_underresolved=True)
    assert main([*ARGS, "--out", str(run)]) == 2
    assert "no branch.json" in capsys.readouterr().err


def test_sigterm_stops_a_branch_in_one_line_and_it_goes_on(branch, tmp_path):
    """SIGTERM (a scheduler's kill) once a point is saved: one line, exit 130 (there was no
    handler: rc -15, nothing said), and the same command then ends as the uninterrupted
    branch."""
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "killed"
    cmd = [sys.executable, "-m", "fem_ade.branch", *ARGS, "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    t0 = time.time()
    while time.time() < t0 + 300 and proc.poll() is None and \
            not (out / "points" / "0001" / "summary.json").exists():
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    err = proc.communicate(timeout=120)[1]
    if proc.returncode == 0:
        pytest.skip("the branch ended before the signal")
    assert proc.returncode == 130 and len(err.strip().splitlines()) == 1, (proc.returncode, err)
    assert "interrupted" in err
    assert main([*ARGS, "--out", str(out)]) == 0
    assert [r["E"] for r in rows(out)] == [r["E"] for r in rows(branch)]


def test_a_point_cut_short_is_made_again(branch, tmp_path):
    """A kill between a point's final.npz and its summary.json leaves the last folder
    without its summary: the resume makes that point again and ends as the whole branch."""
    import shutil

    out = tmp_path / "cut"
    shutil.copytree(branch, out)
    last = sorted((out / "points").iterdir())[-1]
    (last / "summary.json").unlink()
    assert main([*ARGS, "--out", str(out)]) == 0
    assert [r["E"] for r in rows(out)] == [r["E"] for r in rows(branch)]


def test_a_points_time_is_all_of_it(branch):
    """branch.csv's seconds is the whole point — Newton and the stability (it once left the
    stability out) — and its parts are said."""
    for r in rows(branch):
        total, newton, check = (float(r[k]) for k in ("seconds", "newton_s", "stability_s"))
        assert newton > 0 and check > 0 and total >= newton + check - 0.02


@pytest.mark.parametrize("extra, word", [
    (["--param", "da0"], "da0"), (["--step", "0"], "--step"),
    (["--folds", "-1"], "--folds"),
    (["--to", "0.95"], "two different"),
    (["--step", "1e-300"], "--step"), (["--to", "1.05"], "(0, 1]"),
    (["--from", "0"], "v must be"), (["--v", "0.7"], "branch's parameter"),
    (["--branch", "sphere"], "one point"),
])
def test_branch_mistakes_are_one_line(tmp_path, capsys, extra, word):
    args = list(ARGS)
    for i in range(0, len(extra), 2):
        if extra[i] in args:
            args[args.index(extra[i]) + 1] = extra[i + 1]
        else:
            args += extra[i:i + 2]
    code = main([*args, "--out", str(tmp_path / "x")])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and word in err, err
    assert not (tmp_path / "x").exists()


def test_crossing_of_two_branches():
    """Two branches with e linear in v cross where the lines do (exact for linear
    interpolation), from either direction; past a fold a branch is not used; branches that
    do not cross give None."""
    from fem_ade.campaigns.branch_analysis import crossing

    v = np.linspace(0.70, 0.62, 9)
    a = [{"v": x, "e": 1.8 - 4.0 * (x - 0.66)} for x in v]
    b = [{"v": x, "e": 1.8 - 2.5 * (x - 0.66) + 0.003} for x in v[::2]]
    assert crossing(a, b, "v") == pytest.approx(0.66 - 0.003 / 1.5, abs=1e-12)
    assert crossing(a[::-1], b[::-1], "v") == pytest.approx(0.66 - 0.003 / 1.5, abs=1e-12)
    folded = a[:5] + [{"v": 0.665, "e": 5.0}, {"v": 0.69, "e": 6.0}]
    assert crossing(folded, b, "v") is None  # the part before the fold does not cross b
    assert crossing(a, [{"v": x, "e": 9.0} for x in v], "v") is None


def test_a_fold_on_the_phase_field_oblate(tmp_path):
    """The phase-field oblate ends at a fold (studies/results/branches.md): at ε = 0.02,
    R₀ = 0.25 it turns back at v ≈ 0.6765 (measured). Followed down from v = 0.7 with
    --folds 0 the branch stops just past it: the fold is marked between its neighbours, the
    lowest eigenvalue changes sign there and the unstable count goes 0 → 1."""
    out = tmp_path / "oblate"
    assert main(["vesicle", "--branch", "oblate", "--eps", "0.02", "--param", "v", "--from",
                 "0.7", "--to", "0.55", "--step", "0.01", "--folds", "0", "--quiet",
                 "--out", str(out)]) == 0
    table = rows(out)
    folds = [float(r["fold"]) for r in table if r["fold"]]
    assert len(folds) == 1 and 0.670 < folds[0] < 0.685, folds
    k = next(i for i, r in enumerate(table) if r["fold"])
    assert k == len(table) - 2  # the branch ended at the point after its fold
    assert float(table[k - 1]["v"]) > folds[0] and float(table[-1]["v"]) > folds[0]
    assert all(r["unstable"] == "0" for r in table[:k])
    assert table[-1]["unstable"] == "1" and float(table[-1]["lowest_eigenvalue"]) < 0


def test_stability_equals_a_dense_eigensolve(branch):
    """The lowest eigenvalues of H_L v = λPv on {Cᵀv = 0}, C = (∇V, ∇A, P ∂φ/∂z)
    (fem_ade.campaigns.continuation.stability) are those of the dense problem built column by
    column from the
    same operators and restricted to the constraints' null space by QR (LOBPCG, used before,
    missed eigenvalues near zero); the translation is not among them."""
    import scipy.linalg as sla

    from fem_ade.backends.fem.modes import zero_modes
    from fem_ade.backends.fem.newton import NewtonSystem, linearize
    from fem_ade.campaigns.continuation import stability

    scene = vesicle_scene(v=0.95, branch="prolate", eps=0.05, R0=0.2)
    n = json.loads((branch / "branch.json").read_text())["n"]
    be = make_backend("fem", scene, n=n, geometry="axisymmetric", scheme="stabilized",
                      constraints="exact")
    point = json.loads((branch / "points" / "0002" / "summary.json").read_text())
    be.stepper.params = be.params = set_parameter(be.params, "v", point["v"])
    with np.load(branch / "points" / "0002" / "final.npz") as z:
        be._set(np.array(z["phi"]), None)
    sys_ = NewtonSystem(be)
    lin = linearize(sys_, be.phi.copy())
    N, p = be.phi.size, be.params
    eye = np.eye(N)
    H = np.column_stack([sys_.step.hessian_vector(lin.phi, lin.mu, lin.Kphi, e)
                         + sys_.step.constraint_hessian_vector(lin.phi, lin.Kphi, e,
                                                               *lin.lam[:2]) for e in eye])
    K = np.column_stack([be.space.K @ e for e in eye])
    w = be.space.weights
    P = (4 * p.kappa / p.eps**3) * np.diag(w) + (4 * p.kappa / p.eps) * K \
        + p.kappa * p.eps * K @ (K / w[:, None])
    t = zero_modes(be.space, be.phi, 0)[0]  # ∂φ/∂z: the translation along the axis

    Hs = 0.5 * (H + H.T)

    def lowest(C):  # the dense problem on {Cᵀv = 0}: its 4 lowest, and the lowest mode
        # on the null space Z = Q[:, k:] of Cᵀ, Q = I - V T Vᵀ of k Householder reflectors:
        # Zᵀ M Z is the trailing block of Qᵀ M Q (LAPACK's ormqr: O(N²k), not Z's O(N³))
        k = len(C)
        (a, tau), _ = sla.qr(np.column_stack(C), mode="raw")

        def QtMQ(M):
            M = sla.lapack.dormqr("L", "T", a, tau, M, 64 * N)[0]
            return sla.lapack.dormqr("R", "N", a, tau, M, 64 * N)[0][k:, k:]

        vals, vecs = sla.eigh(QtMQ(Hs), QtMQ(P), subset_by_index=[0, 3])
        v = sla.lapack.dormqr("L", "N", a, tau, np.r_[np.zeros(k), vecs[:, 0]][:, None],
                              64 * N)[0][:, 0]  # Z @ vecs[:, 0]
        return vals, abs(v @ P @ t) / np.sqrt((v @ P @ v) * (t @ P @ t))

    dense, along_t = lowest([*lin.C[:2], P @ t])
    assert stability(be) == pytest.approx(dense, rel=1e-6, abs=1e-9)
    # with Newton's pin ∇T in place of P t, the lowest mode is mostly the translation, whose
    # eigenvalue is the mesh's pinning (either sign); on {P t}⊥ it is a shape mode
    pinned, along_t_pinned = lowest(lin.C)
    print(f"lowest {dense[0]:.3e} (translation content {along_t:.3f}); with grad T "
          f"{pinned[0]:.3e} ({along_t_pinned:.3f})")
    assert along_t_pinned > 0.5 and along_t < 0.1


def test_a_branch_ends_at_a_change_of_topology_not_of_label():
    """A genus-0 shape whose label changes (pear → gourd, discocyte → stomatocyte, gourd →
    chain, prolate → a triaxial ellipsoid) is the same branch; opening into a torus or
    pinching into two vesicles ends it."""
    from fem_ade.campaigns.branch_analysis import same_topology

    for a, b in (("pear", "gourd"), ("discocyte", "stomatocyte"), ("gourd", "chain"),
                 ("prolate", "cylinder"), ("prolate", "ellipsoid"), ("torus", "torus"),
                 ("2 vesicles", "2 vesicles")):
        assert same_topology(a, b), (a, b)
    for a, b in (("oblate", "torus"), ("pear", "2 vesicles"), ("stomatocyte", "nested"),
                 ("2 vesicles", "gourd")):
        assert not same_topology(a, b), (a, b)


def test_a_vesicle_branch_fits_the_box_at_both_ends():
    """Without --R0 a vesicle branch takes the family's R₀ of the end where the seed is the
    longest (a prolate followed from v = 0.95 at that v's R₀ ran into the box's ends near
    v = 0.72 at ε = 0.01); a given R₀ is kept."""
    import math

    from fem_ade.campaigns.branch import vesicle_for_branch

    def R0(scene):
        return math.sqrt(scene.params.beta / (4.0 * math.pi))

    both = vesicle_for_branch({"branch": "prolate", "eps": 0.05}, "v", 0.95, 0.7)
    at_end = vesicle_scene(v=0.7, branch="prolate", eps=0.05)
    assert R0(both) == pytest.approx(R0(at_end), abs=1e-6)
    assert R0(both) < R0(vesicle_scene(v=0.95, branch="prolate", eps=0.05)) - 0.01
    assert get_parameter(both.params, "v") == pytest.approx(0.95)
    given = vesicle_for_branch({"branch": "prolate", "eps": 0.05, "R0": 0.2}, "v", 0.95, 0.7)
    assert R0(given) == pytest.approx(0.2)


def test_the_predictor_is_the_quadratic_through_the_last_three_points():
    """On a curved branch (a circle's arc in the (φ, p) plane of two fields, radius 1 in
    the continuation's metric) the prediction Δs past the last of three points Δs apart is
    the quadratic's: O(Δs³) off the arc, where the secant's is O(Δs²) off (the pear at
    ε = 0.01 needed 5-8 Newton iterations a point from it against 6-12, and got past its fold);
    its tangent is the arc's to O(Δs²). From two points: the secant."""
    from fem_ade.campaigns.continuation import Continuation

    scene = vesicle_scene(v=0.95, branch="prolate", eps=0.05, R0=0.2)
    be = make_backend("fem", scene, n=96, geometry="axisymmetric", scheme="stabilized",
                      constraints="exact")
    cont = Continuation(be, "v")
    rng = np.random.default_rng(3)
    u = rng.standard_normal(be.phi.size)
    u /= np.sqrt(cont.inner(u, u))  # ⟨u, u⟩ = 1, θ = 1: the arc is (cos s) u + p = sin s

    def arc(s):
        return be.phi + (np.cos(s) - 1.0) * u, np.sin(s)

    ds = 0.05
    points = [arc(-2 * ds), arc(-ds), arc(0.0)]
    (phi, p), (t_phi, t_p) = cont.predict(points, ds)
    true_phi, true_p = arc(ds)
    quadratic = cont.chord((phi, p), (true_phi, true_p))
    (phi2, p2), (s_phi, s_p) = cont.predict(points[1:], ds)
    secant = cont.chord((phi2, p2), (true_phi, true_p))
    assert secant == pytest.approx(ds * ds, rel=0.1)  # measured: 2.5e-3
    assert quadratic < 2 * ds**3 < secant / 5, (quadratic, secant)  # measured: 1.3e-4
    assert abs(t_p - 1.0) < ds**2 and np.sqrt(cont.inner(t_phi, t_phi)) < ds**2  # 3e-5
    assert cont.theta * cont.inner(t_phi, t_phi) + t_p**2 == pytest.approx(1.0)
    h = cont.chord(points[1], points[2])  # the secant: along the last chord
    assert np.allclose(s_phi, (points[2][0] - points[1][0]) / h)
    assert np.allclose(phi2, points[2][0] + ds * s_phi) and p2 == pytest.approx(
        points[2][1] + ds * s_p)
