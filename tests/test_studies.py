"""Every study script runs in its quick mode and returns figures that make sense.

Studies are found by glob (no hand-kept list); each needs a ``check_<name>`` below that
asserts on what its ``main(["--quick", ...])`` returns (not only that files appear), so a
study without a check fails here.
"""

from __future__ import annotations

import ast
import importlib.util
import json
import math
from pathlib import Path

import numpy as np
import pytest
from report_compare import differences

STUDIES = Path(__file__).resolve().parents[1] / "studies"
SCRIPTS = sorted(STUDIES.glob("*.py"))
#: studies whose quick mode is too long for the default suite (they run with -m slow)
SLOW: set[str] = {"phase_diagram", "ade_plane"}  # sharp solves of 30-60 s (the Dask pieces:
#: test_sweep; the continuation the ADE plane rests on: test_sharp_ref)


def _needs_mpi(path):
    """The scaling study runs under mpirun with petsc4py: skipped where they are missing
    (unless CI installed them: FEM_ADE_REQUIRE_MPI)."""
    import os
    import shutil

    have = importlib.util.find_spec("petsc4py") and importlib.util.find_spec("mpi4py") and (
        shutil.which("mpirun") or shutil.which("mpiexec"))
    if path.stem == "scaling" and not have and not os.environ.get("FEM_ADE_REQUIRE_MPI"):
        pytest.skip("petsc4py, mpi4py and mpirun (scripts/install-petsc.sh)")


def _load(path):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def check_hard_cases(rows, out):
    """Each case runs with E_M never rising between records, stops with a diagnosis, or is
    refused as bad input."""
    assert rows
    for r in rows:
        if r["status"].startswith("completed"):
            assert "rose at 0 of" in r["detail"], r
        else:
            assert r["status"].startswith(("diverged", "refused")), r
            assert r["detail"], r


def check_branches(result, out):
    """The prolate and the oblate followed from v = 0.9 to 0.88; the oblate's and the
    stomatocyte's seeds at v = 0.62, tori at eps = 0.04, excluded as not their branch (as
    at eps = 0.02 in the study); no crossing; the report drawn."""
    first, second = result["pairs"]
    for pair in result["pairs"]:
        assert pair["at"] == {"0.04": None}, pair
    assert all(v is not None and v <= 0.8801 for v in first["last_v"].values()), first
    assert all(v is None for v in second["last_v"].values()), second
    assert all("not this branch" in why for why in second["ended"].values()), second
    assert (out / "branches_quick.md").is_file() and (out / "branches_quick.png").is_file()


def check_ade_limit(result, out):
    """ade_branches.py --quick's line (prolate and oblate at v = 0.85, eps = 0.04) refined
    at eps = 0.02 from Δa₀ = 1.1 up and down to the grid's 1.04 and 1.16: no crossing at
    either ε, the two cells judged by their branches' extrapolated energies (the
    prolate, as the sharp one), each extrapolation the p = 2 formula of the two ε's
    energies; the refined and the coarse lines archived with one branch code's version;
    the report written."""
    (t,) = result["transitions"]
    assert t["coarse"] is None and t["fine"] is None and t["limit"] is None, t
    inside = [c for c in result["cells"] if c["how"] == "extrapolated"]
    assert [c["da0"] for c in inside] == [1.04, 1.16], result["cells"]
    for c in inside:
        assert c["limit"] == c["sharp"] == "prolate", c
        for e in c["e"].values():
            assert e["coarse"] and e["fine"], c
            assert math.isclose(e["limit"], e["fine"] + (e["fine"] - e["coarse"]) / 3)
    assert result["agree"] == len(result["cells"]) == 2, result
    lines = json.loads((out / "ade_limit_quick" / "lines.json").read_text())
    coarse = json.loads((out / "ade_branches_quick" / "lines.json").read_text())
    versions = {x["key"]["version"] for x in [*lines.values(), *coarse.values()]}
    assert len(lines) == 4 and all(x["rows"] for x in lines.values()), lines
    assert len(versions) == 1 and None not in versions, versions  # one code, both ε
    assert (out / "ade_limit_quick.md").is_file()


def check_ade_bifurcations(result, out):
    """v = 0.85 at eps = 0.04 (ade_branches.py --quick's R0), the prolate and the oblate over
    Δa₀ 0.84 … 1.0 with the modes m ≤ 8: the prolate stable in 3D at every point (no end),
    the oblate stable from 0.84 until its m = 2 block turns unstable (measured 0.909), that
    end refined at eps = 0.02 (measured 0.956: it moves up as eps falls) and extrapolated
    with p = 2; the lines archived with their modes and 4 nodes per eps; report, picture."""
    ob, pr = (next(x for x in result["lines"] if x["branch"] == b) for b in ("oblate", "prolate"))
    assert pr["points"] >= 3 and pr["ends"] == [] and len(pr["parts"]) == 1, pr
    assert pr["parts"][0]["from"] == 0.84
    (end,) = ob["ends"]
    assert end["m"] == 2 and end["turns"] == "unstable", end
    coarse, fine = end["da0"]["0.04"], end["da0"]["0.02"]
    assert 0.88 < coarse < 0.94 and coarse < fine < coarse + 0.08, end
    assert math.isclose(end["x0_assumed"], fine + (fine - coarse) / 3)
    for eps in ("0.04", "0.02"):
        lines = json.loads((out / "ade_bifurcations_quick" / f"eps={eps}" / "lines.json")
                           .read_text())
        assert lines and all(x["key"]["modes"] == 8 and x["key"]["nodes_per_eps"] == 4
                             and x["rows"] for x in lines.values()), lines
    assert (out / "ade_bifurcations_quick.md").is_file()
    assert (out / "ade_bifurcations_quick.png").is_file()


def check_ade_branches(result, out):
    """One line at v = 0.85, eps = 0.04: the prolate and the oblate followed in Δa₀ over
    1.04 … 1.16, the prolate the lowest at both grid points as the sharp one is; the report
    and its picture written."""
    assert [p["pf"] for p in result["points"]] == ["prolate", "prolate"]
    assert all(p["pf"] == p["sharp"] for p in result["points"])
    assert all(e is not None for p in result["points"] for e in p["e_pf"].values())
    assert (out / "ade_branches_quick.md").is_file() and (out / "ade-branches_quick.png").is_file()


def check_nonaxisymmetric(result, out):
    """A prolate point of the quick ADE line revolved into 3D: the 3D control lands within
    1e-3 of the axisymmetric e (eps = 0.04 both), the kicked run back on it."""
    (row,) = result["rows"]
    assert abs(row["control"]["e"] / row["e_axisymmetric"] - 1) < 1e-3, row
    assert row["same"] and row["verdict"] == "stable to the kick", row
    assert (out / "nonaxisymmetric_quick.md").is_file()


