"""The isotropic bending energy (issue #16): a constant matrix Q over the vertices, built on
the host from the material mesh whenever the mesh changes.

    E_bend = (B / 2) sum_c x_c^T Q x_c         (c = the three world coordinates, B = k_bend)

For an isometric bend of the flat sheet X(u, v) (cloth barely stretches), the second
derivatives are X_ab = II_ab n, so the plate energy density (B / 2) |II|^2 equals
(B / 2) (|X_uu|^2 + |X_vv|^2 + 2 |X_uv|^2), which is quadratic in the positions: its matrix
is constant, its forces are exact and linear (-B Q x) and its Hessian is B Q itself. It is
isotropic by construction. The hinge energy it replaces bends a strip at 45 degrees to the
mesh lines 0.8-3.8 times too stiffly, because no per-edge energy can be isotropic on a grid
(docs/calibration/bending_models.md).

|II|^2 is split as (tr II)^2 / 2 + |dev II|^2, and the two parts come from different places,
each where it converges:

- tr II at interior vertices: the cotangent Laplacian, (L x)_v / A_v (A_v = a third of the
  areas around v). It is exact for quadratic fields on these meshes and symmetric, so the
  chequerboard mode of criss-cross meshes costs energy.
- |dev II|^2 per face, and tr II at boundary vertices: the face fit. It is the quadratic
  X(u) through the face's three vertices and the three vertices across its edges, in material
  coordinates. Across a boundary edge the missing sixth point is replaced by X_nn = 0, the
  moment-free edge (Poisson ratio 0).

On its own, the face fit is 25-45 % too soft on the alternating pattern, through the
chequerboard, whose fit is pure trace. The Laplacian's trace fixes that, and the face fit's
deviator is blind to the chequerboard.

Measured (docs/calibration/): the linearised cantilever reads 0.96-1.04 B for every pattern,
direction and triangle size of the calibration (0.5-2 cm), against the hinge's 0.94-2.9.

A rigid motion of the flat rest sheet has zero energy: every term is a second derivative, and
those vanish on affine maps. The energy has no rest curvature, so a model with a curved rest
shape (``rest_x``) keeps the hinge energy (cloth/model.py).
"""
import numpy as np
import scipy.sparse as sp

# A face whose six points nearly lie on one conic has an ill-posed quadratic fit; beyond this
# condition number of its (scaled) 6 x 6 system the face gets the least-squares (pseudo-
# inverse) fit instead. Measured: never on the grids (condition ~10); on the hanging sheet
# remeshed for 60 frames from 31 x 31, 3 of 1822 faces, all exactly singular (1e17), the rest
# under 50.
MAX_FIT_CONDITION = 1e8


def face_stencils(faces, edge_faces, edge_opp):
    """(F, 6) vertex indices: the face's three vertices, then in slot 3 + n the vertex across
    the edge opposite the face's vertex n (-1 across a boundary edge)."""
    faces = np.asarray(faces, np.int64)
    ef, eo = np.asarray(edge_faces, np.int64), np.asarray(edge_opp, np.int64)
    sten = np.concatenate([faces, -np.ones((len(faces), 3), np.int64)], axis=1)
    inner = np.flatnonzero(ef[:, 1] >= 0)
    for side in (0, 1):
        f = ef[inner, side]
        own_opp = eo[inner, side]           # this face's vertex opposite the edge
        slot = np.argmax(faces[f] == own_opp[:, None], axis=1)
        sten[f, 3 + slot] = eo[inner, 1 - side]
    return sten


def face_fit(uv, faces, edge_faces, edge_opp, area):
    """(stencil (F, 6), C (F, 3, 6)): X_uu, X_vv and X_uv of face f are C[f] @ x[stencil[f]].
    A missing neighbour's slot holds the face's vertex 0 with zero weight; the fit then obeys
    X_nn = 0 across that edge (n its material normal)."""
    uv, faces = np.asarray(uv, np.float64), np.asarray(faces, np.int64)
    nf = len(faces)
    sten = face_stencils(faces, edge_faces, edge_opp)
    present = sten >= 0
    tri = uv[faces]
    centre = tri.mean(axis=1)
    scale = np.sqrt(2.0 * np.asarray(area, np.float64))[:, None]     # ~ the face's size
    p = (uv[np.maximum(sten, 0)] - centre[:, None]) / scale[:, :, None]
    ones = np.ones((nf, 6))
    V = np.stack([ones, p[..., 0], p[..., 1], 0.5 * p[..., 0] ** 2, 0.5 * p[..., 1] ** 2,
                  p[..., 0] * p[..., 1]], axis=2)
    for n in range(3):
        miss = np.flatnonzero(~present[:, 3 + n])
        t = tri[miss, (n + 2) % 3] - tri[miss, (n + 1) % 3]
        t /= np.linalg.norm(t, axis=1, keepdims=True)
        a, b = t[:, 1], -t[:, 0]                                   # the edge's normal
        zero = np.zeros_like(a)
        V[miss, 3 + n] = np.stack([zero, zero, zero, a * a, b * b, 2 * a * b], axis=1)
    try:
        Vinv = np.linalg.inv(V)
    except np.linalg.LinAlgError:       # an exactly singular face: every face by pinv
        Vinv = np.linalg.pinv(V, rcond=1.0 / MAX_FIT_CONDITION)
    cond = np.abs(V).sum(axis=1).max(axis=1) * np.abs(Vinv).sum(axis=1).max(axis=1)  # 1-norm
    bad = ~(cond < MAX_FIT_CONDITION)
    if bad.any():
        Vinv[bad] = np.linalg.pinv(V[bad], rcond=1.0 / MAX_FIT_CONDITION)
    C = Vinv[:, 3:6, :] / scale[:, :, None] ** 2 * present[:, None, :]
    return np.where(present, sten, faces[:, :1]), C


