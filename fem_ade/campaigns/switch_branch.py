"""Following a non-axisymmetric branch in 3D from a bifurcation of an axisymmetric one
(``python -m fem_ade.switch BRANCH --follow N --out DIR``): pseudo-arclength continuation on
the 3D tensor FEM, with Newton's pins for the rigid motions.

**Where the branch starts.** At a bifurcation in block m ≥ 1 (``fem_ade.branch --modes``) the
axisymmetric state φ₀ (the branch point on its unstable side, revolved onto the 3D mesh) has a
near-zero mode ψ_m(r, z) cos mθ, and the non-axisymmetric branch leaves it along that mode
(a pitchfork: φ₀'s rotations by π/m turn one side of it into the other). Its first two points
are solved at a fixed **amplitude** a of the mode, with the branch's parameter p free (v,
the reduced volume, or Δa₀: see **The parameter** below):

    F(φ, p) = 0,    ⟨ψ̂, φ − φ₀⟩ = a ⟨ψ̂, ψ̂⟩,     a = a₁ = ``step``, then 2a₁ (or a₁ + δ),

ψ̂ = ψ_m cos mθ scaled to max |ψ̂| = 1: :meth:`fem_ade.campaigns.continuation.Continuation.
advance` along the tangent (ψ̂, 0) from (φ₀, p₀) (:func:`_advance` says how the second
is found where Newton does not converge). An axisymmetric state has no m-part, so
this constraint cannot be met on the axisymmetric branch, whatever p: it picks the new
branch. From there the branch is followed as the axisymmetric ones are (the secant, then the
quadratic predictor; Newton's correction on the extended system; the step halved where it
fails, grown by 1.5 where Newton takes ≤ 4 iterations, up to 4·``step``), in the arclength
√(θ⟨Δφ, Δφ⟩ + Δp²) with θ = 1/⟨ψ̂, ψ̂⟩: a step of ``step`` moves the mode's amplitude by
about ``step`` in max norm. Measured (ε = 0.04): starting the secant at φ₀ itself (one point
at amplitude 0.1, then the chord from φ₀ to it) went back onto the oblate at the second point;
the two fixed-amplitude points do not.

**The pins.** Newton's pins (:meth:`fem_ade.backends.fem.newton.NewtonSystem._translations`)
are P times the rigid motions of φ₀ + ψ̂, i.e. with the rotation about the axis, which an
axisymmetric φ₀ alone leaves out (a zero mode of every non-axisymmetric point, unpinned);
the phase of the mode is 0: cos mθ with θ from the mesh's x axis, so that the branch's
mirror planes are the mesh's (a phase in between would leave the rotation's pin a nonzero
multiplier on the cubic mesh, which turns the branch's shapes).

**The parameter** is the one the axisymmetric branch was followed in (its branch.json's
``param``): v for the minimal model's lines, Δa₀ (``da0``) at fixed v for the ADE plane's,
whose m = 2 branch between the oblate and the prolate crosses the plane at constant v.

**The mesh.** 2.56 nodes per ε by default (:data:`NODES_PER_EPS`), order 8: measured from the
minimal model's oblate at ε = 0.04 (its m = 2 bifurcation at v = 0.8246 in the (r, z)
geometry), the branch on 64³ nodes of order 8 starts at v = 0.8240 and goes down in v as the
amplitude grows (a subcritical pitchfork); on 32³ nodes of order 4 (1.28 per ε) it started
at v = 0.804 and went up to a fold at v = 0.828 — a stable piece the finer mesh does not
have. The flow's switch (:mod:`fem_ade.campaigns.switch`) affords the coarser mesh, as it
asks only where the flow goes.

**The octant** (``geometry="octant"``, ``--geometry octant``): for an even m and a state with
an equatorial mirror, the branch is followed on the mirror-symmetric eighth of the box
(:mod:`fem_ade.backends.fem.octant`): cos mθ with θ₀ = 0 is even about the planes x, y =
L/2, so the whole branch lies in that sector. No rigid motion keeps the mirrors, so there are
no pins; the default mesh is the flow's there (order 8, 1.92 nodes per ε). Measured, the
minimal model's oblate at ε = 0.04 (R₀ = 0.25) on 32 nodes per L of order 8: the octant's
first three points equal the box's in v, e and E to the ten digits branch.csv keeps, at 0.27
s a point against 2.0 s (wall, one BLAS thread, nothing else running). Its ``stability`` is
the sector's (perturbations even in x, y and z): a lower bound on the 3D count.

The folder is a branch folder (:mod:`fem_ade.campaigns.branch_folder`): branch.json (what
the branch is: the bifurcation it left, its mesh and step), points/NNNN/ (final.npz: φ on the
3D nodes; summary.json: the row, with its checksums), branch.csv, ended.json and
``branch3d.png`` (e against v beside the axisymmetric branch it left). A second run with the
same arguments goes on from its last point; a killed one loses at most the point it was
solving.
"""

