"""An aggregation multigrid preconditioner of the implicit step's matrix A for the one-kernel
strain solve's PCG on large meshes (``al.solve_al``, preconditioner mode PC_MULTIGRID).

Why: block-Jacobi PCG needs iterations that grow with the cloth's diameter in triangles
(corrections travel one ring of neighbours per iteration), so its budget grows as
sqrt(faces) and a round costs ~N^1.5; the factor of A (factor_precond.py) reaches the soft
global modes in a few iterations but its serial triangular solves and its factorisation grow
faster than the mesh. An application of this one costs less than a product with H.
Measured on captured Newton systems of the falling hanging sheet (frames 3-4, mapping,
linearised at x_hat; |d_8 - d*|_H / |d*|_H after 8 PCG iterations, 1 = nothing found):
block Jacobi 0.82 / 0.88 / 0.90 at 4k / 16k / 32.8k faces, this preconditioner 0.29 / 0.36 /
0.38 (docs/history/multigrid/newton_precond_at_hat.md; a scratch run gave 0.36 at 64.8k, and the
exact factor of A 0.41 / 0.44 at 4k / 16k). Linearised at the previous positions instead,
neither finds much of the step (0.85-0.98 left after 16, block Jacobi 0.96-0.99) and a
two-level space of rigid motions on 8 x 8 patches does best (0.34-0.86;
docs/history/multigrid/newton_precond.md): a lead not followed.

What: the hierarchy is made on the host by pyamg (``smoothed_aggregation_solver`` with
smooth=None: vertices grouped into aggregates of ~10-20 by the strength of their coupling,
tentative prolongators P_l carrying the three translations of each aggregate, coarse
matrices A_{l+1} = P_l^T A_l P_l) from A with pinned rows and columns made the identity,
until the coarsest has at most MAX_COARSE unknowns (inverted densely). The kernel applies

    z = OMEGA D^-1 r + P_0 V(P_0^T r)

with D A's 3x3 diagonal blocks (zero for pinned vertices, whose step is zero) and V a
V-cycle on the coarse levels (one damped Jacobi sweep before and after each coarse
correction, the coarsest solved exactly). The fine level is *additive*: no product with A
at full size, so an application costs less than a product with H (2.1 against 2.8 ms at 64.8k
faces, 0.8 ms at 16k); on the captured systems
it found as much of the step as a multiplicative V-cycle with a Jacobi sweep on A before and
after (0.32 against 0.34 at 4k faces, 0.37 against 0.38 at 32k; scratch runs), which costs
two products with A more. Smoothing with H's diagonal instead of A's found less (0.39-0.46 after 8): the
coarse levels approximate A, and the two must agree. Every part is symmetric, so the
preconditioner is symmetric positive definite, as PCG needs.

The hierarchy is rebuilt when it is REFRESH_SOLVES solves old (A changes slowly, as for the
factor); D is taken from the same A.
"""
import numpy as np
import scipy.sparse as sp
import taichi as ti

from ..system_matrix import mat3
from .buffers import PC_MULTIGRID, T
from .factor_precond import FIRST_AFTER, RefreshedPreconditioner

try:
    import pyamg
    HAVE_PYAMG = True
except ImportError:                                      # pragma: no cover - pinned in reqs
    HAVE_PYAMG = False

# Damping of every Jacobi part (the fine additive one and the coarse sweeps). 0.5-0.6 found
# the most of the step on the captured systems; 1.0 found 10-30 % less after 8 iterations.
OMEGA = 0.5
# The coarsest level's unknowns, solved by a dense inverse (its size is between this and ~3x
# it: the last coarsening step groups ~10 aggregates).
MAX_COARSE = 20
MAX_LEVELS = 20

# The level table in ``ints``: ints[0] = number of levels L (>= 2), then per level l, at
# 1 + STRIDE l: its unknowns n_l, A_l's CSR (ptr and col offsets in ints, values offset in
# reals; the coarsest level: its dense inverse at the values offset; level 0 uses the block
# metric instead), P_l's CSR (rows n_l, columns n_{l+1}; not on the coarsest level), and the
# offset in reals of four work vectors of n_l (r_l, z_l, t_l, and D_l^-1 of the point Jacobi
# sweeps; levels >= 1). reals[0] = OMEGA.
STRIDE = 8
N_, A_PTR, A_COL, A_VAL, P_PTR, P_COL, P_VAL, VEC = range(STRIDE)


