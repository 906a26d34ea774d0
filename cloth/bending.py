"""The isotropic bending energy: a constant matrix Q over the vertices, built on the host from
the material mesh and its pins whenever the mesh changes.

    E_bend = (B / 2) sum_c x_c^T Q x_c         (c = the three world coordinates, B = k_bend)

For an isometric bend of the flat sheet X(u, v) (cloth barely stretches), the second
derivatives are X_ab = II_ab n, so the plate energy density (B / 2) |II|^2 equals
(B / 2) (|X_uu|^2 + |X_vv|^2 + 2 |X_uv|^2), which is quadratic in the positions: its matrix
is constant, its forces are exact and linear (-B Q x) and its Hessian is B Q itself. It is
isotropic by construction, with Poisson ratio 0. The hinge energy it replaces bends a strip
at 45 degrees to the mesh lines 0.8-3.8 times too stiffly (docs/history/bending_models.md).

|II|^2 is split as (tr II)^2 / 2 + |dev II|^2:

- tr II per vertex, by finite volumes over the vertex's cell (Voronoi, or Meyer's mixed cell
  where a face is obtuse, ``cell_areas``): A_v tr II = the flux of grad X out of the cell. The
  cotangent Laplacian is that flux through the cell's inner sides; where the cell meets the
  outline, the flux through its share of the outline is added (``trace_rows``). On the grids'
  right-angled meshes this is exact for quadratic fields at every vertex, whatever the
  pattern: the lumped third of the areas was not (0.75 and 1.5 times the trace at the two
  kinds of vertex of the alternating pattern, which read 1-3 % stiff at 0.5 cm).
- |dev II|^2 per face from the face fit: the quadratic X(u) through the face's three vertices
  and the three across its edges, in material coordinates.

Boundaries, found from the topology and the pins (so a remeshed or sewn mesh gets them too):

- A free edge (one face): the natural boundary condition, no moment across it. The fit
  replaces the missing sixth point by X_nn = 0 (Poisson ratio 0), and the trace's flux through
  the outline comes from that fit's normal slope along the edge. The old trace at boundary
  vertices, the face fit's own over a third of their faces, left the outline soft: strips 2 cm
  wide read 0.79 B on the ledge at 1 cm (docs/calibration/).
- A clamp: faces whose three vertices are pinned (``held_faces``; two rows of pins or more)
  are held flat and carry no energy; the energy lives on the free part, whose edges with them
  are clamped. There the fit's sixth condition is that its slope across the edge equals the
  held face's (a C1 join, the clamp's slope), and the trace's flux through the edge is the held
  face's. The whole stencil over a clamp line is the mirror image of the free side's
  (Ciarlet-Raviart's clamped plate): pinned rows counted as bendable cloth read 10 % soft at
  1 cm, a first-order error (the hinge line's turn got a whole cell's compliance, not half).
  One row of pins (a hanging sheet's top row, a single corner) is no clamp: it holds the
  positions, not the slope, and is a free edge for the energy.

Measured (docs/calibration/, ``python -m benchmarks.calibration`` at 0e98473): the ledge
cantilever reads 0.988-1.001 B at 0.5 cm, 0.953-1.003 at 1 cm, 0.973-1.007 at 2 cm, over
widths 2-16 cm with at least two triangles across, every pattern and direction, 7 and 41.5
deg (was 0.91-0.99, 0.65-0.96, 0.53-0.92); the back-to-back strips 0.971-1.005 (0.922-1.039).

A rigid motion of the flat rest sheet has zero energy: every term is a second derivative or a
flux balance, exact on affine maps. The energy has no rest curvature, so a model with a
curved rest shape (``rest_x``) keeps the hinge energy (cloth/model.py).
"""
import numpy as np
import scipy.sparse as sp

# A face whose six conditions are nearly dependent (its points nearly on one conic) has an
# ill-posed quadratic fit; beyond this condition number of its (scaled) 6 x 6 system the face
# gets the least-squares (pseudo-inverse) fit instead. Measured: never on the grids (condition
# ~10); on the hanging sheet remeshed for 60 frames from 31 x 31, 3 of 1822 faces, all exactly
# singular (1e17), the rest under 50.
MAX_FIT_CONDITION = 1e8