from __future__ import annotations

import json
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from fem_ade.backends.threads import limit_threads
from fem_ade.model.params import ModelError

#: the 3D mesh's nodes per unit length per 1/ε (module docstring: 64 nodes of order 8 at
#: ε = 0.04 in the unit box)
NODES_PER_EPS = 2.56
ORDER = 8
#: the first step: the mode's amplitude (max norm) of the first point
STEP = 0.1
#: a point whose mode amplitude is below this (relative to the branch's largest) has come
#: back to an axisymmetric state: the branch ends there
REJOINED = 0.02
#: the symmetry groups of a body of revolution (:func:`fem_ade.analysis.symmetry.symmetry`):
#: a branch point that has one has rejoined an axisymmetric branch
AXISYMMETRIC = ("D∞h", "C∞v", "Kh")
#: the eigenvalues of each point's 3D stability (with ``stability``)
EIGENVALUES = 4
COLUMNS = ("point", "v", "e", "E", "amplitude", "label", "symmetry", "semi_axes", "unstable_3d",
           "eigenvalues", "newton", "seconds", "s")


def switched_start(branch, index, point, mode, n, order, geometry: str = "cartesian"):
    """(what the branch leaves: the branch, bifurcation, m, point, its eigenvalue and
    v_bifurcation; the 3D FEM backend at the revolved φ₀ on ``n`` nodes of ``order``; ψ̂ on
    its nodes, max |ψ̂| = 1): the start of :func:`follow_switched`. ``geometry="octant"``:
    on the mirror-symmetric eighth of the box (module docstring), for an even m and a state
    with the box's mirrors (checked as :func:`fem_ade.campaigns.switch.switch` does)."""
    from fem_ade.backends.base import make_backend
    from fem_ade.campaigns.switch import (
        check_octant_mirrors,
        check_octant_mode,
        chosen,
        default_nodes,
        octant_nodes,
        start_fields,
    )
    from fem_ade.scenes.catalogue import Scene
    from fem_ade.scenes.fields import meridian_values
    from fem_ade.scenes.initial import FieldIC
    from fem_ade.scenes.vesicle import DT_PER_EPS3

    if geometry not in ("cartesian", "octant"):
        raise ModelError(f"a branch is followed in the cartesian or octant geometry, not "
                         f"{geometry!r}")
    octant = geometry == "octant"
    bif, folder = chosen(branch, index, point, mode)
    m = int(bif["m"])
    if octant:
        check_octant_mode(m)
    params, fields, lam = start_fields(folder, m, 1.0, phase=0.0 if octant else None)
    if octant:
        check_octant_mirrors(folder, fields["phi_grid"])
        n = n or octant_nodes(params, order)
    n = n or default_nodes(params.eps, params.L, order, NODES_PER_EPS)
    with tempfile.TemporaryDirectory() as tmp:
        start = Path(tmp) / "axisymmetric.npz"
        np.savez(start, **{k: fields[k] for k in ("axis", "points", "phi")})
        scene = Scene(name=f"branch-m{m}", params=params, dt=DT_PER_EPS3 * params.eps**3,
                      ic=FieldIC(path=str(start)), n=n, dim=3)
        be = make_backend("fem", scene, n=n, order=order, dt=scene.dt, scheme="stabilized",
                          constraints="exact", **({"geometry": "octant"} if octant else {}))
    mode_only = {**fields, "phi": np.zeros_like(fields["phi"]),
                 "azimuthal_phase": np.array(0.0)}
    psi = meridian_values(mode_only, np.asarray(be.space.doflocs)).ravel()
    param = branch_parameter(branch)
    origin = {"branch": str(Path(branch).resolve()),
              "bifurcation": None if mode is not None else (index or 0), "m": m,
              "point": folder.name, "param": param,
              "eigenvalue": lam, "at_bifurcation": bif.get(param)}
    return origin, be, psi / np.max(np.abs(psi))