def check_cost(result, out):
    """Every run in cost.json's format with a command that names its discretisation; the
    Pareto front is cheaper-and-worse to dearer-and-better; the time to an accuracy agrees
    with the points; p = 4 reaches 1e-4 where p = 1 reaches none of the targets (2D ellipse,
    the quick convergence levels)."""
    from _lib.fits import time_to

    assert time_to([(1.0, 1e-1), (10.0, 1e-3)], 1e-2) == pytest.approx(10**0.5)
    assert time_to([(1.0, 1e-1), (10.0, 1e-3)], 1e-4) is None
    assert time_to([(2.0, 1e-1), (1.0, 1e-3)], 1e-2) == 1.0
    keys = {"scene", "start", "label", "method", "order", "mesh", "n", "nodes", "cpu_s",
            "E_err", "V_err", "A_err", "command"}
    runs = result["runs"]
    assert runs and all(set(r) == keys for r in runs)
    assert all(math.isfinite(r["E_err"]) and r["cpu_s"] > 0 for r in runs)
    for r in runs:
        assert r["command"].startswith(f"python -m fem_ade.run {r['scene']} --backend "
                                       f"{r['method']}"), r
        assert f"--n {r['nodes']} " in r["command"]  # --n counts nodes, for every order
        if r["method"] == "fem":
            assert f"--order {r['order']}" in r["command"]
            assert r["nodes"] == r["order"] * r["n"]
        assert ("--phi0" in r["command"]) == (r["start"] == "resolved")
    for key, s in result["summary"].items():
        front = s["pareto"]
        assert front and all(a["cpu_s"] <= b["cpu_s"] and a["E_err"] > b["E_err"]
                             for a, b in zip(front, front[1:], strict=False))
        tt = s["time_to"]
        assert tt["p1"]["0.01"] is None, key
        assert tt["p4"]["0.0001"] is not None and tt["spectral"]["1e-05"] is not None, key
    assert (out / "cost_quick.md").is_file()
    assert (out / "cost-ellipse-2d-resolved_quick.png").is_file()


def check_convergence(results, out):
    """2D ellipse from a resolved start: p = 1 rates ≈ 2 and p = 2 ≈ 4 in E, V, A, φ; p = 4
    is 1000× more accurate than p = 1 at 96 nodes; the spectral error is tiny; every steady
    run is steady and its error falls with n; the paper's scheme is first order in Δt; the
    stabilized scheme advances physical time more slowly (more so at larger Δt)."""
    sp = results["spatial"]["ellipse-2d"]["starts"]
    rates = sp["resolved"]["rates"]
    print({k: {q: round(v, 2) for q, v in r.items() if v is not None} for k, r in rates.items()})
    for q in ("E", "V", "A", "phi_L2"):
        assert 1.7 < rates["p1"][q] < 2.4, (q, rates["p1"])
        assert 3.5 < rates["p2"][q] < 5.0, (q, rates["p2"])
    rows = sp["resolved"]["rows"]
    err = {(r["label"], r["nodes"]): abs(r["errors"]["E"]) for r in rows}
    assert err[("p4", 96)] < err[("p1", 96)] / 1000
    assert err[("spectral", 64)] < 1e-12
    amg = [r for r in rows if r["label"] == "p4 amg"]
    # the iterative path solves the same system (to its tolerance): measured 1e-9 apart
    assert amg and all(abs(abs(r["errors"]["E"]) - err[("p4", r["nodes"])]) < 1e-7
                       for r in amg)
    st = results["steady"]
    assert all(r["status"] == "steady" for r in st["rows"]), st["rows"]
    p1 = [r["errors"]["E"] for r in st["rows"] if r["label"] == "p1"]
    assert p1 == sorted(p1, reverse=True), p1
    tm = results["temporal"]
    assert 0.8 < tm["orders"]["paper"] < 1.4, tm["orders"]
    slow = [s["slowdown"] for s in tm["slowdown"]]
    assert all(s is not None and s >= 1 for s in slow) and slow[-1] > slow[0], slow
    assert (out / "convergence_quick.md").is_file()
    assert (out / "convergence-ellipse-2d-resolved_quick.png").is_file()


def check_constraints_study(cases, out):
    """Exact constraints hold V = α, A = β; penalties leave a gap that shrinks with M."""
    by = {c["variant"]: c for c in cases}
    assert set(by) == {"M1x", "M10x", "M100x", "exact"}
    exact = by["exact"]["final"]
    assert abs(exact["V"] / by["exact"]["alpha"] - 1) < 1e-8
    assert abs(exact["A"] / by["exact"]["beta"] - 1) < 1e-8
    gaps = [abs(by[v]["final"]["V"] / by[v]["alpha"] - 1) for v in ("M1x", "M10x", "M100x")]
    print("|V/alpha - 1| for M x1, x10, x100:", gaps)
    assert gaps[0] > gaps[1] > gaps[2]
    assert (out / "constraints.md").is_file()


def check_readme_figure(path, out):
    from PIL import Image

    with Image.open(path) as im:
        assert im.size == (1200, 600)
        assert np.asarray(im).std() > 10  # a picture, not a blank canvas


def check_bench(result, out):
    """Every figure is a finite number in bench_quick.json's format; the AMG iteration counts
    of the quick grids are flat (≤ 11 at every order); the exact solves' steps cost a few
    spectral steps (nothing is timed against the clock: only ratios of one run)."""
    import json

    data = json.loads((out / "bench_quick.json").read_text())["figures"]
    assert data == result["figures"] and len(data) > 30
    for name, f in data.items():
        assert set(f) == {"value", "unit", "target", "op"}, name
        assert math.isfinite(f["value"]) and f["value"] > 0, (name, f)
        if name.endswith("PCG its (median)"):
            assert f["value"] <= 11, (name, f)
        if name.endswith("step / spectral") and (" fdm " in name or " fft " in name):
            assert f["value"] < 10, (name, f)  # no PCG loop in the exact solves
    assert any(" p=4 graded fdm " in name for name in data)


def check_gallery(result, out):
    """Every case ran, was analysed and has a verdict; the report and a montage exist."""
    verdicts = result["report"]["verdicts"]
    print(verdicts)
    assert len(verdicts) == len(result["results"]) >= 5
    assert all(isinstance(v, str) and v != "not run" for v in verdicts.values())
    kicked = [a for a in result["results"].values() if a["status"] == "steady"]
    assert kicked, "a quick steady run and its kick"
    text = (out / "gallery.md").read_text()
    assert "| discocyte (Fig. 1) | discocyte |" in text
    assert (out / "montage-spectral.png").is_file()
    # a later sitting that runs (here: reports) other cells keeps these in the report
    gallery = _load(STUDIES / "gallery.py")
    again = gallery.main(["--quick", "--report-only", "--scenes", "torus", "--out", str(out)])
    assert again["report"]["verdicts"] == verdicts
    text = (out / "gallery.md").read_text()
    assert "| discocyte (Fig. 1) | discocyte |" in text and "| torus (Fig. 2) | torus |" in text
    # what is committed is the archive (every analysis, one thumbnail a run): without the run
    # folders the report is the same
    import shutil

    assert (out / "analyses.json").is_file() and list((out / "thumbs").glob("*.png"))
    shutil.rmtree(out / "sweep")
    again = gallery.main(["--quick", "--report-only", "--scenes", "torus", "--out", str(out)])
    assert again["report"]["verdicts"] == verdicts
    assert (out / "montage-spectral.png").is_file()


