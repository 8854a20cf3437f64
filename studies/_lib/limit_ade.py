"""Stage ``ade`` of ``studies/sharp_limit.py``: the ADE term as ε → 0 (axisymmetric FEM),
each case seeded from its sharp membrane with ADE (:mod:`_lib.seeded`), its rows with the
observed orders and its part of the report."""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

from _lib.fits import slope
from _lib.seeded import make_runs
from _lib.sharp import Cache, ade_sharp, branch_key
from fem_ade.analysis.sharp import SPHERE_W
from fem_ade.store.output import write_json_atomic

#: stage ``ade`` (the ADE term as ε → 0, axisymmetric): (branch, v, m₀) at κ̄/κ = ADE_KBAR —
#: a torus, a prolate and a pear with the area difference away from its relaxed value (the
#: pear near the prolate → pear transition, 1.531: at m₀ = 1.7 its neck pinches off in the
#: phase field down to ε = 0.005)
ADE_KBAR = 1.4
ADE_CASES = (("torus", 0.65, 1.3), ("prolate", 0.85, 1.4), ("pear", 0.85, 1.58))


def ade_case_key(branch, v, m0, eps) -> str:
    """An ADE run's key in runs.json."""
    return f"axisymmetric-ade/{branch_key(branch, v)}/m0={m0:g}/{eps:.4f}"


def run_ade(cache: Cache, out: Path, plan) -> None:
    """Stage ``ade``: each ADE case at every ε of the axisymmetric column."""
    path = out / "sharp" / "runs.json"
    runs = json.loads(path.read_text()) if path.is_file() else {}
    jobs = []
    for branch, v, m0 in plan.ade_cases:
        sharp = ade_sharp(cache, branch, v, m0, ADE_KBAR)
        if sharp is None or "e" not in sharp:
            continue
        jobs += [SimpleNamespace(key=ade_case_key(branch, v, m0, eps), sharp=sharp, branch=branch,
                                 eps=eps, backend="axisymmetric",
                                 ade={"kbar": ADE_KBAR, "m0": m0})
                 for eps in plan.axi_eps if ade_case_key(branch, v, m0, eps) not in runs]
    for job, row in make_runs(out / "sharp", jobs):
        key = job.key
        row.pop("section")
        row["m0"] = job.ade["m0"]
        print(f"  {key}: e = {row['e']:.6f} (sharp {job.sharp['e']:.6f}), da diffuse "
              f"{row['da_diffuse']:.5f}, surface {row['da']:.5f} "
              f"(sharp {job.sharp['da']:.5f}), {row['label']}, {row['steps']} steps, "
              f"{row['seconds']} s", flush=True)
        runs[key] = row
        write_json_atomic(path, runs, indent=None)


def ade_rows(cache: Cache, runs: dict, plan) -> list[dict]:
    """Per ADE case: along ε, the model's (diffuse) and the φ = 0 surface's reduced area
    difference, G and W against the sharp membrane's, and their observed orders."""
    c = 3.0 * math.pi * ADE_KBAR / (2.0 * math.sqrt(2.0))  # G / W_sphere = c (m − m₀)²
    out = []
    for branch, v, m0 in plan.ade_cases:
        sharp = ade_sharp(cache, branch, v, m0, ADE_KBAR, compute=False)
        if sharp is None or "e" not in sharp:
            continue
        found = [runs[k] for k in (ade_case_key(branch, v, m0, e) for e in plan.axi_eps)
                 if k in runs]
        found = [r for r in found if r["kept_branch"]]
        if not found:
            continue
        g_sharp = sharp["e"] - sharp["w"]
        row = {"branch": branch, "v": v, "m0": m0, "kbar": ADE_KBAR, "da_sharp": sharp["da"],
               "g_sharp": g_sharp, "w_sharp": sharp["w"], "e_sharp": sharp["e"],
               "eps": [r["eps"] for r in found],
               "da_diffuse": [r["da_diffuse"] for r in found],
               "da_surface": [r["da"] for r in found],
               "g": [r["G"] / SPHERE_W for r in found], "w": [r["W"] / SPHERE_W for r in found],
               "e": [r["e"] for r in found], "labels": [r["label"] for r in found]}
        for name, values, ref in (("da_diffuse", row["da_diffuse"], sharp["da"]),
                                  ("da_surface", row["da_surface"], sharp["da"]),
                                  ("g", row["g"], g_sharp), ("w", row["w"], sharp["w"]),
                                  ("e", row["e"], sharp["e"])):
            row[f"order_{name}"] = slope(row["eps"], [x - ref for x in values])
        row["g_check"] = [c * (m - m0) ** 2 for m in row["da_diffuse"]]
        out.append(row)
    return out


def ade_report(rows: list[dict]) -> list[str]:
    if not rows:
        return []
    lines = ["", "## The ADE term as ε → 0 (axisymmetric FEM)", "",
             f"At κ̄/κ = {ADE_KBAR}: each case seeded from its sharp membrane with ADE, run to a "
             "steady state at every ε. Δa: the reduced area difference — the model's, from its "
             "diffuse ΔA (what its ADE term G sees), and the φ = 0 surface's, ∮H dA/(4πR₀) — "
             "against the sharp membrane's; g = G / W_sphere and w = W / W_sphere against the "
             "sharp ones; p: the observed order (slope of log|error| over the three smallest "
             "ε).", ""]
    for r in rows:
        lines += [f"**{r['branch']}** at v = {r['v']}, m₀ = {r['m0']}: sharp Δa = "
                  f"{r['da_sharp']:.5f}, g = {r['g_sharp']:.5f}, w = {r['w_sharp']:.5f}", "",
                  "| ε | Δa diffuse − sharp | Δa surface − sharp | g − g_sharp | "
                  "w − w_sharp | label |", "|---|---|---|---|---|---|"]
        for i, eps in enumerate(r["eps"]):
            lines.append(f"| {eps:g} | {r['da_diffuse'][i] - r['da_sharp']:+.2e} | "
                         f"{r['da_surface'][i] - r['da_sharp']:+.2e} | "
                         f"{r['g'][i] - r['g_sharp']:+.2e} | {r['w'][i] - r['w_sharp']:+.2e} "
                         f"| {r['labels'][i]} |")

        def fmt(p):
            return "—" if p is None else f"{p:.2f}"

        lines += [f"| p | {fmt(r['order_da_diffuse'])} | {fmt(r['order_da_surface'])} | "
                  f"{fmt(r['order_g'])} | {fmt(r['order_w'])} | |", ""]
    return lines