def branch_parameter(branch: str | Path) -> str:
    """The parameter a branch folder was followed in (its branch.json's ``param``: v, da0,
    …), which the 3D branch that leaves it is followed in too."""
    from fem_ade.store.output import read_json

    path = Path(branch) / "branch.json"
    try:
        return str(read_json(path)["param"])
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise ModelError(f"{path} is not a branch's branch.json ({type(err).__name__})") \
            from None


def _continuation(be, psi, param: str = "v"):
    """The extended system on ``be`` (at φ₀) along ``param`` with the pins of φ₀ + ψ̂ and
    θ = 1/⟨ψ̂, ψ̂⟩."""
    from fem_ade.backends.fem.modes import p_orthogonal, rigid_motions
    from fem_ade.campaigns.continuation import Continuation

    cont = Continuation(be, param)
    if getattr(be, "geometry", "cartesian") != "octant":  # the octant's mirrors: no pins
        cont.sys.translations = p_orthogonal(cont.sys.P, rigid_motions(be, be.phi + psi))
    cont.theta = 1.0 / cont.inner(psi, psi)
    return cont


def _row(be, cont, psi, phi0, newton: int, t0: float, stability: bool) -> dict:
    from fem_ade.analysis.shape import symmetry_group
    from fem_ade.analysis.sharp import reduced_energy
    from fem_ade.scenes.vesicle import get_parameter

    t1 = time.perf_counter()
    row = {"v": get_parameter(be.params, "v"), cont.name: cont.p, "newton": newton}
    if stability:
        from fem_ade.campaigns.stability import cartesian

        stab = cartesian(be, EIGENVALUES)
        row["eigenvalues"] = [float(x) for x in stab.eigenvalues]
        row["unstable_3d"] = int(stab.unstable_3d)
    final = be.diagnostics()
    shape, _ = be.describe_final(final)
    body = (shape or {}).get("body") or {}
    row.update({"e": reduced_energy(final, be.params.kappa), "E": final["E"],
                "amplitude": cont.inner(psi, be.phi - phi0) / cont.inner(psi, psi),
                "label": (shape or {}).get("label"),
                "semi_axes": [round(a, 6) for a in body.get("semi_axes", [])] or None,
                "newton_s": round(t1 - t0, 2), "seconds": round(time.perf_counter() - t0, 2)})
    row["symmetry"] = symmetry_group(shape) if shape else None
    return row


@limit_threads
def follow_switched(branch: str | Path, index: int | None, out: str | Path, *,
                    points: int = 12, step: float = STEP, n: int | None = None,
                    order: int = ORDER, stability: bool = False, point: int | None = None,
                    mode: int | None = None, quiet: bool = False,
                    geometry: str = "cartesian") -> list[dict]:
    """Follow the non-axisymmetric branch born at bifurcation ``index`` of a branch folder
    (module docstring) for ``points`` points into the branch folder ``out``; its rows.
    ``stability``: each point's 3D eigenvalues too (:func:`fem_ade.campaigns.stability.
    cartesian`, the rigid motions out; in the octant, the mirror-symmetric sector's).
    ``point``/``mode``: from that point along that block instead (as
    :func:`fem_ade.campaigns.switch.switch`). ``geometry="octant"``: on the mirror-symmetric
    eighth of the box (module docstring), ``n`` by default at 1.92 nodes per ε."""
    from fem_ade.campaigns.branch_folder import (
        check_out,
        identity_digest,
        load_points,
        lock_folder,
        open_folder,
        write_ended,
    )

    check_follow(points, step)
    say = (lambda text: None) if quiet else (lambda text: print(text, flush=True))
    out = check_out(out)
    origin, be, psi = switched_start(branch, index, point, mode, n, order, geometry)
    identity = _identity(origin, be, step, order, stability)
    made = not out.exists()
    lock = lock_folder(out)
    try:
        tag = identity_digest(open_folder(out, identity))
        phi0 = be.phi.copy()
        cont = _continuation(be, psi, origin["param"])
        anchor = (phi0, cont.p)
        param = origin["param"]
        done = load_points(out, tag, phi0.size, param)
        rows = [r for r, _ in done]
        why = _ended(rows, param) if rows else None  # a branch that ended stays ended
        ds = rows[-1]["ds_next"] if rows else step
        while why is None and len(rows) < points:
            t0 = time.perf_counter()
            corrected, used = _advance(cont, done, anchor, psi, step, ds)
            if corrected is None:
                why = (f"the branch ends at {param} = {cont.p:.6g}: Newton does not converge at "
                       f"an arclength step of {step / 8:.3g}")
                break
            ds = _add_point(out, tag, cont, done, corrected, used, (phi0, psi), step, ds,
                            stability, t0)
            rows.append(done[-1][0])
            say(_line(rows[-1], geometry == "octant", param))
            if (why := _ended(rows, param)) is not None:
                break
        if not rows:
            failed = (f"{why.replace('the branch ends', 'no first point')}: try a finer "
                      "--n, a higher --order or a smaller --step")
        else:
            failed = None
            why = why or f"{points} points"
            say(why)
            write_ended(out, param, rows, why)
            draw(out, rows, origin)
    finally:
        lock.release()
    if failed:
        if made:  # nothing in it but its branch.json: not left behind
            import shutil

            shutil.rmtree(out, ignore_errors=True)
        raise ModelError(failed)
    return rows


