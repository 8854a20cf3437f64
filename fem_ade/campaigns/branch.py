"""Branches of steady states: pseudo-arclength continuation in one parameter, folds, and
stability (issue 32), on the FEM with Newton's method (:mod:`fem_ade.backends.fem.newton`).

    python -m fem_ade.branch vesicle --branch prolate --eps 0.01 --param v --from 0.95 \\
        --to 0.6 [--step 0.01] [--geometry axisymmetric] [--n N] [--order P] --out DIR

A branch starts at ``--from``: the scene's seed run to a steady state by the ``steady``
recipe's flow (to 1e-9 per step) and polished by Newton. Each further point is predicted
from the last ones and corrected by Newton on the extended system (pseudo-arclength, Keller
1977: :mod:`fem_ade.campaigns.continuation`), with an arclength step Δs between
``--step``/8 and 4·``--step``. A fold (turning point) is where the tangent's t_p changes
sign (:func:`fem_ade.campaigns.branch_analysis.mark_folds`). The branch ends at ``--to``,
at a topology change (:func:`fem_ade.campaigns.branch_analysis.same_topology`: an oblate
opening into a torus, a neck closing into two vesicles; a genus-0 shape whose label
changes — pear to gourd, discocyte to stomatocyte — goes on) or where Δs falls below its
least.

Stability: at each point the few lowest eigenvalues of the Hessian of the Lagrangian on the
constraints' tangent space (:func:`fem_ade.campaigns.continuation.stability`; with
``--modes``, those of each azimuthal mode). In the axisymmetric geometry only
axisymmetric directions are seen.

Parameters (the ``vesicle`` family's, mapped to the model's with the seed's R₀ = √(β/4π)
kept): ``v`` (α = (4π/3)R₀³v), ``da0`` (ΔA₀ = 8πDR₀·Δa₀), ``kbar`` (κ̄/κ), ``C``.

The branch folder (:mod:`fem_ade.campaigns.branch_folder`): ``points/NNNN/`` (each point's
φ and row), ``branch.json`` (what the branch is: a resumed one must be the same; its --to
may differ, on the same side of --from: the branch goes on to it), ``branch.csv`` (one
row per point: the parameter, e, E, W, G, unstable, label, fold, ...), ``branch.png`` (e
against the parameter: stable solid, unstable dashed, folds marked) and ``shapes.png``
(the meridians: :mod:`fem_ade.campaigns.branch_analysis`). Killed and started again with
the same command, a branch goes on from its last points — only from points it can vouch
for (:func:`fem_ade.campaigns.branch_folder.load_points`).

This module is the driver and the command: :func:`follow` (where the points are taken,
when the branch ends) and :func:`main`; the numerics, the folder and the reading of the
rows are the three modules above.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from fem_ade.backends.threads import limit_threads
from fem_ade.campaigns.branch_analysis import (
    bifurcations,
    branch_of_label,
    draw,
    mark_folds,
    same_branch,
    same_topology,
)
from fem_ade.campaigns.branch_folder import (
    check_out,
    identity_digest,
    load_points,
    lock_folder,
    open_folder,
    save_point,
    write_branch_table,
    write_ended,
)
from fem_ade.campaigns.continuation import (
    EIGENVALUES,
    GROW_BELOW,
    MIN_STEP,
    Continuation,
    describe_point,
)
from fem_ade.model.params import ModelError
from fem_ade.scenes.vesicle import PARAMETERS, get_parameter, set_parameter  # noqa: F401 (the branch's)

#: the most azimuthal modes a branch computes at each point, and the command line's default
MAX_MODES, DEFAULT_MODES = 32, 8
#: the first point's relaxation (the steady recipe) stops where E changes by less than this
#: per step (relative), then Newton: looser is not cheaper everywhere — measured at
#: ε = 0.005, one thread: the prolate at v = 0.69 36 s at 1e-9 (Newton 2 iterations), 8 s at
#: 1e-7 (6); the pear seeded at (v, Δa₀) = (0.8, 1.64) 255 s (8) and 283 s (52)
SETTLE = 1e-9


# ---------------------------------------------------------------------------------------------
# the parameter
# ---------------------------------------------------------------------------------------------
def check_parameter(params, name: str) -> None:
    if name not in PARAMETERS:
        raise ModelError(f"--param must be one of {', '.join(PARAMETERS)}, got {name!r}")
    if name in ("da0", "kbar") and not params.on("ade"):
        raise ModelError(f"--param {name} moves the ADE term, which is off in this scene "
                         "(the vesicle family: give --kbar and --da0)")
    if name == "C" and not params.on("spontaneous_curvature"):
        raise ModelError("--param C moves the spontaneous curvature, which is off in this "
                         "scene (give --C, e.g. 0.0 is not on: use a small value)")


def check_branch(params, param: str, start, stop, step, folds=None) -> None:
    """A branch's settings (ModelError, one line): the parameter (:func:`check_parameter`),
    two different ends, a step in (0, |to − from|], folds a whole number ≥ 0 or None."""
    check_parameter(params, param)

    def number(x):
        return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)

    if not (number(start) and number(stop)) or start == stop:
        raise ModelError(f"--from and --to must be two different numbers, got {start}, {stop}")
    if param == "v" and not (0 < start <= 1 and 0 < stop <= 1):
        raise ModelError(f"--from and --to of the reduced volume v must be in (0, 1] (v = 1 "
                         f"is the sphere), got {start}, {stop}")
    span = abs(stop - start)
    least = MIN_STEP * max(1.0, abs(start), abs(stop))
    if not (number(step) and least <= step <= span * (1.0 + 1e-9)):
        raise ModelError(f"--step must be in [{least:.3g}, |to - from| = {span:.6g}], got "
                         f"{step}")
    if folds is not None and (isinstance(folds, bool) or not isinstance(folds, int)
                              or folds < 0):
        raise ModelError(f"--folds must be a whole number >= 0, got {folds}")


def check_branch_name(branch) -> None:
    """The sharp branch a followed branch stands for (the vesicle family's, but the sphere:
    it is the point v = 1 of the prolate and the oblate)."""
    from fem_ade.registry import VESICLE_BRANCHES

    if branch == "sphere":
        raise ModelError("--branch sphere: the sphere is one point (v = 1) of the prolate and "
                         "oblate branches; follow --branch prolate or oblate from it")
    if branch not in VESICLE_BRANCHES:
        raise ModelError(f"--branch must be one of {', '.join(VESICLE_BRANCHES)}, got "
                         f"{branch!r}")


# ---------------------------------------------------------------------------------------------
# the driver
# ---------------------------------------------------------------------------------------------
@limit_threads
def follow(scene, *, param: str, start: float, stop: float, step: float, out: Path,
           backend_options: dict | None = None, n: int | None = None, quiet: bool = False,
           max_points: int = 400, folds: int | None = None,
           stable: bool = True, branch: str | None = None, modes: int = 0) -> list[dict]:
    """Follow the branch of ``scene``'s seed in ``param`` from ``start`` to ``stop`` (module
    docstring); the rows of branch.csv. ``folds``: end the branch at the point after its
    ``folds + 1``-th fold (0: the stable part from a stable start; None: go on past folds).
    ``stable=False``: no stability at the points (their ``unstable`` blank): at small ε the
    stability is most of a point's time. ``branch``: the sharp branch the seed stands for
    (the vesicle family's ``branch``); its first point must be one (ModelError otherwise: a
    torus seed that relaxes into an oblate is not followed as a torus). ``modes``: the
    azimuthal modes m = 1 … modes too (docs/model.md §13): each point's lowest eigenvalue
    per mode, its 3D unstable count, and the bifurcations where a mode's lowest eigenvalue
    crosses zero (bifurcations.json, branch.png)."""
    from fem_ade.backends.base import make_backend

    say = (lambda text: None) if quiet else (lambda text: print(text, flush=True))
    check_follow(scene, param=param, start=start, stop=stop, step=step,
                 backend_options=backend_options, n=n, folds=folds, branch=branch,
                 modes=modes)
    options = {"geometry": "axisymmetric", **(backend_options or {})}
    out = check_out(out)
    scene, config, identity = _branch_setup(scene, param, start, stop, step, n, options)
    if not stable:  # (absent when on: the folders of before stay theirs)
        identity["stability"] = False
    if stable and modes:  # (absent for modes = 0: the folders of before stay theirs)
        identity["modes"] = modes
    check = stability_check(stable, modes)
    lock = lock_folder(out)
    try:
        identity = open_folder(out, identity)
        tag = identity_digest(identity)
        be = make_backend("fem", scene, n=config.n, dt=config.dt, scheme="stabilized",
                          constraints="exact", **options)
        cont = Continuation(be, param)
        done = load_points(out, tag, be.phi.size, param)
        if not done:
            done = [_first_point(be, param, cont, out, config.dt, say, check, tag, branch)]
        rows = [r for r, _ in done]
        for r, _ in done:
            cont.theta = r.get("theta", cont.theta)
        meridians = []
        for r, phi in done[-10:]:
            be._set(phi, None)
            meridians.append((r[param], _curves(be)))
        direction = 1.0 if stop > start else -1.0
        ds = rows[-1].get("ds_next", step)  # a resumed branch takes the step it would have
        while (why := _end_of_branch(rows, param, stop, direction, max_points, folds)) is None:
            point = _next_point(be, cont, param, done, direction, ds, step, check)
            if isinstance(point, str):
                why = point
                break
            row, phi = point
            row = save_point(out, len(rows), be, row, tag)
            rows.append(row)
            done.append((row, phi.copy()))
            meridians.append((row[param], _curves(be)))
            say(_line(param, row))
            write_branch_table(out, param, mark_folds(rows, param))
            ds = row["ds_next"]
        if why:
            say(why)
        why = why or f"max_points = {max_points} reached"
        rows = _finish(out, param, rows, meridians, with_modes=bool(modes and stable))
        write_ended(out, param, rows, why)
    finally:
        lock.release()
    return rows


def _finish(out: Path, param: str, rows: list[dict], meridians: list,
            with_modes: bool) -> list[dict]:
    """The branch's table with its folds, its bifurcations (with the azimuthal modes) and
    its pictures; its rows."""
    from fem_ade.store.output import write_json_atomic

    rows = mark_folds(rows, param)
    write_branch_table(out, param, rows)
    if with_modes:
        write_json_atomic(out / "bifurcations.json",
                          {"param": param, "bifurcations": bifurcations(rows, param)})
    draw(out, param, rows, meridians)
    return rows


def stability_check(stable: bool, modes: int):
    """A branch point's stability, ``check(be)``: the m = 0 block's
    :data:`fem_ade.campaigns.continuation.EIGENVALUES` lowest, and with ``modes`` the lowest
    of each block m = 1 … modes (:func:`fem_ade.campaigns.stability.axisymmetric`), each
    block's Lanczos started near the lowest eigenvalues of the point checked before (its
    ``near``: the same eigenvalues, fewer solves); None without ``stable``."""
    if not stable:
        return lambda be: None
    from fem_ade.campaigns.stability import axisymmetric

    before: dict = {}  # the lowest per mode of the point checked before

    def check(be):
        out = axisymmetric(be, (0,), EIGENVALUES, near=before)
        if modes:
            more = axisymmetric(be, range(1, modes + 1), 1, near=before)
            out.modes.update(more.modes)
            out.unstable.update(more.unstable)
            out.unstable_3d += more.unstable_3d
        before.clear()
        before.update({m: out.lowest(m) for m in out.modes})  # (None: no shift tried)
        return out
    return check


def check_follow(scene, *, param: str, start: float, stop: float, step: float,
                 backend_options: dict | None = None, n: int | None = None,
                 folds: int | None = None, branch: str | None = None,
                 modes: int = 0) -> None:
    """What :func:`follow` checks before it makes anything, for a sweep to check its branch
    points before they run (ModelError, one line): the parameter and the ends, the branch's
    name, the geometry, and the run's configuration (n, order, the backend's options, the
    scene a surface of revolution)."""
    if backend_options is not None and not isinstance(backend_options, dict):
        raise ModelError(f"backend_options must be a table, got {backend_options!r}")
    options = {"geometry": "axisymmetric", **(backend_options or {})}
    if options["geometry"] != "axisymmetric":
        raise ModelError(f"a branch is followed in the axisymmetric geometry (its Newton "
                         f"solves and stability are the (r, z) ones), not "
                         f"geometry = {options['geometry']!r}")
    check_branch(scene.params, param, start, stop, step, folds)
    if branch is not None:
        check_branch_name(branch)
    if isinstance(modes, bool) or not isinstance(modes, int) or not 0 <= modes <= MAX_MODES:
        raise ModelError(f"--modes must be a whole number from 0 to {MAX_MODES}, got {modes!r}")
    _branch_setup(scene, param, start, stop, step, n, options)


def _branch_setup(scene, param: str, start: float, stop: float, step: float, n, options):
    """The scene at the branch's start, its run configuration (the ``steady`` recipe's Δt,
    exact constraints, the axisymmetric FEM) and the branch's identity: what its points are
    (not where they stop: a branch run again with another --to on the same side goes on
    from its points, or stops where it had)."""
    from fem_ade.engine.config import RUN_FORMAT, RunConfig
    from fem_ade.engine.runs import recipe

    scene = replace(scene, params=set_parameter(scene.params, param, start))
    steady = recipe("steady", scene)
    config = RunConfig.build(scene, backend="fem", n=n, dt=steady["dt"],
                             until_steady=SETTLE, max_steps=20000, scheme="stabilized",
                             constraints="exact", accelerate=True, backend_options=options)
    config.check(scene)
    identity = {"scene": scene.name, "params": scene.params.as_dict(), "param": param,
                "from": start, "direction": "up" if stop > start else "down", "step": step,
                "n": config.n, "options": options, "format": RUN_FORMAT}
    return scene, config, json.loads(json.dumps(identity, default=str))


def _first_point(be, param: str, cont, out: Path, dt: float, say, check, tag: str,
                 branch: str | None = None) -> tuple[dict, np.ndarray]:
    """The branch's first point: the seed relaxed to its steady state, then Newton's; saved
    as point 0 (ModelError where Newton does not converge, or where it is not of
    ``branch``); ``check``: its stability."""
    from fem_ade.backends.fem.newton import solve_steady
    from fem_ade.engine.loop import run_loop

    t0 = time.perf_counter()
    run_loop(be, dt=dt, until_steady=SETTLE, max_steps=20000, every=10, accelerate=True)
    newton = solve_steady(be, max_iterations=60)
    if not newton.converged:
        raise ModelError(f"the branch's first point did not converge: {newton.message}")
    row = _timed_row(be, param, cont, newton.iterations, t0, check)
    if branch is not None and not same_branch(branch, row["label"]):
        label = row["label"]
        article = "an" if str(label)[:1] in "aeiou" else "a"
        raise ModelError(f"the {branch} seed at {param} = {cont.p:.6g} relaxed into {article} "
                         f"{label}: the phase field has no steady {branch} there to "
                         f"follow (try another --from, or --branch "
                         f"{branch_of_label(row['label']) or row['label']})")
    row["s"] = 0.0
    row = save_point(out, 0, be, row, tag)
    say(_line(param, row))
    return row, be.phi.copy()


def _timed_row(be, param: str, cont, newton: int, t0: float, check) -> dict:
    """The point's row once Newton (started at ``t0``) has converged: its stability
    (``check``), its description, and its time — ``seconds`` all of it, ``newton_s`` and
    ``stability_s`` its parts (the latter None without stability)."""
    t1 = time.perf_counter()
    stab = check(be)
    t2 = time.perf_counter()
    row = describe_point(be, param, cont, newton, 0.0, stab)
    row["seconds"] = round(time.perf_counter() - t0, 2)
    row["newton_s"] = round(t1 - t0, 2)
    row["stability_s"] = None if stab is None else round(t2 - t1, 2)
    return row


def _end_of_branch(rows: list[dict], param: str, stop: float, direction: float,
                   max_points: int, folds: int | None) -> str | None:
    """Why the branch ends at its last point ('' without a word: ``max_points``), or None
    where it goes on."""
    last = rows[-1]
    p_k = last[param]
    if not same_topology(rows[0]["label"], last["label"]):  # a resumed one's too
        return (f"the branch ends at {param} = {p_k:.6g}: its shape became a "
                f"{last['label']} (a topology change)")
    if (p_k - stop) * direction >= 0:
        return f"reached {param} = {stop}"
    if len(rows) >= max_points:
        return ""
    turned = [r["fold"] for r in mark_folds(rows, param) if r["fold"]]
    if folds is not None and len(turned) > folds:
        return f"the branch ends after its fold at {param} = {turned[-1]} (--folds {folds})"
    return None


def _next_point(be, cont, param: str, done: list, direction: float, ds: float,
                step: float, check) -> tuple[dict, np.ndarray] | str:
    """The point one arclength step ``ds`` on from the last of ``done`` (along the tangent
    for the first step, then by secant prediction and Newton's correction, the step cut down
    to step/8 where Newton does not converge): its row and φ, or why the branch ends."""
    last_row, phi_k = done[-1]
    p_k = last_row[param]
    be._set(phi_k, None)
    cont.set_p(p_k)
    history = [(ph, r[param]) for r, ph in done[-3:]]
    first = None
    if len(done) < 2:  # the first step: along the tangent from the Newton system
        first = cont.tangent(phi_k)
        if first[1] * direction < 0:
            first = (-first[0], -first[1])
    ds_min, ds_max = step / 8.0, 4.0 * step
    t0 = time.perf_counter()
    corrected, ds = cont.advance(history, first, ds, ds_min)
    if corrected is None:
        return (f"the branch ends at {param} = {p_k:.6g}: Newton does not converge at an "
                f"arclength step of {ds_min:.3g}")
    phi, p, its = corrected
    be._set(phi, None)
    cont.set_p(p)
    row = _timed_row(be, param, cont, its, t0, check)
    row["s"] = last_row.get("s", 0.0) + ds
    row["ds_next"] = min(ds * 1.5, ds_max) if its <= GROW_BELOW else ds
    return row, phi


def _curves(be):
    from fem_ade.analysis.axishape import meridians

    try:
        return [c.copy() for c in meridians(be).curves]
    except Exception:  # noqa: BLE001 (a picture's curves, never the branch's numbers)
        return []


def vesicle_for_branch(chosen: dict, param: str, start: float, stop: float):
    """The ``vesicle`` scene whose seed is the branch's first point (``param`` at ``start``)
    and, without a given R₀, the R₀ with which the family's seed fits the box at both ends
    of the branch: the smaller of the two defaults (a prolate followed from v = 0.95 at that
    v's R₀ = 0.239 reached the box's ends near v = 0.72 and stopped there, ε = 0.01)."""
    from fem_ade.scenes.catalogue import vesicle_scene

    if "R0" not in chosen:
        sizes = []
        for value in (start, stop):
            try:
                s = vesicle_scene(**{**chosen, param: value})
            except ModelError:  # no seed at that end (outside the family): the start decides
                continue
            sizes.append(math.sqrt(s.params.beta / (4.0 * math.pi)))
        if sizes:
            chosen = {**chosen, "R0": round(min(sizes), 6)}
    return vesicle_scene(**{**chosen, param: start})


def _line(param, row) -> str:
    stable = ("stability not computed" if row["unstable"] is None else
              f"unstable {row['unstable']} (lowest eigenvalue {row['lowest_eigenvalue']:.3g})")
    if row.get("unstable_3d") is not None:
        stable += f", in 3D {row['unstable_3d']}"
    return (f"  {param} = {row[param]:.6g}: e = {row['e']:.8g}, {row['label']}, {stable}, "
            f"Newton {row['newton']}, {row['seconds']} s")


def _parser() -> argparse.ArgumentParser:
    """The command line's parser (its errors one line, exit 2)."""
    from fem_ade.registry import VESICLE_BRANCHES

    ap = argparse.ArgumentParser(prog="python -m fem_ade.branch",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("scene", help="vesicle (the family), a scene name or a .toml file")
    ap.add_argument("--param", required=True, choices=PARAMETERS)
    ap.add_argument("--from", dest="start", type=float, required=True)
    ap.add_argument("--to", dest="stop", type=float, required=True)
    ap.add_argument("--step", type=float, default=0.01,
                    help="the arclength step, in units of the parameter (default 0.01)")
    ap.add_argument("--out", required=True, help="the branch folder")
    ap.add_argument("--geometry", default="axisymmetric", choices=("axisymmetric",),
                    help="axisymmetric (the default and, for now, the only one)")
    ap.add_argument("--n", type=int, help="nodes per L at the finest spacing, as for "
                    "python -m fem_ade.run (default: 2.5 per eps)")
    ap.add_argument("--order", type=int, help="element order (default 8)")
    ap.add_argument("--folds", type=int, help="end the branch past this many folds (0: at "
                    "the first; default: go on past folds)")
    ap.add_argument("--modes", type=int, default=DEFAULT_MODES,
                    help="azimuthal modes m = 0 ... M at each point: the lowest eigenvalue "
                    f"of each, the 3D unstable count, the bifurcations (default "
                    f"{DEFAULT_MODES}; 0: axisymmetric perturbations only)")
    ap.add_argument("--no-stability", dest="stable", action="store_false",
                    help="no stability at the points (their unstable count blank): at small "
                    "eps most of a point's time")
    ap.add_argument("--quiet", action="store_true")
    ves = ap.add_argument_group("the vesicle family")
    for name in ("v", "da0", "kbar", "C", "eps", "R0"):
        ves.add_argument(f"--{name}", type=float)
    ves.add_argument("--branch", choices=VESICLE_BRANCHES)

    def error(message):
        ap.exit(2, f"fem_ade.branch: error: {message}\n")

    ap.error = error
    return ap


def main(argv=None) -> int:
    ap = _parser()
    args = ap.parse_args(argv)
    from fem_ade.store.interrupt import install

    install()  # SIGTERM as SIGINT: the points saved so far stay, the command goes on later
    try:
        from fem_ade.scenes.catalogue import resolve_scene

        chosen = {k: getattr(args, k) for k in ("v", "da0", "kbar", "C", "eps", "R0",
                                                 "branch") if getattr(args, k) is not None}
        if args.param in chosen:
            raise ModelError(f"--{args.param} is the branch's parameter: it goes from --from "
                             f"to --to (leave --{args.param} out)")
        branch = None
        if args.scene == "vesicle":
            branch = chosen.get("branch", "prolate")
            check_branch_name(branch)
            scene = vesicle_for_branch(chosen, args.param, args.start, args.stop)
        elif chosen:
            raise ModelError("--v, --da0, ... describe the vesicle scene; give them with "
                             "the scene vesicle")
        else:
            scene = resolve_scene(args.scene)
        options = {} if args.order is None else {"order": args.order}
        follow(scene, param=args.param, start=args.start, stop=args.stop, step=args.step,
               out=args.out, backend_options=options, n=args.n, quiet=args.quiet,
               folds=args.folds, stable=args.stable, branch=branch, modes=args.modes)
    except ModelError as err:
        print(f"fem_ade.branch: error: {err}", file=sys.stderr)
        return 2
    except np.linalg.LinAlgError as err:
        print(f"fem_ade.branch: error: a linear solve failed ({err}): the branch cannot go on "
              "from here (a smaller --step, or another --from)", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("fem_ade.branch: interrupted; the same command goes on from the last point",
              file=sys.stderr)
        return 130
    print(f"wrote {Path(args.out) / 'branch.csv'} and branch.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
