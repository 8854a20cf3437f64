"""The FEM step on PETSc, distributed over MPI ranks (``--linalg petsc``).

The same mixed step as :mod:`fem_ade.backends.fem.step` — the same
:class:`~fem_ade.backends.fem.step.MixedStep`
code, the same weak forms — with three things swapped:

* **the partition**: the node grid of a tensor mesh (uniform or graded, any order) is split
  by a PETSc DMDA (periodic, stencil width = order) into one box per rank. A rank holds φ,
  μ, Kφ, the GLL weights and the DOF coordinates of its box only, as NumPy arrays (the
  DMDA's natural ordering is the serial backend's C ordering, so the gathered field is the
  serial one, index for index);
* **the matrices**: each rank assembles its own rows of K = Σₖ K₁⁽ᵏ⁾ ⊗ (⊗ diag(w)) — along
  each grid line the 1D band of the serial :class:`fem_ade.backends.fem.tensor.Axis` — and of the
  low-order refined K̃ (p = 1 on the same nodes) for the preconditioner, into PETSc MPIAIJ
  matrices;
* **the solve**: the step's CG runs as a PETSc KSP (``-step_ksp_*``) on a matrix-free S
  (two MatMults per application, the rank-one terms as global dot products) with a shell
  preconditioner P⁻¹ = τ (W + sK̃)⁻¹ W (W + sK̃)⁻¹ whose two inner solves are one
  application of a PETSc preconditioner of W + sK̃ (``-step_inner_pc_*``; default hypre
  BoomerAMG where PETSc has it, else GAMG), the serial path's pyamg V-cycle. (The serial
  default, the exact fast diagonalization, needs whole grid lines on one rank.)

Every global sum of the forms (V, A, ΔA, E and the CG's dot products) is one MPI
allreduce (:data:`fem_ade.backends.fem.solve._ALLREDUCE`). The driver is unchanged: every rank runs
it; the state it sees (``state()``, ``fields()``, ``grid_phi()``) is gathered to every rank,
so checkpoints and outputs have the serial format (the gather holds the whole field on each
rank: 8 bytes per DOF and field — 134 MB at 256³ — the limit of this design; the run
itself holds 1/ranks of the matrices per rank). The command line lets rank 0 write the run
folder (:func:`fem_ade.cli.run.main`).

PETSc options go in the environment variable ``PETSC_OPTIONS`` (PETSc reads it), e.g.
``PETSC_OPTIONS="-step_inner_pc_type gamg"``, ``-step_inner_pc_hypre_boomeramg_strong_threshold
0.5``, ``-step_ksp_monitor``.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import scipy.sparse as sp

from fem_ade.backends.fem import mesh as fmesh
from fem_ade.backends.fem import output
from fem_ade.backends.fem import solve as fsolve
from fem_ade.backends.fem.assemble import tensor_points
from fem_ade.backends.fem.backend import FEMBackend
from fem_ade.backends.fem.tensor import TensorSpace
from fem_ade.model.params import ModelError

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


def _line_matrix(part: Partition, axes) -> sp.csr_matrix:
    """This rank's rows of K = Σₖ K₁⁽ᵏ⁾ ⊗ (⊗_{a≠k} diag(wₐ)) (``axes``: the 1D
    :class:`fem_ade.backends.fem.tensor.Axis` of the mesh), in PETSc's global numbering: along each
    axis the 1D band of K₁, scaled by the other axes' weights."""
    d, shape = len(part.shape), part.shape
    strides = np.cumprod((1,) + tuple(reversed(shape[1:])))[::-1]
    index = [np.arange(b.start, b.stop) for b in part.box]
    rows, cols, vals = [], [], []
    local_rows = np.arange(part.n_local).reshape(part.local_shape)
    for k in range(d):
        ck, vk = _band(axes[k].stiffness, part.box[k])  # (len_k, width)
        col = 0
        val = 1.0
        for a in range(d):
            view = [np.newaxis] * (d + 1)
            view[a] = slice(None)
            if a == k:
                view[d] = slice(None)
                col = col + (ck * int(strides[a]))[tuple(view)]
                val = val * vk[tuple(view)]
            else:
                col = col + (index[a] * int(strides[a]))[tuple(view)]
                val = val * axes[a].weights[part.box[a]][tuple(view)]
        col, val = np.broadcast_arrays(col, val)
        rows.append(np.broadcast_to(local_rows[..., None], col.shape).ravel())
        cols.append(col.ravel())
        vals.append(val.ravel())
    cols = np.asarray(part.ao.app2petsc(np.concatenate(cols).astype(part.PETSc.IntType)))
    local = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), cols.astype(np.int64))),
                          shape=(part.n_local, part.N))
    local.sum_duplicates()  # the padding (value 0) onto its row's first column
    local.eliminate_zeros()
    local.sort_indices()
    return local


