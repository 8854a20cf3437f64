"""The FEM step on PETSc, distributed over MPI ranks (``--linalg petsc``).

The same mixed step as :mod:`fem_ade.fem.step` — the same :class:`~fem_ade.fem.step.MixedStep`
code, the same weak forms — with three things swapped:

* **the partition**: the DOF grid of a tensor mesh (uniform or graded, Q1 or Q2) is split
  by a PETSc DMDA (periodic, box stencil of width = order) into one box per rank. A rank
  holds φ, μ, Kφ, the lumped weights and the DOF coordinates of its box only, as NumPy arrays
  (the DMDA's natural ordering is the serial backend's C ordering, so the gathered field is
  the serial one, index for index);
* **the matrices**: each rank assembles its own rows of K (and of M_L + sK for the
  preconditioner) from the 1D periodic matrices, as the serial Kronecker assembly does
  (:func:`fem_ade.fem.assemble.periodic_1d`), into a PETSc MPIAIJ matrix;
* **the solve**: the step's CG runs as a PETSc KSP (``-step_ksp_*``) on a matrix-free S
  (two MatMults per application, the rank-one terms as global dot products) with a shell
  preconditioner P⁻¹ = τ (M_L + sK)⁻¹ M_L (M_L + sK)⁻¹ whose two inner solves are one
  application of a PETSc preconditioner of M_L + sK (``-step_inner_pc_*``; default hypre
  BoomerAMG where PETSc has it, else GAMG), the serial path's pyamg V-cycle.

Every global sum of the forms (V, A, ΔA, E and the CG's dot products) is one MPI
allreduce (:data:`fem_ade.fem.solve._ALLREDUCE`). The driver is unchanged: every rank runs
it; the state it sees (``state()``, ``fields()``, ``grid_phi()``) is gathered to every rank,
so checkpoints and outputs have the serial format (the gather holds the whole field on each
rank: 8 bytes per DOF and field — 134 MB at 256³ — the limit of this design; the run
itself holds 1/ranks of the matrices per rank). The command line lets rank 0 write the run
folder (:func:`fem_ade.run.main`).

PETSc options go in the environment variable ``PETSC_OPTIONS`` (PETSc reads it), e.g.
``PETSC_OPTIONS="-step_inner_pc_type gamg"``, ``-step_inner_pc_hypre_boomeramg_strong_threshold
0.5``, ``-step_ksp_monitor``.
"""

from __future__ import annotations

import functools
import math
from types import SimpleNamespace

import numpy as np
import scipy.sparse as sp

from ..model import ModelError
from . import mesh as fmesh
from . import output
from . import solve as fsolve
from .assemble import periodic_1d, tensor_points
from .backend import FEMBackend

INSTALL_HINT = ("--linalg petsc needs petsc4py and mpi4py: run scripts/install-petsc.sh "
                "(apt-get install petsc-dev, then pip install -e '.[mpi]' with PETSC_DIR set)")


_PETSC = None


def petsc():
    """petsc4py's PETSc module (initialised with ``PETSC_OPTIONS``, as PETSc reads it);
    ModelError (one line: how to install) when petsc4py or mpi4py is missing."""
    global _PETSC
    if _PETSC is None:
        try:
            import mpi4py  # noqa: F401  (PETSc's communicator as an mpi4py one)
            from petsc4py import PETSc
        except ImportError as err:
            raise ModelError(f"{INSTALL_HINT} ({err})") from None
        _PETSC = PETSc
    return _PETSC


def available() -> bool:
    try:
        petsc()
    except ModelError:
        return False
    return True


