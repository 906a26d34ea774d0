"""The same backward-Euler Newton step as ``ImplicitEuler``, with the linear system assembled as
a Taichi sparse matrix and solved by Eigen (``ti.linalg``): a sparse Cholesky factorisation
(``"llt"`` / ``"ldlt"``) or Taichi's sparse CG on the Jacobi-scaled matrix (``"sparse-cg"``).
``"matrix-free"`` falls back to the parent's matrix-free PCG.

System (identical to dynamics.py, same PSD-projected K, same right-hand side):

    A = (1 + h alpha) M + h (beta + h) K_psd,    A dv = h (f - alpha M v) - h (beta + h) K_psd v

Pinned vertices are eliminated: their dv is prescribed (lands them on their target), the
coupling ``A_fp dv_p`` moves to the right-hand side (computed matrix-free with dynamics.py's
``apply_A``), and only the free-free block ``A_ff`` is assembled (3 rows per free vertex, in
the order of a compact free-vertex index). The direct solvers read only the lower triangle, so
only that is assembled for them (about half the triplets).

Per step: ``_prepare`` (forces, kinematics, rhs, residual, free index; one serial kernel),
``_assemble`` (per-element 3x3 blocks into a ``ti.types.sparse_matrix_builder``) + ``build``,
``factorize`` (``analyze_pattern`` only when the mesh or the pin set changed), ``solve``, and
``_finish`` (scatter dv, update v and x). ``last_timings`` holds the ms of each phase.
The kernels are module-level and take every array as an argument, like dynamics.py's: they
compile once per process, not once per solver. They take dynamics.py's argpacks and its
``coef`` array of the step's scalars.
"""
import time

import numpy as np
import taichi as ti

from .dynamics import (A, T, DynamicsSettings, ElementPack, ImplicitEuler, MeshPack, SolvePack,
                       StatePack, apply_A, constants, edge_vertex, face_block, free_residual,
                       linearise)
from .model import ClothModel

LINEAR_SOLVERS = ("llt", "ldlt", "sparse-cg", "matrix-free")