# What stands in slot 3 + k of a face's fit (across the edge opposite its vertex k).
POINT, FREE_EDGE, CLAMPED_EDGE = 0, 1, 2


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


def held_faces(faces, pinned):
    """(F,) bool: faces whose three vertices are pinned, held flat (the clamp)."""
    if pinned is None:
        return np.zeros(len(faces), bool)
    return np.asarray(pinned, bool)[np.asarray(faces, np.int64)].all(axis=1)


def held_vertices(faces, held, n):
    """(n,) bool: the vertices of held faces (the clamp's)."""
    out = np.zeros(n, bool)
    out[np.asarray(faces, np.int64)[np.asarray(held, bool)].ravel()] = True
    return out


def _values(p):
    """(..., 6): the fit's monomials 1, u, v, u^2 / 2, v^2 / 2, u v at the points p (..., 2)."""
    u, v = p[..., 0], p[..., 1]
    return np.stack([np.ones_like(u), u, v, 0.5 * u * u, 0.5 * v * v, u * v], axis=-1)


def _slopes(p, n):
    """(..., 6): the monomials' derivatives along the directions n (..., 2) at p."""
    u, v, a, b = p[..., 0], p[..., 1], n[..., 0], n[..., 1]
    return np.stack([np.zeros_like(u), a, b, a * u, b * v, a * v + b * u], axis=-1)


class FaceFits:
    """Every face's quadratic fit as linear maps of the values at its stencil ``sten``
    (F, 6): ``coef[f] @ x[sten[f]]`` are the coefficients of ``_values`` in the face's frame
    p = (u - centre) / scale. ``kind`` (F, 3) says what stands in slot 3 + k (POINT,
    FREE_EDGE or CLAMPED_EDGE); ``edge_*`` (F, 3, ...) are the edge opposite vertex k: its
    ends (a, b), length and outward unit normal in material space. On a CLAMPED_EDGE,
    ``held_slope[f, k] @ x[sten[f]]`` is the held face's slope across the edge (grad X . n)."""

    def __init__(self, uv, faces, edge_faces, edge_opp, area, held=None, subset=None):
        uv, faces = np.asarray(uv, np.float64), np.asarray(faces, np.int64)
        held = np.zeros(len(faces), bool) if held is None else np.asarray(held, bool)
        sten = face_stencils(faces, edge_faces, edge_opp)
        # The clamp: vertices of held faces (over the whole mesh, before ``subset``).
        in_held = held_vertices(faces, held, len(uv))
        if subset is not None:
            # The fits of these faces only (a remesh's new faces: ``IsotropicBending``);
            # every array below is then per face of the subset.
            faces, sten, held = faces[subset], sten[subset], held[subset]
            area = np.asarray(area)[subset]
        nf = len(faces)
        tri = uv[faces]
        self.centre = tri.mean(axis=1)
        self.scale = np.sqrt(2.0 * np.asarray(area, np.float64))     # ~ the face's size
        self.edge_a, self.edge_b = tri[:, [1, 2, 0]], tri[:, [2, 0, 1]]
        t = self.edge_b - self.edge_a
        self.edge_len = np.linalg.norm(t, axis=2)
        self.edge_normal = np.stack([t[..., 1], -t[..., 0]], -1) / self.edge_len[..., None]
        # The across vertex's face is held when it and the edge's ends are all pinned.
        across_held = np.zeros((nf, 3), bool)
        if in_held.any():
            pinned = in_held
            for k in range(3):
                across_held[:, k] = (sten[:, 3 + k] >= 0) & pinned[np.maximum(sten[:, 3 + k], 0)] \
                    & pinned[faces[:, (k + 1) % 3]] & pinned[faces[:, (k + 2) % 3]]
        self.kind = np.where(sten[:, 3:] < 0, FREE_EDGE,
                             np.where(across_held & ~held[:, None], CLAMPED_EDGE, POINT))
        p = (uv[np.maximum(sten, 0)] - self.centre[:, None]) / self.scale[:, None, None]
        V = _values(p)                           # rows: the conditions; POINT rows as they are
        R = np.broadcast_to(np.eye(6), (nf, 6, 6)).copy()    # condition = R @ stencil values
        self.held_slope = np.zeros((nf, 3, 6))
        for k in range(3):
            s = 3 + k
            n = self.edge_normal[:, k]
            free = self.kind[:, k] == FREE_EDGE
            # X_nn = 0 across a free edge: no moment there (Poisson ratio 0).
            V[free, s] = np.c_[np.zeros((free.sum(), 3)), n[free, 0] ** 2, n[free, 1] ** 2,
                               2 * n[free, 0] * n[free, 1]]
            R[free, s, s] = 0.0
            sten[free, s] = faces[free, 0]       # a placeholder with zero weight
            cl = np.flatnonzero(self.kind[:, k] == CLAMPED_EDGE)
            if len(cl):
                # The slope across the edge, at its middle (its mean along the edge: the fit's
                # slope is linear there), equals the held face's, whose vertices are the
                # edge's ends and the across vertex.
                mid = 0.5 * (self.edge_a[cl, k] + self.edge_b[cl, k])
                V[cl, s] = _slopes((mid - self.centre[cl]) / self.scale[cl, None], n[cl]) \
                    / self.scale[cl, None]
                q = np.stack([uv[faces[cl, (k + 1) % 3]], uv[faces[cl, (k + 2) % 3]],
                              uv[sten[cl, s]]], axis=1)
                grad = np.linalg.inv(np.stack([q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]], 2))
                slope = np.zeros((len(cl), 6))
                slope[:, (k + 1) % 3] = -((grad[:, 0] + grad[:, 1]) * n[cl]).sum(1)
                slope[:, (k + 2) % 3] = (grad[:, 0] * n[cl]).sum(1)
                slope[:, s] = (grad[:, 1] * n[cl]).sum(1)
                R[cl, s] = slope
                self.held_slope[cl, k] = slope
        self.sten = sten
        self.coef = _solve_fits(V) @ R