class Partition:
    """The DMDA box of this rank in a periodic DOF grid of ``shape`` (serial axis order)."""

    def __init__(self, shape: tuple[int, ...], width: int):
        PETSc = petsc()
        self.PETSc = PETSc
        self.comm = PETSc.COMM_WORLD
        self.mpi = self.comm.tompi4py()
        d = len(shape)
        self.shape = tuple(int(s) for s in shape)
        # DMDA's x (fastest) is the serial backend's last axis: natural order = C order
        self.da = PETSc.DMDA().create(
            dim=d, dof=1, sizes=tuple(reversed(self.shape)),
            boundary_type=(PETSc.DM.BoundaryType.PERIODIC,) * d,
            stencil_type=PETSc.DMDA.StencilType.BOX, stencil_width=width, comm=self.comm)
        ranges = tuple(reversed(self.da.getRanges()))
        self.box = tuple(slice(int(a), int(b)) for a, b in ranges)
        self.local_shape = tuple(b.stop - b.start for b in self.box)
        self.n_local = int(np.prod(self.local_shape))
        self.N = int(np.prod(self.shape))
        self.ao = self.da.getAO()
        self.boxes = self.mpi.allgather(self.box)

    def local(self, full: np.ndarray) -> np.ndarray:
        """This rank's part of a full field (serial order)."""
        return np.ascontiguousarray(np.asarray(full).reshape(self.shape)[self.box]).ravel()

    def gather(self, part: np.ndarray) -> np.ndarray:
        """The full field (serial order) on every rank."""
        parts = self.mpi.allgather(np.ascontiguousarray(part))
        full = np.empty(self.shape)
        for box, p in zip(self.boxes, parts, strict=True):
            full[box] = p.reshape(tuple(b.stop - b.start for b in box))
        return full.ravel()

    def allreduce(self, value: float, op="sum") -> float:
        from mpi4py import MPI

        return float(self.mpi.allreduce(value, op=MPI.MAX if op == "max" else MPI.SUM))

    def vec(self, array=None):
        """A PETSc Vec of this partition (on ``array``'s memory when given)."""
        if array is None:
            return self.PETSc.Vec().createMPI((self.n_local, self.N), comm=self.comm)
        return self.PETSc.Vec().createWithArray(array, size=(self.n_local, self.N),
                                               comm=self.comm)


def _band(A: sp.csr_matrix, rows: slice):
    """(columns, values) of the rows of a 1D matrix as dense (len, width) arrays; short rows
    are padded with their first column and value 0."""
    A = A.tocsr()
    idx = range(rows.start, rows.stop)
    width = max(A.indptr[i + 1] - A.indptr[i] for i in idx)
    cols = np.empty((len(idx), width), dtype=np.int64)
    vals = np.zeros((len(idx), width))
    for r, i in enumerate(idx):
        a, b = A.indptr[i], A.indptr[i + 1]
        cols[r, : b - a] = A.indices[a:b]
        cols[r, b - a:] = A.indices[a]
        vals[r, : b - a] = A.data[a:b]
    return cols, vals


class TensorOperators:
    """This rank's rows of K, its lumped weights and DOF coordinates on a tensor mesh: the
    serial Kronecker assembly restricted to the rank's box (``K = Σ_d ⊗ (K_d or M_d)``)."""

    assembly = "kron"

    def __init__(self, mesh, order: int):
        ones = [periodic_1d(np.asarray(a, float), order) for a in mesh.axes]
        shape = tuple(len(o[2]) for o in ones)
        self.part = Partition(shape, width=order)
        self.order = order
        part, d = self.part, len(shape)
        bands = [(_band(o[0], b), _band(o[1], b)) for o, b in zip(ones, part.box, strict=True)]
        # global (natural = serial C order) column index of every (row, neighbour) pair
        strides = np.cumprod((1,) + tuple(reversed(shape[1:])))[::-1]
        cols = 0
        for a in range(d):
            c = bands[a][0][0]  # (len_a, width_a)
            view = [np.newaxis] * (2 * d)
            view[2 * a], view[2 * a + 1] = slice(None), slice(None)
            cols = cols + (c * int(strides[a]))[tuple(view)]
        vals = 0
        for k in range(d):  # K = sum over axes of K on that axis, M on the others
            term = 1
            for a in range(d):
                v = bands[a][1][1] if a == k else bands[a][0][1]
                view = [np.newaxis] * (2 * d)
                view[2 * a], view[2 * a + 1] = slice(None), slice(None)
                term = term * v[tuple(view)]
            vals = vals + term
        cols, vals = np.broadcast_arrays(cols, vals)
        width = int(np.prod([bands[a][0][0].shape[1] for a in range(d)]))
        # rows in C order over the box: reorder (l0, w0, l1, w1, ...) to (l0, l1, .., w0, w1, ..)
        perm = [2 * a for a in range(d)] + [2 * a + 1 for a in range(d)]
        cols = np.transpose(cols, perm).reshape(part.n_local, width)
        vals = np.transpose(vals, perm).reshape(part.n_local, width)
        petsc_cols = np.asarray(part.ao.app2petsc(cols.ravel().astype(part.PETSc.IntType)))
        local = sp.csr_matrix(
            (vals.ravel(), petsc_cols.astype(np.int64),
             np.arange(0, part.n_local * width + 1, width)), shape=(part.n_local, part.N))
        local.sum_duplicates()  # the padding (value 0) onto its row's first column
        local.sort_indices()
        self.K = DistMatrix(part, local)
        w1 = [np.asarray(o[0].sum(axis=1)).ravel()[b] for o, b in zip(ones, part.box,
                                                                         strict=True)]
        self.weights = functools.reduce(np.multiply.outer, w1).ravel()  # M_L = ⊗ M_L,d
        #: the 1D node locations of the whole mesh (the gathered fields' points)
        self.locs = [o[2] for o in ones]
        self.doflocs = tensor_points([x[b] for x, b in zip(self.locs, part.box, strict=True)])
        self.n_dofs = part.N
        self.M = None
        self.basis = None