class MultigridPreconditioner(RefreshedPreconditioner):
    """The multigrid arrays the kernel reads (``apply``): ``ints`` (the level table, then
    the CSR index arrays), ``reals`` (OMEGA, the CSR values, the coarsest inverse, the work
    vectors) and ``blocks`` (the inverses of A's 3x3 diagonal blocks, zero for pinned
    vertices). The arrays grow as needed (an ndarray's size is not part of a kernel's
    signature: no recompilation). The life cycle is ``RefreshedPreconditioner``'s."""
    mode = PC_MULTIGRID

    def __init__(self, metric, first_after=FIRST_AFTER):
        super().__init__(metric, first_after)
        self.ints = ti.ndarray(ti.i32, 1)
        self.reals = ti.ndarray(float, 1)
        self.blocks = ti.ndarray(mat3, max(metric.n, 1))
        self.levels = []                     # unknowns per level (the last hierarchy)
        self.host = None                     # the numpy arrays of the last upload

    def refresh(self, values, pinned):
        """Build the hierarchy of the block matrix with these values (the metric's pattern,
        pinned rows and columns already the identity) and upload it."""
        m = self.metric
        A = sp.bsr_matrix((values, m.col_np, m.ptr_np), shape=(3 * m.n, 3 * m.n))
        self.host = build(A, pinned)
        self.levels = [int(n) for n in self.host["levels"]]
        ints, reals = self.host["ints"], self.host["reals"]
        if len(ints) > self.ints.shape[0]:
            self.ints = ti.ndarray(ti.i32, int(1.25 * len(ints)))
        if len(reals) > self.reals.shape[0]:
            self.reals = ti.ndarray(float, int(1.25 * len(reals)))
        if m.n > self.blocks.shape[0]:
            self.blocks = ti.ndarray(mat3, m.n)
        _upload(self.ints, ints)
        _upload(self.reals, reals)
        _upload(self.blocks, self.host["blocks"])
        self.ready = True


class MultigridStub:
    """One-element arrays for solve_al's multigrid arguments when it does not use the
    multigrid (of its types, so that solve_al compiles once)."""

    def __init__(self):
        self.ints, self.reals = ti.ndarray(ti.i32, 1), ti.ndarray(float, 1)
        self.blocks = ti.ndarray(mat3, 1)


def _upload(arr, values):
    """values into the front of the (possibly longer) ndarray arr."""
    full = np.zeros(arr.shape + tuple(values.shape[1:]), values.dtype)
    full[: len(values)] = values
    arr.from_numpy(full)


def build(A, pinned):
    """The hierarchy of the (3n x 3n, BSR) matrix A as the kernel's arrays: a dict with
    "ints", "reals", "blocks" (see the level table above), "levels" (unknowns per level) and
    the scipy matrices ("A": per level, "P": per level but the last, "coarse_inverse") for
    ``apply_reference``."""
    n = A.shape[0] // 3
    free = ~np.asarray(pinned[:n], bool)
    B = np.zeros((3 * n, 3))
    for a in range(3):
        B[a::3, a] = free                              # translations; pinned vertices stay
    ml = pyamg.smoothed_aggregation_solver(A.tobsr(blocksize=(3, 3)), B=B, smooth=None,
                                           max_coarse=MAX_COARSE, max_levels=MAX_LEVELS)
    mats = [sp.csr_matrix(lv.A) for lv in ml.levels]
    prolong = [sp.csr_matrix(lv.P) for lv in ml.levels[:-1]]
    if len(mats) < 2:
        raise ValueError("multigrid needs a mesh with more than MAX_COARSE unknowns")
    coarse_inverse = np.linalg.pinv(mats[-1].toarray())
    blocks = np.zeros((n, 3, 3))
    blocks[free] = np.linalg.inv(_diagonal_blocks(A)[free])
    L = len(mats)
    ints, reals = [np.zeros(1 + STRIDE * L, np.int64)], [np.array([OMEGA])]
    n_int, n_real = len(ints[0]), 1
    table = ints[0]
    table[0] = L

    def put_int(a):
        nonlocal n_int
        ints.append(np.asarray(a, np.int64))
        n_int += len(a)
        return n_int - len(a)

    def put_real(a):
        nonlocal n_real
        reals.append(np.asarray(a, np.float64).ravel())
        n_real += reals[-1].size
        return n_real - reals[-1].size

    for l in range(L):
        row = table[1 + STRIDE * l:1 + STRIDE * (l + 1)]
        row[N_] = mats[l].shape[0]
        if l == L - 1:
            row[A_VAL] = put_real(coarse_inverse)
        elif l > 0:
            row[A_PTR], row[A_COL] = put_int(mats[l].indptr), put_int(mats[l].indices)
            row[A_VAL] = put_real(mats[l].data)
        if l < L - 1:
            row[P_PTR], row[P_COL] = put_int(prolong[l].indptr), put_int(prolong[l].indices)
            row[P_VAL] = put_real(prolong[l].data)
        if l > 0:
            d = mats[l].diagonal()
            row[VEC] = put_real(np.concatenate([np.zeros(3 * row[N_]),
                                                1.0 / np.where(d != 0.0, d, 1.0)]))
    return dict(ints=np.concatenate(ints).astype(np.int32), reals=np.concatenate(reals),
                blocks=blocks, levels=[m.shape[0] for m in mats], A=mats, P=prolong,
                coarse_inverse=coarse_inverse)


def _diagonal_blocks(A):
    """(n, 3, 3): the diagonal 3x3 blocks of the BSR matrix A."""
    B = A.tobsr(blocksize=(3, 3))
    n = B.shape[0] // 3
    rows = np.repeat(np.arange(n), np.diff(B.indptr))
    out = np.zeros((n, 3, 3))
    on = B.indices == rows
    out[rows[on]] = B.data[on]
    return out


