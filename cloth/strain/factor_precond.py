"""A sparse Cholesky factor of the implicit step's matrix A (the projection's metric) as the
PCG preconditioner of the one-kernel strain solve (``al.solve_al``, argument ``use_factor``).

Why: at rest most of an exact Newton step's energy lies in the cloth's soft global modes
(swinging, bending), which block-Jacobi CG barely reaches: on resting substeps at resolution
25, 16 block-Jacobi iterations left 96 % of the step's H-norm unresolved, while the factor of
the *previous* substep's matrix left 0.3-7 % after 16 and 5-18 % after 8
(``benchmarks.newton_precond``). The unresolved motion is what the "resting" cloth's velocity
was made of. A factorisation costs ~25 triangular solves, so it is made on the host (CHOLMOD,
the lumped pattern of ``linalg.SparseCholesky``) only when the old one has gone stale, and
the kernel applies it by two triangular solves with L (~2 nnz(L) multiply-adds: 54k entries
at 1.2k faces, 264k at 4k).

Why A and not the Newton matrix H: a factor of a late round's H (a 4-64x larger penalty)
made the next solves take 5-100 rounds, and a factor of a round-0 H kicked the resting cloth
at every refresh (KE 1.5e-7 -> 1.1e-5 J), since the inexact solve's answer depends on the
preconditioner and H jumps with the active set. A changes slowly.

The host keeps one ``FactorPreconditioner`` per mesh pattern; ``usable`` says whether the
kernel may use it; ``after_solve`` refactorises A when there is no factor yet or it is
REFRESH_SOLVES solves old.
"""
import numpy as np
import taichi as ti

from .. import linalg

# Refactorise the metric every REFRESH_SOLVES solves (it changes as the cloth deforms). The
# first factor is made after FIRST_AFTER solves on a mesh: remeshing every frame makes a new
# pattern each substep, and a factor made after its only solve would never be used.
REFRESH_SOLVES = 10
FIRST_AFTER = 2


class FactorPreconditioner:
    """The factor arrays the kernel reads (``al.precondition``): L of P A P^T = L L^T (A the
    metric with pinned rows and columns made the identity, like the Newton matrix's) stored
    twice in packed arrays, by columns and by rows, the permutation (``perm[k]``: the
    original index of permuted row k) and two scalar work vectors. The arrays grow as
    needed (an ndarray's size is not part of a kernel's signature: no recompilation)."""

    def __init__(self, metric):
        self.metric = metric
        self.chol = linalg.SparseCholesky(metric.ptr_np, metric.col_np, metric.n,
                                          backend="cholmod", core=metric.core_np)
        self.n3 = n3 = 3 * metric.n
        self.perm = ti.ndarray(ti.i32, n3)
        self.ptr = ti.ndarray(ti.i32, 2 * (n3 + 1))
        self.work = ti.ndarray(float, 2 * n3)
        self.capacity = 0                       # entries of L per half of idx / val
        self.idx = ti.ndarray(ti.i32, 1)
        self.val = ti.ndarray(float, 1)
        self.ready = False
        self.solves_since = 0
        self.solves = 0                         # on this pattern
        self.pinned = None                      # the pinned mask the factor was made with

    def usable(self, pinned):
        """Whether the kernel may use the factor: it exists and was made with these pins (a
        vertex pinned since, e.g. held by the mouse, would get a nonzero step from it; the
        next ``after_solve`` remakes it)."""
        if self.ready and not np.array_equal(self.pinned, pinned):
            self.ready = False
        return self.ready

    def refresh(self, values):
        """Factorise the lumped matrix of these block values (the pattern's order) and
        upload L and the permutation."""
        self.chol.factorize(values)
        by_cols, perm = self.chol.lower_factor()
        by_cols.sort_indices()                  # the diagonal first in each column
        by_rows = by_cols.tocsr()
        by_rows.sort_indices()                  # the diagonal last in each row
        nnz = by_cols.nnz
        if nnz > self.capacity:
            self.capacity = int(1.25 * nnz)
            self.idx = ti.ndarray(ti.i32, 2 * self.capacity)
            self.val = ti.ndarray(float, 2 * self.capacity)
        cap = self.capacity
        idx, val = np.zeros(2 * cap, np.int32), np.zeros(2 * cap)
        idx[:nnz], val[:nnz] = by_cols.indices, by_cols.data
        idx[cap:cap + nnz], val[cap:cap + nnz] = by_rows.indices, by_rows.data
        self.idx.from_numpy(idx)
        self.val.from_numpy(val)
        self.ptr.from_numpy(np.concatenate([by_cols.indptr, by_rows.indptr + cap])
                            .astype(np.int32))
        self.perm.from_numpy(np.asarray(perm, np.int32))
        self.ready = True

    def after_solve(self, pinned):
        """Refactorise the metric when there is no factor yet or the factor is REFRESH_SOLVES
        solves old, but not before FIRST_AFTER solves on this pattern. Returns whether it
        did."""
        self.solves_since += 1
        self.solves += 1
        if self.solves < FIRST_AFTER or (self.ready and self.solves_since <
                                          REFRESH_SOLVES):
            return False
        self.refresh(self.pinned_metric(pinned))
        self.pinned = np.array(pinned[: self.metric.n], bool)
        self.solves_since = 0
        return True

    def pinned_metric(self, pinned):
        """The metric's block values with the rows and columns of pinned vertices made the
        identity (as in the Newton matrix: a pinned vertex's step is zero)."""
        m = self.metric
        values = m.val.to_numpy()[: m.nnz].copy()
        rows = np.repeat(np.arange(m.n), np.diff(m.ptr_np))
        fixed = pinned[rows] | pinned[m.col_np]
        values[fixed] = 0.0
        values[fixed & (rows == m.col_np)] = np.eye(3)
        return values


class FactorStub:
    """One-element arrays for solve_al's factor arguments when it runs block Jacobi."""

    def __init__(self):
        self.perm, self.ptr, self.idx = (ti.ndarray(ti.i32, 1) for _ in range(3))
        self.val, self.work = ti.ndarray(float, 1), ti.ndarray(float, 1)
