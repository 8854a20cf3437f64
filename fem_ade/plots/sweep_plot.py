"""The pictures of a sweep (:mod:`fem_ade.campaigns.sweep`): the phase diagram and the end shapes.

``phase-diagram.png``: the sweep's first axis across, its second (or the seeds) up; each run a
marker coloured by its end state (its shape label; a seed's marker shape), beside the others
of its point; the lowest-energy end state of each point ringed in black; a point whose seeds
end in different states marked "×" (metastable); behind them, where the sharp reference has
the seeds' branches, the lowest sharp branch at each point as a coloured cell.
A sweep of one axis draws, instead of the second axis, each run's energy e = (W + G) over a
sharp sphere's bending energy, beside the sharp energy of its seed's branch (lines): the
lowest state along the axis and where it changes, against the sharp reference's.
``montage.png``: each run's ``shape.png`` (when the runs render), one row per seed.
"""

from __future__ import annotations

from pathlib import Path

from fem_ade.store.status import HAS_RESULT

COLOURS = {"sphere": "#7f7f7f", "prolate": "#1f77b4", "cylinder": "#6baed6",
           "gourd": "#9ecae1", "chain": "#c6dbef", "oblate": "#ff7f0e", "discocyte": "#fdae6b",
           "torus": "#9467bd", "pear": "#d62728", "stomatocyte": "#2ca02c",
           "ellipsoid": "#17becf"}
MARKERS = "osD^v<>ph"


def _colour(label: str | None) -> str:
    if not label:
        return "white"
    if label.endswith("vesicles"):
        return "#8c564b"
    return COLOURS.get(label, "#e377c2")


def draw(rows: list[dict], sweep, out: Path) -> list[Path]:
    """Draw what the rows allow; the paths written: the phase diagram of the grid's points
    (without axes: the energies of the listed points along their first scene key that all of
    them set, if any) and the montage of the end shapes."""
    written = []
    listed = {p["name"] for p in sweep.listed}
    grid = [r for r in rows if r["point"] not in listed]
    if grid and (sweep.axes or not listed):
        written.append(phase_diagram(grid, sweep, out / "phase-diagram.png"))
    elif rows:
        key = next((k for k in sweep.columns()
                    if all(isinstance(r.get(k), (int, float)) for r in rows)), None)
        if key is not None:
            written.append(energy_diagram(rows, sweep, out / "phase-diagram.png", key))
    montage = shape_montage(rows, sweep, out / "montage.png")
    if montage is not None:
        written.append(montage)
    return written