class TensorOperators:
    """This rank's rows of K, its GLL weights and DOF coordinates on a tensor mesh (the serial
    :class:`fem_ade.backends.fem.tensor.TensorSpace` restricted to the rank's box), and the rows of
    the
    low-order refined K̃ that the inner preconditioner works on (K itself for p = 1)."""

    assembly = "tensor"
    axes = None  # no fast diagonalization across ranks: the solve is PETSc's CG
    basis = None

    def __init__(self, mesh, order: int):
        serial = TensorSpace(mesh.axes, order)
        self.part = Partition(serial.shape, width=order)
        self.order = order
        part = self.part
        self.K = DistMatrix(part, _line_matrix(part, serial.axes))
        self.K_tilde = (self.K if order == 1 else
                        DistMatrix(part, _line_matrix(part, serial.lor().axes)))
        w1 = [a.weights[b] for a, b in zip(serial.axes, part.box, strict=True)]
        self.weights = functools.reduce(np.multiply.outer, w1).ravel()  # W = ⊗ wₐ
        #: the 1D node locations of the whole mesh (the gathered fields' points)
        self.locs = serial.node_axes
        self.doflocs = tensor_points([x[b] for x, b in zip(self.locs, part.box, strict=True)])
        self.n_dofs = part.N
        self.serial = serial  # 1D data only (for the gathered fields' output)

    def laplacian(self, x):
        """μ = W⁻¹Kx on this rank's DOFs."""
        return (self.K @ x) / self.weights

    def preconditioner_stiffness(self):
        return self.K_tilde

    def describe(self) -> dict:
        return self.serial.describe()


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
    """The solver interface of :mod:`fem_ade.backends.fem.solve` on PETSc: Ŝx = r by KSP CG
    (matrix-free
    S, the rank-one terms as global dot products, shell preconditioner P⁻¹ = τ B⁻¹ W B⁻¹,
    B = W + sK̃ by one PETSc PC application)."""

    def __init__(self, space: TensorOperators, S, *, kind="amg", rtol=None,
                 stabilized=False, cache=None):
        PETSc, part = space.part.PETSc, space.part
        self.part, self.K, self.S = part, space.K, S
        self.tau, self.c, self.ke = S.tau, S.c, S.ke
        self.s = S.shift(stabilized)
        self.kind = {"auto": "amg", "chebyshev": "amg"}.get(kind, kind)
        self.rtol = fsolve.DEFAULT_RTOL if rtol is None else float(rtol)
        self.m = np.ascontiguousarray(space.weights, dtype=float)
        self.minv = 1.0 / self.m
        self.mv, self.minvv = part.vec(self.m.copy()), part.vec(self.minv.copy())
        key = ("petsc", self.kind, self.s)
        self.high_order = space.order > 1
        if cache is not None and key in cache:
            self.inner, self.B = cache[key]
        else:
            # B = W + sK̃ for the PC; for p > 1 the inner solve is INNER_ITERATIONS CG
            # iterations on the high-order W + sK preconditioned by it (as the serial path)
            self.B = space.preconditioner_stiffness().shifted(self.s, self.m)
            self.inner = PETSc.KSP().create(comm=part.comm)
            self.inner.setOptionsPrefix("step_inner_")
            if self.high_order:
                self.B_high = space.K.shifted(self.s, self.m)
                self.inner.setOperators(self.B_high.mat, self.B.mat)
                self.inner.setType("cg")
                self.inner.setNormType(PETSc.KSP.NormType.NONE)
                self.inner.setTolerances(rtol=0.0, atol=0.0, max_it=fsolve.INNER_ITERATIONS)
            else:
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
        self.S_mat = PETSc.Mat().createPython(((part.n_local, part.N), (part.n_local, part.N)),
                                              context=_ShellS(self), comm=part.comm)
        self.S_mat.setUp()
        self.ksp = PETSc.KSP().create(comm=part.comm)
        self.ksp.setOptionsPrefix("step_")
        self.ksp.setOperators(self.S_mat)
        self.ksp.setType("fcg" if self.high_order else "cg")  # inner iterations: flexible
        self.ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
        pc = self.ksp.getPC()
        pc.setType("python")
        pc.setPythonContext(_ShellP(self))
        self.ksp.setInitialGuessNonzero(True)
        self.ksp.setFromOptions()
        self._b, self._x = part.vec(), part.vec()

    # S x = (m/τ) x + K (c x + κε W⁻¹ K x) + Σ σ b (b·x)
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

    def solve(self, rhs, x0=None, scales=None, low_rank=()):
        """([x with ‖r − Ŝx‖ ≤ rtol·scale], total its), as
        :meth:`fem_ade.backends.fem.solve.KrylovSolver.solve`."""
        self.low_rank = [(sig, self.part.vec(np.ascontiguousarray(v, dtype=float)))
                         for sig, v in low_rank]
        xs, total = [], 0
        for j, r in enumerate(rhs):
            start = np.zeros_like(r) if x0 is None or x0[j] is None else x0[j]
            scale = fsolve.norm(r) if scales is None or scales[j] is None else scales[j]
            if scale == 0.0:
                xs.append(np.zeros_like(r))
                continue
            self._b.setArray(np.asarray(r, dtype=float))
            self._x.setArray(np.asarray(start, dtype=float))
            self.ksp.setTolerances(rtol=1e-300, atol=self.rtol * scale, max_it=500)
            self.ksp.solve(self._b, self._x)
            xs.append(self._x.getArray().copy())
            total += int(self.ksp.getIterationNumber())
        return xs, total


