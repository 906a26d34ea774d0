"""A sparse Cholesky factor of the implicit step's matrix A (the projection's metric) as the
PCG preconditioner of the one-kernel strain solve (``al.solve_al``, mode PC_FACTOR), and of
the dynamics' CG on the same matrix (``dynamics.ImplicitEuler.set_preconditioner``).

Why: at rest most of an exact Newton step's energy lies in the cloth's soft global modes
(swinging, bending), which block-Jacobi CG barely reaches: on resting substeps at resolution
25, 16 block-Jacobi iterations left 96 % of the step's H-norm unresolved, while the factor of
the *previous* substep's matrix left 0.3-7 % after 16 and 5-18 % after 8
(docs/history/newton_precond.md). The unresolved motion is what the "resting" cloth's velocity
was made of. A factorisation costs ~25 triangular solves, so it is made on the host (CHOLMOD,
the lumped pattern of ``linalg.SparseCholesky``, ordered by vertices) only when the old one
has gone stale, and the kernel applies it by two block triangular solves with L (6.2k 3x3
blocks at 1.2k faces, 11.6k at 1.9k; the vertex ordering fills L as much as CHOLMOD's own
scalar one: 53.8k against 54k entries at 1.2k faces). In blocks an application costs 0.051
ms at 1.2k faces against 0.086 ms entry by entry (one index per block, and 3x3 products).

Why A and not the Newton matrix H: a factor of a late round's H (a 4-64x larger penalty)
made the next solves take 5-100 rounds, and a factor of a round-0 H kicked the resting cloth
at every refresh (KE 1.5e-7 -> 1.1e-5 J), since the inexact solve's answer depends on the
preconditioner and H jumps with the active set. A changes slowly.

The host keeps one ``FactorPreconditioner`` per mesh pattern; ``usable`` says whether the
kernel may use it; ``after_solve`` refactorises A when there is no factor yet or it is
REFRESH_SOLVES solves old.
"""
import numpy as np
import scipy.sparse as sp
import taichi as ti

from .. import linalg
from ..system_matrix import mat3, vec3
from .buffers import PC_FACTOR, T

# Refactorise the metric every REFRESH_SOLVES solves (it changes as the cloth deforms). The
# first factor is made after FIRST_AFTER solves on a mesh: remeshing every frame makes a new
# pattern each substep, and a factor made after its only solve would never be used. A pattern
# whose predecessor lasted LASTING_SOLVES solves or more (a remesh applied every few frames,
# RemeshParams.defer_ops) gets its factor before its first solve instead: the solves without
# it cost more than the factor. Measured on hanging (mapping, ~900 faces, remeshes applied
# every 4-5 frames): the two frames after each remesh took 20-45 ms against 12-15 with the
# factor (150-250 PCG iterations against ~55).
REFRESH_SOLVES = 10
FIRST_AFTER = 2
LASTING_SOLVES = 3


class RefreshedPreconditioner:
    """The life cycle the factor and the multigrid (multigrid.py) share: made from the metric
    with pinned rows and columns the identity (``pinned_values``) after FIRST_AFTER solves on
    a pattern, remade every REFRESH_SOLVES solves and whenever the pins change. A subclass
    sets ``mode`` (the kernel's PC_* switch) and implements ``refresh(values, pinned)``."""

    def __init__(self, metric, first_after=FIRST_AFTER):
        self.metric = metric
        self.ready = False
        self.solves_since = 0
        self.solves = 0                         # on this pattern
        self.pinned = None                      # the pinned mask it was made with
        self.made = 0                           # how many times it was made
        self.first_after = first_after          # 0: made before the pattern's first solve

    def before_solve(self, pinned):
        """Make it now, before the pattern's first solve, when ``first_after`` is 0 (the
        metric's values are those this solve uses). Returns whether it did."""
        if self.first_after > 0 or self.solves > 0 or self.ready:
            return False
        self._make(pinned)
        return True

    def usable(self, pinned):
        """Whether the kernel may use it: it exists and was made with these pins (a vertex
        pinned since, e.g. held by the mouse, would get a nonzero step from it; the next
        ``after_solve`` remakes it)."""
        if self.ready and not np.array_equal(self.pinned, pinned):
            self.ready = False
        return self.ready

    def after_solve(self, pinned):
        """Remake it when there is none yet or it is REFRESH_SOLVES solves old, but not
        before FIRST_AFTER solves on this pattern. Returns whether it did."""
        self.solves_since += 1
        self.solves += 1
        if self.solves < self.first_after or (self.ready and self.solves_since <
                                               REFRESH_SOLVES):
            return False
        self._make(pinned)
        return True

    def _make(self, pinned):
        pinned = np.array(pinned[: self.metric.n], bool)
        self.refresh(pinned_values(self.metric, pinned), pinned)
        self.pinned = pinned
        self.solves_since = 0
        self.made += 1
        self.ready = True