def _solve_fits(V):
    """V^-1 per face; the pseudo-inverse where V is ill-conditioned (MAX_FIT_CONDITION)."""
    try:
        Vinv = np.linalg.inv(V)
    except np.linalg.LinAlgError:       # an exactly singular face: every face by pinv
        Vinv = np.linalg.pinv(V, rcond=1.0 / MAX_FIT_CONDITION)
    cond = np.abs(V).sum(axis=1).max(axis=1) * np.abs(Vinv).sum(axis=1).max(axis=1)  # 1-norm
    bad = ~(cond < MAX_FIT_CONDITION)
    if bad.any():
        Vinv[bad] = np.linalg.pinv(V[bad], rcond=1.0 / MAX_FIT_CONDITION)
    return Vinv


def face_fit(uv, faces, edge_faces, edge_opp, area, held=None):
    """(stencil (F, 6), C (F, 3, 6)): X_uu, X_vv and X_uv of face f are C[f] @ x[stencil[f]]
    (the ``FaceFits`` of the mesh, second derivatives in material units)."""
    fits = FaceFits(uv, faces, edge_faces, edge_opp, area, held)
    return fits.sten, fits.coef[:, 3:6] / fits.scale[:, None, None] ** 2


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


def cell_areas(uv, faces):
    """(F, 3): each face's share of its vertices' cells, Meyer et al.'s mixed area: the
    Voronoi (circumcentric) share where the face is not obtuse (then the cotangent Laplacian
    is the flux through the cell's sides), else half the face to the obtuse vertex and a
    quarter to the others (positive on any mesh)."""
    P = np.asarray(uv, np.float64)[np.asarray(faces, np.int64)]
    cot = np.empty((len(P), 3))
    for k in range(3):
        a, b = P[:, (k + 1) % 3] - P[:, k], P[:, (k + 2) % 3] - P[:, k]
        cot[:, k] = (a * b).sum(1) / np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])
    share = np.empty((len(P), 3))
    for k in range(3):
        i, j = (k + 1) % 3, (k + 2) % 3
        # The cell's part of the face: two right triangles on the half edges k-i and k-j.
        share[:, k] = (((P[:, i] - P[:, k]) ** 2).sum(1) * cot[:, j]
                       + ((P[:, j] - P[:, k]) ** 2).sum(1) * cot[:, i]) / 8.0
    obtuse = (cot < 0).any(axis=1)
    a, b = P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]
    area = 0.5 * np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])
    share[obtuse] = np.where(cot[obtuse] < 0, 0.5, 0.25) * area[obtuse, None]
    return share