def check_scaling(result, out):
    """Every case measured on every rank, the model fitted from them, the iteration counts
    the same within one from 1 to 2 ranks, the same energy."""
    cases = result["cases"]
    assert sorted(cases) == ["16-1", "16-2", "24-1", "24-2"]
    for n in (16, 24):
        one, two = cases[f"{n}-1"], cases[f"{n}-2"]
        assert len(one["memory_mb"]) == 1 and len(two["memory_mb"]) == 2
        assert abs(one["its_median"] - two["its_median"]) <= 1
        assert two["local_dofs_rank0"] < one["dofs"]
        assert abs(one["E"] - two["E"]) <= 1e-6 * abs(one["E"])
    model = result["model"]
    assert model["m1_bytes"] > 0 and model["t1_s"] > 0
    assert "| 256³ |" in (out / "scaling.md").read_text()


def check_regenerate(result, out):
    """The one command that writes studies/results runs every study that has results there,
    each with that folder as --out (the other studies write under runs/)."""
    studies = {p.stem for p in SCRIPTS} - {"regenerate"}
    assert set(result) == studies, set(result) ^ studies
    assert all("--out studies/results" in line for line in result.values()), result
    from fem_ade.campaigns.sweep_file import load_sweep

    regenerate = _load(STUDIES / "regenerate.py")
    listed = regenerate.SWEEPS
    assert set(listed) | set(regenerate.MEASUREMENTS) == studies  # each study is one or the other
    assert not set(listed) & set(regenerate.MEASUREMENTS)
    for name, files in listed.items():  # each listed sweep file is one that loads
        assert name in result and all(f in result[name] for f in files)
        for f in files:
            if f.endswith(".toml"):
                assert load_sweep(STUDIES.parent / f).points()


def check_eps_ladder(result, out):
    """The quick ladder: ε = 0.08 from the seed; 0.04 from the seed, from 0.08's end as it is
    (its start field is that end's, node for node) and re-profiled (tanh(2 artanh φ) of it);
    the rows archived before the report, which has a row per ε."""
    import json

    assert [r["eps"] for r in result] == [0.08, 0.04]
    assert set(result[1]) == {"eps", "seed", "from 2ε", "re-profiled", "re-seeded", "own shape"}
    root = out / "eps_ladder-quick"
    assert json.loads((root / "ladder.json").read_text())["rows"] == result
    with np.load(root / "points" / "eps=0.08_seed=prolate" / "final.npz") as z:
        end = np.array(z["phi"])
    with np.load(root / "points" / "from-2eps_eps=0.04" / "initial.npz") as z:
        assert np.array_equal(z["phi"], end)
    with np.load(root / "reprofiled" / "eps=0.04_seed=prolate.start.npz") as z:
        assert np.allclose(z["phi"], np.tanh(2.0 * np.arctanh(np.clip(end, -1 + 1e-15,
                                                                        1 - 1e-15))))
    text = (out / "eps_ladder-quick.md").read_text()
    assert "| 0.08 | " in text and "| 0.04 | " in text
    # the sweep file's [run] sharp = false: no comparison with the sharp prolate after a run
    summary = json.loads((root / "points" / "eps=0.08_seed=prolate" / "summary.json")
                         .read_text())
    assert summary["sharp_reference"] is None and summary["shape"]["label"]


def check_sharp_limit(result, out):
    """The sharp prolate and oblate at v = 0.8 as the reference gives them (to 1e-8); the
    seeded phase-field prolate's energy above the sharp one and falling as ε falls
    (spectral); the axisymmetric column at the same ε, its two resolutions within 1e-3."""
    w = {r["branch"]: r["w"] for r in result["branches"]}
    assert abs(w["prolate"] - 1.387440432444) < 1e-8 and abs(w["oblate"] - 1.452538628565) < 1e-8
    rows = {r["backend"]: r for r in result["rows"]}
    assert set(rows) == {"spectral", "axisymmetric"}
    axi = rows["axisymmetric"]
    assert axi["eps"] == [0.08, 0.064, 0.05] and all(e > axi["e_sharp"]
                                                     for e in axi["e_phase_field"])
    assert axi["disc_over_eps_effect"] is None or axi["disc_over_eps_effect"] < 1e-3
    row = rows["spectral"]
    e = row["e_phase_field"]
    assert row["branch"] == "prolate" and len(e) == 3 and row["eps"] == [0.08, 0.064, 0.05]
    assert all(a > b > row["e_sharp"] for a, b in zip(e, e[1:], strict=False)), e
    assert e[-1] < 1.5 * row["e_sharp"], e
    assert (out / "sharp_limit.md").is_file() and (out / "sharp-eps.png").is_file()


def check_axisymmetric(result, out):
    """The resolution table (order 4 at ε = 0.05: more nodes, a smaller error), the cost
    table of the three methods, and the axisymmetric block of bench.json."""
    errs = {r["nodes_per_eps"]: r["error"] for r in result["resolution"]}
    assert set(errs) == {1.5, 2.5} and errs[2.5] < errs[1.5] < 0.05
    cost = result["cost"]
    assert set(cost["runs"]) == {"axisymmetric FEM (p = 8)", "3D FEM (p = 8)", "3D spectral"}
    assert all(p["error"] < 0.05 for pts in cost["runs"].values() for p in pts)
    assert "axisymmetric" in json.loads((out / "bench.json").read_text())
    assert (out / "axisymmetric.md").is_file() and (out / "axisymmetric-cost.png").is_file()


def check_ade_plane(result, out):
    """At v = 0.85, κ̄/κ = 1.4, m₀ 1.76 and 1.8: the pear below the prolate (its area difference
    follows m₀, the prolate's stays at 1.0848), and the quick phase-field runs reported."""
    (plane,) = result["planes"]
    assert plane["v"] == 0.85
    for row in plane["sharp"]:
        assert row["lowest"] == "pear" and row["pear"] < row["prolate"] - 0.1, row
    assert (out / "ade_plane.md").is_file() and (out / "ade-plane.png").is_file()
    text = (out / "ade_plane.md").read_text()
    assert "| 1.80 |" in text and "Phase field at ε = 0.05" in text


def check_sweep_scaling(result, out):
    """One and two local workers and an external scheduler each run every point to its end;
    the figures are positive and finite."""
    rows = result["rows"]
    assert [(r["how"], r["workers"]) for r in rows] == [("local", 1), ("local", 2),
                                                       ("external", 2)]
    for r in rows:
        assert r["points"] == 2 and r["wall_s"] > 0 and r["task_s_mean"] > 0
        assert math.isfinite(r["overhead_per_task_s"]) and r["speedup"] > 0
    assert "| external | 2 |" in (out / "sweep_scaling_quick.md").read_text()


def check_phase_diagram(result, out):
    """Both sweeps, small: every run ends (or fails with a reason), the notes compare the
    lowest end state with the sharp one at each point, the pictures are drawn."""
    assert set(result) == {"minimal", "ade"}
    assert len(result["minimal"]) == 4 and len(result["ade"]) == 8
    for rows in result.values():
        for r in rows:
            assert r["status"] in ("steady", "max_steps", "failed"), r
            assert r["status"] != "failed" or r["reason"], r
    for r in result["minimal"]:  # Willmore: no closed genus-0 surface bends less than a sphere
        if r["status"] != "failed" and r["genus"] == "0":
            assert r["e"] > 1.0, r
    text = (out / "phase_diagram_quick.md").read_text()
    assert "| lowest end state (e) | sharp lowest of genus 0 (e) | sharp torus e |" in text
    assert (out / "phase_diagram" / "ade-quick" / "phase-diagram.png").is_file()