def petsc_solver(kind, space, S, *, rtol=None, stabilized=False, cache=None, eigenbasis=None):
    """:func:`fem_ade.backends.fem.solve.make_solver` for ``--linalg petsc`` (PCG only)."""
    if kind in fsolve.EXACT:
        raise ModelError("--linalg petsc solves by PCG: --solver fdm/fft are the serial exact "
                         "solvers (use amg, jacobi or auto)")
    return PetscStepSolver(space, S, kind=kind, rtol=rtol, stabilized=stabilized, cache=cache)


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


def check_options(scene, n, *, order=1, mesh=None, solver="auto") -> None:
    """What ``--linalg petsc`` takes: a tensor mesh (uniform or graded), any order, an
    iterative solver; petsc4py importable."""
    kind, _ = fmesh.parse_option(mesh)
    if kind not in ("uniform", "graded"):
        raise ModelError("--linalg petsc needs a tensor mesh (uniform or graded), not a file")
    if solver in fsolve.EXACT:
        raise ModelError("--linalg petsc solves by PCG: --solver fdm/fft are the serial exact "
                         "solvers (use amg, jacobi or auto)")
    petsc()


class PETScFEMBackend(FEMBackend):
    """:class:`fem_ade.backends.fem.backend.FEMBackend` with its DOFs distributed over the MPI ranks
    (module docstring): ``make_backend("fem", ..., linalg="petsc")`` builds one (the
    registry's variant of the FEM for that option)."""

    linalg = "petsc"
    solver_factory = staticmethod(petsc_solver)

    @classmethod
    def check_options(cls, scene, n, *, order=1, mesh=None, solver="auto", linalg="petsc",
                      rtol=None, geometry="cartesian", domain=None) -> float:
        """The FEM's checks, then what ``--linalg petsc`` takes (:func:`check_options`)."""
        spacing = super().check_options(scene, n, order=order, mesh=mesh, solver=solver,
                                        linalg=linalg, rtol=rtol, geometry=geometry,
                                        domain=domain)
        check_options(scene, n, order=order, mesh=mesh, solver=solver)
        return spacing

    def _space(self):
        ops = TensorOperators(self.mesh, self.order)
        self.part = ops.part
        fsolve._ALLREDUCE = self.part.allreduce if self.part.mpi.Get_size() > 1 else None
        return ops

    def _view(self):
        """The serial space the output functions need (1D data only, matrix-free)."""
        return self.space.serial

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
        if phi.shape != (self.space.n_dofs,):
            raise ModelError(f"the state has {phi.size} values of phi; this FEM space "
                             f"(order {self.order}, n = {self.n} nodes per axis) has "
                             f"{self.space.n_dofs}")
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
                "points": tensor_points(self.space.locs)}

    def grid_phi(self) -> np.ndarray:
        return output.uniform_grid_field(self.mesh, self._view(), self.part.gather(self.phi),
                                         self.n)[0]

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