class SparseImplicitEuler(ImplicitEuler):
    """``ImplicitEuler`` whose linear solve is a sparse direct (or sparse CG) solve.

    ``linear_solver``: ``llt`` (default), ``ldlt``, ``sparse-cg`` or ``matrix-free``.
    After a step: ``last_timings`` (ms: prepare, assembly, analyze, factorize, solve, finish),
    ``last_cg_iters`` (0 for a direct solve) and ``last_cg_residual`` (relative 2-norm residual
    of the free rows, computed only when ``check_residual``)."""

    def __init__(self, model: ClothModel, settings: DynamicsSettings = None, stitches=None,
                 linear_solver="llt", check_residual=False):
        if linear_solver not in LINEAR_SOLVERS:
            raise ValueError(f"unknown linear solver '{linear_solver}': use one of "
                             f"{', '.join(LINEAR_SOLVERS)}")
        self.linear_solver = linear_solver
        self.check_residual = check_residual
        self._builder = None
        self._builder_key = None
        self._solver = None
        self._pattern_key = None
        self.last_timings = {}
        rt = ti.lang.impl.get_runtime()
        self._dtype = ti.f64 if rt.default_fp == ti.f64 else ti.f32
        super().__init__(model, settings, stitches)

    def on_mesh_changed(self):
        super().on_mesh_changed()
        m = self.model
        if getattr(self, "_free_for", None) != m.v_cap:
            self.free_index = ti.ndarray(ti.i32, m.v_cap)
            self._free_for = m.v_cap
        self._pattern_key = None       # the sparsity pattern must be analysed again

    # -- public API ---------------------------------------------------------------------------
    def step(self, h):
        if self.linear_solver == "matrix-free":
            return super().step(h)
        self.model.mark_step_start()
        m, s = self.model, self.settings
        direct = self.linear_solver in ("llt", "ldlt")
        self.last_preconditioner = "direct" if direct else self.linear_solver
        T = {}
        t0 = time.perf_counter()
        coef, mesh, state = self._constants(h), self._mesh(), self._state()
        # Warm start only helps the iterative solver; a direct solve starts from dv_free = 0.
        n_free = int(_prepare(0 if direct else 1, coef, mesh, state, self._elems, self._cg,
                              self.free_index))
        t1 = time.perf_counter()
        T["prepare"] = 1e3 * (t1 - t0)
        n = 3 * n_free
        if n == 0:
            _finish(np.zeros(1), h, m.n_verts, 0, *self._finish_arrays())
            self.last_cg_iters, self.last_cg_residual = 0, 0.0
            self.last_timings = T
            return 0
        lower = 1 if direct else 0
        scaled = 0 if direct else 1
        self._ensure_builder(n, m)
        _assemble(self._builder, lower, scaled, coef, mesh, self._elems, self._cg,
                  self.free_index)
        A = self._builder.build()
        t2 = time.perf_counter()
        T["assembly"] = 1e3 * (t2 - t1)
        b = np.zeros(n, dtype=np.float64 if self._dtype == ti.f64 else np.float32)
        _gather(b, m.n_verts, scaled, self.res, self.precond, self.free_index)
        iters = 0
        if direct:
            key = (m.n_verts, m.n_faces, m.n_edges, n_free, self.n_stitches, self.linear_solver)
            if self._pattern_key != key:
                self._solver = ti.linalg.SparseSolver(dtype=self._dtype,
                                                      solver_type=self.linear_solver.upper(),
                                                      ordering="AMD")
                self._solver.analyze_pattern(A)
                self._pattern_key = key
            t3 = time.perf_counter()
            T["analyze"] = 1e3 * (t3 - t2)
            self._solver.factorize(A)
            t4 = time.perf_counter()
            T["factorize"] = 1e3 * (t4 - t3)
            x = self._solver.solve(b)
            if not self._solver.info():
                raise RuntimeError("sparse factorisation failed: the system matrix is not "
                                   "positive definite (non-finite state or zero masses?)")
            t5 = time.perf_counter()
            T["solve"] = 1e3 * (t5 - t4)
        else:
            t4 = time.perf_counter()
            T["analyze"] = T["factorize"] = 0.0
            # Jacobi-scaled system S A S y = S r with S = diag(A)^-1/2; stop on the absolute
            # residual tol * |S r| (close to the matrix-free code's preconditioned criterion).
            bn = float(np.linalg.norm(b))
            x = self._sparse_cg(A, b, s.cg_max_iters, max(s.cg_tol * bn, 1e-300))
            t5 = time.perf_counter()
            T["solve"] = 1e3 * (t5 - t4)
            iters = -1   # Taichi's SparseCG does not report its iteration count
        if self.check_residual:
            r = b - (A @ x if not direct else self._sym_matvec(A, x))
            self.last_cg_residual = float(np.linalg.norm(r) / max(np.linalg.norm(b), 1e-300))
        else:
            self.last_cg_residual = 0.0
        _finish(np.ascontiguousarray(x, dtype=b.dtype), h, m.n_verts, scaled,
                *self._finish_arrays())
        T["finish"] = 1e3 * (time.perf_counter() - t5)
        self.last_timings = T
        self.last_cg_iters = iters
        return iters

    def _sparse_cg(self, A, b, max_iter, atol):
        """Taichi's (unpreconditioned) sparse CG from x0 = 0. ``ti.linalg.SparseCG`` prints
        its iteration count to stdout on every solve, so the core solver is built here with
        verbose off when this Taichi version has it; the count is not returned either way."""
        try:
            from taichi._lib import core as _ti_core
            make = _ti_core.make_double_cg_solver if self._dtype == ti.f64 else \
                _ti_core.make_float_cg_solver
            cg = make(A.matrix, int(max_iter), float(atol), False)
            cg.set_b(b)
            cg.set_x(np.zeros_like(b))
            cg.solve()
            return np.asarray(cg.get_x())
        except (ImportError, AttributeError, TypeError):
            x, _ = ti.linalg.SparseCG(A, b, x0=np.zeros_like(b), max_iter=max_iter,
                                      atol=atol).solve()
            return np.asarray(x)

    @staticmethod
    def _sym_matvec(L, x):
        """A x for A stored as its lower triangle L: L x + L^T x - diag(L) x."""
        d = np.array([L[i, i] for i in range(L.shape[0])]) if L.shape[0] < 3000 else None
        if d is None:
            raise ValueError("check_residual with a direct solver is for small systems")
        return L @ x + L.transpose() @ x - d * x

    # -- helpers ------------------------------------------------------------------------------
    def _finish_arrays(self):
        return self._mesh(), self._state(), self._cg, self.free_index

    def _ensure_builder(self, n, m):
        # Triplets (full blocks; the lower triangle needs about half): 9 per free vertex
        # (mass), 81 per face, 144 per interior edge, 36 per stitch, 9 per bending entry.
        cap = 9 * m.n_verts + 81 * m.n_faces + 144 * self.n_hinges + 36 * self.n_stitches + \
            9 * m.n_bend
        key = (n, cap)
        if self._builder_key != key:
            self._builder = ti.linalg.SparseMatrixBuilder(n, n, max_num_triplets=cap,
                                                          dtype=self._dtype)
            self._builder_key = key


