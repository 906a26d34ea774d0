"""The implicit step's system matrix as a 3x3-block sparse matrix (BSR in Taichi ndarrays).

    A = (1 + h alpha) M + h (beta + h) K_psd        (dynamics.py's linearised backward Euler)

Under coupling "implicit" the strain projection minimises ``1/2 (x - x_hat)^T A (x - x_hat)``
instead of the paper's mass-weighted distance: one linearised backward-Euler step with the
limits as constraints. Its constraint forces then meet the same inertia and elastic stiffness
as the dynamics' forces, so a cloth at rest is an exact fixed point (with the mass metric the
projection's correction disagrees with the dynamics' response, by h^2 K / M ~ 100 on the soft
cloth, and the hanging sheet never settles).

The pattern (which vertex pairs couple: faces, bending stencils, stitches) is built on the
host when the mesh changes; ``slots`` map every element's local block (n, m) to its place in
``val``. For the split projection the same pattern holds the lumped masses on its diagonal
(``fill_diagonal``), so the solver has one code path, and the strain solve writes its Newton
matrix into that pattern either way (``al.newton_matrix``).
"""
import numpy as np
import taichi as ti

from . import ndarrays

mat3 = ti.types.matrix(3, 3, float)
vec3 = ti.types.vector(3, float)


class BlockMatrix:
    """Pattern and values of a symmetric 3x3-block matrix over ``n`` vertices.

    ptr (n + 1), col (nnz): CSR of the block pattern (rows sorted, diagonal included);
    val (nnz, 3x3): values; diag (n): slot of each row's diagonal block;
    face_slot (F, 9), edge_slot (E, 16), stitch_slot (S, 4): slots of element blocks,
    row-major over the element's local vertices; bend_slot (nnz of the bending matrix): the
    slot of each of its entries, in its row order (``build_pattern``).

    The Taichi arrays may be longer than the pattern (only their first rows are its): a
    pattern built with ``reuse`` takes over the arrays of one that is no longer used, when
    they are long enough, since a remesh makes a new pattern every frame and allocating its
    eight arrays cost more than filling them. ``sibling`` is the same pattern with values of
    its own."""

    def __init__(self, n, pairs_i, pairs_j, reuse=None):
        self.n = int(n)
        self.n_bend = 0
        key = np.concatenate([pairs_i, np.arange(n)]).astype(np.int64) * n + \
            np.concatenate([pairs_j, np.arange(n)]).astype(np.int64)
        uniq, inverse = np.unique(key, return_inverse=True)
        rows, cols = uniq // n, uniq % n
        self.nnz = len(uniq)
        ptr = np.zeros(n + 1, np.int64)
        np.add.at(ptr, rows + 1, 1)
        self.ptr_np = np.cumsum(ptr).astype(np.int32)
        self.col_np = cols.astype(np.int32)
        self._slots = inverse.ravel()[: len(pairs_i)].astype(np.int32)
        self.diag_np = inverse.ravel()[len(pairs_i):].astype(np.int32)
        self._spare = {} if reuse is None else reuse._arrays()
        self._grow = reuse is not None            # room for the next, larger meshes
        self.ptr = self._put("ptr", ti.i32, self.ptr_np)
        self.col = self._put("col", ti.i32, self.col_np)
        self.diag = self._put("diag", ti.i32, self.diag_np)
        self.val = self._array("val", mat3, self.nnz)

    def _array(self, name, dtype, rows, width=None):
        """An array of at least ``rows`` rows (one, if none): the spare one of that name when
        it is long enough, else a new one with a quarter more room."""
        arr = self._spare.pop(name, None)
        rows = max(int(rows), 1)
        if arr is None or arr.shape[0] < rows:
            rows = int(1.25 * rows) if self._grow else rows
            arr = ti.ndarray(dtype, rows if width is None else (rows, width))
        return arr

    def _put(self, name, dtype, values, width=None):
        arr = self._array(name, dtype, len(values), width)
        if len(values):
            ndarrays.put_rows(arr, values)
        return arr

    def _arrays(self):
        """Every Taichi array of this pattern, by name (for a new pattern to take over)."""
        names = ("ptr", "col", "diag", "val", "face_slot", "edge_slot", "stitch_slot",
                 "bend_slot")
        return {k: getattr(self, k) for k in names if hasattr(self, k)}

    def sibling(self, reuse_val=None):
        """A BlockMatrix with this pattern (its arrays shared) and a value array of its own
        (``reuse_val``'s when that is long enough)."""
        import copy
        twin = copy.copy(self)
        twin._spare = {} if reuse_val is None else {"val": reuse_val}
        twin._grow = reuse_val is not None
        twin.val = twin._array("val", mat3, self.nnz)
        return twin

    def to_scipy(self, val=None):
        """The matrix as a scipy CSR matrix (3n x 3n), for tests and direct solvers; ``val``:
        other values in this pattern (an ndarray of 3x3 blocks, e.g. a Newton matrix)."""
        import scipy.sparse as sp
        v = (self.val if val is None else val).to_numpy()[: self.nnz]
        return sp.bsr_matrix((v, self.col_np, self.ptr_np), shape=(3 * self.n, 3 * self.n)).tocsr()