class DistMatrix:
    """A PETSc MPIAIJ matrix acting on this rank's NumPy parts: ``A @ x``, ``diagonal()``."""

    def __init__(self, part: Partition, local: sp.csr_matrix | None = None, mat=None):
        self.part = part
        PETSc = part.PETSc
        if mat is None:
            mat = PETSc.Mat().createAIJ(
                size=((part.n_local, part.N), (part.n_local, part.N)),
                csr=(local.indptr.astype(PETSc.IntType), local.indices.astype(PETSc.IntType),
                     local.data), comm=part.comm)
            mat.assemble()
        self.mat = mat
        self.shape = (part.N, part.N)
        self._x, self._y = part.vec(), part.vec()

    def __matmul__(self, x):
        self._x.setArray(np.asarray(x, dtype=float))
        self.mat.mult(self._x, self._y)
        return self._y.getArray().copy()

    def diagonal(self) -> np.ndarray:
        return self.mat.getDiagonal().getArray().copy()

    def shifted(self, s: float, m: np.ndarray) -> DistMatrix:
        """diag(m) + s·self, a new matrix."""
        B = self.mat.copy()
        B.scale(s)
        B.setDiagonal(self.part.vec(np.ascontiguousarray(m, dtype=float)),
                      addv=self.part.PETSc.InsertMode.ADD_VALUES)
        return DistMatrix(self.part, mat=B)


