"""Stage ``transitions`` of ``studies/sharp_limit.py``: where the phase field's lowest branch
changes at each ε, from seeded steady states around each sharp transition (axisymmetric
FEM), extrapolated to ε → 0 beside the sharp one."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from _lib.fits import extrapolate
from _lib.limit_ade import ADE_KBAR, ade_case_key
from _lib.limit_eps import case_key
from _lib.seeded import make_runs
from _lib.sharp import Cache, ade_sharp, crossing
from fem_ade.store.output import write_json_atomic
from fem_ade.store.status import Status

#: stage ``transitions`` (axisymmetric): where the phase field's lowest branch changes at each
#: ε, from seeded steady states on three points around the sharp transition — the minimal
#: model's (upper branch, lower branch, v) and the ADE plane's prolate → pear at v = 0.85,
#: κ̄/κ = ADE_KBAR, along m₀ (from 1.53: at 1.48 the sharp pear relaxes to the prolate)
TRANSITION_EPS = (0.02, 0.01, 0.005, 0.0025)
MINIMAL_TRANSITIONS = (("prolate", "oblate", (0.62, 0.65, 0.68)),
                       ("oblate", "stomatocyte", (0.56, 0.59, 0.62)))
PEAR_TRANSITION = (0.85, ("prolate", "pear"), (1.53, 1.58, 1.63))


def run_transitions(cache: Cache, out: Path, plan) -> None:
    """Stage ``transitions``: the seeded steady states around each transition."""
    path = out / "sharp" / "runs.json"
    runs = json.loads(path.read_text()) if path.is_file() else {}
    jobs = []

    def one(key, sharp, branch, eps, **ade):
        if key not in runs and sharp is not None and "w" in sharp:
            jobs.append(SimpleNamespace(key=key, sharp=sharp, branch=branch, eps=eps,
                                        backend="axisymmetric", ade=ade))

    for eps in plan.transition_eps:
        for upper, lower, vs in plan.minimal_transitions:
            for v in vs:
                for b in (upper, lower):
                    one(case_key("axisymmetric", b, v, eps), cache.get(b, v), b, eps)
        if plan.pear_transition:
            v, branches, m0s = plan.pear_transition
            for m0 in m0s:
                for b in branches:
                    one(ade_case_key(b, v, m0, eps), ade_sharp(cache, b, v, m0, ADE_KBAR), b, eps,
                        kbar=ADE_KBAR, m0=m0)
    for job, row in make_runs(out / "sharp", jobs):
        key = job.key
        row.pop("section")
        row.update({k: v for k, v in job.ade.items() if k == "m0"})
        print(f"  {key}: e = {row['e']:.6f}, {row['label']}"
              f"{'' if row['kept_branch'] else ' LEFT the branch'}, {row['steps']} steps, "
              f"{row['seconds']} s", flush=True)
        runs[key] = row
        write_json_atomic(path, runs, indent=None)


def _root(xs: list[float], ds: list[float]) -> float | None:
    """The x where d changes sign between the points (quadratic through three, linear
    through two), or None."""
    pts = sorted(zip(xs, ds, strict=True))
    if len(pts) < 2 or not any(a[1] * b[1] <= 0 for a, b in zip(pts, pts[1:], strict=False)):
        return None
    x, d = [p[0] for p in pts], [p[1] for p in pts]
    if len(pts) >= 3:
        roots = [r.real for r in np.roots(np.polyfit(x, d, 2)) if abs(r.imag) < 1e-12
                 and x[0] <= r.real <= x[-1]]
        if roots:
            return float(min(roots, key=lambda r: abs(r - np.mean(x))))
    for (x0, d0), (x1, d1) in zip(pts, pts[1:], strict=False):
        if d0 * d1 <= 0:
            return x0 - d0 * (x1 - x0) / (d1 - d0)
    return None


def transition_rows(cache: Cache, runs: dict, plan) -> list[dict]:
    """Per transition: its location at each ε (where both branches were kept at ≥ 2 of the
    points), the observed order and the extrapolation to ε → 0, beside the sharp one."""
    out = []
    def minimal_key(b, v):
        return lambda eps: case_key("axisymmetric", b, v, eps)

    def ade_key(b, v, m):
        return lambda eps: ade_case_key(b, v, m, eps)

    cases = [(f"{u} → {lo}", "v", [(v, minimal_key(u, v), minimal_key(lo, v)) for v in vs],
              crossing(cache, u, lo, float(np.mean(vs)), compute=False).get("v"))
             for u, lo, vs in plan.minimal_transitions]
    if plan.pear_transition:
        v, (u, lo), m0s = plan.pear_transition
        es = {b: [(ade_sharp(cache, b, v, m, ADE_KBAR, compute=False) or {}).get("e")
                  for m in m0s] for b in (u, lo)}
        sharp_x = None
        if all(e is not None for b in es for e in es[b]):
            sharp_x = _root(list(m0s), [a - b for a, b in zip(es[u], es[lo], strict=True)])
        cases.append((f"{u} → {lo} (v = {v}, κ̄/κ = {ADE_KBAR})", "m0",
                      [(m, ade_key(u, v, m), ade_key(lo, v, m)) for m in m0s],
                      sharp_x))
    for name, along, points, sharp_x in cases:
        at = {}
        for eps in plan.transition_eps:
            xs, ds = [], []
            for x, ku, kl in points:
                ru, rl = runs.get(ku(eps)), runs.get(kl(eps))
                if ru and rl and all(r["kept_branch"] and r.get("status") == Status.STEADY
                                     for r in (ru, rl)):  # a run cut at max_steps: no point
                    xs.append(x)
                    ds.append(ru["e"] - rl["e"])
            at[eps] = _root(xs, ds)
        have = [(e, x) for e, x in at.items() if x is not None]
        row = {"transition": name, "along": along, "sharp": sharp_x,
               "at": {f"{e:g}": x for e, x in at.items()}, "extrapolated": None,
               "order": None}
        if len(have) >= 2:
            x0, p, observed = extrapolate([e for e, _ in have], [x for _, x in have])
            row.update(extrapolated=x0, order=p, order_observed=observed)
        out.append(row)
    return out


def transitions_report(rows: list[dict], plan) -> list[str]:
    if not rows:
        return []
    lines = ["", "## Where the lowest branch changes, from the phase field (axisymmetric FEM)",
             "", "Seeded steady states at three points around each sharp transition; at each "
             "ε the root of the difference of the two branches' e (a quadratic through the "
             "points where both reached a steady state on their branch), then the observed "
             "order and Richardson over the smallest ε. — : a branch left (opened, pinched "
             "or budded) at too many of the points.", "",
             "| transition | along | " + " | ".join(f"ε = {e:g}" for e in plan.transition_eps)
             + " | p | ε → 0 | sharp |", "|---|---|" + "---|" * (len(plan.transition_eps) + 3)]
    for r in rows:
        cells = ["—" if r["at"][f"{e:g}"] is None else f"{r['at'][f'{e:g}']:.4f}"
                 for e in plan.transition_eps]
        ex = "—" if r["extrapolated"] is None else f"{r['extrapolated']:.4f}"
        p = "—" if r["order"] is None else (f"{r['order']:.2f}"
                                            + ("" if r.get("order_observed") else " (assumed)"))
        sh = "—" if r["sharp"] is None else f"{r['sharp']:.4f}"
        lines.append(f"| {r['transition']} | {r['along']} | " + " | ".join(cells)
                     + f" | {p} | {ex} | {sh} |")
    return lines + [""]