class FactorPreconditioner(RefreshedPreconditioner):
    """The factor arrays the kernel reads (``al.precondition``): L of P A P^T = L L^T (A the
    metric with pinned rows and columns made the identity, like the Newton matrix's; P a
    fill-reducing ordering of the vertices) in 3x3 blocks, stored twice so that both
    triangular solves gather: by block rows (L's strictly lower blocks, for L y = b) and by
    block columns (the same blocks transposed, for L^T w = y), then the inverses of the
    diagonal blocks. ``perm[k]`` is the vertex of block row k; ``work`` is a vec3 vector.
    The arrays grow as needed (an ndarray's size is not part of a kernel's signature: no
    recompilation)."""
    mode = PC_FACTOR

    def __init__(self, metric, first_after=FIRST_AFTER, spare=None):
        super().__init__(metric, first_after)
        # The symbolic analysis (ordering, lumped pattern) waits for the first ``refresh``:
        # it costs ~6 ms at 900 faces, and on a mesh remeshed every frame the factor is never
        # made (FIRST_AFTER), while this object is made for every new pattern.
        self._chol = None
        n = metric.n
        # The arrays of ``spare`` (the last mesh's factor) where they are long enough: the
        # kernel reads only the rows of this n, and a Taichi array costs ~1-3 ms to make
        # (five per remesh otherwise).
        old = spare if isinstance(spare, FactorPreconditioner) else None
        fits = old is not None and old.perm.shape[0] >= n and old.ptr.shape[0] >= 2 * (n + 1)
        self.perm = old.perm if fits else ti.ndarray(ti.i32, n)
        self.ptr = old.ptr if fits else ti.ndarray(ti.i32, 2 * (n + 1))
        self.work = old.work if fits else ti.ndarray(vec3, n)
        self.capacity = old.capacity if old is not None else 0     # blocks in idx / val
        self.idx = old.idx if old is not None else ti.ndarray(ti.i32, 1)
        self.val = old.val if old is not None else ti.ndarray(mat3, 1)
        self.blocks = 0                         # 3x3 blocks of L (the last factor)

    @property
    def chol(self):
        """The SparseCholesky of the metric's pattern (made at first use)."""
        if self._chol is None:
            m = self.metric
            self._chol = linalg.SparseCholesky(m.ptr_np, m.col_np, m.n, backend="cholmod",
                                               core=m.core_np, vertex_order=True)
        return self._chol

    def refresh(self, values, pinned=None):
        """Factorise the lumped matrix of these block values (the pattern's order, pinned
        rows and columns already the identity) and upload L's blocks and the vertex
        ordering."""
        self.chol.factorize(values)
        L, perm3 = self.chol.lower_factor()
        n = self.metric.n
        rows = _block_rows(L)
        cols = _block_rows(L.T)                 # L^T's block rows: L's columns, transposed
        diag_inv = np.linalg.inv(rows["diag"])
        n_fwd, n_bwd = len(rows["idx"]), len(cols["idx"])
        total = n_fwd + n_bwd + n
        if total > self.capacity:
            self.capacity = int(1.25 * total)
            self.idx = ti.ndarray(ti.i32, self.capacity)
            self.val = ti.ndarray(mat3, self.capacity)
        val = np.zeros((self.capacity, 3, 3))
        val[:n_fwd], val[n_fwd:n_fwd + n_bwd] = rows["val"], cols["val"]
        val[n_fwd + n_bwd:total] = diag_inv
        idx = np.zeros(self.capacity, np.int32)
        idx[:n_fwd], idx[n_fwd:n_fwd + n_bwd] = rows["idx"], cols["idx"]
        self.val.from_numpy(val)
        self.idx.from_numpy(idx)
        # (Arrays taken from a larger mesh's factor keep their length: padded.)
        ptr = np.concatenate([rows["ptr"], cols["ptr"] + n_fwd]).astype(np.int32)
        self.ptr.from_numpy(np.r_[ptr, np.zeros(self.ptr.shape[0] - len(ptr), np.int32)])
        perm = (perm3[0::3] // 3).astype(np.int32)
        self.perm.from_numpy(np.r_[perm, np.zeros(self.perm.shape[0] - n, np.int32)])
        self.blocks = n_fwd + n
        self.ready = True


@ti.func
def apply(nv, perm: T, ptr: T, idx: T, val: T, work: T, r: T, z: T):
    """z = P^T L^-T L^-1 P r: the factor's two block triangular solves (the arrays of
    ``FactorPreconditioner``: ``val`` holds L's strictly lower blocks by block rows
    (``ptr[0..nv]``), the same blocks transposed by block columns (``ptr[nv + 1..2 nv + 1]``),
    then the inverses of the diagonal blocks; ``idx`` the other block index of each;
    ``perm[k]`` the vertex of block row k; ``work`` a vec3 vector)."""
    for k in range(nv):
        work[k] = r[perm[k]]
    diag = ptr[2 * nv + 1]
    for i in range(nv):                      # L y = P r, by block rows
        acc = work[i]
        for q in range(ptr[i], ptr[i + 1]):
            acc -= val[q] @ work[idx[q]]
        work[i] = val[diag + i] @ acc
    for jj in range(nv):                     # L^T w = y, by block columns of L
        j = nv - 1 - jj
        acc = work[j]
        for q in range(ptr[nv + 1 + j], ptr[nv + 2 + j]):
            acc -= val[q] @ work[idx[q]]
        work[j] = val[diag + j].transpose() @ acc
    for k in range(nv):
        z[perm[k]] = work[k]


def pinned_values(metric, pinned):
    """The metric's block values with the rows and columns of pinned vertices made the
    identity (as in the Newton matrix: a pinned vertex's step is zero)."""
    values = metric.val.to_numpy()[: metric.nnz].copy()
    rows = np.repeat(np.arange(metric.n), np.diff(metric.ptr_np))
    fixed = pinned[rows] | pinned[metric.col_np]
    values[fixed] = 0.0
    values[fixed & (rows == metric.col_np)] = np.eye(3)
    return values


def _block_rows(M):
    """A lower (or upper) triangular matrix with 3x3 blocks, by block rows: the strictly
    off-diagonal blocks ("val", "idx": block column, "ptr": per block row) and the diagonal
    blocks ("diag")."""
    B = sp.csr_matrix(M).tobsr(blocksize=(3, 3))
    B.sort_indices()
    n = B.shape[0] // 3
    block_row = np.repeat(np.arange(n), np.diff(B.indptr))
    on_diag = B.indices == block_row
    if on_diag.sum() != n:
        raise linalg.FactorizationError("the factor lacks a diagonal block")
    off = ~on_diag
    ptr = np.concatenate([[0], np.cumsum(np.bincount(block_row[off], minlength=n))])
    return dict(val=B.data[off], idx=B.indices[off], ptr=ptr, diag=B.data[on_diag])


class FactorStub:
    """One-element arrays for solve_al's factor arguments when it does not use the factor
    (of the factor's types, so that solve_al compiles once)."""

    def __init__(self):
        self.perm, self.ptr, self.idx = (ti.ndarray(ti.i32, 1) for _ in range(3))
        self.val, self.work = ti.ndarray(mat3, 1), ti.ndarray(vec3, 1)
