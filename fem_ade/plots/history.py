"""A run's ``history.png`` (:func:`render_history`): the energy and its parts, and V/α, A/β,
ΔA/ΔA₀, against time.

Why a module of its own: the one picture a new physics term touches (its energy column's
legend and colour), apart from the 3D views (:mod:`.shapes`) and the run folder's command
(:mod:`.render`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fem_ade.model.params import ENERGY_COLUMNS, TERMS, Params
from fem_ade.plots.figures import save_figure


def render_history(history, path: str | Path, params: Params, *,
                   title: str | None = None, physical_time: bool = True) -> Path:
    """Write ``history.png``: energies (left; log scale when the parts differ by more than a
    factor 20) and V/α, A/β, ΔA/ΔA₀ (right) against t — or against the iteration when t is
    not a physical time (``physical_time`` False: a run with momentum).

    ``history``: the columns of ``history.csv`` (a dict of arrays, or the file's path).
    E, W, G are read; T₁ = M₁(V − α)², T₂ = M₂(A − β)² are computed from V, A when their
    effect is on (``params``). A part that is 0 throughout (an effect that is off) is left out,
    and so is ΔA/ΔA₀ if ΔA is 0 throughout or ΔA₀ = 0. Returns the path written.
    """
    from matplotlib.figure import Figure

    from fem_ade.store.output import read_history

    hist = read_history(history) if isinstance(history, (str, Path)) else history
    if "t" not in hist or len(hist["t"]) == 0:
        raise ValueError("the history has no rows")
    hist = {k: np.asarray(v, dtype=float) for k, v in hist.items()}
    t = hist["t"] if physical_time or "step" not in hist else hist["step"]
    xlabel = "t" if physical_time or "step" not in hist else \
        "iteration (momentum: t is not a physical time)"
    alpha, beta, delta_A0 = params.alpha, params.beta, params.delta_A0
    parts = {name: hist.get(name) for name in ENERGY_COLUMNS}  # E, W, G
    for term in TERMS:  # the penalties' T1, T2 from their functionals
        if term.penalty and params.on(term.effect) and term.functional in hist:
            parts[term.energy] = term.energy_of(params, hist[term.functional])
    labels = {"E": "E$_M$ (total)", "W": "W (bending)", "G": "G (ADE)",
              "T1": "T$_1$ = M$_1$(V−α)²", "T2": "T$_2$ = M$_2$(A−β)²"}
    styles = {"E": ("k", 2.4), "W": ("#c0392b", 1.5), "G": ("#2c7fb8", 1.5),
              "T1": ("#27ae60", 1.3), "T2": ("#8e44ad", 1.3)}

    fig = Figure(figsize=(12, 4.8), dpi=100)
    ax1, ax2 = fig.subplots(1, 2)
    shown = []
    for name, v in parts.items():
        if v is None or not np.any(v != 0):
            continue
        colour, lw = styles.get(name, ("0.4", 1.3))  # a new term: grey, its name
        ax1.plot(t, v, color=colour, lw=lw, label=labels.get(name, name),
                 marker="o" if len(t) < 15 else None, ms=3)
        shown.append(v[v != 0])
    values = np.concatenate(shown) if shown else np.ones(1)
    if np.all(values > 0) and values.max() > 20.0 * values.min():
        ax1.set_yscale("log")  # parts of very different sizes
    else:
        ax1.ticklabel_format(axis="y", useOffset=False)
    ax1.set_xlabel(xlabel)
    ax1.set_ylabel("energy")
    ax1.set_title("energy and its parts")
    ax1.legend(fontsize=9, loc="best")
    ax1.grid(True, which="both", alpha=0.25)

    ratios = []
    if "V" in hist and alpha:
        ratios.append(("V/α", hist["V"] / alpha, "#27ae60"))
    if "A" in hist and beta:
        ratios.append(("A/β", hist["A"] / beta, "#8e44ad"))
    if "dA" in hist and delta_A0 and np.any(hist["dA"] != 0):
        ratios.append(("ΔA/ΔA$_0$", hist["dA"] / delta_A0, "#2c7fb8"))
    for label, v, colour in ratios:
        ax2.plot(t, v, color=colour, lw=1.8, label=label,
                 marker="o" if len(t) < 15 else None, ms=3)
    ax2.axhline(1.0, color="0.4", lw=1.0, ls="--", label="target")
    ax2.set_xlabel(xlabel)
    ax2.set_ylabel("ratio to target")
    ax2.set_title("volume, area and area difference")
    ax2.legend(fontsize=9, loc="best")
    ax2.grid(True, alpha=0.25)
    for ax in (ax1, ax2):
        ax.ticklabel_format(axis="x", style="sci", scilimits=(-3, 3))
    ax2.ticklabel_format(axis="y", useOffset=False)
    if title:
        fig.suptitle(title, fontsize=13, fontweight="bold")
    fig.tight_layout()
    path = Path(path)
    save_figure(fig, path, dpi=100)
    return path