# -- kernels ----------------------------------------------------------------------------------
@ti.kernel
def _prepare(warm: ti.i32, coef: A, mesh: MeshPack, state: StatePack, elems: ElementPack,
             cg: SolvePack, free_index: A) -> ti.i32:
    """Forces, rhs, prescribed pinned dv, residual r = b - A dv0 in ``res`` (free rows),
    the compact free-vertex index and the diagonal blocks of A in ``precond``."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        c = constants(coef)
        linearise(c, mesh, state, elems, cg)
        n_free = 0
        for i in range(c.nv):
            if mesh.vert_pinned[i] != 0:
                cg.dv[i] = (mesh.vert_pin_target[i] - state.x[i]) / c.h - state.v[i]
                free_index[i] = -1
            else:
                if warm == 0:
                    cg.dv[i] = ti.Vector([0.0, 0.0, 0.0])
                free_index[i] = n_free
                n_free += 1
        apply_A(cg.dv, cg.Ap, c, mesh, elems)
        free_residual(c, mesh, cg)
        cg.scalars[2] = n_free
    return ti.cast(cg.scalars[2], ti.i32)


@ti.func
def scale_of(i, c, scaled: ti.i32, precond: T):
    s = 1.0
    if scaled != 0:
        s = 1.0 / ti.sqrt(precond[i][c, c])
    return s


@ti.func
def add_block(B: T, va, vb, blk, lower: ti.i32, scaled: ti.i32, precond: T, free_index: T):
    """B[rows of va, cols of vb] += blk for free va, vb (lower triangle only if asked).
    Runtime loops, not static ones: an unrolled assembly kernel takes minutes to compile."""
    ra, rb = free_index[va], free_index[vb]
    if ra >= 0 and rb >= 0:
        for a, c in ti.ndrange(3, 3):
            r, col = 3 * ra + a, 3 * rb + c
            if lower == 0 or r >= col:
                B[r, col] += blk[a, c] * scale_of(va, a, scaled, precond) * \
                    scale_of(vb, c, scaled, precond)


@ti.kernel
def _assemble(B: ti.types.sparse_matrix_builder(), lower: ti.i32, scaled: ti.i32, coef: A,
              mesh: MeshPack, elems: ElementPack, cg: SolvePack, free_index: A):
    """The free-free block of A = (1 + h alpha) M + h (beta + h) K_psd, element by element:
    the blocks whose action is ``add_K_product(..., exact=0)`` and whose diagonal is
    ``add_K_diagonal``. Uses the kinematics left by ``_prepare``."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        c = constants(coef)
        sc = c.h * (c.beta + c.h)
        I = ti.Matrix.identity(float, 3)
        for i in range(c.nv):
            add_block(B, i, i, (1.0 + c.h * c.alpha) * mesh.vert_mass[i] * I, lower, scaled,
                      cg.precond, free_index)
        for f in range(c.nf):
            tri = mesh.face_verts[f]
            A = mesh.face_rest_area[f]
            for n in ti.static(range(3)):
                for q in ti.static(range(3)):
                    add_block(B, tri[n], tri[q], sc * A * face_block(f, n, q, c, elems),
                              lower, scaled, cg.precond, free_index)
        for e in range(c.ne):
            if mesh.edge_faces[e][1] >= 0:
                kk = sc * c.kb * mesh.edge_bend_weight[e]
                G = elems.edge_grad[e]
                for n, q in ti.ndrange(4, 4):
                    gn = ti.Vector([G[n, 0], G[n, 1], G[n, 2]])
                    gq = ti.Vector([G[q, 0], G[q, 1], G[q, 2]])
                    add_block(B, edge_vertex(e, n, mesh), edge_vertex(e, q, mesh),
                              kk * gn.outer_product(gq), lower, scaled, cg.precond,
                              free_index)
        for i in range(mesh.bend_ptr.shape[0] - 1):
            for kq in range(mesh.bend_ptr[i], mesh.bend_ptr[i + 1]):
                add_block(B, i, mesh.bend_col[kq], sc * c.kb * mesh.bend_val[kq] * I, lower,
                          scaled, cg.precond, free_index)
        for s in range(c.nst):
            a, b = mesh.stitch[s][0], mesh.stitch[s][1]
            add_block(B, a, a, sc * c.kst * I, lower, scaled, cg.precond,
                      free_index)
            add_block(B, b, b, sc * c.kst * I, lower, scaled, cg.precond,
                      free_index)
            add_block(B, a, b, -sc * c.kst * I, lower, scaled, cg.precond,
                      free_index)
            add_block(B, b, a, -sc * c.kst * I, lower, scaled, cg.precond,
                      free_index)


@ti.kernel
def _gather(b: A, nv: ti.i32, scaled: ti.i32, res: A, precond: A, free_index: A):
    for i in range(nv):
        r = free_index[i]
        if r >= 0:
            for c in ti.static(range(3)):
                b[3 * r + c] = res[i][c] * scale_of(i, c, scaled, precond)


@ti.kernel
def _finish(sol: A, h: float, nv: ti.i32, scaled: ti.i32, mesh: MeshPack, state: StatePack,
            cg: SolvePack, free_index: A):
    """dv_free += solution (unscaled), then v += dv, x += h v, pins exactly on target."""
    for i in range(nv):
        r = free_index[i]
        if r >= 0:
            for c in ti.static(range(3)):
                cg.dv[i][c] += sol[3 * r + c] * scale_of(i, c, scaled, cg.precond)
        state.v[i] += cg.dv[i]
        state.x[i] += h * state.v[i]
        if mesh.vert_pinned[i] != 0:
            state.x[i] = mesh.vert_pin_target[i]