def cotan_laplacian(uv, faces):
    """The cotangent Laplacian (V x V, positive semi-definite: sum over faces of the
    cotangent-weighted (x_i - x_j)^2 / 2)."""
    uv, faces = np.asarray(uv, np.float64), np.asarray(faces, np.int64)
    n = len(uv)
    rows, cols, vals = [], [], []
    for k in range(3):
        i, j, o = faces[:, k], faces[:, (k + 1) % 3], faces[:, (k + 2) % 3]
        a, b = uv[i] - uv[o], uv[j] - uv[o]
        w = 0.5 * (a * b).sum(1) / np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])
        rows += [i, j, i, j]
        cols += [j, i, i, j]
        vals += [-w, -w, w, w]
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         (n, n))


def _face_rows(sten, rows, n):
    """The (k F) x n operator whose row k f + r is rows[r][f] on face f's stencil."""
    F, k = len(sten), len(rows)
    D = np.stack(rows, 1)
    r = np.repeat((np.arange(F)[:, None] * k + np.arange(k)[None, :])[:, :, None], 6, 2)
    return sp.csr_matrix((D.ravel(), (r.ravel(), np.repeat(sten[:, None, :], k, 1).ravel())),
                         (k * F, n))


def isotropic_matrix(uv, faces, edge_verts, edge_faces, edge_opp, area):
    """Q (V x V, symmetric positive semi-definite, CSR) of E = (B / 2) sum_c x_c^T Q x_c."""
    uv, faces = np.asarray(uv, np.float64), np.asarray(faces, np.int64)
    area = np.asarray(area, np.float64)
    ev, ef = np.asarray(edge_verts, np.int64), np.asarray(edge_faces, np.int64)
    n = len(uv)
    lumped = np.zeros(n)
    np.add.at(lumped, faces.ravel(), np.repeat(area / 3.0, 3))
    boundary = np.zeros(n, bool)
    boundary[ev[ef[:, 1] < 0].ravel()] = True
    # (tr II)^2 / 2: A_v ((L x)_v / A_v)^2 at interior vertices ...
    interior = np.where(boundary, 0.0, 1.0 / np.maximum(lumped, 1e-300))
    Li = sp.diags(interior) @ cotan_laplacian(uv, faces)
    trace = Li.T @ sp.diags(np.where(boundary, 0.0, lumped)) @ Li
    # ... and the face fit's trace over the boundary vertices' thirds of their faces.
    sten, C = face_fit(uv, faces, ef, edge_opp, area)
    T = _face_rows(sten, [C[:, 0] + C[:, 1]], n)
    near_boundary = sum(np.where(boundary[faces[:, k]], area / 3.0, 0.0) for k in range(3))
    trace = trace + T.T @ sp.diags(near_boundary) @ T
    # |dev II|^2 = (X_uu - X_vv)^2 / 2 + 2 X_uv^2 from the face fit, over every face.
    D = _face_rows(sten, [(C[:, 0] - C[:, 1]) / np.sqrt(2.0), np.sqrt(2.0) * C[:, 2]], n)
    Q = 0.5 * trace + D.T @ sp.diags(np.repeat(area, 2)) @ D
    Q = (0.5 * (Q + Q.T)).tocsr()
    # Rows that sum to exactly zero (they do up to round-off: every term is a second
    # derivative): the kernels then apply Q to differences x_k - x_i, whose accuracy does not
    # depend on how far the cloth is from the origin.
    Q = (Q - sp.diags(np.asarray(Q.sum(axis=1)).ravel())).tocsr()
    Q.sum_duplicates()
    Q.eliminate_zeros()
    return Q


def rows_with_diagonal_first(Q):
    """(ptr (V + 1,) i32, col (nnz,) i32, val (nnz,) f64) of a square CSR matrix with each
    row's diagonal entry first (present even where it is zero): the kernels read the diagonal
    block for the preconditioner at ptr[i]."""
    Q = sp.coo_matrix(Q)
    n = Q.shape[0]
    diag = np.arange(n)
    # COO -> CSR sums duplicates and keeps explicit zeros (an addition of matrices drops them).
    Q = sp.csr_matrix((np.r_[Q.data, np.zeros(n)], (np.r_[Q.row, diag], np.r_[Q.col, diag])),
                      (n, n))
    Q.sort_indices()
    rows = np.repeat(np.arange(n), np.diff(Q.indptr))
    not_diag = Q.indices != rows
    order = np.lexsort((not_diag, rows))     # by row, the diagonal first, then by column
    return (Q.indptr.astype(np.int32), Q.indices[order].astype(np.int32),
            Q.data[order].astype(np.float64))
