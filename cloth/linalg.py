"""Sparse Cholesky factorisation of a symmetric positive-definite 3x3-block matrix
(``system_matrix.BlockMatrix``), with the symbolic analysis (fill-reducing ordering) done once
per pattern and only the numeric factorisation repeated.

Backend: CHOLMOD (SuiteSparse, through scikit-sparse; simplicial: on this 2-core CPU faster than
supernodal from 1k to 16k triangles) when
it is installed, else SciPy's SuperLU (an LU of the same matrix, re-ordered every call: correct
but slower). ``make`` installs CHOLMOD (scripts/ensure_suitesparse.sh and requirements.txt).

Cost, measured on the AL's Newton matrix of the hanging cloth, idle 2-core CPU: with the hinge
bending's pattern (~32 entries a row) 5.3 ms per numeric factorisation at 1.1k triangles
(1875 unknowns) and 46 ms at 4k (6348); AMD, METIS and nested-dissection orderings within
10 % of each other. The isotropic bending couples two rings of vertices (~53 entries a row):
240-280 ms at 4k, simplicial or supernodal alike, hence the lumped factorisation of the face
and seam blocks (``core``): 16-30 ms at 4k, a solve 0.7-1.5 ms. Reusing a factorisation as a
CG preconditioner (``solve_reusing``) saves new ones where consecutive Newton matrices are alike.
"""
import numpy as np
import scipy.sparse as sp

try:
    from sksparse.cholmod import CholmodNotPositiveDefiniteError, analyze
    HAVE_CHOLMOD = True
except ImportError:                      # pragma: no cover - depends on the machine
    HAVE_CHOLMOD = False


_warned = False


def _warn_once():
    global _warned
    _warned = True
    import sys
    print("loom: CHOLMOD (scikit-sparse) is not installed, so the sparse Cholesky uses SciPy's "
          "SuperLU (slower); `make` installs it (scripts/ensure_cholmod.sh)", file=sys.stderr)


# What "solved by a factorisation" means for a lumped one (``SparseCholesky`` with ``core``):
# CG preconditioned by it runs to this relative residual.
EXACT_RTOL = 1e-10


class FactorizationError(RuntimeError):
    """The Newton matrix is not positive definite (a non-finite state or zero masses)."""


def scalar_csr(ptr, col, n):
    """The scalar CSR of a block CSR pattern (3x3 blocks, ``ptr``, ``col``): (order, indices,
    indptr, r_idx, c_idx) with scalar entry e in CSR order taken from
    ``val.ravel()[order[e]]`` (block k's entry (a, b) is ``9 k + 3 a + b``, the block
    order) and r_idx / c_idx the scalar row and column of each entry in block order.

    Where every block row's columns ascend (the patterns of system_matrix.py), the CSR order
    is written down directly: scalar row 3 i + a holds, block by block, the three entries
    (a, 0..2) of each block of block row i, so the entry (k, a, b) lands at
    9 ptr[i] + 3 a len_i + 3 (k - ptr[i]) + b. Otherwise, by sorting (the same result; the
    sort cost 8 ms of a 900-face factor's set-up)."""
    nnzb = len(col)
    rows = np.repeat(np.arange(n), np.diff(ptr))
    # Scalar entry (3 i + a, 3 j + b) of block k = (i, j) is val.ravel()[9 k + 3 a + b];
    # scipy orders CSR entries by row then column.
    k = np.arange(nnzb)
    a, b = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
    r_idx = (3 * rows[:, None, None] + a[None]).ravel()
    c_idx = (3 * col[:, None, None] + b[None]).ravel()
    same_row = rows[1:] == rows[:-1]
    if np.all(col[1:][same_row] > col[:-1][same_row]):
        length = np.diff(ptr)[rows]
        pos = (9 * ptr[rows][:, None, None] + 3 * a[None] * length[:, None, None]
               + 3 * (k - ptr[rows])[:, None, None] + b[None]).ravel()
        order = np.empty(9 * nnzb, np.int64)
        order[pos] = np.arange(9 * nnzb)
    else:
        order = np.lexsort((c_idx, r_idx))
    counts = np.bincount(r_idx, minlength=3 * n)
    indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return order, c_idx[order].astype(np.int64), indptr, r_idx, c_idx