def apply_reference(h, r):
    """z = M^-1 r as the kernel computes it, in numpy (for tests; r flat, 3n)."""
    n = len(h["blocks"])
    mats, P = h["A"], h["P"]

    def cycle(l, rl):
        if l == len(mats) - 1:
            return h["coarse_inverse"] @ rl
        dinv = 1.0 / mats[l].diagonal()
        z = OMEGA * dinv * rl
        z = z + P[l] @ cycle(l + 1, P[l].T @ (rl - mats[l] @ z))
        return z + OMEGA * dinv * (rl - mats[l] @ z)

    fine = OMEGA * np.einsum("nij,nj->ni", h["blocks"], r.reshape(n, 3)).ravel()
    return fine + P[0] @ cycle(1, P[0].T @ r)


@ti.func
def _csr_row(ints: T, reals: T, ptr, col, val, i, x_off):
    """Row i of the CSR matrix at (ptr, col, val) times the vector at x_off in reals."""
    acc = 0.0
    for k in range(ints[ptr + i], ints[ptr + i + 1]):
        acc += reals[val + k] * reals[x_off + ints[col + k]]
    return acc


@ti.func
def _restrict(ints: T, reals: T, row, n, src_off, dst_off):
    """reals[dst:dst + n_{l+1}] = P_l^T (reals[src:src + n]) (P_l's table row ``row``)."""
    for j in range(ints[row + STRIDE + N_]):
        reals[dst_off + j] = 0.0
    for i in range(n):
        ri = reals[src_off + i]
        for k in range(ints[ints[row + P_PTR] + i], ints[ints[row + P_PTR] + i + 1]):
            reals[dst_off + ints[ints[row + P_COL] + k]] += reals[ints[row + P_VAL] + k] * ri


@ti.func
def apply(nv, ints: T, reals: T, blocks: T, r: T, z: T):
    """z = M^-1 r (vec3 arrays over the nv vertices): the fine additive part and the coarse
    V-cycle of the module docstring. Runs serially (inside the solve's one kernel)."""
    L = ints[0]
    omega = reals[0]
    top = 1                                           # level 0's table row
    # Level 1's right-hand side: P_0^T r.
    r1 = ints[top + STRIDE + VEC]
    for j in range(ints[top + STRIDE + N_]):
        reals[r1 + j] = 0.0
    for i in range(3 * nv):
        ri = r[i // 3][i % 3]
        for k in range(ints[ints[top + P_PTR] + i], ints[ints[top + P_PTR] + i + 1]):
            reals[r1 + ints[ints[top + P_COL] + k]] += reals[ints[top + P_VAL] + k] * ri
    # Down the coarse levels: z_l = omega D^-1 r_l, t_l = r_l - A_l z_l, r_{l+1} = P^T t_l.
    for l in range(1, L - 1):
        row = 1 + STRIDE * l
        n, v = ints[row + N_], ints[row + VEC]
        for i in range(n):
            reals[v + n + i] = omega * reals[v + 3 * n + i] * reals[v + i]
        for i in range(n):
            reals[v + 2 * n + i] = reals[v + i] - _csr_row(ints, reals, ints[row + A_PTR],
                                                            ints[row + A_COL],
                                                            ints[row + A_VAL], i, v + n)
        _restrict(ints, reals, row, n, v + 2 * n, ints[row + STRIDE + VEC])
    # The coarsest level, exactly: z = A^-1 r.
    row = 1 + STRIDE * (L - 1)
    n, v, inv = ints[row + N_], ints[row + VEC], ints[row + A_VAL]
    for i in range(n):
        acc = 0.0
        for j in range(n):
            acc += reals[inv + i * n + j] * reals[v + j]
        reals[v + n + i] = acc
    # Up: z_l += P_l z_{l+1}, then z_l += omega D^-1 (r_l - A_l z_l).
    for ll in range(L - 2):
        l = L - 2 - ll
        row = 1 + STRIDE * l
        n, v = ints[row + N_], ints[row + VEC]
        below = ints[row + STRIDE + VEC] + ints[row + STRIDE + N_]       # z_{l+1}
        for i in range(n):
            reals[v + n + i] += _csr_row(ints, reals, ints[row + P_PTR], ints[row + P_COL],
                                         ints[row + P_VAL], i, below)
        for i in range(n):
            reals[v + 2 * n + i] = reals[v + i] - _csr_row(ints, reals, ints[row + A_PTR],
                                                            ints[row + A_COL],
                                                            ints[row + A_VAL], i, v + n)
        for i in range(n):
            reals[v + n + i] += omega * reals[v + 3 * n + i] * reals[v + 2 * n + i]
    # The fine level: z = omega D^-1 r + P_0 z_1.
    z1 = ints[top + STRIDE + VEC] + ints[top + STRIDE + N_]
    for k in range(nv):
        zk = omega * (blocks[k] @ r[k])
        for a in ti.static(range(3)):
            zk[a] += _csr_row(ints, reals, ints[top + P_PTR], ints[top + P_COL],
                              ints[top + P_VAL], 3 * k + a, z1)
        z[k] = zk
