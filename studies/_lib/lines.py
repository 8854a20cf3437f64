"""The ADE plane's lines (``studies/ade_branches.py`` at ε = 0.01, ``studies/ade_limit.py`` at
0.005): branches of the ``vesicle`` family followed in Δa₀ along lines of fixed v
(κ̄/κ = 1.4), each line a point of one branch sweep, archived in ``lines.json`` under what it
is (:func:`line_key`); which of a line's points are its branch (:func:`kept`); the sharp
lines and R₀ the first study keeps. A line's point is named by :func:`line_name` (its folder
under ``OUT/ade_branches/sweep/points``), by which the nonaxisymmetric study finds the lines
it revolves into 3D."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace


def line_name(v: float, name: str) -> str:
    """A line's point in the sweep (its folder's name)."""
    return f"v={v:g}_{name}"


KBAR = 1.4


EPS = 0.01


V = tuple(round(0.6 + 0.05 * i, 2) for i in range(8))


BRANCHES = ("prolate", "pear", "oblate", "stomatocyte", "torus")


#: where each branch's phase-field line starts and ends; the pear (it exists at large Δa₀
#: only, and at 1.64 its neck is closed at ε = 0.01) is followed up and down from just above
#: the least m₀ at which the sharp pear was found (``PEAR_INSIDE``)
DEFAULT_SPAN = (0.8, 1.64)


PEAR_INSIDE = 0.02


#: the torus is also followed down from here (at v = 0.6, ε = 0.01, its seed at Δa₀ = 0.8
#: closes its hole: a discocyte, which opens into the torus at Δa₀ = 1.09)
TORUS_MIDDLE = 1.2


#: the genus-0 branches told apart by da where their labels do not (a pear whose label reads
#: gourd, a discocyte with deep dimples)
PAIRED = {"prolate": "pear", "pear": "prolate", "oblate": "stomatocyte",
          "stomatocyte": "oblate"}


STEP = 0.04


#: the branch code the plane's lines are followed with, in their archive's key (a line
#: archived with another is followed again): 1 at e4098a1; 2 the continuation's predictor,
#: its stability without the translation mode and its convergence test; 3 direct solves
#: (PARDISO or SuperLU: Newton's and shift-invert Lanczos's)
LINE_VERSION = 3


#: a genus-0 point whose label names neither branch of its pair is the one whose sharp da is
#: nearest its surface's, within this (the pear's da is 0.17–0.2 above the prolate's, the
#: stomatocyte's 0.2–0.6 below the oblate's: ``studies/results/ade_plane.md``; at ε/R₀ = 0.06 the
#: stomatocyte's surface da is 0.1 below the sharp one's)
DA_TOL = 0.15


#: --quick: one line, two branches, a short span, coarse
QUICK = SimpleNamespace(eps=0.04, v=(0.85,), da0=(1.04, 1.16), branches=("prolate", "oblate"),
                        span=(1.04, 1.16), step=0.06, sharp_m0=(1.0, 1.04, 1.12, 1.16, 1.2))


def line_spans(branch: str, sharp_rows: list[dict], quick: bool) -> list[tuple]:
    """(name, (from, to)) of the phase-field lines of ``branch`` on one v: one from 0.8 up;
    the pear's two, up and down from just above the sharp pear's least m₀ (none where
    there is no sharp pear)."""
    if quick:
        return [(branch, QUICK.span)]
    if branch == "torus":  # where its hole closes at 0.8 (v = 0.6), it opens further up
        return [(branch, DEFAULT_SPAN), ("torus-down", (TORUS_MIDDLE, DEFAULT_SPAN[0])),
                ("torus-up", (TORUS_MIDDLE, DEFAULT_SPAN[1]))]
    if branch != "pear":
        return [(branch, DEFAULT_SPAN)]
    if not sharp_rows:
        return []
    start = round(sharp_rows[0]["m0"] + PEAR_INSIDE, 4)
    return [("pear-up", (start, DEFAULT_SPAN[1])), ("pear-down", (start, DEFAULT_SPAN[0]))]


def line_key(v: float, branch: str, name: str, span, R0: float, eps: float, step,
             **more) -> dict:
    """What a phase-field line is (its archived rows are reused only for the same): the
    branch followed in Δa₀ over ``span`` at v, R₀, ε and κ̄, its step, and the model's
    physics version and the branch code's (:data:`LINE_VERSION`); ``more``: what else a
    study's lines are followed with (``modes``)."""
    from fem_ade.model.params import PHYSICS_VERSION

    return {"v": v, "branch": branch, "line": name, "from": span[0], "to": span[1],
            "R0": R0, "eps": eps, "kbar": KBAR, "step": step, "physics": PHYSICS_VERSION,
            "version": LINE_VERSION, **more}