def outline_flux(fits, live):
    """(F, 3, 6): each face's flux of grad X through the outline's edges it has, as rows of
    its stencil (row r: the share of the face's vertex r, over the half edge next to it):
    through a clamped edge the held face's slope, through a free edge the fit's slope across
    it (linear along the edge). Zero for held faces and inner edges."""
    flux = np.zeros((len(fits.sten), 3, 6))
    for k in range(3):
        ra, rb = (k + 1) % 3, (k + 2) % 3          # the ends of the edge opposite vertex k
        cl = np.flatnonzero(live & (fits.kind[:, k] == CLAMPED_EDGE))
        half = 0.5 * fits.edge_len[cl, k, None] * fits.held_slope[cl, k]
        flux[cl, ra] += half
        flux[cl, rb] += half
        fr = np.flatnonzero(live & (fits.kind[:, k] == FREE_EDGE))
        scale = fits.scale[fr, None]
        nrm = fits.edge_normal[fr, k]
        ga, gb = (np.einsum("fi,fij->fj", _slopes((e[fr, k] - fits.centre[fr]) / scale, nrm),
                            fits.coef[fr]) / scale for e in (fits.edge_a, fits.edge_b))
        el = fits.edge_len[fr, k, None]
        # The half edge next to an end: the slope there is (3 g_end + g_other) / 4.
        flux[fr, ra] += el * (3 * ga + gb) / 8
        flux[fr, rb] += el * (ga + 3 * gb) / 8
    return flux


def _sparse(rows, cols, vals, n):
    return sp.csr_matrix((np.ravel(vals), (np.ravel(rows), np.ravel(cols))), (n, n))


def trace_rows(uv, faces, fits, live, n):
    """(T (V x V), A (V,)): tr II at vertex v is (T x)_v, over the cell of area A_v on the
    live (not held) faces; A_v = 0 where a vertex has none. A_v tr II = the flux of grad X out
    of the cell: the cotangent Laplacian's through its inner sides; through a clamped edge,
    the held face's slope over the half edge at each end; through a free edge, the fit's slope
    across it (linear along the edge) over each end's half."""
    A = np.zeros(n)
    np.add.at(A, faces[live].ravel(), cell_areas(uv, faces[live]).ravel())
    out = outline_flux(fits, live)
    flux = [-cotan_laplacian(uv, faces[live]),
            _sparse(np.repeat(faces, 6, axis=1), np.tile(fits.sten, (1, 3)), out, n)]
    inv = np.where(A > 0, 1.0 / np.where(A > 0, A, 1.0), 0.0)
    return sp.diags(inv) @ sum(flux[1:], flux[0]), A


def _face_rows(sten, rows, n):
    """The (k F) x n operator whose row k f + r is rows[r][f] on face f's stencil."""
    F, k = len(sten), len(rows)
    D = np.stack(rows, 1)
    r = np.repeat((np.arange(F)[:, None] * k + np.arange(k)[None, :])[:, :, None], 6, 2)
    return sp.csr_matrix((D.ravel(), (r.ravel(), np.repeat(sten[:, None, :], k, 1).ravel())),
                         (k * F, n))


def isotropic_matrix(uv, faces, edge_verts, edge_faces, edge_opp, area, pinned=None):
    """Q (V x V, symmetric positive semi-definite, CSR) of E = (B / 2) sum_c x_c^T Q x_c.
    ``pinned`` (V,) bool: faces with three pinned vertices are the clamp (``held_faces``)."""
    uv, faces = np.asarray(uv, np.float64), np.asarray(faces, np.int64)
    area = np.asarray(area, np.float64)
    n = len(uv)
    live = ~held_faces(faces, pinned)
    fits = FaceFits(uv, faces, edge_faces, edge_opp, area, ~live)
    # (tr II)^2 / 2 over the vertices' cells ...
    T, A = trace_rows(uv, faces, fits, live, n)
    trace = T.T @ sp.diags(A) @ T
    # ... and |dev II|^2 = (X_uu - X_vv)^2 / 2 + 2 X_uv^2 over the live faces.
    C = fits.coef[:, 3:6] / fits.scale[:, None, None] ** 2
    D = _face_rows(fits.sten, [(C[:, 0] - C[:, 1]) / np.sqrt(2.0), np.sqrt(2.0) * C[:, 2]], n)
    Q = 0.5 * trace + D.T @ sp.diags(np.repeat(np.where(live, area, 0.0), 2)) @ D
    Q = (0.5 * (Q + Q.T)).tocsr()
    # Rows that sum to exactly zero (they do up to round-off: every term vanishes on affine
    # maps): the kernels then apply Q to differences x_k - x_i, whose accuracy does not
    # depend on how far the cloth is from the origin.
    Q = (Q - sp.diags(np.asarray(Q.sum(axis=1)).ravel())).tocsr()
    Q.sum_duplicates()
    Q.eliminate_zeros()
    return Q