class PetscStepSolver:
    """:class:`fem_ade.fem.solve.StepSolver` on PETSc: S x = b by KSP CG (matrix-free S,
    shell preconditioner P⁻¹ = τ B⁻¹ M_L B⁻¹, B = M_L + sK by one PETSc PC application)."""

    def __init__(self, M, K: DistMatrix, m, *, dt, kappa, eps, kind="amg", rtol=None,
                 degree=None, grid=None, s0=0.0, s2=0.0, cache=None, lumped=True):
        if not lumped:
            raise ModelError("--linalg petsc takes the lumped mass only")
        PETSc, part = K.part.PETSc, K.part
        self.part, self.K = part, K
        self.tau = dt if s0 == 0.0 else 1.0 / (1.0 / dt + s0)
        self.c = s2 - 2.0 * kappa / eps
        if s0 != 0.0 or s2 != 0.0:
            s_opt = fsolve.preconditioner_shift(self.tau, self.c, kappa * eps)
            grid_ratio = fsolve.SHIFT_GRID
            self.s = grid_ratio ** round(math.log(s_opt) / math.log(grid_ratio))
        else:
            self.s = math.sqrt(dt * kappa * eps)
        self.kind = {"auto": "amg", "chebyshev": "amg"}.get(kind, kind)
        self.rtol = fsolve.DEFAULT_RTOL if rtol is None else float(rtol)
        self.ke, self.dt = kappa * eps, dt
        self.m = np.ascontiguousarray(m, dtype=float)
        self.minv = 1.0 / self.m
        self.mv, self.minvv = part.vec(self.m.copy()), part.vec(self.minv.copy())
        key = ("petsc", self.kind, self.s)
        if cache is not None and key in cache:
            self.inner, self.B = cache[key]
        else:
            self.B = K.shifted(self.s, self.m)
            self.inner = PETSc.KSP().create(comm=part.comm)
            self.inner.setOptionsPrefix("step_inner_")
            self.inner.setOperators(self.B.mat)
            self.inner.setType("preonly")
            pc = self.inner.getPC()
            if self.kind == "jacobi":
                pc.setType("jacobi")
            elif _has_hypre(PETSc):
                pc.setType("hypre")
                pc.setHYPREType("boomeramg")
                _defaults(PETSc, "step_inner_", HYPRE_DEFAULTS)
            else:
                pc.setType("gamg")
            self.inner.setFromOptions()
            self.inner.setUp()
            if cache is not None:
                if len(cache) >= 4:
                    cache.pop(next(iter(cache)))
                cache[key] = (self.inner, self.B)
        self.levels = None
        self.low_rank = ()
        self._t1, self._t2, self._y = part.vec(), part.vec(), part.vec()
        self.S = PETSc.Mat().createPython(((part.n_local, part.N), (part.n_local, part.N)),
                                          context=_ShellS(self), comm=part.comm)
        self.S.setUp()
        self.ksp = PETSc.KSP().create(comm=part.comm)
        self.ksp.setOptionsPrefix("step_")
        self.ksp.setOperators(self.S)
        self.ksp.setType("cg")
        self.ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
        pc = self.ksp.getPC()
        pc.setType("python")
        pc.setPythonContext(_ShellP(self))
        self.ksp.setInitialGuessNonzero(True)
        self.ksp.setFromOptions()
        self._b, self._x = part.vec(), part.vec()

    # S x = (m/τ) x + K (c x + κε M_L⁻¹ K x) + Σ σ b (b·x)
    def mult(self, x, y):
        self.K.mat.mult(x, self._t1)
        self._t1.pointwiseMult(self._t1, self.minvv)
        self._t1.scale(self.ke)
        self._t1.axpy(self.c, x)
        self.K.mat.mult(self._t1, y)
        self._t2.pointwiseMult(x, self.mv)
        y.axpy(1.0 / self.tau, self._t2)
        for sig, bv in self.low_rank:
            y.axpy(sig * bv.dot(x), bv)

    def precondition_vec(self, r, z):
        self.inner.solve(r, self._y)
        self._y.pointwiseMult(self._y, self.mv)
        self.inner.solve(self._y, z)
        z.scale(self.tau)

    def solve(self, b, x0, ref=None, scale=None, low_rank=()):
        """(x, its): ‖b − Ŝx‖ ≤ rtol·scale, as :meth:`fem_ade.fem.solve.StepSolver.solve`."""
        self.low_rank = [(sig, self.part.vec(np.ascontiguousarray(v, dtype=float)))
                         for sig, v in low_rank]
        self._b.setArray(np.asarray(b, dtype=float))
        self._x.setArray(np.asarray(x0, dtype=float))
        if scale is None:
            ref = x0 if ref is None else ref
            r = self._b.copy()
            xr = self.part.vec(np.ascontiguousarray(ref, dtype=float))
            self.mult(xr, self._y)
            r.axpy(-1.0, self._y)
            scale = r.norm()
        if scale == 0.0:
            return np.array(ref if ref is not None else x0, dtype=float, copy=True), 0
        self.ksp.setTolerances(rtol=1e-300, atol=self.rtol * scale, max_it=500)
        self.ksp.solve(self._b, self._x)
        return self._x.getArray().copy(), int(self.ksp.getIterationNumber())


#: BoomerAMG tuned for 3D (PETSc's defaults coarsen slowly there: ≈ 8× the cost per
#: application at 32³); the user's ``-step_inner_pc_hypre_*`` options take precedence
HYPRE_DEFAULTS = {"pc_hypre_boomeramg_coarsen_type": "HMIS",
                  "pc_hypre_boomeramg_interp_type": "ext+i",
                  "pc_hypre_boomeramg_strong_threshold": "0.5",
                  "pc_hypre_boomeramg_P_max": "4",
                  "pc_hypre_boomeramg_agg_nl": "1"}


def _defaults(PETSc, prefix: str, values: dict) -> None:
    """Set PETSc options ``prefix + key`` that the user has not set."""
    opts = PETSc.Options()
    for key, value in values.items():
        if not opts.hasName(prefix + key):
            opts.setValue(prefix + key, value)


def _has_hypre(PETSc) -> bool:
    try:
        pc = PETSc.PC().create(comm=PETSc.COMM_SELF)
        pc.setType("hypre")
        pc.destroy()
        return True
    except PETSc.Error:
        return False


class _ShellS:
    def __init__(self, solver):
        self.solver = solver

    def mult(self, mat, x, y):
        self.solver.mult(x, y)