class SparseCholesky:
    """Factorise and solve a BlockMatrix pattern's values.

    ``factorize(val)`` takes the block values (nnz, 3, 3) in the pattern's order; ``solve(b)``
    takes a (3n,) right-hand side. ``backend`` is "cholmod" or "superlu".

    ``core`` (bool per block, optional): factorise only these blocks, with every other entry
    lumped onto its row's diagonal as |value|. The lumped matrix is A + (D - E) with E the
    dropped entries and D their absolute row sums, and D - E is diagonally dominant, so it
    stays positive definite and bounds A from above; ``solve_reusing`` then finishes with
    conjugate gradients on A. Why: the isotropic bending couples vertices two rings apart
    and tripled the entries of the strain solve's Newton matrix; its factorisation went from
    46 to 240-280 ms at 4k triangles (1M entries in L). Factorising the face and seam pairs
    only, with the bending's far entries lumped, took 16-30 ms there, and CG preconditioned
    by it reached 1e-4 in 0-2 iterations on the Newton matrices of a hanging frame (their
    bending entries are small beside the constraints' and the mass)."""

    def __init__(self, ptr, col, n, backend=None, core=None, vertex_order=False):
        self.n = int(n)
        # With ``vertex_order`` (CHOLMOD only) the fill-reducing ordering is of the vertices,
        # each vertex's three rows kept together, so L is made of 3x3 blocks
        # (``lower_factor``): the strain solve's kernel applies it block by block.
        self.vertex_order = bool(vertex_order)
        self._order = None           # (indices, indptr, source entry) of the reordered matrix
        if backend is None:
            backend = "cholmod" if HAVE_CHOLMOD else "superlu"
            if not HAVE_CHOLMOD and not _warned:
                _warn_once()
        if backend == "cholmod" and not HAVE_CHOLMOD:
            raise ImportError("CHOLMOD is not installed: run `make test` (it installs "
                              "libsuitesparse-dev and scikit-sparse)")
        self.backend = backend
        ptr, col = np.asarray(ptr, np.int64), np.asarray(col, np.int64)
        order, self._indices, self._indptr, r_idx, c_idx = scalar_csr(ptr, col, self.n)
        self._perm = order
        self._factor = None
        self._lu = None
        self._lumped = None
        if core is not None and not np.all(core):
            # Scalar entries in CSR order that belong to core blocks (block = src // 9).
            keep = np.asarray(core, bool)[self._perm // 9]
            rows_sorted = r_idx[order]
            k_counts = np.bincount(rows_sorted[keep], minlength=3 * self.n)
            k_ptr = np.concatenate([[0], np.cumsum(k_counts)]).astype(np.int64)
            k_cols = c_idx[order][keep].astype(np.int64)
            # Position of each scalar row's diagonal within the kept entries.
            diag_pos = np.flatnonzero(k_cols == rows_sorted[keep])
            if len(diag_pos) != 3 * self.n:
                raise ValueError("the core blocks must hold the diagonal")
            self._lumped = dict(keep=np.flatnonzero(keep), drop=np.flatnonzero(~keep),
                                drop_rows=rows_sorted[~keep], diag_pos=diag_pos,
                                indptr=k_ptr, indices=k_cols)

    def matrix(self, val):
        """The values as a scipy CSC matrix (symmetric, so CSR arrays serve as CSC)."""
        data = np.asarray(val, np.float64).reshape(-1)[self._perm]
        return sp.csc_matrix((data, self._indices, self._indptr), shape=(3 * self.n,) * 2)

    def factorize(self, val):
        """Factorise the values (with ``core``: the lumped matrix, a preconditioner)."""
        self._factorize_matrix(self._to_factor(self.matrix(val)))

    def _to_factor(self, A):
        """A itself, or with ``core`` the lumped matrix of its core blocks."""
        if self._lumped is None:
            return A
        L = self._lumped
        data = A.data[L["keep"]]         # a copy (fancy index)
        data[L["diag_pos"]] += np.bincount(L["drop_rows"], weights=np.abs(A.data[L["drop"]]),
                                           minlength=3 * self.n)
        return sp.csc_matrix((data, L["indices"], L["indptr"]), shape=A.shape)

    @property
    def exact(self):
        """Whether a factorisation solves the matrix exactly (no ``core`` lumping)."""
        return self._lumped is None

    def _factorize_matrix(self, A):
        if self.backend == "cholmod":
            try:
                if self.vertex_order:
                    A = self._vertex_ordered(A)
                if self._factor is None:
                    self._factor = analyze(A, mode="simplicial", ordering_method="natural"
                                           if self.vertex_order else "default")
                self._factor.cholesky_inplace(A)
            except CholmodNotPositiveDefiniteError as err:
                raise FactorizationError(f"Newton matrix not positive definite ({err})") from None
        else:
            from scipy.sparse.linalg import splu
            self._lu = splu(A)

    def solve(self, b):
        if self.backend == "cholmod":
            b = np.asarray(b, np.float64)
            if self.vertex_order:
                x = np.empty_like(b)
                x[self._perm3] = self._factor(b[self._perm3])
                return x
            return self._factor(b)
        return self._lu.solve(np.asarray(b, np.float64))

    def _vertex_ordered(self, A):
        """P A P^T for a fill-reducing ordering of the vertices (AMD on the vertex graph of
        A's pattern), rows 3 i .. 3 i + 2 of a vertex kept in order. The ordering and the
        entry map are made at the first call (A's pattern is fixed per instance)."""
        if self._order is None:
            n = self.n
            rows = np.repeat(np.arange(3 * n), np.diff(A.indptr)) // 3
            graph = sp.csc_matrix((np.ones(len(rows)), (rows, A.indices // 3)), shape=(n, n))
            graph = graph + sp.identity(n, format="csc")
            vperm = analyze(graph.tocsc(), mode="simplicial", ordering_method="amd").P()
            self._perm3 = (3 * vperm[:, None] + np.arange(3)[None]).ravel()
            tagged = sp.csc_matrix((np.arange(1.0, A.nnz + 1.0), A.indices.copy(),
                                    A.indptr.copy()), shape=A.shape)
            moved = tagged[self._perm3][:, self._perm3].tocsc()
            moved.sort_indices()
            self._order = (moved.indices, moved.indptr, moved.data.astype(np.int64) - 1)
        indices, indptr, src = self._order
        return sp.csc_matrix((A.data[src], indices, indptr), shape=A.shape)

    def lower_factor(self):
        """(L, perm) of the last factorisation (CHOLMOD only): L lower triangular (scipy CSC)
        with P A P^T = L L^T, perm[k] the row of A that is row k of P A P^T. With
        ``vertex_order`` perm keeps each vertex's rows together (perm[3 k + c] = 3 v + c)."""
        if self.backend != "cholmod" or self._factor is None:
            raise RuntimeError("lower_factor needs a CHOLMOD factorisation")
        if self.vertex_order:
            return self._factor.L().tocsc(), self._perm3
        return self._factor.L().tocsc(), self._factor.P()

    @property
    def has_factor(self):
        return self._factor is not None or self._lu is not None

    def solve_reusing(self, val, b, rtol=1e-3, max_iters=8):
        """Solve A x = b for the block values ``val``, preconditioning conjugate gradients
        with the last factorisation (of an earlier, similar matrix) and factorising ``val``
        only when that does not reach ``rtol`` in ``max_iters`` iterations (or there is no
        factor yet). Returns (x, CG iterations, refactorised).

        Why: the AL's Newton matrices of one frame, and of consecutive frames of a cloth near
        rest, differ only where constraints switch, so an old factor is a nearly exact
        preconditioner; a new factorisation costs ~25 solves (4k triangles: 45-75 ms against
        ~2 ms a solve on this 2-core CPU)."""
        b = np.asarray(b, np.float64)
        A = self.matrix(val)
        if self.has_factor:
            # A lumped factorisation costs only a few solves: try the old one for fewer
            # iterations before making a new one (measured on hanging res 25, mapping: with 8,
            # every Newton step still refactorised, and the attempts cost more than that).
            tries = max_iters if self.exact else min(max_iters, 2)
            x, iters, ok = pcg(A, b, self.solve, rtol, tries)
            if ok:
                return x, iters, False
        self._factorize_matrix(self._to_factor(A))
        if self.exact:
            return self.solve(b), 0, True
        # The lumped factor is a preconditioner: finish with CG on A, to the accuracy of a
        # solve by an exact factor (measured on hanging res 25 at rest: with CG to 1e-3
        # only, the AL needed 2 rounds where the exact factor's steps needed 1). The cap only
        # guards a pathological matrix, whose solve is then inexact.
        x, iters, _ok = pcg(A, b, self.solve, min(rtol, EXACT_RTOL), 4 * max_iters)
        return x, iters, True


def pcg(A, b, precondition, rtol, max_iters):
    """Preconditioned conjugate gradients for the SPD matrix A (scipy sparse) from the
    preconditioned guess x0 = P b. Returns (x, iterations, converged to |r| <= rtol |b|)."""
    x = precondition(b)
    r = b - A @ x
    goal = rtol * np.linalg.norm(b)
    if np.linalg.norm(r) <= goal:
        return x, 0, True
    z = precondition(r)
    p = z.copy()
    rz = r @ z
    for k in range(1, max_iters + 1):
        Ap = A @ p
        pAp = p @ Ap
        if not pAp > 0.0:
            break
        alpha = rz / pAp
        x += alpha * p
        r -= alpha * Ap
        if np.linalg.norm(r) <= goal:
            return x, k, True
        z = precondition(r)
        rz_new = r @ z
        p = z + (rz_new / rz) * p
        rz = rz_new
    return x, max_iters, False