def phase_diagram(rows: list[dict], sweep, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    from fem_ade.plots.figures import save_figure

    axes = list(sweep.axes)
    xkey = axes[0] if axes else None
    ykey = axes[1] if len(axes) > 1 else None
    if xkey and not ykey:
        return energy_diagram(rows, sweep, path, xkey)
    seeds = list(sweep.seeds)
    xs = sorted({r[xkey] for r in rows}) if xkey else [0]
    ys = sorted({r[ykey] for r in rows}) if ykey else [0]
    dx = (min((b - a for a, b in zip(xs, xs[1:], strict=False)), default=1.0))
    dy = (min((b - a for a, b in zip(ys, ys[1:], strict=False)), default=1.0))
    fig, ax = plt.subplots(figsize=(7.5, 5.2))
    groups = {}
    for r in rows:
        groups.setdefault((r.get(xkey, 0), r.get(ykey, 0)), []).append(r)
    labels_seen = set()
    for (x, y), rs in groups.items():
        # the sharp lowest branch of the seeds at this point, as a cell behind
        sharp = [(r["e_sharp_seed"], r["seed"]) for r in rs
                 if isinstance(r.get("e_sharp_seed"), float)]
        if sharp:
            branch = min(sharp)[1]
            ax.add_patch(plt.Rectangle((x - dx / 2, y - dy / 2), dx, dy, alpha=0.18,
                                       color=_colour(branch), lw=0))
        done = [r for r in rs if r.get("status") in HAS_RESULT and r.get("e") is not None]
        best = min(done, key=lambda r: r["e"]) if done else None
        ends = {r.get("label") for r in done}
        for r in rs:
            i = seeds.index(r["seed"]) if r["seed"] in seeds else 0
            off = (i - (len(seeds) - 1) / 2) * dx * 0.22
            label = r.get("label") if r.get("status") in HAS_RESULT else None
            labels_seen.add(label)
            ax.plot(x + off, y, MARKERS[i % len(MARKERS)], ms=9, mfc=_colour(label),
                    mec="black" if r is best else "0.5", mew=2.0 if r is best else 0.6)
        if len(ends) > 1:
            ax.plot(x, y + dy * 0.32, "x", color="black", ms=6)
    handles = [Line2D([], [], marker="s", ls="", mfc=_colour(lab), mec="0.5", ms=8,
                      label=lab or "failed / not run") for lab in sorted(
                          labels_seen, key=lambda s: s or "~")]
    handles += [Line2D([], [], marker=MARKERS[i % len(MARKERS)], ls="", mfc="white", mec="k",
                       ms=8, label=f"seed {s}") for i, s in enumerate(seeds)]
    handles += [Line2D([], [], marker="o", ls="", mfc="white", mec="k", mew=2, ms=8,
                       label="lowest energy at the point"),
                Line2D([], [], marker="x", ls="", color="k", label="seeds end differently")]
    ax.legend(handles=handles, fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax.set_xlabel(xkey or "")
    ax.set_ylabel(ykey or "")
    if not ykey:
        ax.set_yticks([])
    ax.set_xlim(xs[0] - dx * 0.7, xs[-1] + dx * 0.7)
    ax.set_ylim(ys[0] - dy * 0.7, ys[-1] + dy * 0.7)
    ax.set_title(f"sweep {sweep.name}: end states (cells: the sharp reference's lowest "
                 "branch)", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=110, colours=64)
    plt.close(fig)
    return path


def energy_diagram(rows: list[dict], sweep, path: Path, xkey: str) -> Path:
    """One axis: e along it per seed (markers coloured by the end state), the sharp energy of
    each seed's branch (lines), the lowest end state per point ringed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    from fem_ade.plots.figures import save_figure

    seeds = list(sweep.seeds)
    fig, ax = plt.subplots(figsize=(7.5, 5.0))
    seen = set()
    for i, s in enumerate(seeds):
        mine = sorted((r for r in rows if r["seed"] == s), key=lambda r: r[xkey])
        sharp = [(r[xkey], r["e_sharp_seed"]) for r in mine
                 if isinstance(r.get("e_sharp_seed"), float)]
        if sharp:
            ax.plot(*zip(*sharp, strict=True), "-", color=_colour(s), lw=1.2)
        for r in mine:
            if r.get("status") in HAS_RESULT and r.get("e") is not None:
                seen.add(r.get("label"))
                ax.plot(r[xkey], r["e"], MARKERS[i % len(MARKERS)], ms=8,
                        mfc=_colour(r.get("label")), mec="0.4", mew=0.6)
    for x in sorted({r[xkey] for r in rows}):
        done = [r for r in rows if r[xkey] == x and r.get("status") in HAS_RESULT
                and r.get("e") is not None]
        if done:
            best = min(done, key=lambda r: r["e"])
            ax.plot(x, best["e"], "o", ms=14, mfc="none", mec="black", mew=1.5)
    handles = [Line2D([], [], marker="s", ls="", mfc=_colour(lab), mec="0.5", ms=8,
                      label=f"ends {lab}") for lab in sorted(seen, key=lambda s: s or "~")]
    handles += [Line2D([], [], marker=MARKERS[i % len(MARKERS)], ls="-", color=_colour(s),
                       mfc="white", mec="k", ms=8, label=f"seed {s} (line: its sharp e)")
                for i, s in enumerate(seeds)]
    handles += [Line2D([], [], marker="o", ls="", mfc="none", mec="k", mew=1.5, ms=12,
                       label="lowest at the point")]
    ax.legend(handles=handles, fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax.set(xlabel=xkey, ylabel="e = (W + G) / W_sphere",
           title=f"sweep {sweep.name}: end states and energies")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path, dpi=110, colours=64)
    plt.close(fig)
    return path


def shape_montage(rows: list[dict], sweep, path: Path, width: int = 240) -> Path | None:
    from PIL import Image, ImageDraw

    root = path.parent / "points"
    cells = [(r, root / r["point"] / "shape.png") for r in rows]
    cells = [(r, p) for r, p in cells if p.is_file()]
    if not cells:
        return None
    seeds = list(sweep.seeds)
    order = sorted({r["point"].rsplit("_seed=", 1)[0] for r, _ in cells})
    from PIL import ImageFont

    font = ImageFont.load_default(size=15)
    thumbs = {}
    for r, p in cells:
        with Image.open(p) as im:  # the 3D view: the left half, below the titles
            w, h = im.size
            view = im.convert("RGB").crop((0, int(0.26 * h), w // 2, int(0.92 * h)))
            view = view.resize((width, round(width * view.size[1] / view.size[0])))
        cell = Image.new("RGB", (width, view.size[1] + 40), "white")
        cell.paste(view, (0, 40))
        name = r["point"].rsplit("_seed=", 1)[0].replace("_", " ")
        ImageDraw.Draw(cell).text((4, 2), f"{name} · {r['seed']}\nends {r.get('label')}",
                                  fill="black", font=font)
        thumbs[(r["point"].rsplit("_seed=", 1)[0], r["seed"])] = cell
    h = max(t.size[1] for t in thumbs.values())
    sheet = Image.new("RGB", (width * len(order), h * len(seeds)), "white")
    for i, key in enumerate(order):
        for j, s in enumerate(seeds):
            if (key, s) in thumbs:
                sheet.paste(thumbs[(key, s)], (i * width, j * h))
    sheet.quantize(64).save(path, optimize=True)
    return path