def check_azimuthal(result, out):
    """The prolate and the oblate at ε = 0.04 with modes m ≤ 3: the prolate stable in 3D
    all along, the oblate unstable in m = 2 at v = 0.85 (two 3D directions) and stable past
    its m = 2 bifurcation near v = 0.80; the report and picture written."""
    prolate, oblate = result["branches"]
    assert prolate["unstable_3d_at_start"] == 0 and not prolate["bifurcations"]
    assert oblate["unstable_3d_at_start"] == 2
    assert [b["m"] for b in oblate["bifurcations"]] == [2]
    assert 0.78 < oblate["bifurcations"][0]["v"] < 0.815
    text = (out / "azimuthal_quick.md").read_text()
    assert "m = 2 at" in text and (out / "azimuthal_quick.png").is_file()


def check_ade_azimuthal(result, out):
    """Two cells at ε = 0.04 with m ≤ 3: each made at its (v, Δa₀) as its branch, its
    lowest eigenvalue and its m in the report; the oblate at v = 0.9 is stable in 3D.
    ``--refine`` (in --quick: every cell) made both again on a finer mesh at the same ε
    (more nodes, a nearby eigenvalue: the same state) and at ε/2, each in the report."""
    oblate, prolate = result["cells"]
    assert oblate["same"] and prolate["same"] and oblate["unstable_3d"] == 0
    assert oblate["lowest_m"] in range(4) and prolate["lowest"] is not None
    text = (out / "ade_azimuthal_quick.md").read_text()
    assert "Of 2 cells: 2 made" in text and (out / "ade_azimuthal_quick.png").is_file()
    finer, half = result["refined"]["nodes=4"], result["refined"]["half-eps"]
    assert [c["eps"] for c in finer + half] == [0.04, 0.04, 0.02, 0.02], (finer, half)
    root = out / "ade_azimuthal_quick"
    for coarse, fine in zip(result["cells"], finer, strict=True):
        n = {f: json.loads((root / f / cell / "branch.json").read_text())["n"]
             for f in (".", "refined/nodes=4") for cell in [f"v={coarse['v']:g}_da0="
                                                             f"{coarse['da0']:g}"]}
        assert n["refined/nodes=4"] > n["."], n  # (another mesh, not the same folder)
        assert fine["same"] and fine["lowest_m"] == coarse["lowest_m"]
        assert abs(fine["lowest"] - coarse["lowest"]) < 0.1 * abs(coarse["lowest"]) + 0.05
    assert all(c["same"] for c in half) and "## The flagged cells refined" in text
    # the tie-break mesh (ε/2, 4 per ε) only where the two before leave the cell undecided
    decide = _load(STUDIES / "ade_azimuthal.py").decided
    decided = [decide([f, h]) for f, h in zip(finer, half, strict=True)]
    tie = result["refined"]["half-eps-4"]
    assert [cell["v"] for cell in tie] == [c["v"] for c, d in zip(finer, decided, strict=True)
                                          if d == "undecided"], (decided, tie)


def check_solver_bench(result, out):
    """At ε = 0.04: one continuation point by both solvers to the same energy, the m = 0
    block by both eigen-solvers to 1e-8, the lowest of m ≤ 8 with and without the shift near
    the point before's to 1e-8, and by both sparse codes where both are installed
    (PARDISO first, the default there), every time positive."""
    r = result["0.04"]
    assert r["E_direct"] == pytest.approx(r["E_minres"], rel=1e-9)
    assert r["eigenvalues_agree"] < 1e-8
    assert r["code"] in ("pardiso", "superlu") and r["code"] in r
    if "code_ratios" in r:
        assert r["code"] == "pardiso" and "superlu" in r
        assert r["codes_agree"]["E"] < 1e-9 and r["codes_agree"]["eigenvalues_m0"] < 1e-8
    assert r["lowest_agree"] < 1e-8  # shifted near the point before's or not
    assert all(r[k] > 0 for k in ("newton_direct_s", "stability_m0_s", "stability_m8_s",
                                  "stability_m8_alone_s"))
    assert (out / "solver_bench_quick.json").is_file()


def check_fourier_bench(result, out):
    """At ε = 0.04 on n_θ = 4: the three preconditioners give one solve's solution to 1e-6
    (measured 7.9e-9), and Newton reaches the same E with the coarse step and without it
    (7e-15) in fewer GMRES iterations in all (measured 352 against 624); every figure
    printed is there."""
    solve, c, b = result["one_solve"], result["newton_coarse"], result["newton_blocks"]
    assert solve["solutions_differ"] < 1e-6
    assert all(solve[k]["gmres"] > 0 and solve[k]["total_s"] >= 0
               for k in ("blocks", "coarse", "kept"))
    assert c["converged"] and b["converged"] and result["newton_E_differ"] < 1e-10
    assert sum(c["gmres"]) < 0.75 * sum(b["gmres"])
    assert set(result["ratios"]) == {"gmres", "solve_made", "solve_kept", "newton"}
    assert (out / "fourier_bench_quick.json").is_file()


def check_newton3d_bench(result, out):
    """At ε = 0.04 on 32³: Newton with the pins converges in no more iterations than
    without (measured 2 against 3), keeps the pins' values (1.2e-7) and the centroid
    (6e-6 L), where without them it slides (0.86, 8.7e-4); six pins on the tilted prolate.
    The coarse space reaches the same state as P alone (E to 4e-16, φ to 2e-13) in fewer
    MINRES iterations (3.6× measured), and the 3D stability's eigenvalues do not depend on
    ARPACK's Lanczos vectors (2e-13)."""
    pinned, free = result["pinned"], result["free"]
    assert abs(result["coarse_E_difference"]) < 1e-12
    assert result["coarse_phi_difference"] < 1e-9 and result["minres_ratio"] > 2
    assert result["stability"]["eigenvalues_agree"] < 1e-8
    assert result["pins"] == 6 and pinned["converged"] and free["converged"]
    assert pinned["iterations"] <= free["iterations"]
    assert pinned["pins_moved"] < 1e-5 and pinned["centroid_moved"] < 5e-5
    assert free["pins_moved"] > 0.1 and free["centroid_moved"] > 2e-4
    assert (out / "newton3d_bench_quick.json").is_file()


def check_switch(result, out):
    """At ε = 0.04 on 32³: the oblate's m = 2 saddle, switched into 3D, ends on a stable
    steady state (Newton converges from it; no negative 3D eigenvalue) of the oblate's v,
    elongated like the prolate and within 0.5 % of the axisymmetric prolate's e (measured:
    −0.11 % on this coarse mesh), below the oblate's."""
    (c,) = result["switches"]
    assert c["status"] == "steady" and c["unstable_3d"] == 0
    assert c["label"] in ("prolate", "cylinder") and c["e"] < c["oblate_e"]
    assert abs(c["e"] / c["prolate_e"] - 1) < 5e-3
    a, b, cc = c["semi_axes"]
    assert a > 2 * b and abs(b / cc - 1) < 0.15
    assert (out / "switch_quick.md").is_file() and (out / "switch_quick-eps=0.04.png").is_file()