class _ShellP:
    def __init__(self, solver):
        self.solver = solver

    def apply(self, pc, r, z):
        self.solver.precondition_vec(r, z)


def check_options(scene, n, *, order=1, mesh=None, solver="auto", products="nodal",
                  mass="lumped") -> None:
    """What ``--linalg petsc`` takes: a tensor mesh (uniform or graded), Q1 or Q2, the
    lumped mass and nodal products, an iterative solver; petsc4py importable."""
    kind, _ = fmesh.parse_option(mesh)
    if kind not in ("uniform", "graded"):
        raise ModelError("--linalg petsc needs a tensor mesh (uniform or graded), not a file")
    if solver == "fft":
        raise ModelError("--linalg petsc solves by PCG: --solver fft is the serial direct "
                         "path (use amg, jacobi or auto)")
    if mass != "lumped" or products != "nodal":
        raise ModelError("--linalg petsc takes the lumped mass and nodal products")
    petsc()


class PETScFEMBackend(FEMBackend):
    """:class:`fem_ade.fem.backend.FEMBackend` with its DOFs distributed over the MPI ranks
    (module docstring): ``FEMBackend(..., linalg="petsc")`` builds one."""

    linalg = "petsc"
    solver_class = PetscStepSolver

    def _operators(self, assembly: str):
        ops = TensorOperators(self.mesh, self.order)
        self.part = ops.part
        fsolve._ALLREDUCE = self.part.allreduce if self.part.mpi.Get_size() > 1 else None
        return ops

    def _fft_grid(self):
        return None  # the direct Fourier path is serial

    def _view(self):
        """The serial operators' description the output functions need (tensor, order)."""
        return SimpleNamespace(assembly="kron", order=self.order)

    # -- the state: gathered to every rank, so checkpoints have the serial format -----------
    def state(self) -> dict[str, np.ndarray]:
        g = self.part.gather
        s = {"phi": g(self.phi), "mu": g(self.mu), **self.ramp_state()}
        for k, v in self.stepper.state().items():
            s[k] = g(v) if k in ("z_V", "z_A") else v
        if self.phi_prev is not None:
            s["phi_prev"] = g(self.phi_prev)
        return s

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        phi = np.array(state.get("phi", np.zeros(0)), dtype=float).ravel()
        if phi.shape != (self.ops.n_dofs,):
            raise ModelError(f"the state has {phi.size} values of phi; this FEM space "
                             f"(Q{self.order}, n = {self.n}) has {self.ops.n_dofs}")
        local = {k: (self.part.local(np.asarray(v, dtype=float).ravel())
                     if k in ("phi", "mu", "phi_prev", "z_V", "z_A") else v)
                 for k, v in state.items()}
        self._set(local["phi"], local.get("phi_prev"))
        self.stepper.set_state(local)
        self.set_ramp_state(state)
        self.stepper.ramp = self.ramp

    def extrapolate(self, anchor: dict, beta: float) -> None:
        self._set(self.phi + beta * (self.phi - self.part.local(anchor["phi"])), self.phi_prev)

    def max_abs_phi(self) -> float:
        m = self.part.allreduce(float(np.max(np.abs(self.phi))), op="max")
        return m if math.isfinite(m) else math.nan

    # -- measurements on the gathered field ---------------------------------------------------
    def fields(self) -> dict[str, np.ndarray]:
        return {"phi": self.part.gather(self.phi), "mu": self.part.gather(self.mu),
                "points": tensor_points(self.ops.locs)}

    def grid_phi(self) -> np.ndarray:
        return output.uniform_grid_field(self.mesh, self._view(), self.part.gather(self.phi),
                                         self.order * self.n)[0]

    def output_mesh(self):
        if self._out is None:
            self._out = output.closed_mesh(self.mesh, self._view())
        return self._out[0], self._out[1]

    def point_data(self) -> dict[str, np.ndarray]:
        self.output_mesh()
        index = self._out[2]
        return {"phi": self.part.gather(self.phi)[index], "mu": self.part.gather(self.mu)[index]}

    def info(self) -> dict:
        out = super().info()
        solver = self.stepper.solver
        inner = solver.inner.getPC().getType() if solver is not None else None
        out.update(linalg="petsc", ranks=self.part.mpi.Get_size(),
                   local_dofs=self.part.n_local, inner_pc=inner,
                   solver=f"PETSc KSP cg + {inner}" if inner else "PETSc KSP cg")
        return out