def line_point(key: dict) -> dict:
    """A line as a listed point of the branch sweep: the vesicle of its branch at the line's
    start, or the pear's seed (:func:`fem_ade.scenes.pear.pear_scene`, by continuation where
    it must) as the point's own scene; ModelError where the pear has none."""
    branch = {"param": "da0", "from": key["from"], "to": key["to"], "step": key["step"],
              "folds": 0, "modes": key.get("modes", 0)}
    spec = {"name": line_name(key["v"], key["line"]), "seed": key["branch"],
            "branch": branch, "base": "vesicle",
            "scene": {"v": key["v"], "kbar": KBAR, "eps": key["eps"], "R0": key["R0"]}}
    if key.get("nodes_per_eps"):  # else the default 2.5 nodes per ε
        from fem_ade.backends.fem.axisym import DEFAULT_ORDER, default_nodes
        from fem_ade.scenes.catalogue import vesicle_scene

        L = vesicle_scene(sharp_seed=False, **spec["scene"], da0=key["from"],
                          branch=key["branch"]).params.L
        spec["run"] = {"n": default_nodes(key["eps"], L, DEFAULT_ORDER, key["nodes_per_eps"])}
    if key["branch"] == "pear":
        from fem_ade.scenes.catalogue import scene_to_mapping
        from fem_ade.scenes.pear import pear_scene

        spec.update(base=scene_to_mapping(pear_scene(key["v"], key["from"], key["eps"],
                                                     key["R0"], KBAR)), scene={})
    return spec


def archived(archive: dict, key: dict) -> dict | None:
    """A line's entry in ``archive`` where it was archived with ``key`` (None: not followed
    with these settings)."""
    got = archive.get(line_name(key["v"], key["line"]))
    return got if got is not None and got["key"] == key else None


def load_archive(base: Path) -> dict:
    """The lines archived in ``base/lines.json`` ({} where none are)."""
    path = base / "lines.json"
    return json.loads(path.read_text()) if path.is_file() else {}


def run_quick_plane(out: Path, workers: int) -> None:
    """``ade_branches.py --quick`` into ``out`` (its line, R₀ and sharp cache: what a study's
    quick mode builds on), quietly, as its own process."""
    import subprocess
    import sys

    script = Path(__file__).resolve().parents[1] / "ade_branches.py"
    subprocess.run([sys.executable, str(script), "--quick", "--out", str(out),
                    "--workers", str(workers)], check=True, stdout=subprocess.DEVNULL)


def run_lines(base: Path, keys: list[dict], archive: dict, workers: int) -> None:
    """Follow the lines not in ``archive`` (or archived with another key) as one branch
    sweep in ``base/sweep`` (:mod:`fem_ade.campaigns.sweep`: a Dask task per line, resumable, a
    failure recorded with its reason), and archive each line's outcome in
    ``base/lines.json`` as soon as the sweep has ended (:func:`archive_line`)."""
    from fem_ade.campaigns.sweep import run_sweep
    from fem_ade.campaigns.sweep_file import listed_sweep
    from fem_ade.model.params import ModelError
    from fem_ade.store.output import write_json_atomic

    specs, todo = [], []
    for key in keys:
        name = line_name(key["v"], key["line"])
        if archived(archive, key):
            continue
        try:
            specs.append(line_point(key))
            todo.append(key)
        except ModelError as err:  # no pear to start from, even by continuation
            archive[name] = {"key": key, "rows": [], "missing": str(err), "seconds": None}
    if specs:
        run_sweep(listed_sweep(base.name, specs), base / "sweep", workers=workers, quiet=True)
    for key in todo:
        name = line_name(key["v"], key["line"])
        archive[name] = archive_line(base / "sweep" / "points" / name, key)
    write_json_atomic(base / "lines.json", archive, indent=None, make_folder=True)