def check_ade_octant(result, out):
    """At ε = 0.04: the oblate past its m = 2 bifurcation, revolved onto the octant, stays an
    axisymmetric oblate within 2e-4 of its (r, z) e (the control); kicked along cos 2θ it
    leaves it for an elongated body of lower e (measured: a gourd, e 0.063 below)."""
    (c,) = result["cases"]
    control, kicked = c["control"], c["kicked"]
    assert c["rz"]["lowest"][2] < 0 and control["status"] == kicked["status"] == "steady"
    assert abs(control["e"] / c["rz"]["e"] - 1) < 2e-4
    assert control["semi_axes"][0] < 1.2 * control["semi_axes"][1]  # still round in x, y
    assert kicked["e"] < control["e"] - 0.01
    assert kicked["semi_axes"][0] > 2 * kicked["semi_axes"][1]  # elongated
    assert (out / "ade_octant_quick.md").is_file() and (out / "ade_octant_quick.png").is_file()


def check_branch3d(result, out):
    """At ε = 0.04 on 32³ nodes of order 8: three points of the oblate's m = 2 branch in 3D,
    the first two at the mode's amplitudes 0.1 and 0.2, each triaxial (three different
    semi-axes: the mode's D2 shape) with its e within 2 % of the oblate's at the same v
    (they meet at the bifurcation), the report and figure written."""
    (c,) = result["cases"]
    assert c["m"] == 2 and len(c["rows"]) == 3
    rows = c["rows"]
    assert [r["amplitude"] for r in rows[:2]] == pytest.approx([0.1, 0.2], abs=1e-9)
    for r in rows:
        a1, a2, a3 = r["semi_axes"]
        assert a1 > a2 * 1.005 and a2 > a3 * 1.05
        if r["e_oblate"] is not None:
            assert abs(r["e"] / r["e_oblate"] - 1) < 0.02
        assert r["unstable_3d"] is not None and len(r["eigenvalues"]) == 4
    assert (out / "branch3d_quick.md").is_file() and (out / "branch3d_quick.png").is_file()


def check_branch3d_octant(result, out):
    """At ε = 0.04 on 32 nodes per L of order 8: the octant's first two points of the
    oblate's m = 2 branch equal the box's from the same (r, z) window (v and e to 1e-10),
    the ladder's least-squares fit v = v_c + c a² over its 3 points is numpy's, and the
    branch's points are triaxial with the mode's amplitude growing."""
    (c,) = result["cases"]
    ctl = result["control"]
    assert ctl["points"] == 2 and ctl["dv"] < 1e-10 and ctl["de"] < 1e-10
    (m,) = c["ladder"]
    v = [r["v"] for r in m["rows"]]
    a2 = np.array([r["amplitude"] ** 2 for r in m["rows"]])
    c_fit, vc_fit = np.polyfit(a2, v, 1)  # the fit, made independently
    assert len(v) == 3 and m["v_c"] == pytest.approx(vc_fit, abs=1e-12)
    assert m["c"] == pytest.approx(c_fit, rel=1e-9)
    assert m["residual"] == pytest.approx(np.max(np.abs(vc_fit + c_fit * a2 - v)), rel=1e-6)
    rows = c["rows"]
    assert [r["amplitude"] for r in rows[:2]] == pytest.approx([0.1, 0.2], abs=1e-9)
    assert all(b["amplitude"] > a["amplitude"] for a, b in zip(rows, rows[1:], strict=False))
    for r in rows[1:]:
        a1, a2, a3 = r["semi_axes"]
        assert a1 > a2 * 1.005 and a2 > a3 * 1.05
        assert r["unstable_3d"] is not None and len(r["eigenvalues"]) == 2
    assert (out / "branch3d_octant_quick.md").is_file()
    assert (out / "branch3d_octant_quick.png").is_file()


def check_starfish(result, out):
    """At ε = 0.02, v = 0.5 between Δa₀ = 1.35 and 1.46: the discocyte's block m = 3 turns
    unstable (a window opens; measured at 1.41 on the full line), the other blocks m ≥ 2
    stay stable; the unstable mode lives inside the rim where the body is ~2 ε thick
    (not a rim mode); the report and figure written."""
    (x,) = result["lines"]
    assert x["failed"] is None and result["switches"] == []
    w = _load(STUDIES / "starfish.py").windows(x)
    assert list(w) == [3], w
    ((lo, hi),) = w[3]
    assert 1.38 < lo < 1.44 and hi is None
    site = x["sites"]["3"]  # inside the rim, where the body is ~2 ε thick (measured 2.03)
    assert site["eigenvalue"] < 0 and site["r_over_rim"] < 0.6 and site["thickness_eps"] < 3
    assert (out / "starfish_quick.md").is_file() and (out / "starfish_quick.png").is_file()


def check_triaxial(result, out):
    """The oblate at ε = 0.04, v = 0.85 (unstable in m = 2), its m = 2 branch on the
    Fourier–(r, z) geometry at two amplitudes, in v: each point steady (v an unknown of the
    bordered Newton system, the pin's multiplier zero: measured 5.7e-10 and 4.8e-8), its
    first cosine the amplitude's size, n_θ doubled at the second (its top cosine 2.8e-3 of
    the first on 4 angles: measured). The bifurcation is
    subcritical in v there (measured: v 0.79927, then 0.79875; e above the oblate's by
    3.9e-7, then 6.3e-6): the branch lies on the oblate's stable side and above it."""
    (line,) = result["lines"]
    assert line["failed"] is None and line["rows"][0]["lowest_m2"] < 0
    pts = result["points"]
    assert [x["amplitude"] for x in pts] == [0.1, 0.2] and result["param"] == "v"
    assert [x["n_theta"] for x in pts] == [4, 8]
    for x in pts:
        assert x["method"] == "bordered" and abs(x["lam_pin"]) < 1e-6
        assert x["cosines"][0] == pytest.approx(1.0, abs=0.05)
        assert 0.5 * x["amplitude"] < x["cosines"][1] < 1.5 * x["amplitude"]
        assert x["tail"] <= 1e-3 and math.isfinite(x["e"])
    assert pts[1]["v"] < pts[0]["v"] < line["rows"][0]["v"]
    assert 0 < pts[0]["e"] - pts[0]["e_oblate"] < pts[1]["e"] - pts[1]["e_oblate"]
    text = (out / "triaxial_quick.md").read_text()
    assert text.count("| 0.1 |") == 1 and text.count("| 0.2 |") == 1


def check_starfish_octant(result, out):
    """A short discocyte line at ε = 0.01, v = 0.7 (its blocks m = 2, 3, 4 unstable from
    Δa₀ = 1.45: measured on the full line from 1.456), 10 steps of the octant's m = 4 flow
    from it and 10 of the reseeded run at ε = 0.02: each end described (a body of genus 0
    with the octant's mirrors, e finite, the discocyte's e beside the flow's within 2 % after
    10 steps), the report written with a row per end."""
    (line,) = result["lines"]
    assert line["failed"] is None and line["branch"] == "oblate"
    assert all(r["lowest"][m] < 0 for r in line["rows"] for m in (2, 3, 4))
    (sw,), (re,) = result["switches"], result["ladder"]
    assert (sw["m"], sw["eps"], sw["geometry"], sw["n"]) == (4, 0.01, "octant", 128)
    assert (re["eps"], re["geometry"], re["n"]) == (0.02, "octant", 96)
    for x in (sw, re):
        assert x["status"] == "max_steps" and x["steps"] == 10 and x["genus"] == [0]
        assert x["stability"] is None and math.isfinite(x["e"])
    study = _load(STUDIES / "starfish_octant.py")
    disc = study.e_at_da0(line, sw["da0"])
    assert disc == pytest.approx(sw["e"], rel=0.02)
    assert study.e_at_da0(line, 9.0) is None
    text = (out / "starfish_octant_quick.md").read_text()
    assert text.count("| m = 4 | 0.01 |") == 1 and text.count("| reseeded | 0.02 |") == 1
    # the reseeded end's three lowest sector eigenvectors, each kicked and run 10 steps
    dirs = result["directions"]
    assert [r["j"] for r in dirs] == [0, 1, 2]
    lams = [r["eigenvalue"] for r in dirs]
    assert lams == sorted(lams) and all(map(math.isfinite, lams))
    for r in dirs:
        assert r["parity"] in ("A1", "B1") and 0 <= r["mixed"] <= 1
        assert (r["end"]["status"], r["end"]["steps"], r["end"]["n"]) == ("max_steps", 10, 96)
        assert math.isfinite(r["end"]["e"]) and r["end"]["genus"] == [0]
    assert text.count("kicked flow's end") == 1 and text.count(" steps, ") >= 5