def check_follow(points, step) -> None:
    """ModelError (one line) for a number of points or a step ``follow_switched`` cannot
    take."""
    if isinstance(points, bool) or not isinstance(points, int) or points < 1:
        raise ModelError(f"--follow takes the number of points, a positive integer, got "
                         f"{points!r}")
    if not (isinstance(step, (int, float)) and math.isfinite(step) and 0 < step <= 1):
        raise ModelError(f"--step is the mode's amplitude per step, in (0, 1], got {step!r}")


def _identity(origin: dict, be, step: float, order: int, stability: bool) -> dict:
    """What the branch is (its branch.json): the bifurcation it left, its model, mesh and
    step."""
    from fem_ade.engine.config import RUN_FORMAT

    identity = {"switched_from": {k: origin[k] for k in ("branch", "bifurcation", "m",
                                                         "point")},
                "params": be.params.as_dict(), "param": origin["param"], "step": step, "n": be.n,
                "order": order, "stability": bool(stability), "format": RUN_FORMAT}
    if getattr(be, "geometry", "cartesian") == "octant":  # the box's folders keep their digest
        identity["geometry"] = "octant"
    return json.loads(json.dumps(identity, default=str))


def _add_point(out: Path, tag: str, cont, done: list, corrected, used: float, base,
               step: float, ds: float, stability: bool, t0: float) -> float:
    """The corrected point (φ, v, Newton's iterations) described, saved (point k of
    ``out``) and added to ``done``; the next arclength step."""
    from fem_ade.campaigns.branch_folder import save_point

    phi, p, its = corrected
    cont.be._set(phi, None)
    cont.set_p(p)
    rows = [r for r, _ in done]
    row = _row(cont.be, cont, base[1], base[0], its, t0, stability)
    row["s"] = (rows[-1]["s"] + used) if rows else used
    if len(rows) >= 2:
        ds = min(used * 1.5, 4 * step) if its <= 4 else used
    row["ds_next"] = ds
    row = save_point(out, len(rows), cont.be, row, tag)
    done.append((row, phi.copy()))
    _write_table(out, [*rows, row], cont.name)
    return ds


def _advance(cont, done: list, anchor: tuple, psi, step: float, ds: float):
    """The next point of the branch past ``done`` (its (row, φ)): the first at the mode's
    amplitude a₁ = ``step`` off the anchor (φ₀, p₀), the second at 2a₁ predicted from φ₀
    or, where Newton does not converge from there, at a₁ + δ predicted from the first, δ =
    ``step``/2 halved until it does (measured at ε = 0.02 on 96³ nodes: 2a₁ from φ₀ did not
    converge, and :meth:`~fem_ade.campaigns.continuation.Continuation.advance`'s halving
    landed on the first point again; on 32³ nodes of order 8 at ε = 0.04, a₁ + step from the
    first point did not converge where 2a₁ from φ₀ did), then one arclength step ``ds`` by
    the predictor (``advance``)."""
    tangent = (psi / math.sqrt(cont.theta * cont.inner(psi, psi)), 0.0)
    if not done:  # the amplitude ``step`` off the anchor
        cont.be._set(anchor[0], None)
        cont.set_p(anchor[1])
        return cont.advance([anchor], tangent, step, step / 8)
    if len(done) == 1:  # the amplitude 2a₁ off the anchor, else a₁ + δ from point 0
        row, phi1 = done[0]
        twice = cont.correct(anchor[0] + 2 * step * tangent[0], anchor[1], anchor, tangent,
                             2 * step)
        if twice is not None:
            return twice, step
        delta = step / 2
        while delta >= step / 8:
            corrected = cont.correct(phi1 + delta * tangent[0], row[cont.name], anchor, tangent,
                                     row["amplitude"] + delta)
            if corrected is not None:
                return corrected, delta
            delta *= 0.5
        return None, delta
    last_row, phi_k = done[-1]
    cont.be._set(phi_k, None)
    cont.set_p(last_row[cont.name])
    return cont.advance([(ph, r[cont.name]) for r, ph in done[-3:]], None, ds, step / 8)