def archive_line(folder: Path, key: dict) -> dict:
    """A followed line's archive entry: its rows (branch.csv, the columns the report reads),
    or why it has none (its failure record's reason), and its seconds (the task's wall
    time: the seed and every Newton point)."""
    from fem_ade.campaigns.branch_folder import read_branch_table
    from fem_ade.engine.jobs import failure_record, read_failure, read_summary

    failed, summary = read_failure(folder), read_summary(folder)
    if failed is not None or summary is None:
        reason = failed["reason"] if failed else "not run"
        record = json.loads(failure_record(folder).read_text()) if failed else {}
        return {"key": key, "rows": [], "seconds": record.get("seconds"),
                "missing": reason.removeprefix("ModelError: ")}
    modes = key.get("modes", 0)
    rows = [_plain(r, modes) for r in read_branch_table(folder)]
    out = {"key": key, "rows": rows, "missing": None, "seconds": summary.get("seconds")}
    forks = folder / "bifurcations.json"
    if modes and forks.is_file():
        out["bifurcations"] = json.loads(forks.read_text())["bifurcations"]
    return out


def _plain(row: dict, modes: int = 0) -> dict:
    """A row's columns the reports read (with ``modes``: what tells the branch — e, the
    surface's da, the label, the fold — and each mode's lowest eigenvalue, the 3D unstable
    count and the seconds: ``studies/ade_bifurcations.py`` reads no more)."""
    keep = ("da0", "e", "E", "W", "G", "v_surface", "da_surface", "label", "unstable",
            "lowest_eigenvalue", "fold", "newton", "seconds")
    if modes:
        keep = ("da0", "e", "da_surface", "label", "fold", "seconds",
                *(f"lowest_m{m}" for m in range(modes + 1)), "unstable_3d")
    return {k: row.get(k) for k in keep}


# ---------------------------------------------------------------------------------------------
# the plane
# ---------------------------------------------------------------------------------------------
def on_branch(row: dict, branch: str, sharp: dict) -> bool:
    """Whether a phase-field point is ``branch``: a torus is labelled one; a genus-0 shape
    must be labelled as ``branch`` or its pair's other branch (:data:`PAIRED`), and where both
    have a sharp shape near this Δa₀ its surface's da must be nearer ``branch``'s, else
    (only ``branch``'s) within DA_TOL or labelled ``branch``."""
    from fem_ade.campaigns.branch_analysis import branch_of_label

    family = branch_of_label(row["label"])
    if branch == "torus" or family == "torus":
        return branch == family == "torus"
    if family not in (branch, PAIRED[branch]):
        return False
    own, other = (_da_distance(row, sharp.get(b, [])) for b in (branch, PAIRED[branch]))
    if own is None:
        return family == branch and other is None
    if other is None:
        return family == branch or own < DA_TOL
    return own < other


def _da_distance(row: dict, rows: list[dict]) -> float | None:
    """|da of the point's surface − the sharp branch's da at its Δa₀| (None: no sharp shape
    within 0.2 of its Δa₀; a branch's da changes slowly along Δa₀)."""
    pts = [(r["m0"], r["da"]) for r in rows]
    if row.get("da_surface") is None or not pts or \
            not pts[0][0] - 0.2 <= row["da0"] <= pts[-1][0] + 0.2:
        return None
    m, d = zip(*pts, strict=True)
    return abs(row["da_surface"] - _interp(row["da0"], m, d))