# ---------------------------------------------------------------------------------------------
# Orthotropic bending (docs/method.md §9.11): B_warp, B_weft, and the plate's twist from them
# ---------------------------------------------------------------------------------------------
def orthotropic_stretch(b_warp, b_weft):
    """alpha = (B_warp / B_weft)^(1/8): the material coordinates along the warp are divided by
    it and those along the weft multiplied by it (``orthotropic_coordinates``). 1.0 exactly
    when the two are equal."""
    if b_warp == b_weft:
        return 1.0
    return float((b_warp / b_weft) ** 0.125)


def strip_rigidity(b_warp, b_weft, angle):
    """The B a narrow strip cut at ``angle`` (rad) from the warp reads on the orthotropic
    plate: 1 / sqrt(B) = cos^2 / sqrt(B_warp) + sin^2 / sqrt(B_weft) (the plate's compliance
    along the strip, its transverse curvature and twist free; docs/method.md §9.11)."""
    c2, s2 = np.cos(angle) ** 2, np.sin(angle) ** 2
    return 1.0 / (c2 / np.sqrt(b_warp) + s2 / np.sqrt(b_weft)) ** 2


def orthotropic_coordinates(uv, faces, grain, alpha):
    """Material coordinates on which the isotropic plate is the orthotropic one.

    The isotropic energy (B'/2) |II|^2 integrated over coordinates u' = s1 / alpha,
    v' = s2 alpha (s1, s2: the coordinates along the warp and the weft, alpha beta = 1 keeps
    every area) is, in the original coordinates, (1/2) (B_warp k11^2 + B_weft k22^2
    + 2 H k12^2) with B_warp = B' alpha^4, B_weft = B' / alpha^4 and H = B' = sqrt(B_warp B_weft):
    the orthotropic plate with no Poisson coupling and Huber's twisting rigidity
    (D12 + 2 D66 = sqrt(D11 D22), with D12 = 0). Every part of ``isotropic_matrix`` (the
    cells' trace, the faces' deviator, free edges, clamps) is then the same construction on the
    mapped mesh, and its natural boundary conditions are the orthotropic plate's (the energy
    is the same functional). A strip along direction t (angle t from the warp) reads
    1 / sqrt(B(t)) = cos^2 t / sqrt(B_warp) + sin^2 t / sqrt(B_weft) (docs/method.md §9.11).

    The map is one linear map per connected piece of cloth, so every face of a piece must
    have the same grain (``grain`` (F, 2, 2), columns warp and weft); a piece whose faces
    disagree raises ValueError."""
    uv = np.asarray(uv, np.float64)
    faces = np.asarray(faces, np.int64)
    grain = np.asarray(grain, np.float64)
    n = len(uv)
    out = uv.copy()
    if alpha == 1.0:
        return out
    from scipy.sparse.csgraph import connected_components
    rows = np.repeat(faces[:, 0], 2)
    cols = faces[:, 1:].ravel()
    graph = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), (n, n))
    ncomp, label = connected_components(graph, directed=False)
    face_label = label[faces[:, 0]]
    for c in range(ncomp):
        fs = np.flatnonzero(face_label == c)
        if not len(fs):
            continue
        g = grain[fs[0]]
        if np.abs(grain[fs] - g).max() > 1e-9:
            raise ValueError("orthotropic bending needs one grain per piece of cloth: piece "
                             f"{c} (faces from {fs[0]}) has faces whose warp differs")
        vs = label == c
        s = uv[vs] @ g                       # (s1, s2): along the warp and the weft
        out[vs] = np.c_[s[:, 0] / alpha, s[:, 1] * alpha] @ np.linalg.inv(g)
    return out


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