ARGS = {"readme_figure": ["--steps", "2", "--n", "24"], "ade_azimuthal": ["--quick", "--refine"]}
#: where each study writes by default (under the current directory)
DEFAULT_OUT = {"gallery": "runs/gallery", "readme_figure": "runs/readme"}


def _checkout_status() -> str | None:
    """``git status`` of the checkout (None where it is not a git checkout)."""
    import subprocess

    root = STUDIES.parent
    if not (root / ".git").exists():
        return None
    r = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=all"],
                       capture_output=True, text=True)
    return r.stdout if r.returncode == 0 else None


@pytest.mark.parametrize("path", [pytest.param(p, marks=pytest.mark.slow) if p.stem in SLOW
                                  else p for p in SCRIPTS], ids=[p.stem for p in SCRIPTS])
def test_study_quick_mode(path, tmp_path, capsys, monkeypatch):
    """Each study's quick mode, run as documented (no --out, from some folder): its figures
    make sense, it writes under runs/ there, and the checkout is left as it was."""
    _needs_mpi(path)
    module = _load(path)
    assert capsys.readouterr().out == "", "a study must be quiet on import"
    check = globals().get(f"check_{path.stem}")
    assert check is not None, f"add check_{path.stem} to tests/test_studies.py"
    before = _checkout_status()
    monkeypatch.chdir(tmp_path)
    result = module.main(ARGS.get(path.stem, ["--quick"]))
    check(result, tmp_path / DEFAULT_OUT.get(path.stem, "runs/studies"))
    assert _checkout_status() == before, "the study wrote into the checkout"


def test_gallery_plan():
    """The gallery's plan: d halves ε in the variant each scene's verdict rests on (b for the
    discocyte, the seeded c for the torus), only on the spectral backend; the seedless ε = 0.05
    scenes have no c and say why; --steps-a sets the paper recipe's length."""
    gallery = _load(STUDIES / "gallery.py")
    cases = gallery.plan(["discocyte", "torus", "biconcave"], ["spectral", "fem"],
                         gallery.VARIANTS, quick=False, max_steps=300, steps_a=700)
    by = {(c["variant"], c["backend"], c["scene"]): c["kwargs"] for c in cases}
    assert by[("d", "spectral", "torus")]["ic"] == "seeded"
    assert by[("d", "spectral", "torus")]["n"] == 128
    assert "ic" not in by[("d", "spectral", "discocyte")]
    assert not any(k[0] == "d" and k[1] == "fem" for k in by)
    assert not any(k[0] == "d" and k[2] == "biconcave" for k in by)
    assert ("c", "spectral", "biconcave") not in by
    assert gallery.no_seed("c", "biconcave") and gallery.no_seed("c-loc", "cylinder")
    assert gallery.no_seed("c", "torus") is None and gallery.no_seed("b", "biconcave") is None
    assert by[("a", "fem", "torus")]["steps"] == 700
    assert by[("b", "spectral", "torus")]["max_steps"] == 300
    with pytest.raises(SystemExit):
        gallery.main(["--steps-a", "0", "--report-only"])
    # d is the sharp-interface check: ε halved, the reduced targets (v₀, Δa₀) the same
    for name in ("discocyte", "torus"):
        base = gallery.scene_for({"variant": "b", "scene": name}).params
        half = gallery.scene_for({"variant": "d", "scene": name}).params
        assert half.eps == pytest.approx(base.eps / 2)
        assert half.reduced_targets() == pytest.approx(base.reduced_targets(), rel=1e-12)


def test_gallery_keeps_an_interrupted_run(tmp_path):
    """A run stopped by Ctrl-C is not analysed or slimmed (its checkpoint stays for the next
    sitting): the gallery stops instead; a failed one is reported with its reason and
    left out; a kick skipped because its case did not end steady is not looked at."""
    import json

    from fem_ade.engine.jobs import record_failure

    gallery = _load(STUDIES / "gallery.py")
    case = gallery.plan(["discocyte"], ["spectral"], ["b"], quick=True)[0]
    folder = gallery.case_dir(tmp_path, case)
    folder.mkdir(parents=True)
    (folder / "summary.json").write_text(json.dumps({"status": "interrupted"}))
    (folder / "checkpoint.npz").write_bytes(b"x")
    with pytest.raises(KeyboardInterrupt):
        gallery.finish_case(tmp_path, case, {}, keep=False)
    assert (folder / "checkpoint.npz").is_file()
    assert not (folder / "analysis.json").exists()
    (folder / "summary.json").write_text(json.dumps({"status": "steady"}))
    record_failure(gallery.kick_dir(folder), "ModelError: made to fail")
    assert gallery.finish_case(tmp_path, case, {}, keep=False) is None
    assert (folder / "checkpoint.npz").is_file()


def test_gallery_is_one_sweep_of_listed_points():
    """Every case is a listed point of the paper's scene with its variant's changes and
    options; every case but the paper's recipe (a) has a kick after it, when it is steady."""
    gallery = _load(STUDIES / "gallery.py")
    cases = gallery.plan(["discocyte", "torus"], ["spectral", "fem"], gallery.VARIANTS,
                         quick=True)
    specs = [gallery.point_spec(c) for c in cases]
    kicks = [gallery.kick_spec(s) for c, s in zip(cases, specs, strict=True) if c["variant"] != "a"]
    sweep = gallery.as_sweep(specs + kicks)
    points = {p.name: p for p in sweep.points()}
    assert len(points) == len(cases) + len(kicks)
    for c in cases:
        point = points[gallery.point_name(c["variant"], c["backend"], c["scene"])]
        assert point.scene() == gallery.scene_for(c)
        assert point.options(point.scene())["n"] == c["kwargs"]["n"]
    kick = points["d_spectral_torus_kick"]
    assert kick.after == "d_spectral_torus" and kick.when == ("steady",)
    assert kick.options(kick.scene())["perturb"] == gallery.KICK[0]
    assert points["d_spectral_torus"].scene().params.eps == pytest.approx(
        gallery.scene_for({"variant": "b", "scene": "torus"}).params.eps / 2)