def _interp(x, xs, ys):
    import numpy as np

    return float(np.interp(x, xs, ys))


def kept(rows: list[dict], branch: str, sharp: dict) -> list[dict]:
    """The line's points up to its first fold, from its start while they are the branch."""
    out = []
    for r in rows:
        if not on_branch(r, branch, sharp):
            break
        out.append(r)
        if r.get("fold") not in (None, ""):
            break
    return out


def kept_lines(res: dict, branch: str, sharp: dict) -> list[dict]:
    """The kept points of a branch's lines (the pear's two), in order of Δa₀, each once."""
    rows = [r for line in res["lines"] for r in kept(line["rows"], branch, sharp)]
    return sorted({round(r["da0"], 12): r for r in rows}.values(), key=lambda r: r["da0"])


def archived_sharp(base: Path, v_list, branches) -> dict:
    """--report-only: the kept sharp lines (ModelError where one is missing)."""
    from fem_ade.model.params import ModelError

    sharp = {v: {} for v in v_list}
    for v in v_list:
        for b in branches:
            path = base / "sharp" / f"{b}-v={v:g}.json"
            if not path.is_file():
                raise ModelError(f"{path} is missing: run the study (without --report-only)")
            sharp[v][b] = json.loads(path.read_text())["rows"]
    return sharp


def archived_sizes(base: Path, v_list) -> dict:
    """--report-only: each line's R₀ as kept in ``base/R0.json``."""
    from fem_ade.model.params import ModelError

    path = base / "R0.json"
    known = {float(k): x for k, x in json.loads(path.read_text()).items()} \
        if path.is_file() else {}
    missing = [v for v in v_list if v not in known]
    if missing:
        raise ModelError(f"{path} has no R0 for v = {missing}: run the study first")
    return known


def plane_lines(sharp: dict, R0: dict, v_list, branches, eps: float, step: float,
                quick: bool, **more) -> tuple[dict, list[dict]]:
    """The plane's lines: {(v, branch): [(name, span), …]} (:func:`line_spans`) and their
    keys (:func:`line_key`, with ``more``), in that order."""
    spans = {(v, b): line_spans(b, sharp[v].get(b, []), quick) for v in v_list for b in branches}
    keys = [line_key(v, b, name, span, R0[v], eps, step, **more)
            for (v, b), lines in spans.items() for name, span in lines]
    return spans, keys


def curve(rows: list[dict], key: str = "da0", value: str = "e"):
    """``value`` along one branch as a function of ``key``: a cubic spline through its points
    where there are four, else linear; (the function, its range), None for fewer than two
    points."""
    import numpy as np
    from scipy.interpolate import CubicSpline

    pts = sorted({r[key]: r[value] for r in rows}.items())
    if len(pts) < 2:
        return None
    xs, ys = map(np.array, zip(*pts, strict=True))
    f = CubicSpline(xs, ys) if len(pts) >= 4 else (lambda x: np.interp(x, xs, ys))
    return f, float(xs[0]), float(xs[-1])


def at(c, x: float) -> float | None:
    """A :func:`curve` at ``x``, None outside its points (or for no curve)."""
    return None if c is None or not c[1] - 1e-9 <= x <= c[2] + 1e-9 else float(c[0](x))


def cross(a, b, centre: float) -> float | None:
    """The root of e_a − e_b nearest ``centre`` where both curves are defined (Brent on each
    sign change of a fine sampling), None where they do not cross."""
    import numpy as np
    from scipy.optimize import brentq

    if a is None or b is None:
        return None
    lo, hi = max(a[1], b[1]), min(a[2], b[2])
    if not lo < hi:
        return None
    xs = np.linspace(lo, hi, 401)
    d = a[0](xs) - b[0](xs)
    roots = [float(brentq(lambda x: float(a[0](x) - b[0](x)), xs[i], xs[i + 1]))
             for i in range(len(xs) - 1) if d[i] == 0.0 or d[i] * d[i + 1] < 0]
    return min(roots, key=lambda x: abs(x - centre)) if roots else None