def _element_pairs(elems):
    """All (row, col) vertex pairs of each element, row-major: (E * k * k,) each."""
    k = elems.shape[1]
    i = np.repeat(elems, k, axis=1).ravel()
    j = np.tile(elems, (1, k)).ravel()
    return i, j


def build_pattern(n_verts, faces, edge_verts, edge_opp, stitches, bend_rows=(), bend_cols=(),
                  reuse=None):
    """The BlockMatrix of the implicit step over a mesh: faces (F, 3), interior edges' bending
    stencils (x0, x1, x2, x3) = (edge_verts, edge_opp), stitch pairs (S, 2) and the entries
    (bend_rows, bend_cols) of the isotropic bending matrix (cloth/bending.py), whose slots
    go to ``bend_slot``. ``reuse``: a BlockMatrix no longer in use whose arrays it may take
    over."""
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    stencil = np.concatenate([np.asarray(edge_verts, np.int64).reshape(-1, 2),
                              np.asarray(edge_opp, np.int64).reshape(-1, 2)], axis=1)
    boundary = stencil[:, 3] < 0
    stencil[boundary] = stencil[boundary, :1]     # unused: every slot on (x0, x0)
    stitches = np.asarray(stitches, np.int64).reshape(-1, 2)
    bend_rows = np.asarray(bend_rows, np.int64).ravel()
    bend_cols = np.asarray(bend_cols, np.int64).ravel()
    parts = [_element_pairs(faces), _element_pairs(stencil), _element_pairs(stitches),
             (bend_rows, bend_cols)]
    pi = np.concatenate([p[0] for p in parts])
    pj = np.concatenate([p[1] for p in parts])
    B = BlockMatrix(n_verts, pi, pj, reuse=reuse)
    nf, ne, ns, nb = len(faces), len(stencil), len(stitches), len(bend_rows)
    s = B._slots
    B.n_bend = nb
    ends = np.cumsum([0, 9 * nf, 16 * ne, 4 * ns, nb])
    # The blocks of face and seam pairs (the diagonal among them): the pattern of the strain
    # constraints' Newton terms. The bending stencils reach further (two rings of vertices);
    # a factorisation that lumps them (linalg.SparseCholesky, ``core``) has a third of the
    # entries and a tenth of the cost.
    B.core_np = np.zeros(B.nnz, bool)
    B.core_np[s[ends[0]:ends[1]]] = True
    B.core_np[s[ends[2]:ends[3]]] = True
    B.core_np[B.diag_np] = True
    for n, (name, k) in enumerate((("face_slot", 9), ("edge_slot", 16), ("stitch_slot", 4),
                                   ("bend_slot", 1))):
        seg = s[ends[n]: ends[n + 1]]
        setattr(B, name, B._put(name, ti.i32, seg.reshape((-1, k) if k > 1 else (-1,)),
                                width=k if k > 1 else None))
    B._spare = {}
    return B


def pattern_of(model, stitches=(), reuse=None):
    """``build_pattern`` over a ClothModel's current mesh (its hinge stencils under the hinge
    energy, its bending matrix's entries under the isotropic one) and the seam pairs
    ``stitches``. The hinge stencils are left out under isotropic bending: the kernels run
    over no hinges then (``ImplicitEuler.n_hinges``), and they were 16 of the ~50 pairs per
    face the pattern sorts."""
    c = model._np_cache
    ev, eo = (c["edges"], c["edge_opp"]) if model.bending == "hinge" else \
        (np.zeros((0, 2), np.int32), np.zeros((0, 2), np.int32))
    return build_pattern(model.n_verts, model.faces, ev, eo, stitches, *model.bend_pattern(),
                         reuse=reuse)


@ti.kernel
def fill_diagonal(n: int, diag: ti.types.ndarray(), val: ti.types.ndarray(),
                  mass: ti.types.ndarray()):
    for i in range(n):
        val[diag[i]] = mass[i] * ti.Matrix.identity(float, 3)


@ti.kernel
def mean_diagonal(n: int, diag: ti.types.ndarray(), val: ti.types.ndarray(),
                  pinned: ti.types.ndarray()) -> float:
    """Mean of trace / 3 of the free rows' diagonal blocks: the metric's typical "mass" per
    vertex (the lumped mass for M; mostly h^2 K for the implicit step's A on soft cloth)."""
    total, count = 0.0, 0
    for i in range(n):
        if pinned[i] == 0:
            b = val[diag[i]]
            total += (b[0, 0] + b[1, 1] + b[2, 2]) / 3.0
            count += 1
    return total / ti.max(count, 1)