def test_package_verdicts_are_the_committed_gallerys():
    """fem_ade/verdicts.json (what ``python -m fem_ade.run --list`` shows) is made from the
    committed gallery's archive by ``studies/gallery.py --report-only``: no verdict there
    that the archive does not give, none missing."""
    import json

    gallery = _load(STUDIES / "gallery.py")
    made = gallery.merged_verdicts(gallery.archived_verdicts(), {})
    assert made == json.loads(gallery.VERDICTS.read_text())


#: the studies that rebuild their committed report from their archived rows (the run folders
#: are not committed: each finished run is skipped, each cached row read), with the arguments
#: that made it; phase_diagram's (30 s of sharp solves) runs with -m slow
REPORTS = {"constraints_study": [], "sharp_limit": [], "gallery": [], "ade_plane": [],
           "axisymmetric": [], "nonaxisymmetric": ["--eps", "0.02"], "eps_ladder": [],
           "phase_diagram": [], "branches": [], "ade_branches": [], "azimuthal": [],
           "ade_azimuthal": [], "branch3d": [], "starfish": [], "ade_limit": [],
           "ade_bifurcations": [], "ade_octant": [], "branch3d_octant": [],
           "starfish_octant": [], "switch": [], "triaxial": []}


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow)
                                  if n in SLOW - {"ade_plane"} else n for n in REPORTS])
def test_committed_report_is_rebuilt_from_its_rows(name, tmp_path, monkeypatch):
    """``--report-only`` on a copy of the committed results (git's files only) leaves every
    committed file as it is, to the digits it means (tests/report_compare.py: JSON floats to
    1e-9 relative, printed numbers to their last digit, integers and words exactly, pictures
    to 0.02 % of their pixels): a report says what its rows say, and no committed table or
    picture is out of date (sharp_limit.md once lacked a paragraph of its notes). Byte
    equality was a property of one machine: a fresh one rewrote sharp_limit.json's floats in
    their 16th digit."""
    import shutil
    import subprocess

    root = STUDIES.parent
    listed = subprocess.run(["git", "-C", str(root), "ls-files", "studies/results"],
                            capture_output=True, text=True)
    if listed.returncode != 0 or not listed.stdout.strip():
        pytest.skip("not a git checkout: the committed files are not known")
    files = listed.stdout.split()
    for f in files:
        (tmp_path / f).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(root / f, tmp_path / f)
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "studies" / "results"
    out_of = {"gallery": out / "gallery"}
    _load(STUDIES / f"{name}.py").main(["--report-only", "--out", str(out_of.get(name, out)),
                                        *REPORTS[name]])
    changed = {f: d for f in files
               if (d := differences(f, (root / f).read_bytes(), (tmp_path / f).read_bytes()))}
    assert not changed, f"{name} --report-only changed {changed}"


def test_report_comparison_keeps_meaning_and_catches_stale_reports():
    """The report test's comparison (tests/report_compare.py): a float's last bits, a number
    on a rounding boundary and a re-encoded equal picture pass; a changed count, a value
    moved beyond its printed digits, a changed word, a float off by 1e-6 in JSON and a
    changed picture fail."""
    import io

    from PIL import Image

    assert not differences("a.json", b'{"order_e": 1.5264050679115821, "n": 3}',
                           b'{"order_e": 1.526405067911581, "n": 3}')
    assert differences("a.json", b'{"order_e": 1.5264050679115821}', b'{"order_e": 1.5264066}')
    assert differences("a.json", b'{"n": 3}', b'{"n": 4}')
    assert differences("a.json", b'{"a": 1, "b": 2}', b'{"b": 2, "a": 1}')
    assert not differences("a.md", b"e = 4.452 (-21.7%)\n", b"e = 4.453 (-21.7%)\n")
    assert differences("a.md", b"e = 4.452\n", b"e = 4.454\n")
    assert differences("a.md", b"57 of 64 cells\n", b"58 of 64 cells\n")
    assert differences("a.md", b"prolate 0.61\n", b"oblate 0.61\n")
    assert differences("a.md", b"a\nb\n", b"a\n")

    def png(value, spot=None, level=9):
        im = Image.new("RGB", (100, 100), (value, value, value))
        if spot is not None:
            for i in range(30):
                im.putpixel((i, i), spot)
        buf = io.BytesIO()
        im.save(buf, format="PNG", compress_level=level)
        return buf.getvalue()

    assert png(200, level=1) != png(200)
    assert not differences("a.png", png(200, level=1), png(200))
    assert differences("a.png", png(200), png(200, (0, 0, 0)))


def test_committed_results_stay_under_6_5_mb():
    """A clone carries the results a reader needs, not bulk run data (≤ 6.5 MB in all: 5.18 MB
    with the azimuthal study's nine branch tables and the ADE plane's 64 cells, 2026-12-04;
    6.06 MB with the ADE lines' modes at two ε, 2026-12-07; 6.25 MB with the D2 branch on
    the octant, 2026-12-07 (the cap was 6.2 MB); 6.30 MB with the starfish on the octant,
    2026-12-07 (the cap was 6.3 MB); 6.44 MB with the triaxial branch on the Fourier-(r, z)
    geometry, 2026-12-07 (the cap was 6.35 MB); 6.45 MB with that branch followed to a = 1.0
    and its figure's fifth panel, 2026-12-07 (the cap was 6.45 MB); one run folder's
    final.npz is 1-20 MB)."""
    import subprocess

    root = STUDIES.parent
    listed = subprocess.run(["git", "-C", str(root), "ls-files", "studies/results"],
                            capture_output=True, text=True)
    if listed.returncode != 0 or not listed.stdout.strip():
        pytest.skip("not a git checkout: the committed files are not known")
    sizes = {f: (root / f).stat().st_size for f in listed.stdout.split() if (root / f).is_file()}
    total = sum(sizes.values())
    largest = sorted(sizes, key=sizes.get)[-3:]
    assert total <= 6_500_000, f"{total / 1e6:.2f} MB committed; the largest: {largest}"


def test_ade_plane_runs_each_seed_as_a_point_of_one_sweep(tmp_path, monkeypatch):
    """The ADE plane's phase-field stage hands its seeded runs to _lib.seeded.make_runs (one
    sweep: each run a point of its own under OUT/ade/sweep) with their ADE, and archives
    each row in runs.json (its quick mode is slow; this plumbing broke once without a
    default-suite test noticing: a call without the folder the runs needed)."""
    ade_plane = _load(STUDIES / "ade_plane.py")
    calls = []

    def fake(root, jobs, workers=2):
        calls.append((root, jobs))
        return [(job, {"section": None, "e": 1.0}) for job in jobs]

    monkeypatch.setattr(ade_plane, "make_runs", fake)
    plane = ade_plane.QUICK[0.85]
    cache = {ade_plane._key(b, 0.85): {"rows": [{"m0": 1.8, "e": 1.0}]} for b in plane.branches}
    runs = ade_plane.pf_stage(tmp_path, ade_plane.QUICK, cache, 0.08, say=lambda text: None)
    ((root, jobs),) = calls
    assert root == tmp_path / "ade" and sorted(j.branch for j in jobs) == ["pear", "prolate"]
    assert all(j.ade == {"kbar": ade_plane.KBAR, "m0": 1.8} and j.eps == 0.08 for j in jobs)
    assert len({j.key for j in jobs}) == 2
    assert sorted(runs) == sorted(j.key for j in jobs) and all(r["m0"] == 1.8
                                                              for r in runs.values())
    assert json.loads((tmp_path / "ade" / "runs.json").read_text()) == runs


