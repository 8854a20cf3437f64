"""The axisymmetric geometry of the FEM backend: a vesicle that is a surface of revolution, as
a phase field on the meridional half-plane (r, z) with the measure 2πr dr dz (docs/model.md
§11).

The weak forms are the Cartesian ones (:mod:`fem_ade.backends.fem.forms`,
:mod:`fem_ade.backends.fem.step`):
only the space changes. It is a tensor space of a radial axis r ∈ [0, R] and an axis
z ∈ [z₀, z₁] (:class:`fem_ade.backends.fem.tensor.BoundedAxis`), spectral elements of any order with
Gauss–Lobatto–Jacobi (0, 1) points in the cells at the axis, natural (zero-flux) ends on
r = R, z = z₀, z = z₁ — so W = w_r ⊗ w_z, K = K_r ⊗ W_z + W_r ⊗ K_z, and the step is solved
exactly by fast diagonalization as in 3D (the 1D generalized eigenproblems K_r v = λ W_r v,
K_z v = λ W_z v). The integrals are those of the 3D body of revolution: V, A, ΔA, W, G are
the 3D run's numbers.

Which scenes: those whose initial shape is a surface of revolution about a vertical line
(:meth:`fem_ade.scenes.initial.Shape.axis_of_revolution`): the axis r = 0 is that line, z the box's
z.

The domain: by default r ≤ R = L/√π and z ∈ [0, L] — the cylinder with the box's volume and
height, so that the paper's volume functional, whose far field carries part of α (model §8),
sees the far field of the box; ``domain="R,z0,z1"`` sets it (the result does not depend on it
once the membrane is a few ε from its edges: ``tests/test_axisymmetric.py``).

The mesh: ``uniform`` (cells of h = L·p/n) or ``graded[:m]`` (the default): cells of h over
the box of the initial membrane widened by m·L (m = 0.05) on every side, and outside it
cells that grow by :data:`GROWTH` per cell up to :data:`MAX_COARSE` times — the far field,
where φ is −1 to many digits, costs a few cells. ``n`` counts nodes per L at the finest
spacing (n/p cells of order p), as in 3D; its default follows ε (:data:`NODES_PER_EPS`).
A run whose membrane leaves the fine zone says so (``info()["fine_zone"]``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from fem_ade.backends.fem.backend import FEMBackend
from fem_ade.backends.fem.tensor import BoundedAxis, TensorSpace
from fem_ade.model.params import ModelError
from fem_ade.registry import RUN_ORDERS
from fem_ade.scenes.catalogue import Scene

#: nodes per ε at the finest spacing of the default resolution (n = ⌈L·this/(ε·p)⌉ cells per
#: L). Measured (studies/axisymmetric.py, its resolution stage; docs/model.md §11): E's
#: relative error at steady state is below 1e-4 from 2 nodes per ε at order 4 on every shape tried
NODES_PER_EPS = 2.5
#: the default element order of the axisymmetric geometry (:data:`fem_ade.registry.RUN_ORDERS`)
DEFAULT_ORDER = RUN_ORDERS["axisymmetric"]
#: the graded mesh: the fine zone's margin around the initial membrane (a fraction of L)
DEFAULT_MARGIN = 0.05
#: the graded mesh: the ratio of neighbouring cells outside the fine zone, and the largest
#: cell over the fine one
GROWTH, MAX_COARSE = 1.3, 12.0
#: |φ| below this marks the membrane's band (the initial one: the fine zone; the final one:
#: whether it stayed there)
BAND = 0.999
#: |φ| below this is the membrane proper: an initial membrane that reaches the domain's edge
#: is refused (the natural edge would mirror it)
CUT = 0.9
#: φ on the revolved uniform grid (``grid_phi``, final.npz's phi_grid) at most this many
#: points per axis
GRID_LIMIT = 128


# ---------------------------------------------------------------------------------------------
# options
# ---------------------------------------------------------------------------------------------
def parse_mesh(mesh) -> tuple[str, float | None]:
    """The axisymmetric ``mesh`` option: ("uniform", None) or ("graded", margin)."""
    if mesh is None or mesh == "graded":
        return "graded", DEFAULT_MARGIN
    if mesh == "uniform":
        return "uniform", None
    if isinstance(mesh, str) and mesh.startswith("graded:"):
        try:
            margin = float(mesh[len("graded:"):])
        except ValueError:
            margin = math.nan
        if not (math.isfinite(margin) and 0.0 <= margin <= 1.0):
            raise ModelError(f"--mesh graded:m (axisymmetric) needs a margin 0 <= m <= 1 (a "
                             f"fraction of L), got {mesh!r}")
        return "graded", margin
    raise ModelError(f"the axisymmetric geometry takes --mesh uniform or graded[:m] (graded "
                     f"to the initial membrane, margin m·L), got {mesh!r}")


def axis_of(scene: Scene) -> tuple[float, float]:
    """(x, y) of the scene's axis of revolution; ModelError (one line) if its initial shape
    is not a surface of revolution about a vertical line."""
    if scene.dim != 3:
        raise ModelError(f"scene {scene.name} is {scene.dim}D: the axisymmetric geometry "
                         "takes 3D scenes whose shape is a surface of revolution")
    axis = scene.ic.axis_of_revolution()
    if axis is None:
        raise ModelError(f"scene {scene.name}: its initial shape ({scene.ic.kind}) is not a "
                         "surface of revolution about a vertical axis; run it in 3D (the "
                         "default --geometry cartesian)")
    return axis


def seeded_axis(scene: Scene, ic: str) -> tuple[float, float]:
    """The axis of the shape a run with ``ic`` starts from (``seeded``: the paper's figure's)."""
    if ic == "seeded" and not scene.ic.is_field:
        from dataclasses import replace

        from fem_ade.scenes.seeds import seeded_shape

        return axis_of(replace(scene, ic=seeded_shape(scene.name)))
    return axis_of(scene)


def parse_domain(domain, L: float) -> tuple[float, float, float]:
    """(R, z₀, z₁) of the ``domain`` option "R,z0,z1" (None: L/√π, 0, L)."""
    if domain is None:
        return L / math.sqrt(math.pi), 0.0, L
    try:
        values = [float(x) for x in str(domain).split(",")]
    except ValueError:
        values = []
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise ModelError(f"--domain needs three numbers R,z0,z1 (the half-plane r <= R, "
                         f"z0 <= z <= z1), got {domain!r}")
    R, z0, z1 = values
    if not (R > 0 and z1 > z0):
        raise ModelError(f"--domain R,z0,z1 needs R > 0 and z1 > z0, got {domain!r}")
    return R, z0, z1


def default_cells(eps: float, L: float, order: int, per_eps: float = NODES_PER_EPS) -> int:
    """Cells per L whose nodes are ``per_eps`` per ε (default :data:`NODES_PER_EPS`; at
    least 8 cells)."""
    return max(8, math.ceil(L * per_eps / (eps * order) - 1e-9))


def default_nodes(eps: float, L: float, order: int, per_eps: float = NODES_PER_EPS) -> int:
    """The default n (or that of ``per_eps`` nodes per ε): nodes per L at the finest
    spacing, p times :func:`default_cells`."""
    return order * default_cells(eps, L, order, per_eps)


# ---------------------------------------------------------------------------------------------
# the mesh
# ---------------------------------------------------------------------------------------------
def graded_vertices(lo: float, hi: float, a: float, b: float, h: float) -> np.ndarray:
    """Cell vertices of [lo, hi]: cells of about ``h`` over [a, b] (clipped to [lo, hi]) and,
    away from it, cells growing by :data:`GROWTH` up to :data:`MAX_COARSE`·h, the sizes of
    each side scaled to end at lo and hi."""
    a, b = max(lo, a), min(hi, b)
    if b - a < h:
        a, b = max(lo, 0.5 * (a + b) - 0.5 * h), min(hi, 0.5 * (a + b) + 0.5 * h)

    def side(length):
        if length < 0.75 * h:
            return None  # joined to the fine zone
        sizes, size = [], h
        while sum(sizes) < length:
            size = min(size * GROWTH, MAX_COARSE * h)
            sizes.append(size)
        sizes = np.array(sizes)
        if len(sizes) > 1 and sum(sizes) - length > 0.5 * sizes[-1]:
            sizes = sizes[:-1]
        return np.cumsum(sizes * (length / sizes.sum()))

    left, right = side(a - lo), side(hi - b)
    if left is None:
        a = lo
    if right is None:
        b = hi
    fine = np.linspace(a, b, max(1, round((b - a) / h)) + 1)
    parts = [fine]
    if left is not None:
        parts.insert(0, (a - left)[::-1])
    if right is not None:
        parts.append(b + right)
    x = np.concatenate(parts)
    x[0], x[-1] = lo, hi
    return x


@dataclass
class RZMesh:
    """The tensor mesh of the half-plane: radial cell vertices ``r`` (from 0), axial ``z``,
    the fine zone ((r_a, r_b), (z_a, z_b)) and the fine cell size ``h`` (L·p/n for n nodes
    per L)."""

    kind: str
    r: np.ndarray
    z: np.ndarray
    fine: tuple[tuple[float, float], tuple[float, float]]
    h: float
    L: float
    margin: float | None = None
    dim = 2
    is_tensor = True
    source = ""

    @property
    def axes(self):
        return (self.r, self.z)

    @property
    def cells_per_axis(self) -> tuple[int, int]:
        return len(self.r) - 1, len(self.z) - 1

    @property
    def h_min(self) -> float:
        return float(min(np.diff(self.r).min(), np.diff(self.z).min()))

    @property
    def h_max(self) -> float:
        return float(max(np.diff(self.r).max(), np.diff(self.z).max()))

    def describe(self) -> dict:
        return {"kind": self.kind, "geometry": "axisymmetric",
                "domain": [float(self.r[-1]), float(self.z[0]), float(self.z[-1])],
                "cells": list(self.cells_per_axis), "h_fine": self.h,
                "fine_zone": [list(map(float, self.fine[0])), list(map(float, self.fine[1]))],
                "margin": self.margin, "h_min": self.h_min, "h_max": self.h_max}


def make_mesh(kind: str, margin, cells: int, L: float, domain, band=None) -> RZMesh:
    """The mesh of ``kind`` ("uniform" or "graded") with cells of L/cells (graded: over
    ``band``, the box ((r_a, r_b), (z_a, z_b)) of the initial membrane, widened by
    margin·L)."""
    R, z0, z1 = domain
    h = L / cells
    if kind == "uniform" or band is None:
        r = np.linspace(0.0, R, max(1, round(R / h)) + 1)
        z = np.linspace(z0, z1, max(1, round((z1 - z0) / h)) + 1)
        return RZMesh("uniform", r, z, ((0.0, R), (z0, z1)), h, L)
    m = margin * L
    (ra, rb), (za, zb) = band
    r = graded_vertices(0.0, R, ra - m, rb + m, h)
    z = graded_vertices(z0, z1, za - m, zb + m, h)
    fine_r = (float(r[0]) if ra - m <= 0.75 * h else max(0.0, ra - m), min(R, rb + m))
    fine_z = (max(z0, za - m), min(z1, zb + m))
    return RZMesh("graded", r, z, (fine_r, fine_z), h, L, margin)


def membrane_band(phi: np.ndarray, r: np.ndarray, z: np.ndarray, level: float = BAND):
    """((r_a, r_b), (z_a, z_b)): the box of the nodes of the (r, z) grid where |φ| < level,
    or None where there are none."""
    where = np.abs(phi) < level
    if not where.any():
        return None
    ri, zi = np.nonzero(where)
    return (float(r[ri.min()]), float(r[ri.max()])), (float(z[zi.min()]), float(z[zi.max()]))


def axisymmetric_perturbation(R: float, z0: float, z1: float, seed: int, kmax: int = 2):
    """ψ(r, z), |ψ| ≤ 1: a seeded combination of cos(πkr/R)·cos(πj(z − z₀)/(z₁ − z₀) + φ)
    (k, j ≤ kmax, not both 0) — smooth across the axis (even in r), the axisymmetric
    counterpart of :func:`fem_ade.scenes.catalogue.smooth_perturbation`."""
    rng = np.random.default_rng(seed)
    modes = [(k, j) for k in range(kmax + 1) for j in range(kmax + 1) if k or j]
    amps = rng.standard_normal(len(modes))
    phases = rng.uniform(0.0, 2.0 * math.pi, len(modes))
    amps /= np.sum(np.abs(amps))

    def psi(points):
        r, z = points
        out = np.zeros(np.shape(r))
        for (k, j), a, ph in zip(modes, amps, phases, strict=True):
            out += a * np.cos(math.pi * k * r / R) * np.cos(math.pi * j * (z - z0) / (z1 - z0)
                                                            + ph)
        return out

    return psi


# ---------------------------------------------------------------------------------------------
# the backend
# ---------------------------------------------------------------------------------------------
class AxisymmetricFEMBackend(FEMBackend):
    """The FEM backend in the axisymmetric geometry (module docstring); the Backend protocol.

    Options beyond the Cartesian FEM's: ``geometry="axisymmetric"``; ``domain`` "R,z0,z1"
    (default: r ≤ L/√π, 0 ≤ z ≤ L); ``mesh`` "graded[:m]" (default) or "uniform"; ``order``
    (default :data:`DEFAULT_ORDER`); ``n`` nodes per L at the finest spacing, n/p cells of
    order p (default :func:`default_nodes`). The step is solved exactly (``solver``
    auto/fdm) or, as a check, by PCG with AMG (``amg``, ``chebyshev``, ``jacobi``).
    """

    geometry = "axisymmetric"

    def __init__(self, scene: Scene, *, n: int, order: int = DEFAULT_ORDER, mesh=None,
                 domain=None, geometry: str = "axisymmetric", linalg: str = "numpy", **kw):
        if geometry != "axisymmetric":
            raise ModelError(f"{type(self).__name__} runs geometry='axisymmetric', not "
                             f"{geometry!r}")
        if linalg != "numpy":
            raise ModelError("the axisymmetric geometry runs in one process (--linalg numpy)")
        self.axis = seeded_axis(scene, kw.get("ic", "consistent"))
        self.domain = parse_domain(domain, scene.params.L)
        self.mesh_kind, self.margin = parse_mesh(mesh)
        self._ic = (kw.get("ic", "consistent"), kw.get("perturb", 0.0), kw.get("seed", 0))
        super().__init__(scene, n=n, order=order, mesh=mesh, linalg=linalg,
                         geometry=geometry, **kw)

    # -- the protocol's class methods ---------------------------------------------------------
    @classmethod
    def default_n(cls, scene: Scene, *, order: int = DEFAULT_ORDER, **options) -> int:
        """Nodes per L with :data:`NODES_PER_EPS` per ε (the scene's n is a 3D grid's)."""
        if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or order < 1:
            order = DEFAULT_ORDER
        return default_nodes(scene.params.eps, scene.params.L, int(order))

    @classmethod
    def run_options(cls, options: dict) -> dict:
        """The order of a run that gives none: :data:`DEFAULT_ORDER`."""
        return {"order": DEFAULT_ORDER, **options}

    @classmethod
    def nodes_per_axis(cls, n: int, **options) -> int | None:
        """None: the (r, z) grid is no cubic grid (run.json keeps the scene's n)."""
        return None

    @classmethod
    def min_cells(cls, **options) -> int:
        return 4

    @classmethod
    def is_tensor(cls, mesh) -> bool:
        """Always: the (r, z) mesh is a tensor mesh (its option is checked by
        :meth:`check_options`)."""
        return True

    @classmethod
    def memory_bytes(cls, scene: Scene, n: int, *, order: int = DEFAULT_ORDER, mesh=None,
                     domain=None, solver: str = "auto", **options) -> float:
        """At most a uniform mesh's: the state and work vectors per node, the dense 1D
        eigenbases, and with PCG + AMG the assembled low-order matrices."""
        R, z0, z1 = parse_domain(domain, scene.params.L)
        per_L = float(n) / scene.params.L
        nr, nz = per_L * R + 1, per_L * (z1 - z0) + 1
        per_node = cls.bytes_per_dof if solver in ("auto", "fdm") else cls.bytes_per_krylov_dof
        return per_node * nr * nz + 16.0 * (nr * nr + nz * nz)

    @classmethod
    def check_options(cls, scene: Scene, n: int, *, order: int = DEFAULT_ORDER, mesh=None,
                      solver: str = "auto", linalg: str = "numpy", rtol=None,
                      geometry: str = "axisymmetric", domain=None) -> float:
        """The scene (a surface of revolution), domain, mesh, order, solver; returns the
        finest node spacing L/n."""
        from fem_ade.backends.base import check_choice
        from fem_ade.backends.fem.solve import EXACT
        from fem_ade.registry import FEM_ORDERS, FEM_SOLVERS

        if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or \
                order not in FEM_ORDERS:
            raise ModelError(f"--order must be an integer from 1 to {FEM_ORDERS[-1]}, "
                             f"got {order!r}")
        check_choice("FEM solver", solver, FEM_SOLVERS)
        if linalg != "numpy":
            raise ModelError("the axisymmetric geometry runs in one process: --linalg petsc "
                             "is for 3D meshes")
        if solver == "fft":
            raise ModelError("solver 'fft' needs a periodic uniform mesh; the axisymmetric "
                             "step is solved exactly by 'fdm' (the default)")
        if rtol is not None and (solver in ("auto", *EXACT)):
            raise ModelError("--rtol sets the tolerance of the PCG solvers (amg, chebyshev, "
                             "jacobi); this run solves each step exactly (fdm)")
        if rtol is not None and not (isinstance(rtol, float | int) and 1e-14 <= rtol < 1):
            raise ModelError(f"--rtol must be a number in [1e-14, 1) (below it round-off "
                             f"never lets PCG stop), got {rtol}")
        axis_of(scene)  # a seeded start's shape is checked when it is built (seeded_axis)
        parse_mesh(mesh)
        R, z0, z1 = parse_domain(domain, scene.params.L)
        L = scene.params.L
        h = L * order / n  # the finest cell
        if R < 2 * h or z1 - z0 < 2 * h:
            raise ModelError(f"--domain {R:g},{z0:g},{z1:g} is less than 2 cells of "
                             f"L·p/n = {h:.3g} across")
        return L / n

    # -- geometry ------------------------------------------------------------------------------
    def _make_mesh(self, cells: int, mesh):
        band = self._initial_band()  # also checks that the membrane is inside the domain
        return make_mesh(self.mesh_kind, self.margin, cells, self.params.L, self.domain,
                         band if self.mesh_kind == "graded" else None)

    def _space(self):
        p = self.order
        return TensorSpace([BoundedAxis(self.mesh.r, p, radial=True),
                            BoundedAxis(self.mesh.z, p)], p)

    def points3(self, points: np.ndarray) -> np.ndarray:
        """The 3D points (x, y, z) of the meridional half-plane's (r, z): x = axis + r."""
        r, z = points
        return np.stack([self.axis[0] + r, np.full_like(r, self.axis[1]), z])

    def initial_field(self, points: np.ndarray, *, ic: str, perturb: float,
                      seed: int) -> np.ndarray:
        """φ₀ at the (r, z) ``points`` (2, ...): the scene's initial condition in the plane
        through the axis, not repeated with the box's period, perturbed axisymmetrically."""
        R, z0, z1 = self.domain
        psi = axisymmetric_perturbation(R, z0, z1, seed)
        return self.scene.initial_phi(self.points3(points), ic=ic, perturb=perturb,
                                      seed=seed, periodic=False,
                                      perturbation=lambda pts: psi(points))

    def _initial_band(self):
        """The box of the initial membrane, probed on a uniform (r, z) grid of ≤ 4·10⁵
        points (at most ε/2 apart)."""
        R, z0, z1 = self.domain
        eps = self.params.eps
        step = max(0.5 * eps, math.sqrt(R * (z1 - z0) / 4e5))
        r = np.linspace(0.0, R, max(2, math.ceil(R / step)) + 1)
        z = np.linspace(z0, z1, max(2, math.ceil((z1 - z0) / step)) + 1)
        rr, zz = np.meshgrid(r, z, indexing="ij")
        ic, perturb, seed = self._ic
        phi = self.initial_field(np.stack([rr, zz]), ic=ic, perturb=perturb, seed=seed)
        band = membrane_band(phi, r, z)
        where = f"the domain r <= {R:g}, {z0:g} <= z <= {z1:g}"
        if band is None:
            raise ModelError(f"scene {self.scene.name}: the initial field has no membrane in "
                             f"{where}")
        (_, rb), (za, zb) = membrane_band(phi, r, z, level=CUT)
        if rb >= r[-1] or za <= z[0] or zb >= z[-1]:
            raise ModelError(f"scene {self.scene.name}: the initial membrane reaches the edge "
                             f"of {where} (its natural edges would mirror it): give a larger "
                             "--domain R,z0,z1")
        return band

    # -- output --------------------------------------------------------------------------------
    def fields(self) -> dict[str, np.ndarray]:
        """φ, μ at the nodes, their (r, z) ``points`` (2, N), the node axes ``r``, ``z``, and
        what rebuilds the space: the cell vertices, the order, the fine zone."""
        ar, az = self.space.axes
        (ra, rb), (za, zb) = self.mesh.fine
        return {"phi": self.phi.copy(), "mu": self.mu.copy(),
                "points": self.space.doflocs.copy(), "r": ar.nodes.copy(),
                "z": az.nodes.copy(), "axis": np.array(self.axis),
                # what rebuilds the space (fem_ade.analysis.axishape.Meridians.from_fields)
                "r_vertices": self.mesh.r.copy(), "z_vertices": self.mesh.z.copy(),
                "order": np.array(self.order), "fine_zone": np.array([ra, rb, za, zb])}

    def phi_rz(self) -> np.ndarray:
        """φ as an (N_r, N_z) array."""
        return self.phi.reshape(self.space.shape)

    def grid_phi(self) -> np.ndarray:
        """φ revolved onto the scene box's uniform grid x_j = jL/m (m = n, at most
        :data:`GRID_LIMIT`): what a 3D run started from this one (``--phi0``) reads. Points
        beyond the half-plane's radius take its value at r = R."""
        L = self.params.L
        m = max(8, min(self.n, GRID_LIMIT))
        x = np.arange(m) * (L / m)
        ar, az = self.space.axes
        R = ar.nodes[-1]
        rs = np.linspace(0.0, R, 4 * m + 1)  # fine radial samples, linear between them
        table = self.space.interpolate_to([rs, x])(self.phi)  # (len(rs), m)
        X, Y = np.meshgrid(x - self.axis[0], x - self.axis[1], indexing="ij")
        rho = np.minimum(np.hypot(X, Y), R).ravel()
        t = rho / (rs[1] - rs[0])
        i = np.minimum(t.astype(int), len(rs) - 2)
        f = (t - i)[:, None]
        vals = (1.0 - f) * table[i] + f * table[i + 1]  # (m², m)
        return vals.reshape(m, m, m)

    def output_mesh(self):
        """The (r, z) node grid as quadrilaterals in the plane y = 0 (x = r): ParaView's
        Rotational Extrusion about z revolves it."""
        if self._out is None:
            from fem_ade.backends.fem.output import grid_cells

            ar, az = self.space.axes
            R, Z = np.meshgrid(ar.nodes, az.nodes, indexing="ij")
            points = np.stack([R.ravel(), np.zeros(R.size), Z.ravel()], axis=1)
            kind, cells = grid_cells([ar.size, az.size])
            self._out = (points, [(kind, cells)], np.arange(self.space.n_dofs))
        return self._out[0], self._out[1]

    def fine_zone_report(self) -> dict:
        """Whether the membrane (|φ| < BAND) stayed in the graded mesh's fine zone."""
        ar, az = self.space.axes
        band = membrane_band(self.phi_rz(), ar.nodes, az.nodes)
        if band is None or self.mesh.kind != "graded":
            return {"inside": True, "band": band}
        (ra, rb), (za, zb) = self.mesh.fine
        tol = 1e-12 * self.params.L
        inside = (band[0][0] >= ra - tol and band[0][1] <= rb + tol and
                  band[1][0] >= za - tol and band[1][1] <= zb + tol)
        return {"inside": bool(inside), "band": band}

    def describe_final(self, final: dict, grid: np.ndarray | None = None):
        """The shape of the final φ = 0 meridians (:mod:`fem_ade.analysis.axishape`)."""
        from fem_ade.analysis.axishape import describe_axisymmetric

        return describe_axisymmetric(self, final, grid)

    def resolution_per_length(self) -> float:
        """Nodes per L at the finest spacing (n): the in-run sharp comparison's test."""
        return float(self.n)

    def info(self) -> dict:
        info = super().info()
        ar, az = self.space.axes
        R, z0, z1 = self.domain
        zone = self.fine_zone_report()
        kind = info["solver"]
        gap = self.mesh.h / self.order
        info.update({
            "geometry": "axisymmetric",
            "resolution": (f"axisymmetric, order {self.order} (GLL, GLJ at the axis), "
                           f"{ar.size} x {az.size} nodes (r x z) on r <= {R:.4g}, "
                           f"{z0:.4g} <= z <= {z1:.4g}, {self.mesh.kind} mesh, finest node "
                           f"gap ~ {gap:.3g} ({self.params.eps / gap:.3g} per eps), solver "
                           f"{kind}"),
            "element": f"Q{self.order} (GLL; GLJ(0,1) in the cells at the axis)",
            "nodes": [int(ar.size), int(az.size)],
            "axis": list(self.axis),
            "fine_zone": {"inside": zone["inside"],
                          "membrane_box": None if zone["band"] is None else
                          [list(zone["band"][0]), list(zone["band"][1])]},
        })
        return info


class SavedMeshBackend(AxisymmetricFEMBackend):
    """An axisymmetric backend on the very mesh a saved field was computed on — its
    ``fields`` (:meth:`AxisymmetricFEMBackend.fields`: the cell vertices, the order, the fine
    zone, the axis) — at that field: what reads a branch point's or a run's end exactly
    (its steady state on its own discretization). ``params`` the model's; ``n`` the nodes per
    L of the fine zone (the run's or branch's n)."""

    def __init__(self, params, fields: dict, *, n: int, constraints: str = "exact",
                 scheme: str = "stabilized"):
        from fem_ade.scenes.initial import Sphere

        self._saved = {k: np.asarray(v) for k, v in fields.items()}
        r, z = self._saved["r_vertices"], self._saved["z_vertices"]
        ax, ay = (float(x) for x in self._saved["axis"])
        R0 = math.sqrt(params.beta / (4.0 * math.pi))
        scene = Scene("saved", params, 1e-6,
                      Sphere(centre=(ax, ay, 0.5 * (z[0] + z[-1])), radius=R0))
        super().__init__(scene, n=n, order=int(self._saved["order"]), mesh="graded",
                         domain=f"{float(r[-1])!r},{float(z[0])!r},{float(z[-1])!r}", scheme=scheme,
                         constraints=constraints)
        phi = np.asarray(self._saved["phi"], dtype=float).ravel()
        if phi.size != self.space.n_dofs:
            raise ModelError(f"the saved field has {phi.size} nodes, its mesh {self.space.n_dofs}")
        self._set(phi, None)

    def _make_mesh(self, cells: int, mesh):
        f = self._saved
        ra, rb, za, zb = (float(x) for x in f["fine_zone"])
        L = self.params.L
        return RZMesh("graded", np.asarray(f["r_vertices"], dtype=float),
                      np.asarray(f["z_vertices"], dtype=float), ((ra, rb), (za, zb)), L / cells, L,
                      DEFAULT_MARGIN)


class SavedField:
    """An axisymmetric run's final field rebuilt from its final.npz (what
    :func:`fem_ade.analysis.axishape.meridians` needs of a backend: ``space``, ``phi``, ``domain``,
    ``mesh.fine``, ``params.eps``)."""

    def __init__(self, data, eps: float):
        order = int(data["order"])
        r, z = np.asarray(data["r_vertices"]), np.asarray(data["z_vertices"])
        self.space = TensorSpace([BoundedAxis(r, order, radial=True), BoundedAxis(z, order)],
                                 order)
        self.phi = np.asarray(data["phi"], dtype=float)
        if self.phi.shape != (self.space.n_dofs,):
            raise ValueError(f"phi has {self.phi.size} values, its space {self.space.n_dofs}")
        self.domain = (float(r[-1]), float(z[0]), float(z[-1]))
        ra, rb, za, zb = (float(x) for x in data["fine_zone"])
        self.mesh = SimpleNamespace(fine=((ra, rb), (za, zb)))
        self.params = SimpleNamespace(eps=eps)
