"""The README's picture: ``discocyte`` with the FEM backend (Q1, 48³, the paper's Δt).

    python studies/readme_figure.py [--steps 400] [--out studies/results/readme]

Runs the scene through the CLI's Python API and keeps ``shape.png`` as ``discocyte.png``
(and ``history.png`` as ``discocyte-history.png``).
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
from pathlib import Path

from fem_ade.runs import simulate
from fem_ade.scenes import get_scene


def main(argv=None) -> Path:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--n", type=int, default=48)
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "readme"))
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        run = Path(tmp) / "run"
        result = simulate(get_scene("discocyte"), backend="fem", n=args.n, steps=args.steps,
                          every=20, out=run, quiet=False)
        shutil.copy(run / "shape.png", out / "discocyte.png")
        shutil.copy(run / "history.png", out / "discocyte-history.png")
    print(result.message, result.shape)
    return out / "discocyte.png"


if __name__ == "__main__":
    main()