def test_ade_limit_takes_the_pear_at_a_cell_from_its_own_line():
    """ade_limit: where the pear's span lines stop short of a cell (at ε = 0.005 they end
    within 0.004 of their start), the pear's e there is the first point of its line seeded at
    the cell; a seed that became another shape makes the pear absent there (a note says
    so), and a cell line not followed leaves the cell unreached (ε = 0.01's verdict)."""
    lim = _load(STUDIES / "ade_limit.py")
    v, R0 = 0.8, 0.229
    reg = {"v": v, "branches": ["prolate", "pear"], "centre": 1.54, "span": [1.49, 1.64],
           "x_pf": None, "x_sharp": None}
    coarse = {"lines": [], "points": [{"v": v, "da0": 1.64, "pf": "prolate", "sharp": "pear"}]}
    sharp = {v: {"prolate": [], "pear": []}}

    def line(key, rows):
        rows = [{"da0": x, "e": e, "label": label, "fold": None} for x, e, label in rows]
        return {"key": key, "rows": rows, "missing": None, "seconds": 1.0}

    def judged(cell_label):
        archive = {}
        for key in lim.region_keys(reg, R0):
            lab = key["branch"]
            xs = (1.54, 1.56, 1.6, 1.64) if lab == "prolate" else (1.54, 1.5435)
            archive[lim.adl.line_name(v, key["line"])] = line(key, [(x, x, lab) for x in xs])
        assert sorted(lim.cell_keys(reg, R0, [1.4, 1.52, 1.64])) == [1.52, 1.64]
        if cell_label:
            key = lim.cell_keys(reg, R0, [1.64])[1.64]
            archive[lim.adl.line_name(v, key["line"])] = line(key, [(1.64, 1.0, cell_label)])
        res = lim.judged(coarse, sharp, [reg], {v: R0}, archive, [], {})
        return res["cells"][0], res["notes"]

    cell, notes = judged("pear")
    assert cell["limit"] == "pear" and cell["e"]["pear"]["fine"] == 1.0, cell
    assert cell["how"].startswith("ε = 0.005 ") and not notes, (cell, notes)
    cell, notes = judged("2 vesicles")
    assert cell["limit"] == "prolate" and cell["e"]["pear"]["fine"] is None, cell
    assert "but not to this cell" not in cell["how"], cell  # absent, not unreached
    assert notes == ["v = 0.8, pear@1.640-cell: its seed there became a 2 vesicles"], notes
    cell, _ = judged(None)
    assert cell["limit"] == "prolate" and "but not to this cell" in cell["how"], cell


def test_seeded_runs_are_points_of_one_sweep(tmp_path):
    """_lib.seeded.make_runs: two seeded steady states (the quick prolate at ε = 0.08 on the
    axisymmetric FEM, a second ε) as one sweep, each run in its own point folder, and the
    rows equal to what the same run made alone gives (_lib.seeded.seeded, simulated here);
    a second call finds them done and runs nothing."""
    from types import SimpleNamespace

    import _lib.seeded as seeded
    from _lib.sharp import Cache
    from fem_ade.engine.runs import recipe, simulate

    cache = Cache(tmp_path / "solves.json")
    sharp = cache.get("prolate", 0.8)
    jobs = [SimpleNamespace(key=f"axisymmetric/prolate@0.8000/{eps:.4f}", sharp=sharp,
                            branch="prolate", eps=eps, backend="axisymmetric", ade={})
            for eps in (0.08, 0.064)]
    made_runs = seeded.make_runs(tmp_path / "sharp", jobs)
    assert [job for job, _ in made_runs] == jobs
    rows = {job.key: row for job, row in made_runs}
    points = tmp_path / "sharp" / "sweep" / "points"
    assert sorted(p.name for p in points.iterdir() if p.is_dir()) == sorted(
        seeded.point_name(j.key) for j in jobs)
    made = seeded.seeded(sharp, "prolate", 0.08, "axisymmetric")
    alone = simulate(made.scene, **recipe("steady", made.scene), **made.run)
    assert rows[jobs[0].key]["steps"] == alone.steps
    assert rows[jobs[0].key]["W"] == alone.final["W"]  # bit for bit
    stamp = (points / seeded.point_name(jobs[0].key) / "summary.json").stat().st_mtime_ns
    again = seeded.make_runs(tmp_path / "sharp", jobs)
    assert [r["e"] for _, r in again] == [r["e"] for r in rows.values()]
    assert (points / seeded.point_name(jobs[0].key) / "summary.json").stat(
    ).st_mtime_ns == stamp


def _reaches_another_study(source: str, studies: set[str]) -> list[str]:
    """What in a study's (or the library's) source reaches another study: ``sys.path``
    touched, a module loaded from its file (``spec_from_file_location``), or a study
    imported by its name (``import X``, ``from X import``, ``import_module("X")``)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Attribute) and node.attr == "path" \
                and isinstance(node.value, ast.Name) and node.value.id == "sys":
            found.append(f"{node.lineno}: sys.path")
        elif isinstance(node, ast.Attribute) and node.attr == "spec_from_file_location" \
                or isinstance(node, ast.Name) and node.id == "spec_from_file_location":
            found.append(f"{node.lineno}: spec_from_file_location")
        elif isinstance(node, ast.Import):
            found += [f"{node.lineno}: import {a.name}" for a in node.names
                      if a.name.split(".")[0] in studies]
        elif isinstance(node, ast.ImportFrom) and not node.level:
            module = node.module or ""
            if module.split(".")[0] in studies:
                found.append(f"{node.lineno}: from {module} import")
            found += [f"{node.lineno}: from {module} import {a.name}" for a in node.names
                      if (module, a.name) in (("sys", "path"),
                                              ("importlib.util", "spec_from_file_location"))]
        elif isinstance(node, ast.Call) and node.args \
                and isinstance(node.args[0], ast.Constant) \
                and getattr(node.func, "attr", getattr(node.func, "id", None)) in (
                    "import_module", "__import__") \
                and str(node.args[0].value).split(".")[0] in studies:
            found.append(f"{node.lineno}: import_module({node.args[0].value!r})")
    return found


def test_no_study_imports_another():
    """Each study stands on fem_ade and the studies' library (studies/_lib) alone: none
    touches sys.path, loads a file as a module, or imports another study (they once did, by
    path, for a cache, a fit or a seed); what they share is in _lib. A leak of each kind,
    put back in a source, is caught."""
    studies = {p.stem for p in SCRIPTS}
    sources = [*SCRIPTS, *sorted((STUDIES / "_lib").glob("*.py"))]
    found = {p.relative_to(STUDIES).as_posix(): leaks for p in sources
             if (leaks := _reaches_another_study(p.read_text(), studies))}
    assert found == {}, found
    leaks = ("import sys\nsys.path.insert(0, 'studies')\n",
             "from sys import path\n",
             "def f():\n    from sharp_limit import make_runs\n",
             "import ade_plane as plane\n",
             "import importlib.util\nimportlib.util.spec_from_file_location('c', 'cost.py')\n",
             "from importlib.util import spec_from_file_location\n",
             "import importlib\nimportlib.import_module('convergence')\n")
    for leak in leaks:
        assert _reaches_another_study(leak, studies), leak
    assert _reaches_another_study("from _lib.fits import time_to\nimport sys\n", studies) == []

