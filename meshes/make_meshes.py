"""Write the sample periodic box meshes of this folder (hexahedra on [0, 1]³, 12 cells per side).

- ``box12_uniform.vtu``: equal cells;
- ``box12_graded.vtu``: smoothly graded spacing per axis (largest/smallest cell 1.86);
- ``box12_perturbed.vtu``: the uniform nodes moved by a smooth periodic displacement that keeps
  each face in place, so the cells are general (non-affine) hexahedra.

All three have matching nodes on opposite faces, which is what ``fem_ade.backends.fem.mesh.from_file``
needs to identify them periodically. Run: ``python meshes/make_meshes.py [OUTDIR]``.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import meshio
import numpy as np

N = 12


def _write(path: Path, x, y, z, displace=None):
    from skfem import MeshHex1
    from skfem.io.meshio import to_meshio

    mesh = MeshHex1.init_tensor(x, y, z)
    if displace is not None:
        mesh = MeshHex1(mesh.p + displace(mesh.p), mesh.t)
    meshio.write(path, to_meshio(mesh))
    return path


def _graded(n, shift, g=0.3):
    s = np.linspace(0.0, 1.0, n + 1)
    wave = np.sin(2 * math.pi * (s - shift)) - math.sin(-2 * math.pi * shift)
    return s - g / (2 * math.pi) * wave


def _wobble(p, a=0.02):
    """d_i = a sin(2πx_i) ∏_{j≠i} cos(2πx_j): zero normal motion on every face, periodic."""
    s, c = np.sin(2 * math.pi * p), np.cos(2 * math.pi * p)
    return a * np.stack([s[0] * c[1] * c[2], c[0] * s[1] * c[2], c[0] * c[1] * s[2]])


def main(outdir: str | Path | None = None, n: int = N) -> list[Path]:
    """Write box{n}_uniform/graded/perturbed.vtu into ``outdir`` (default: this folder)."""
    out = Path(outdir) if outdir else Path(__file__).parent
    out.mkdir(parents=True, exist_ok=True)
    u = np.linspace(0.0, 1.0, n + 1)
    return [
        _write(out / f"box{n}_uniform.vtu", u, u, u),
        _write(out / f"box{n}_graded.vtu", *(_graded(n, 0.13 * k) for k in range(3))),
        _write(out / f"box{n}_perturbed.vtu", u, u, u, displace=_wobble),
    ]


if __name__ == "__main__":
    for p in main(sys.argv[1] if len(sys.argv) > 1 else None):
        print(p)