# ---------------------------------------------------------------------------------------------
# The same matrix from per-face terms, reused across remeshes (docs/remesh/remesh_frame.md)
# ---------------------------------------------------------------------------------------------
def face_terms(uv, faces, edge_faces, edge_opp, area, held, subset=None):
    """Every face's share of Q, which depends on its stencil alone (its three vertices, the
    three across its edges, and which of them belong to the clamp): a dict of
    ``sten`` (S, 6) the stencil (free edges: a placeholder vertex with zero weights),
    ``flux`` (S, 3, 6) its rows of the trace's flux (the cotangent Laplacian's part through
    the cell sides inside the face, and the outline's part through its clamped or free
    edges; row r is the face's vertex r), ``cell`` (S, 3) its share of its vertices' cells
    and ``dev`` (S, 6, 6) its |dev II|^2 term. Held faces contribute nothing. ``subset``: of
    these faces only (the others' terms come from an earlier mesh)."""
    uv, faces = np.asarray(uv, np.float64), np.asarray(faces, np.int64)
    idx = np.arange(len(faces)) if subset is None else np.asarray(subset, np.int64)
    fits = FaceFits(uv, faces, edge_faces, edge_opp, area, held, subset=idx)
    f = faces[idx]
    live = ~np.asarray(held, bool)[idx]
    S = len(idx)
    flux = np.zeros((S, 3, 6))
    # Minus the cotangent Laplacian (cotan_laplacian, face by face).
    for k in range(3):
        i, j, o = k, (k + 1) % 3, (k + 2) % 3
        a, b = uv[f[:, i]] - uv[f[:, o]], uv[f[:, j]] - uv[f[:, o]]
        w = np.where(live, 0.5 * (a * b).sum(1) / np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]),
                     0.0)
        flux[:, i, i] -= w
        flux[:, j, j] -= w
        flux[:, i, j] += w
        flux[:, j, i] += w
    flux += outline_flux(fits, live)                    # as in trace_rows
    cell = np.zeros((S, 3))
    cell[live] = cell_areas(uv, f[live])
    C = fits.coef[:, 3:6] / fits.scale[:, None, None] ** 2
    d = np.stack([(C[:, 0] - C[:, 1]) / np.sqrt(2.0), np.sqrt(2.0) * C[:, 2]], 1)   # (S, 2, 6)
    w = np.where(live, np.asarray(area, np.float64)[idx], 0.0)
    dev = np.einsum("s,ski,skj->sij", w, d, d)
    return dict(sten=fits.sten, flux=flux, cell=cell, dev=dev)


def assemble(terms, faces, n):
    """Q (CSR) from the faces' terms (``face_terms``): (1/2) F^T diag(1/A) F with F the
    summed flux rows and A the summed cells (T = diag(1/A) F is ``trace_rows``' operator),
    plus the |dev II|^2 terms, symmetrised, rows made to sum to zero (``isotropic_matrix``)."""
    faces = np.asarray(faces, np.int64)
    sten, flux = terms["sten"], terms["flux"]
    F = sp.csr_matrix((flux.ravel(), (np.repeat(faces, 6, axis=1).ravel(),
                                      np.tile(sten, (1, 3)).ravel())), (n, n))
    A = np.bincount(faces.ravel(), terms["cell"].ravel(), minlength=n)
    inv = np.where(A > 0, 1.0 / np.where(A > 0, A, 1.0), 0.0)
    dev = sp.csr_matrix((terms["dev"].ravel(), (np.repeat(sten, 6, axis=1).ravel(),
                                                np.tile(sten, (1, 6)).ravel())), (n, n))
    Q = 0.5 * (F.T @ sp.diags(inv) @ F) + dev
    Q = (0.5 * (Q + Q.T)).tocsr()
    Q = (Q - sp.diags(np.asarray(Q.sum(axis=1)).ravel())).tocsr()
    Q.sum_duplicates()
    Q.eliminate_zeros()
    return Q