def _ended(rows: list[dict], param: str = "v") -> str | None:
    """Why the branch ends at its last point: a topology change, or at an axisymmetric
    state — the one it left (the mode's amplitude below :data:`REJOINED` of its largest) or
    another (its symmetry one of :data:`AXISYMMETRIC` after an earlier point's was not: the
    first points, a small amplitude off the revolved state, may pass the symmetry's
    tolerance); None where it goes on. ``param``: the parameter the branch is followed in."""
    from fem_ade.campaigns.branch_analysis import same_topology

    row = rows[-1]
    at = f"{param} = {row[param]:.6g}"
    if not same_topology(rows[0]["label"], row["label"]):
        return f"the branch ends at {at}: its shape became a {row['label']}"
    largest = max(abs(r["amplitude"]) for r in rows)
    if len(rows) > 2 and abs(row["amplitude"]) < REJOINED * largest:
        return (f"the branch rejoins an axisymmetric one at {at} (its mode's "
                f"amplitude {row['amplitude']:.3g})")
    earlier = [r.get("symmetry") for r in rows[:-1]]
    if row.get("symmetry") in AXISYMMETRIC and any(g and g not in AXISYMMETRIC
                                                   for g in earlier):
        return (f"the branch reaches an axisymmetric shape ({row['symmetry']}, about another "
                f"axis) at {at}")
    return None


def _line(row: dict, octant: bool = False, param: str = "v") -> str:
    from fem_ade.campaigns.stability import count_text

    axes = ", ".join(f"{a:.4f}" for a in row["semi_axes"] or [])
    where = "even in x, y and z (the octant's)" if octant else "in 3D"
    stab = ("" if row.get("unstable_3d") is None else
            f", unstable {count_text(row['unstable_3d'], row.get('eigenvalues'))} {where}")
    return (f"  {param} = {row[param]:.6g}: e = {row['e']:.7g}, amplitude {row['amplitude']:.4g}, "
            f"{row['label']} ({axes}){stab}, Newton {row['newton']}, {row['seconds']} s")


def _write_table(out: Path, rows: list[dict], param: str = "v") -> None:
    """branch.csv: :data:`COLUMNS`, and the parameter after v where it is another."""
    from fem_ade.store.tables import write_table

    columns = list(COLUMNS) if param == "v" else [*COLUMNS[:2], param, *COLUMNS[2:]]
    write_table(out / "branch.csv", columns, [{**r, "point": k} for k, r in enumerate(rows)])


def draw(out: Path, rows: list[dict], origin: dict) -> Path:
    """branch3d.png: e against the branch's parameter (v or Δa₀) of the 3D branch (its
    points) beside the axisymmetric branch it left (that branch's branch.csv), the
    bifurcation marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fem_ade.campaigns.branch_folder import read_branch_table
    from fem_ade.plots.figures import save_figure

    param = origin.get("param", "v")
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    try:
        axi = [r for r in read_branch_table(Path(origin["branch"])) if r.get("e") != ""]
        ax.plot([r[param] for r in axi], [r["e"] for r in axi], "o-", color="0.55", ms=3,
                label="the axisymmetric branch it left")
    except (OSError, KeyError, ValueError):
        pass
    ax.plot([r[param] for r in rows], [r["e"] for r in rows], "s-", color="C3", ms=4,
            label=f"the m = {origin['m']} branch in 3D")
    if origin.get("at_bifurcation"):
        ax.axvline(origin["at_bifurcation"], color="0.7", lw=0.8, ls=":")
    ax.set_xlabel({"v": "v", "da0": "Δa₀"}.get(param, param))
    ax.set_ylabel("e = (W + G) / W_sphere")
    ax.legend(frameon=False, fontsize=8)
    ax.set_title(f"from {Path(origin['branch']).name}, point {origin['point']}", fontsize=9)
    path = out / "branch3d.png"
    save_figure(fig, path)
    plt.close(fig)
    return path