class IsotropicBending:
    """``isotropic_matrix`` for a mesh that changes by remeshing: each face's terms
    (``face_terms``) are kept, and after a remesh only the faces whose stencil changed (new,
    reshaped, beside one that was, or whose clamp flags changed) are computed again; the
    others are carried over through the remesh's vertex map. The matrix is then assembled
    from the terms as a rebuild would (``assemble``): the same to round-off
    (tests/test_bending_update.py). ``last_reused``: how many faces' terms the last call
    carried over."""

    def __init__(self):
        self._faces = self._key = self._terms = None
        self.last_reused = 0

    @staticmethod
    def _face_key(faces, sten, held, in_held):
        """Per face what its terms depend on besides the material coordinates (which never
        change for a vertex): its vertices in order, its across vertices (-1: a free edge),
        whether it is held and which stencil vertices belong to the clamp."""
        s = np.where(sten >= 0, sten, -1)
        return np.concatenate([faces, s[:, 3:], held[:, None],
                               in_held[np.maximum(s, 0)] & (s >= 0)], axis=1).astype(np.int64)

    def matrix(self, uv, faces, edge_faces, edge_opp, area, pinned=None, vertex_map=None):
        """Q of the mesh (as ``isotropic_matrix``). ``vertex_map`` (old vertex -> new, -1
        where removed; a remesh's ``stats["vertex_map"]``) says that this mesh is a remesh of
        the previous call's; without it every face is computed."""
        uv, faces = np.asarray(uv, np.float64), np.asarray(faces, np.int64)
        n = len(uv)
        held = held_faces(faces, pinned)
        in_held = held_vertices(faces, held, n)
        sten = face_stencils(faces, edge_faces, edge_opp)
        key = self._face_key(faces, sten, held, in_held)
        source = -np.ones(len(faces), np.int64)      # the old face whose terms fit, per face
        if vertex_map is not None and self._key is not None:
            source = self._match(key, np.asarray(vertex_map, np.int64), n)
        fresh = np.flatnonzero(source < 0)
        terms = {}
        if len(fresh) < len(faces):
            kept = np.flatnonzero(source >= 0)
            vmap = np.asarray(vertex_map, np.int64)
            new = face_terms(uv, faces, edge_faces, edge_opp, area, held, subset=fresh) \
                if len(fresh) else None
            for name, old in self._terms.items():
                arr = np.empty((len(faces),) + old.shape[1:], old.dtype)
                arr[kept] = old[source[kept]]
                if new is not None:
                    arr[fresh] = new[name]
                terms[name] = arr
            # Carried stencils are in the old numbering; free-edge placeholders are the
            # face's own first vertex, which survives with the face.
            terms["sten"][kept] = vmap[terms["sten"][kept]]
        else:
            terms = face_terms(uv, faces, edge_faces, edge_opp, area, held)
        self.last_reused = len(faces) - len(fresh)
        self._faces, self._key, self._terms = faces, key, terms
        return assemble(terms, faces, n)

    def _match(self, key, vmap, n):
        """Per new face, the old face with the same key once the old one is renumbered by
        ``vmap`` (-1: none). Candidates by the directed edge from vertex 0 to vertex 1 (one
        face per directed edge in a manifold mesh), then every column compared."""
        old = self._key.copy()
        ok = np.ones(len(old), bool)
        ids = np.r_[0:3, 3:6]                    # vertex columns (3-5: -1 on free edges)
        for c in ids:
            col = old[:, c]
            mapped = np.where(col >= 0, vmap[np.maximum(col, 0)], -1)
            ok &= (col < 0) | (mapped >= 0)
            old[:, c] = mapped
        old_code = old[:, 0] * n + old[:, 1]
        new_code = key[:, 0] * n + key[:, 1]
        cand = np.flatnonzero(ok)
        order = cand[np.argsort(old_code[cand], kind="stable")]
        pos = np.searchsorted(old_code[order], new_code)
        pos = np.minimum(pos, max(len(order) - 1, 0))
        src = order[pos] if len(order) else np.zeros(len(key), np.int64)
        same = (len(order) > 0) & np.all(old[src] == key, axis=1) if len(order) else \
            np.zeros(len(key), bool)
        return np.where(same, src, -1)
