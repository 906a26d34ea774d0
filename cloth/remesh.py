"""Adaptive anisotropic remeshing in material space (Narain, Samii, O'Brien 2012), once per frame.

Host-side numpy/Python: ``remesh(mesh, params)`` returns a new ``MeshArrays``. Outline:

1. Sizing field. Per face a symmetric 2x2 metric ``M`` in material space; an edge ``du`` is
   "too long" when ``du^T M du > 1``. ``M`` bounds four criteria (``metric_max``), each
   written so that the quantity it bounds changes by at most its ``refine_*`` limit across
   one edge:
   curvature (turning of the normal), velocity gradient, compression (buckling to come) and,
   when an obstacle is given, proximity. Each face's metric has its eigenvalues clamped by
   ``size_min``/``size_max`` and ``aspect_min``; the clamped metrics are averaged to the
   vertices (weighted by material area).
2. Operations, each one local, checked, and either applied whole or not at all:
   split edges too long in the metric (longest first), flip to the anisotropic Delaunay
   triangulation, collapse edges whose removal makes no edge too long and inverts nothing,
   flip again. A collapse merges one end of the edge into the other or, where that would
   make too long an edge, both ends into a new vertex at the edge's midpoint (see
   ``_collapse_phase``). Collapses keep a hysteresis margin below the split threshold,
   except for edges too short to be half of a recent split (see ``_collapse_limit``).
3. Transfer. A split puts the new vertex at the edge's material midpoint and gives it the
   midpoint of x, v (exact linear interpolation in material space); a collapse to the
   midpoint makes its vertex the same way. Flips and collapses never move a vertex that
   survives them, so existing vertices keep uv, x, v, pins exactly. New faces inherit grain
   and ``face_data`` rows from the face they were cut from.

The mutable mesh during the operations is plain Python lists (faces and a vertex -> faces
index); numpy does everything that touches the whole mesh at once (sizing, candidate lists).

"""
import heapq
import math
import time

import numpy as np

from cloth.model import MeshArrays, ModelError, build_edges, dihedral_angles, \
    signed_material_areas
from cloth import metrics
from cloth.remesh_params import RemeshParams  # noqa: F401 (re-exported)

# A triangle counts as degenerate when twice its area is below this fraction of its longest
# edge squared (relative, so it works at any mesh scale).
_AREA_REL_EPS = 1e-9
# Boundary vertices may be collapsed away only when the boundary through them is straight to
# this relative tolerance (sine of the kink angle), so boundary length and area are kept.
_COLLINEAR_EPS = 1e-10
# Flip only when the Delaunay test fails by this margin (sine of the angle excess): a regular
# grid is exactly co-circular everywhere and must not flip back and forth.
_FLIP_EPS = 1e-6
# A split may not create a triangle of quality (``_Work.quality``) below this fraction of
# aspect_min unless the triangle it cuts is already worse. Measured on hanging, drape and the
# t-shirt (mapping): ordinary splits never made one below 0.14 (1st percentile 0.21-0.29);
# the chains of splits toward a seam that made slivers go down to 0.
_SPLIT_QUALITY = 0.5
# A flip or a collapse is refused when a triangle it makes is deformed more than this (the
# largest |principal stretch - 1|, ``_stretch_error``) and more than the triangles it
# replaces. Both change a patch's deformation (a split does not: its vertex is the edge's
# midpoint in both spaces): across a fold the new edge is a chord of the curved cloth, and
# the drape's remeshes left triangles 50-100 % compressed, which the projection after each
# remesh then unfolded (170-1,200 ms, and the kinetic energy of a resting sheet up from 1e-6
# to 1e-4 J). Measured on drape --remesh, 90 frames, three starts 1 nm apart
# (docs/remesh/drape.md): 0.1 made the frames cheapest; 0.05 refused so many collapses that
# the sheet grew past 4,000 faces; 0.15 and 0.2 cost more again.
_STRETCH_GUARD = 0.1


# ---------------------------------------------------------------------------------------------
# Sizing field (numpy, whole mesh)
# ---------------------------------------------------------------------------------------------
# The sizing keeps a stack of symmetric 2x2 matrices [[a, b], [b, c]] as its three coordinate
# columns (a, b, c), each a contiguous array: numpy's (N, 2, 2) stacks are strided, and reading
# or writing their entries cost several times the arithmetic (the sizing runs every frame of a
# remeshed scene: measured on the resting drape at 3k faces, ``mesh_sizing`` and
# ``pending_operations`` together 8.5 -> 5.1 ms with columns).
def _columns(M):
    """(a, b, c) of stacked symmetric 2x2 matrices (N, 2, 2) (b: the mean of the two
    off-diagonal entries)."""
    return (np.ascontiguousarray(M[:, 0, 0]), 0.5 * (M[:, 0, 1] + M[:, 1, 0]),
            np.ascontiguousarray(M[:, 1, 1]))


def _stacked(S):
    """The (N, 2, 2) stack of columns (a, b, c)."""
    a, b, c = S
    out = np.empty((len(a), 2, 2))
    out[:, 0, 0], out[:, 1, 1] = a, c
    out[:, 0, 1] = out[:, 1, 0] = b
    return out


def _eig(S):
    """Closed-form eigen-decomposition of symmetric columns (a, b, c): (lo, hi, cs, sn), the
    eigenvalues lo <= hi, (cs, sn) the unit eigenvector of hi and (-sn, cs) that of lo."""
    a, b, c = S
    mean, r = 0.5 * (a + c), np.hypot(0.5 * (a - c), b)
    phi = 0.5 * np.arctan2(2.0 * b, a - c)        # direction of the larger eigenvalue
    return mean - r, mean + r, np.cos(phi), np.sin(phi)


def _from_eig(lo, hi, cs, sn):
    """The columns of lo (-sn, cs)(-sn, cs)^T + hi (cs, sn)(cs, sn)^T (``_eig``'s inverse)."""
    cc, ss = cs * cs, sn * sn
    return lo * ss + hi * cc, (hi - lo) * cs * sn, lo * cc + hi * ss


def _square(S):
    """S S of symmetric columns (= S^T S)."""
    a, b, c = S
    return a * a + b * b, b * (a + c), b * b + c * c


def _pullback(g00, g01, g11, B):
    """B^T G B for symmetric G (columns g00, g01, g11) and general 2x2 B (its entries b00,
    b01, b10, b11 as columns): with G the Gram matrix of two edge vectors and B = Dm^-1, the
    quantity's gradient in material space squared (F^T F for positions)."""
    b00, b01, b10, b11 = B
    t00, t01 = g00 * b00 + g01 * b10, g00 * b01 + g01 * b11      # G B
    t10, t11 = g01 * b00 + g11 * b10, g01 * b01 + g11 * b11
    return b00 * t00 + b10 * t10, b00 * t01 + b10 * t11, b01 * t01 + b11 * t11


def _edge_grams(cols, i, j, k):
    """(e1.e1, e1.e2, e2.e2) for the edge vectors e1 = p_j - p_i, e2 = p_k - p_i of every
    face, the points given as coordinate columns ``cols``."""
    e1 = [c.take(j) - c.take(i) for c in cols]
    e2 = [c.take(k) - c.take(i) for c in cols]
    dot = lambda p, q: sum(a * b for a, b in zip(p, q))
    return dot(e1, e1), dot(e1, e2), dot(e2, e2)


def _scaled(S, s):
    return tuple(col * s for col in S)


def _max_columns(A, B):
    """``metric_max`` on columns."""
    cax, cay, ra = 0.5 * (A[0] - A[2]), A[1], 0.5 * (A[0] + A[2])
    cbx, cby, rb = 0.5 * (B[0] - B[2]), B[1], 0.5 * (B[0] + B[2])
    dx, dy = cbx - cax, cby - cay
    d = np.hypot(dx, dy)
    r = 0.5 * (ra + d + rb)
    t = np.where(d > 0.0, (r - ra) / np.where(d > 0.0, d, 1.0), 0.0)
    cx, cy = cax + t * dx, cay + t * dy
    a_in_b, b_in_a = d + ra <= rb, d + rb <= ra
    r = np.where(a_in_b, rb, np.where(b_in_a, ra, r))
    cx = np.where(a_in_b, cbx, np.where(b_in_a, cax, cx))
    cy = np.where(a_in_b, cby, np.where(b_in_a, cay, cy))
    return r + cx, cy, r - cx


def metric_max(A, B):
    """The smallest-trace metric M with M - A and M - B positive semidefinite (stacks of
    symmetric 2x2): an edge short enough in M is short enough in both, and M is no finer than
    that needs. ARCSim combines its sizing terms so (``tensor_max``); their sum, which Loom
    used before, is finer by up to sqrt(2) in length where two terms ask for the same size.

    A symmetric 2x2 matrix [[a, b], [b, c]] is the disk with centre ((a - c) / 2, b) and
    radius (a + c) / 2 (its eigenvalues are the radius plus and minus the centre's length),
    and M - A is positive semidefinite exactly when M's disk contains A's: M is the smallest
    disk containing both. Folded over several terms this bounds each of them, and can be
    finer than the smallest metric that does: on the drape at frame 30 its trace is within
    1 % of that one's in 99.4 % of the faces, 6 % at most (Welzl's algorithm, as ARCSim, would
    give the smallest)."""
    return _stacked(_max_columns(_columns(A), _columns(B)))


SIZING_TERMS = ("curvature", "velocity", "compression", "obstacle")


def face_sizing(mesh, params, obstacle_distance=None, edges=None):
    """Per-face sizing metric (F, 2, 2) in material space before clamping, and face areas:
    the terms of ``face_sizing_terms`` combined by ``metric_max``. ``edges``:
    ``build_edges(mesh.faces)`` if the caller has it already."""
    M, area = _face_metric(mesh, params, obstacle_distance, edges)
    return _stacked(M), area


def _face_metric(mesh, params, obstacle_distance, edges):
    """``face_sizing`` as columns."""
    terms, area = _face_terms(mesh, params, obstacle_distance, edges)
    M = None
    for T in terms.values():
        M = T if M is None else _max_columns(M, T)
    return M, area


def face_sizing_terms(mesh, params, obstacle_distance=None, edges=None):
    """Each criterion's per-face metric (a dict over ``SIZING_TERMS``, (F, 2, 2) each, the
    obstacle term only with ``obstacle_distance``) before clamping, and face areas."""
    terms, area = _face_terms(mesh, params, obstacle_distance, edges)
    return {name: _stacked(T) for name, T in terms.items()}, area


def _face_terms(mesh, params, obstacle_distance, edges):
    """``face_sizing_terms`` as columns."""
    faces = mesh.faces
    i, j, k = (np.ascontiguousarray(faces[:, c], dtype=np.intp) for c in range(3))
    u, v = (np.ascontiguousarray(mesh.uv[:, c]) for c in range(2))
    e1u, e1v = u.take(j) - u.take(i), v.take(j) - v.take(i)
    e2u, e2v = u.take(k) - u.take(i), v.take(k) - v.take(i)
    det = e1u * e2v - e2u * e1v
    area = 0.5 * det
    Dm_inv = (e2v / det, -e2u / det, -e1v / det, e1u / det)   # entries 00, 01, 10, 11

    # Curvature: discrete shape operator in material space. Each edge's dihedral angle theta
    # is a bend across the edge, spread over the two faces beside it: S = sum theta |e| n n^T
    # / (2 A) with n the in-plane unit normal of the edge. |S du| is then the turning of the
    # normal along du, bounded by refine_angle.
    ev, ef, eo = build_edges(faces) if edges is None else edges
    theta = dihedral_angles(mesh.x, ev, eo)
    eu, evv = u.take(ev[:, 1]) - u.take(ev[:, 0]), v.take(ev[:, 1]) - v.take(ev[:, 0])
    elen = np.hypot(eu, evv)
    nu, nv = -evv / elen, eu / elen
    w = 0.5 * theta * elen
    inner = ef[:, 1] >= 0
    side = np.concatenate([ef[:, 0], ef[inner, 1]])
    S = []
    for t in (w * nu * nu, w * nu * nv, w * nv * nv):
        S.append(np.bincount(side, np.concatenate([t, t[inner]]), minlength=len(faces)) / area)
    S = tuple(S)
    if params.curvature_smoothing:
        corner = faces.reshape(-1)
        weight_sum = np.maximum(np.bincount(corner, np.repeat(area, 3), minlength=len(u)),
                                1e-300)
        for _ in range(params.curvature_smoothing):
            S = _face_mean(_vertex_mean(S, area, corner, weight_sum), i, j, k)
    S2 = _square(S)
    terms = {"curvature": _scaled(S2, 1.0 / params.refine_angle ** 2)}

    # Velocity gradient (3x2): bounds the velocity difference across an edge.
    vel = [np.ascontiguousarray(mesh.v[:, c]) for c in range(3)]
    terms["velocity"] = _scaled(_pullback(*_edge_grams(vel, i, j, k), Dm_inv),
                                1.0 / params.refine_velocity ** 2)

    # Compression: a region compressed (Green strain e = F^T F - I below 0 along a direction)
    # will buckle, and is refined before the wrinkles form: along it, the metric m that
    # solves c^2 m^2 + e m + k^2 = 0 (the larger root), k the curvature across that direction
    # (S^2's adjugate). Flat (k = 0), m = -e / c^2: size_min at a compression of about
    # refine_compression, c^2 = 2 refine_compression size_min^2. Curved across it, the
    # surface resists buckling there (a shell, or a rib, is stiffer against compression
    # along it than a flat sheet) and asks for less; nothing below a compression of about
    # c k / sqrt(2). Where the root is complex, the square root of the negative discriminant
    # is taken negative, so that the metric falls continuously to 0 (ARCSim's
    # compression_metric with rib_stiffening 1).
    pos = [np.ascontiguousarray(mesh.x[:, c]) for c in range(3)]
    ea, eb, ec = _pullback(*_edge_grams(pos, i, j, k), Dm_inv)       # F^T F, F = Ds Dm^-1
    e = (ea - 1.0, eb, ec - 1.0)
    c2 = 2.0 * params.refine_compression * params.size_min ** 2
    ka, kb, kc = S2[2], -S2[1], S2[0]             # adj(S^2): the curvature across
    qa, qb, qc = _square(e)                       # e symmetric: e^T e
    lo, hi, cs, sn = _eig((qa - 4.0 * c2 * ka, qb - 4.0 * c2 * kb, qc - 4.0 * c2 * kc))
    root = lambda lam: np.sign(lam) * np.sqrt(np.abs(lam))
    ra, rb, rc = _from_eig(root(lo), root(hi), cs, sn)
    lo, hi, cs, sn = _eig((ra - e[0], rb - e[1], rc - e[2]))
    scale = 1.0 / (2.0 * c2)
    terms["compression"] = _from_eig(np.maximum(lo, 0.0) * scale, np.maximum(hi, 0.0) * scale,
                                     cs, sn)

    # Obstacle proximity: the material gradient g of the obstacle distance d; within
    # obstacle_reach of an obstacle, the change of d across an edge must stay below
    # refine_obstacle * (|d| + size_min). A sheet lying on an obstacle, flat or curved with
    # it (d the same at its vertices, g ~ 0), is not refined by this term, only where it
    # approaches or leaves it; farther than the reach, not at all (ARCSim: nearest-obstacle
    # planes within 10 repulsion thicknesses).
    if obstacle_distance is not None:
        d = np.asarray(obstacle_distance(mesh.x), dtype=np.float64).reshape(-1)
        if d.shape != (len(u),) or not np.all(np.isfinite(d)):
            raise ModelError("obstacle_distance must return one finite distance per vertex")
        di, dj, dk = d.take(i), d.take(j), d.take(k)
        d1, d2 = dj - di, dk - di
        near = np.minimum(np.minimum(di, dj), dk) < params.obstacle_reach
        g0 = np.where(near, Dm_inv[0] * d1 + Dm_inv[2] * d2, 0.0)       # Dm^-T (d1, d2)
        g1 = np.where(near, Dm_inv[1] * d1 + Dm_inv[3] * d2, 0.0)
        s2 = (params.refine_obstacle * ((np.abs(di) + np.abs(dj) + np.abs(dk)) / 3.0
                                        + params.size_min)) ** 2
        terms["obstacle"] = (g0 * g0 / s2, g0 * g1 / s2, g1 * g1 / s2)
    return terms, area


def _vertex_mean(S, area, corner, weight_sum):
    """Area-weighted average at the vertices of symmetric per-face columns S; ``corner``:
    the faces' vertex indices flattened, ``weight_sum`` each vertex's summed face areas."""
    n = len(weight_sum)
    return tuple(np.bincount(corner, np.repeat(area * col, 3), minlength=n) / weight_sum
                 for col in S)


def _face_mean(S, i, j, k):
    """Each face's mean of its three vertices' symmetric columns S."""
    return tuple((col.take(i) + col.take(j) + col.take(k)) / 3.0 for col in S)


def vertex_sizing(face_M, area, faces, n_verts, params):
    """Each face's metric clamped (``clamp_metric``), then the area-weighted average of the
    clamped metrics at the vertices. (V, 2, 2).

    Clamped first, as ARCSim does: a mean of metrics whose eigenvalues lie within the bounds
    and the aspect limit lies within them too, and one sharply curved face (a crease whose
    metric asks for far below ``size_min``) counts in its vertices' mean as a face at
    ``size_min``, not as a metric that outweighs all of the vertex's other faces. Averaged
    unclamped and clamped after, such a face set its three vertices' finest size to
    ``size_min``: on the draped sheet (frame 30) that was the finest size of 78 % of the
    vertices, against 18 % clamped first, and the metric asked for 3.3k faces against 3.0k."""
    return _stacked(_vertex_sizing(_columns(face_M), area, faces, n_verts, params))


def _vertex_sizing(M, area, faces, n_verts, params):
    """``vertex_sizing`` on columns."""
    corner = faces.reshape(-1)
    weight_sum = np.maximum(np.bincount(corner, np.repeat(area, 3), minlength=n_verts), 1e-300)
    return _vertex_mean(_clamp(M, params), area, corner, weight_sum)


def clamp_metric(M, params):
    """Clamp metric eigenvalues to [1/size_max^2, 1/size_min^2] and the anisotropy so that the
    short axis is at least aspect_min times the long one."""
    return _stacked(_clamp(_columns(M), params))


def _clamp(M, params):
    """``clamp_metric`` on columns."""
    lo, hi, cs, sn = _eig(M)
    lo = np.clip(lo, 1.0 / params.size_max ** 2, 1.0 / params.size_min ** 2)
    hi = np.clip(hi, 1.0 / params.size_max ** 2, 1.0 / params.size_min ** 2)
    return _from_eig(np.maximum(lo, params.aspect_min ** 2 * hi), hi, cs, sn)


def _sym_eig2(M):
    """``_eig`` of stacked symmetric 2x2 matrices: (lam (N, 2) ascending, V (N, 2, 2) with
    the eigenvectors as columns)."""
    lo, hi, cs, sn = _eig(_columns(M))
    V = np.stack([np.stack([-sn, cs], axis=1), np.stack([cs, sn], axis=1)], axis=2)
    return np.stack([lo, hi], axis=1), V


# ---------------------------------------------------------------------------------------------
# Mutable mesh and the three local operations (Python, one edge at a time)
# ---------------------------------------------------------------------------------------------
def _cross2(ax, ay, bx, by):
    return ax * by - ay * bx


def _normal(p, q, r):
    """Unnormalised world normal of triangle (p, q, r)."""
    ax, ay, az = q[0] - p[0], q[1] - p[1], q[2] - p[2]
    bx, by, bz = r[0] - p[0], r[1] - p[1], r[2] - p[2]
    return (ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx)


def _dot3(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _stretch_error(pu, qu, ru, px, qx, rx):
    """max |s - 1| over the principal stretches s of the triangle mapped from material
    points (pu, qu, ru) to world points (px, qx, rx): 0 undeformed, 1 collapsed to a line.
    Plain floats, not numpy: it runs once per tried flip or collapse, where a numpy call's
    overhead alone cost a guard on flips 14 ms a remesh on the T-shirt
    (``_stretch_error_np`` is the whole-mesh version)."""
    a0, a1, b0, b1 = qu[0] - pu[0], qu[1] - pu[1], ru[0] - pu[0], ru[1] - pu[1]
    det = a0 * b1 - a1 * b0
    if det == 0.0:
        return math.inf
    e = (qx[0] - px[0], qx[1] - px[1], qx[2] - px[2])
    f = (rx[0] - px[0], rx[1] - px[1], rx[2] - px[2])
    g00, g01, g11 = _dot3(e, e), _dot3(e, f), _dot3(f, f)
    # C = Dm^-T G Dm^-1 with Dm^-1 = [[b1, -b0], [-a1, a0]] / det: its trace and determinant.
    i00, i01, i10, i11 = b1 / det, -b0 / det, -a1 / det, a0 / det
    c00 = i00 * (g00 * i00 + g01 * i10) + i10 * (g01 * i00 + g11 * i10)
    c11 = i01 * (g00 * i01 + g01 * i11) + i11 * (g01 * i01 + g11 * i11)
    dC = max(g00 * g11 - g01 * g01, 0.0) / (det * det)
    half = 0.5 * (c00 + c11)
    root = math.sqrt(max(half * half - dC, 0.0))
    return max(abs(math.sqrt(half + root) - 1.0), abs(math.sqrt(max(half - root, 0.0)) - 1.0))


class _FacesAt:
    """vertex -> set of its faces. A set is made on first use from the input incidence, since
    one frame's operations usually touch few vertices; once made, the set is the truth."""

    def __init__(self, faces, n_verts):
        flat = faces.reshape(-1)
        self._face_of = (np.argsort(flat, kind="stable") // 3).tolist()
        counts = np.bincount(flat, minlength=n_verts)
        self._start = np.concatenate([[0], np.cumsum(counts)]).tolist()
        self._sets = [None] * n_verts

    def __getitem__(self, a):
        s = self._sets[a]
        if s is None:
            s = self._sets[a] = set(self._face_of[self._start[a]:self._start[a + 1]])
        return s

    def __setitem__(self, a, faces):
        self._sets[a] = faces

    def append(self, faces):
        self._sets.append(faces)


class _Work:
    """The mesh while it is being remeshed: per-vertex Python lists (uv, x, v, metric as
    (m00, m01, m11), pins), faces as lists (None once removed), ``vf`` the set of faces at
    each vertex, ``origin`` the input face each face descends from (for grain and face_data),
    ``bnd`` whether a vertex lies on the material boundary."""

    def __init__(self, mesh, Mv, frozen, params, edges=None):
        self.p = params
        self.uv = mesh.uv.tolist()
        self.x = mesh.x.tolist()
        self.v = mesh.v.tolist()
        self.pinned = mesh.pinned.tolist()
        self.pin_target = mesh.pin_target.tolist()
        self.frozen = frozen.tolist()
        self.keep = (mesh.pinned | frozen).tolist()
        M3 = np.stack([Mv[:, 0, 0], Mv[:, 0, 1], Mv[:, 1, 1]], axis=1)
        self.M = M3.tolist()
        self.faces = mesh.faces.tolist()
        self.origin = list(range(len(self.faces)))
        # numpy mirror of the faces (with spare rows for new faces) kept in step by
        # set_face/add_face, so whole-mesh passes need no list -> array conversion.
        nf = len(self.faces)
        self._faces_np = np.zeros((2 * nf + 16, 3), dtype=np.int64)
        self._faces_np[:nf] = mesh.faces
        self._face_alive = np.zeros(2 * nf + 16, dtype=bool)
        self._face_alive[:nf] = True
        self.alive = [True] * len(self.uv)
        self.vf = _FacesAt(mesh.faces, len(self.uv))
        self.n_split = self.n_flip = self.n_collapse = 0
        self.split_parents = []     # (a, b) of each vertex a split made, in order
        self.touched = set()        # vertices whose neighbourhood a collapse changed
        # numpy copies for the whole-mesh passes; per-vertex rows never change once made, so
        # they are only extended after splits (see snapshot()).
        self._uv_np, self._M_np = mesh.uv.copy(), M3
        self._keep_np = np.asarray(self.keep, dtype=bool)
        ev, ef, eo = build_edges(mesh.faces) if edges is None else edges
        self._snap = (self._op_count(), mesh.faces.astype(np.int64), ev, ef, eo)
        bnd = np.zeros(len(self.uv), dtype=bool)
        be = ev[ef[:, 1] < 0]
        bnd[be[:, 0]] = bnd[be[:, 1]] = True
        self.bnd = bnd.tolist()

    def _op_count(self):
        return self.n_split + self.n_flip + self.n_collapse

    def snapshot(self):
        """The current mesh as numpy for whole-mesh passes: (faces, edge_verts, edge_faces,
        edge_opp, uv, metric (V, 3) as (m00, m01, m11), keep mask). Rebuilt only when an
        operation happened."""
        n_old, n = len(self._uv_np), len(self.uv)
        if n > n_old:
            self._uv_np = np.concatenate([self._uv_np, np.array(self.uv[n_old:])])
            self._M_np = np.concatenate([self._M_np, np.array(self.M[n_old:])])
            self._keep_np = np.concatenate([self._keep_np, np.array(self.keep[n_old:], bool)])
        if self._snap[0] != self._op_count():
            faces = self.faces_array()
            self._snap = (self._op_count(), faces) + build_edges(faces)
        return self._snap[1:] + (self._uv_np, self._M_np, self._keep_np)

    # -- face storage -------------------------------------------------------------------------
    def set_face(self, f, tri):
        """Replace face f by ``tri`` (a vertex list), or remove it (None)."""
        self.faces[f] = tri
        self._face_alive[f] = tri is not None
        if tri is not None:
            self._faces_np[f] = tri

    def add_face(self, tri, origin):
        g = len(self.faces)
        if g == len(self._faces_np):             # out of spare rows: double them
            self._faces_np = np.concatenate([self._faces_np, np.zeros_like(self._faces_np)])
            self._face_alive = np.concatenate([self._face_alive,
                                               np.zeros_like(self._face_alive)])
        self.faces.append(None)
        self.origin.append(origin)
        self.set_face(g, tri)
        return g

    def faces_array(self):
        """Live faces (F, 3) in face-slot order."""
        return self._faces_np[:len(self.faces)][self._face_alive[:len(self.faces)]]

    # -- queries ------------------------------------------------------------------------------

    def edge_faces(self, a, b):
        return self.vf[a] & self.vf[b]

    def neighbours(self, a):
        out = set()
        for f in self.vf[a]:
            out.update(self.faces[f])
        out.discard(a)
        return out

    def metric_len2(self, a, b):
        """Squared edge length in the metric averaged over the two ends."""
        ma, mb = self.M[a], self.M[b]
        du = self.uv[b][0] - self.uv[a][0]
        dv = self.uv[b][1] - self.uv[a][1]
        return 0.5 * ((ma[0] + mb[0]) * du * du + 2 * (ma[1] + mb[1]) * du * dv
                      + (ma[2] + mb[2]) * dv * dv)

    def stretch_error(self, i, j, k):
        """``_stretch_error`` of face (i, j, k)."""
        return _stretch_error(self.uv[i], self.uv[j], self.uv[k], self.x[i], self.x[j], self.x[k])

    def undeformed_enough(self, new_errors, old_faces):
        """Whether a flip's or a collapse's new triangles (their ``stretch_error``s) pass the
        stretch guard against the faces they replace (``_STRETCH_GUARD``; ``_flip_allowed_np``
        is the same rule for flips over the whole mesh). The replaced faces are read only
        when a new one is past the guard (most operations make none)."""
        new = max(new_errors, default=0.0)
        return new <= _STRETCH_GUARD or \
            new <= max((self.stretch_error(*self.faces[f]) for f in old_faces), default=0.0)

    def area_ok(self, i, j, k):
        """Counter-clockwise and not degenerate in material space."""
        p, q, r = self.uv[i], self.uv[j], self.uv[k]
        ax, ay, bx, by = q[0] - p[0], q[1] - p[1], r[0] - p[0], r[1] - p[1]
        cx, cy = r[0] - q[0], r[1] - q[1]
        longest = max(ax * ax + ay * ay, bx * bx + by * by, cx * cx + cy * cy)
        return _cross2(ax, ay, bx, by) > _AREA_REL_EPS * longest

    def _metric(self, i, j, k):
        """The face's average metric, as (m00, m01, m11)."""
        return [sum(self.M[t][c] for t in (i, j, k)) / 3.0 for c in range(3)]

    @staticmethod
    def _quality_uv(m, p, q, r):
        """4 sqrt(3) A / sum |e|^2 of the triangle (p, q, r) (material points) in metric m."""
        det = max(m[0] * m[2] - m[1] * m[1], 0.0)
        two_area = _cross2(q[0] - p[0], q[1] - p[1], r[0] - p[0], r[1] - p[1])
        s = 0.0
        for s0, s1 in ((p, q), (q, r), (r, p)):
            du, dv = s1[0] - s0[0], s1[1] - s0[1]
            s += m[0] * du * du + 2 * m[1] * du * dv + m[2] * dv * dv
        return 2.0 * math.sqrt(3.0) * two_area * math.sqrt(det) / s if s > 0 else 0.0

    def quality(self, i, j, k):
        """4 sqrt(3) A / sum |e|^2 measured in the face's average metric: 1 for a triangle that
        is equilateral in the metric, 0 when degenerate."""
        return self._quality_uv(self._metric(i, j, k), self.uv[i], self.uv[j], self.uv[k])

    @staticmethod
    def rotate_to(tri, a):
        """The face's vertices in counter-clockwise order starting at ``a``."""
        i = tri.index(a)
        return tri[i], tri[(i + 1) % 3], tri[(i + 2) % 3]

    def around_edge(self, f, a, b):
        """Face f's vertices (p, q, r) counter-clockwise with (p, q) its edge {a, b}."""
        p, q, r = self.rotate_to(self.faces[f], a)
        return (p, q, r) if q == b else self.rotate_to(self.faces[f], b)

    def split_ok(self, a, b):
        # An edge between two frozen vertices (a seam) keeps its vertex list unchanged.
        if self.frozen[a] and self.frozen[b]:
            return False
        # A split may not make a triangle worse than _SPLIT_QUALITY allows (nor worse than the
        # one it cuts, if that one already was): next to an edge that cannot be split (a seam, or
        # a boundary kink) splitting the face's shorter edges puts each new vertex halfway to
        # that edge and, repeated, makes slivers of zero area (the t-shirt's seams did this at
        # its first remesh, 8656 of 13688 faces).
        mid = [0.5 * (s + t) for s, t in zip(self.uv[a], self.uv[b])]
        for f in self.edge_faces(a, b):
            p, q, r = self.around_edge(f, a, b)
            floor = min(_SPLIT_QUALITY * self.p.aspect_min, self.quality(p, q, r))
            m = self._metric(p, q, r)
            if min(self._quality_uv(m, self.uv[p], mid, self.uv[r]),
                   self._quality_uv(m, mid, self.uv[q], self.uv[r])) < floor:
                return False
        return True

    # -- split -------------------------------------------------------------------------------
    def _midpoint_vertex(self, a, b, boundary):
        """Append a vertex at the material midpoint of (a, b) with the means of the ends' x, v
        and metric, unpinned (its pin target where it is); returns its index. Its parents go
        to ``split_parents`` for ``transfer_vertex_data``."""
        m = len(self.uv)
        self.split_parents.append((a, b))
        mid = lambda arr: [0.5 * (s + t) for s, t in zip(arr[a], arr[b])]
        self.uv.append(mid(self.uv))
        self.x.append(mid(self.x))
        self.v.append(mid(self.v))
        self.M.append(mid(self.M))
        self.pinned.append(False)
        self.pin_target.append(list(self.x[m]))
        self.frozen.append(False)
        self.keep.append(False)
        self.alive.append(True)
        self.bnd.append(boundary)
        self.vf.append(set())
        return m

    def split(self, a, b):
        """Insert a vertex at the material midpoint of edge (a, b); each face beside the edge
        becomes two. Always valid: the halves of a valid triangle are valid. Returns the new
        vertex and the opposite vertices."""
        fs = self.edge_faces(a, b)
        m = self._midpoint_vertex(a, b, len(fs) == 1)
        opp = []
        for f in fs:
            p, q, r = self.around_edge(f, a, b)
            self.set_face(f, [p, m, r])
            g = self.add_face([m, q, r], self.origin[f])
            self.vf[q].discard(f)
            self.vf[q].add(g)
            self.vf[r].add(g)
            self.vf[m].update((f, g))
            opp.append(r)
        self.n_split += 1
        return m, opp

    # -- flip --------------------------------------------------------------------------------
    def flip_wanted(self, a, b, c, d):
        """Anisotropic Delaunay test for interior edge (a, b) with faces (a, b, c) and
        (b, a, d): flip when the two angles facing the edge, measured in the metric averaged
        over the four vertices, sum to more than pi, i.e. sin(alpha_c + alpha_d) < 0."""
        m = [sum(self.M[t][s] for t in (a, b, c, d)) for s in range(3)]
        ua, ub, uc, ud = self.uv[a], self.uv[b], self.uv[c], self.uv[d]

        def dot(p, q):
            return m[0] * p[0] * q[0] + m[1] * (p[0] * q[1] + p[1] * q[0]) + m[2] * p[1] * q[1]

        pc, qc = (ua[0] - uc[0], ua[1] - uc[1]), (ub[0] - uc[0], ub[1] - uc[1])
        pd, qd = (ub[0] - ud[0], ub[1] - ud[1]), (ua[0] - ud[0], ua[1] - ud[1])
        sdet = math.sqrt(max(m[0] * m[2] - m[1] * m[1], 0.0))
        sin_c, cos_c = sdet * _cross2(*pc, *qc), dot(pc, qc)
        sin_d, cos_d = sdet * _cross2(*pd, *qd), dot(pd, qd)
        norm = math.sqrt(dot(pc, pc) * dot(qc, qc) * dot(pd, pd) * dot(qd, qd))
        return sin_c * cos_d + cos_c * sin_d < -_FLIP_EPS * norm

    def flip_quad(self, a, b):
        """(f0, f1, c, d) for an interior edge with faces f0 = (a, b, c), f1 = (b, a, d)."""
        fs = self.edge_faces(a, b)
        if len(fs) != 2:
            return None
        f0, f1 = fs
        if self.rotate_to(self.faces[f0], a)[1] != b:
            f0, f1 = f1, f0
        return f0, f1, self.rotate_to(self.faces[f0], a)[2], self.rotate_to(self.faces[f1], b)[2]

    def flip(self, a, b):
        """Replace edge (a, b) by (c, d) if the result is valid in material and world space."""
        quad = self.flip_quad(a, b) if a != b else None
        if quad is None:
            return False
        f0, f1, c, d = quad
        if c == d or self.edge_faces(c, d):          # (c, d) already an edge: non-manifold
            return False
        if not (self.area_ok(a, d, c) and self.area_ok(d, b, c)):
            return False
        # World space: neither new triangle may face against the old pair.
        x = self.x
        n_old = [s + t for s, t in zip(_normal(x[a], x[b], x[c]), _normal(x[b], x[a], x[d]))]
        if _dot3(_normal(x[a], x[d], x[c]), n_old) <= 0 or \
                _dot3(_normal(x[d], x[b], x[c]), n_old) <= 0:
            return False
        # Nor deform the patch (``_STRETCH_GUARD``: a flip across a fold cuts it).
        if not self.undeformed_enough([self.stretch_error(a, d, c),
                                       self.stretch_error(d, b, c)], (f0, f1)):
            return False
        self.set_face(f0, [a, d, c])
        self.set_face(f1, [d, b, c])
        self.vf[b].discard(f0)
        self.vf[a].discard(f1)
        self.vf[d].add(f0)
        self.vf[c].add(f1)
        self.n_flip += 1
        return True

    # -- collapse ----------------------------------------------------------------------------
    def boundary_collapse_ok(self, a, b, fs):
        """A boundary vertex may only slide along a boundary edge onto a neighbour, and only
        where the boundary is straight through it (not a corner), so the boundary polygon
        stays the same."""
        if len(fs) != 1:
            return False
        others = [n for n in self.neighbours(a) if n != b and len(self.edge_faces(a, n)) == 1]
        if len(others) != 1:                 # not a simple boundary vertex
            return False
        pa, pb, pc = self.uv[a], self.uv[b], self.uv[others[0]]
        bx, by, cx, cy = pb[0] - pa[0], pb[1] - pa[1], pc[0] - pa[0], pc[1] - pa[1]
        lb, lc = math.hypot(bx, by), math.hypot(cx, cy)
        return abs(_cross2(bx, by, cx, cy)) <= _COLLINEAR_EPS * lb * lc and bx * cx + by * cy < 0

    def _replace_faces(self, gone, changed, v):
        """A collapse's edit: drop the faces ``gone`` (those on the collapsed edge) and turn
        each (f, q, r) of ``changed`` into the face (v, q, r)."""
        for f in gone:
            for t in self.faces[f]:
                self.vf[t].discard(f)
            self.set_face(f, None)
        for f, q, r in changed:
            self.set_face(f, [v, q, r])
            self.vf[v].add(f)

    def collapse(self, a, b):
        """Remove vertex a by merging it into b, if that keeps the mesh manifold, keeps the
        boundary, creates no edge longer than ``_collapse_limit`` in the metric, no triangle
        worse than aspect_min, and inverts no triangle in material or world space."""
        if a == b or self.keep[a] or not self.alive[a]:
            return False
        fs = self.edge_faces(a, b)
        if not fs:
            return False
        if self.bnd[a] and not self.boundary_collapse_ok(a, b, fs):
            return False
        # Link condition: a and b may share only the vertices opposite their edge.
        na = self.neighbours(a)
        opp = {t for f in fs for t in self.faces[f]} - {a, b}
        if na & self.neighbours(b) != opp:
            return False
        limit = _collapse_limit(self.p, self.metric_len2(a, b))
        for n in na - opp - {b}:
            if self.metric_len2(b, n) > limit:
                return False
        x = self.x
        changed = []
        for f in self.vf[a] - fs:
            _, q, r = self.rotate_to(self.faces[f], a)
            if not self.area_ok(b, q, r) or self.quality(b, q, r) < self.p.aspect_min:
                return False
            if _dot3(_normal(x[a], x[q], x[r]), _normal(x[b], x[q], x[r])) <= 0:
                return False
            changed.append((f, q, r))
        if not self.undeformed_enough([self.stretch_error(b, q, r) for _, q, r in changed],
                                      self.vf[a]):
            return False
        # Apply: drop the faces on the edge, re-point a's other faces to b.
        self._replace_faces(fs, changed, b)
        self.vf[a] = set()
        self.alive[a] = False
        self.n_collapse += 1
        self.touched.update(na)
        return True


    def collapse_to_midpoint(self, a, b):
        """Replace both ends of edge (a, b) by one new vertex at its material midpoint (made as
        a split makes one: ``_midpoint_vertex``), if neither end is pinned or frozen, the
        boundary keeps its polygon (an interior edge, or a boundary edge whose ends both lie
        where the boundary is straight), the mesh stays manifold, and no edge from the new
        vertex is longer than ``_collapse_limit``, no triangle worse than aspect_min and none
        inverted in material or world space.

        Why besides ``collapse``: merging a into b moves every edge of a to b, so in a mesh of
        edges L it makes edges up to 2 L (to the neighbour of a opposite b); the midpoint
        makes them up to about 1.5 L. A mesh refined for a metric that then relaxes (a landing
        refines, the sheet comes to rest) has edges of 0.5-0.7 in the relaxed metric, which
        merges can never coarsen under the collapse limit and midpoint collapses can."""
        if a == b or self.keep[a] or self.keep[b] or not (self.alive[a] and self.alive[b]):
            return False
        fs = self.edge_faces(a, b)
        if not fs:
            return False
        if (self.bnd[a] or self.bnd[b]) and not (self.boundary_collapse_ok(a, b, fs)
                                                 and self.boundary_collapse_ok(b, a, fs)):
            return False
        na, nb = self.neighbours(a), self.neighbours(b)
        opp = {t for f in fs for t in self.faces[f]} - {a, b}
        if na & nb != opp:
            return False
        ma, mb = self.M[a], self.M[b]
        mm = [0.5 * (s + t) for s, t in zip(ma, mb)]
        um = [0.5 * (s + t) for s, t in zip(self.uv[a], self.uv[b])]
        limit = _collapse_limit(self.p, self.metric_len2(a, b))
        for n in (na | nb) - {a, b}:
            mn, du, dv = self.M[n], self.uv[n][0] - um[0], self.uv[n][1] - um[1]
            if 0.5 * ((mn[0] + mm[0]) * du * du + 2 * (mn[1] + mm[1]) * du * dv
                      + (mn[2] + mm[2]) * dv * dv) > limit:
                return False
        x = self.x
        xm = [0.5 * (s + t) for s, t in zip(x[a], x[b])]
        changed = []
        for end in (a, b):
            for f in self.vf[end] - fs:
                _, q, r = self.rotate_to(self.faces[f], end)
                pq, pr = self.uv[q], self.uv[r]
                ax, ay, bx, by = pq[0] - um[0], pq[1] - um[1], pr[0] - um[0], pr[1] - um[1]
                longest = max(ax * ax + ay * ay, bx * bx + by * by,
                              (pr[0] - pq[0]) ** 2 + (pr[1] - pq[1]) ** 2)
                if _cross2(ax, ay, bx, by) <= _AREA_REL_EPS * longest:
                    return False
                mf = [(mm[c] + self.M[q][c] + self.M[r][c]) / 3.0 for c in range(3)]
                if self._quality_uv(mf, um, pq, pr) < self.p.aspect_min:
                    return False
                if _dot3(_normal(x[end], x[q], x[r]), _normal(xm, x[q], x[r])) <= 0:
                    return False
                changed.append((f, q, r))
        if not self.undeformed_enough([_stretch_error(um, self.uv[q], self.uv[r], xm, x[q], x[r])
                                       for _, q, r in changed], self.vf[a] | self.vf[b]):
            return False
        m = self._midpoint_vertex(a, b, len(fs) == 1)
        self._replace_faces(fs, changed, m)
        self.vf[a], self.vf[b] = set(), set()
        self.alive[a] = self.alive[b] = False
        self.n_collapse += 1
        self.touched.update(na | nb | {m})
        self.touched -= {a, b}
        return True


# ---------------------------------------------------------------------------------------------
# Phases (candidate lists in numpy, operations in a Python loop)
# ---------------------------------------------------------------------------------------------
def _edge_len2(uv, M, a, b):
    """Metric length^2 of edges (a, b) (index arrays), metric averaged over the two ends.
    Gathers from contiguous columns: several times faster than gathering (N, 2) rows."""
    u, v, m0, m1, m2 = (np.ascontiguousarray(c) for c in (uv[:, 0], uv[:, 1], M[:, 0],
                                                          M[:, 1], M[:, 2]))
    # Native-width indices: ``take`` converts any other width on every call (ten times here;
    # measured at 4k faces: 11 ms per call on the collapse candidates' 80k pairs from int32).
    a, b = np.asarray(a, np.intp), np.asarray(b, np.intp)
    du, dv = u.take(b) - u.take(a), v.take(b) - v.take(a)
    return 0.5 * ((m0.take(a) + m0.take(b)) * du * du + 2 * (m1.take(a) + m1.take(b)) * du * dv
                  + (m2.take(a) + m2.take(b)) * dv * dv)


def _split_phase(w, max_ops):
    """Split every edge longer than 1 in the metric, longest first; halves still too long
    go back on the heap, so one call refines by as many levels as needed."""
    _, ev, _, _, uv, Mv, _ = w.snapshot()
    l2 = _edge_len2(uv, Mv, ev[:, 0], ev[:, 1])
    long = np.flatnonzero(l2 > 1.0)
    heap = [(-l2[e], int(ev[e, 0]), int(ev[e, 1])) for e in long]
    heapq.heapify(heap)
    while heap and w.n_split < max_ops:
        _, a, b = heapq.heappop(heap)
        if not w.edge_faces(a, b) or not w.split_ok(a, b):
            continue
        m, opp = w.split(a, b)
        for n in (a, b, *opp):
            l2n = w.metric_len2(m, n)
            if l2n > 1.0:
                heapq.heappush(heap, (-l2n, m, n))


def _flip_wanted_np(uv, Mv, a, b, c, d):
    """Vectorised ``_Work.flip_wanted`` for arrays of quads (same test, same margin). Written on
    coordinate columns gathered with ``take``: gathering (N, 2) and (N, 3) rows cost several
    times as much (the remesh check runs it over every interior edge each frame)."""
    a, b, c, d = (np.asarray(q, np.intp) for q in (a, b, c, d))
    m0, m1, m2 = (np.ascontiguousarray(Mv[:, r]) for r in range(3))
    m0, m1, m2 = ((col.take(a) + col.take(b) + col.take(c) + col.take(d)) for col in (m0, m1, m2))
    u, v = np.ascontiguousarray(uv[:, 0]), np.ascontiguousarray(uv[:, 1])
    ua, ub, uc, ud = u.take(a), u.take(b), u.take(c), u.take(d)
    va, vb, vc, vd = v.take(a), v.take(b), v.take(c), v.take(d)
    pc, qc, pd, qd = (ua - uc, va - vc), (ub - uc, vb - vc), (ub - ud, vb - vd), (ua - ud, va - vd)

    def dot(p, q):
        return m0 * p[0] * q[0] + m1 * (p[0] * q[1] + p[1] * q[0]) + m2 * p[1] * q[1]

    def cross(p, q):
        return p[0] * q[1] - p[1] * q[0]

    sdet = np.sqrt(np.maximum(m0 * m2 - m1 ** 2, 0.0))
    val = sdet * (cross(pc, qc) * dot(pd, qd) + dot(pc, qc) * cross(pd, qd))
    norm = np.sqrt(dot(pc, pc) * dot(qc, qc) * dot(pd, pd) * dot(qd, qd))
    return val < -_FLIP_EPS * norm


def _stretch_error_np(uv, x, faces):
    """``_stretch_error`` of every face (F, 3) at once (``metrics.singular_values``); inf for a
    face degenerate in material space."""
    e, f = uv[faces[:, 1]] - uv[faces[:, 0]], uv[faces[:, 2]] - uv[faces[:, 0]]
    det = e[:, 0] * f[:, 1] - e[:, 1] * f[:, 0]
    ok = det != 0.0
    inv = np.stack([np.stack([f[:, 1], -f[:, 0]], 1), np.stack([-e[:, 1], e[:, 0]], 1)], 1)
    inv /= np.where(ok, det, 1.0)[:, None, None]
    eta = metrics.singular_values(metrics.deformation_gradients(x, faces, inv))
    return np.where(ok, np.abs(eta - 1.0).max(axis=1), np.inf)


def _flip_allowed_np(uv, x, a, b, c, d):
    """Vectorised stretch guard of ``_Work.flip``: the new pair (a, d, c), (d, b, c) no more
    deformed than ``_STRETCH_GUARD`` allows or than the pair (a, b, c), (b, a, d) it replaces."""
    err = lambda i, j, k: _stretch_error_np(uv, x, np.stack([i, j, k], axis=1))
    new = np.maximum(err(a, d, c), err(d, b, c))
    old = np.maximum(err(a, b, c), err(b, a, d))
    return new <= np.maximum(_STRETCH_GUARD, old)


def _flip_phase(w, max_rounds=8):
    """Flip interior edges that fail the anisotropic Delaunay test (found for the whole mesh
    at once), then recheck the four edges around each flip; the margin in the test makes this
    terminate on co-circular grids.

    A flip never brings back an edge this phase has flipped away. With one fixed metric that
    cannot happen anyway (a Delaunay flip sequence never re-creates an edge it removed), but
    each quad is judged in the metric averaged over its own four vertices, so a ring of
    nearly co-circular vertices can cycle through its triangulations: in the drape scene five
    edges of a pentagon were flipped ~2600 times each in one call, until the budget ran out.
    Refusing re-created edges makes every phase finite; the budget stays as a backstop."""
    faces, ev, ef, eo, uv, Mv, _ = w.snapshot()
    inner = np.flatnonzero(ef[:, 1] >= 0)
    a, b, c, d = ev[inner, 0], ev[inner, 1], eo[inner, 0], eo[inner, 1]
    bad = _flip_wanted_np(uv, Mv, a, b, c, d)
    queue = list(zip(a[bad].tolist(), b[bad].tolist()))
    budget = max_rounds * (len(queue) + 1) + len(faces)
    removed = set()                  # edges (low, high) flipped away in this phase
    while queue and budget > 0:
        a, b = queue.pop()
        budget -= 1
        quad = w.flip_quad(a, b)
        if quad is None:
            continue
        c, d = quad[2], quad[3]
        if (min(c, d), max(c, d)) in removed:
            continue
        if w.flip_wanted(a, b, c, d) and w.flip(a, b):
            removed.add((min(a, b), max(a, b)))
            queue.extend(((a, c), (c, b), (b, d), (d, a)))


def _collapse_limit(params, own2):
    """Largest squared metric length of the edges that collapsing an edge of squared metric
    length ``own2`` may create (``own2`` a float or an array).

    The margin below the split threshold 1 is a hysteresis against split/collapse cycles: the
    halves of an edge split because it was longer than 1 are each at least 1/2 long, and
    collapsing one would re-create the split edge. Keeping every collapse under 1 - margin
    stops that, but it also caps coarsening: greedy collapses jam with the edges spread over
    roughly half to all of the limit, so a flat sheet stalled at a mean edge of about
    0.6 x size_max. An edge shorter than (1 - margin) / 2, though, cannot be such a half unless
    the metric has coarsened by more than the margin since the split, the same condition the
    margin asks for; so collapsing it may create edges up to the split threshold itself (never
    longer, or the next split pass would undo it)."""
    keep = (1.0 - params.collapse_margin) ** 2
    if np.ndim(own2) == 0:                   # one edge, from _Work.collapse
        return 1.0 if own2 <= 0.25 * keep else keep
    return np.where(own2 <= 0.25 * keep, 1.0, keep)


def _collapse_candidates(w, only=None):
    """Directed edges (a -> b) worth trying, in sweep order (below): a removable, the edge
    itself shorter than the collapse limit (a longer edge would leave longer ones behind) and
    every new edge (b, n) to a's other neighbours n short enough (``_collapse_limit`` of the
    collapsed edge's length). Computed for all edges at once; the exact check is redone per
    collapse since earlier collapses change the neighbourhoods.
    ``only``: optional vertex mask restricting which vertices a are tried."""
    _, ev, _, eo, uv, Mv, keep = w.snapshot()
    limit = (1.0 - w.p.collapse_margin) ** 2
    own = _edge_len2(uv, Mv, ev[:, 0], ev[:, 1])
    # Directed edges a -> b, grouped by a (CSR), with the vertices opposite the edge.
    src = np.concatenate([ev[:, 0], ev[:, 1]])
    order = np.argsort(src, kind="stable")
    src = src[order]
    dst = np.concatenate([ev[:, 1], ev[:, 0]])[order]
    opp = np.concatenate([eo, eo])[order]
    own = np.concatenate([own, own])[order]
    deg = np.bincount(src, minlength=len(uv))
    start = np.cumsum(deg) - deg
    try_a = ~keep if only is None else ~keep & only
    cand = np.flatnonzero(try_a[src] & (own <= limit))
    if len(cand) == 0:
        return []
    # Expand every candidate (a -> b) over the neighbours n of a.
    a, b = src[cand], dst[cand]
    reps = deg[a]
    first = np.cumsum(reps) - reps
    pair = np.repeat(np.arange(len(cand)), reps)
    n = dst[start[a[pair]] + np.arange(reps.sum()) - first[pair]]
    bp, op = b[pair], opp[cand][pair]
    l2 = _edge_len2(uv, Mv, bp, n)
    # Edges (b, n) that exist already (n == b, or n opposite the edge) are not new.
    l2[(n == bp) | (n == op[:, 0]) | (n == op[:, 1])] = 0.0
    sel = np.flatnonzero(np.maximum.reduceat(l2, first) <= _collapse_limit(w.p, own[cand]))
    # Order: a sweep across the sheet (by u, then v), and for each vertex a its shortest edge
    # first. Greedy collapses jam once every remaining one would create a too-long edge; made
    # in no spatial order (shortest-first is that on a near-uniform mesh) they jam early, with
    # gaps of anything between half and all of the limit. Sweeping, each collapse is made next
    # to the ones before it, which packs the vertices closer to the limit (as in 1D, where a
    # left-to-right sweep leaves every gap at the limit): a flat sheet's mean edge ends 3-9 %
    # longer than with shortest-first (tests/test_remesh.py, flat sheet).
    sel = sel[np.lexsort((own[cand][sel], uv[a[sel], 1], uv[a[sel], 0]))]
    return list(zip(a[sel].tolist(), b[sel].tolist()))


def _midpoint_candidates(w, only=None):
    """Edges (a, b) worth collapsing to their midpoint, in sweep order (by the midpoint's u,
    then v, then length): neither end kept, the edge shorter than the collapse limit, and every
    edge from the midpoint to the ends' neighbours short enough (``_collapse_limit``, the
    midpoint's metric the mean of the ends'), computed for all edges at once; the exact check
    is redone per collapse. ``only``: optional vertex mask, an edge tried if either end is in."""
    _, ev, _, eo, uv, Mv, keep = w.snapshot()
    limit = (1.0 - w.p.collapse_margin) ** 2
    own = _edge_len2(uv, Mv, ev[:, 0], ev[:, 1])
    ok = (own <= limit) & ~keep[ev[:, 0]] & ~keep[ev[:, 1]]
    if only is not None:
        ok &= only[ev[:, 0]] | only[ev[:, 1]]
    cand = np.flatnonzero(ok)
    if len(cand) == 0:
        return []
    # Neighbours of each vertex (CSR over the directed edges), expanded over both ends.
    src = np.concatenate([ev[:, 0], ev[:, 1]])
    order = np.argsort(src, kind="stable")
    dst = np.concatenate([ev[:, 1], ev[:, 0]])[order]
    deg = np.bincount(src, minlength=len(uv))
    start = np.cumsum(deg) - deg
    ends = np.concatenate([ev[cand, 0], ev[cand, 1]])
    owner = np.concatenate([np.arange(len(cand))] * 2)
    reps = deg[ends]
    first = np.cumsum(reps) - reps
    pair = np.repeat(np.arange(len(ends)), reps)
    n = dst[start[ends[pair]] + np.arange(reps.sum()) - first[pair]]
    e = cand[owner[pair]]
    a, b = ev[e, 0], ev[e, 1]
    mid = 0.5 * (uv[a] + uv[b])
    mm = 0.5 * (Mv[a] + Mv[b])
    d = uv[n] - mid
    m2 = 0.5 * (mm + Mv[n])
    l2 = m2[:, 0] * d[:, 0] ** 2 + 2 * m2[:, 1] * d[:, 0] * d[:, 1] + m2[:, 2] * d[:, 1] ** 2
    l2[(n == a) | (n == b)] = 0.0
    worst = np.zeros(len(cand))
    np.maximum.at(worst, owner[pair], l2)
    sel = cand[worst <= _collapse_limit(w.p, own[cand])]
    mid = 0.5 * (uv[ev[sel, 0]] + uv[ev[sel, 1]])
    sel = sel[np.lexsort((own[sel], mid[:, 1], mid[:, 0]))]
    return list(zip(ev[sel, 0].tolist(), ev[sel, 1].tolist()))


def _collapse_phase(w):
    """Collapse rounds: the first tries every vertex, later ones only the vertices around
    the collapses of the round before (nothing else changed). In each round, merges of one
    end into the other first (they keep a vertex where it is), then collapses to the midpoint
    of the edges whose merges were all refused (``_Work.collapse_to_midpoint``)."""
    only = None
    for _ in range(w.p.collapse_rounds):
        w.touched = set()
        for a, b in _collapse_candidates(w, only):
            w.collapse(a, b)
        if only is not None:
            only = np.concatenate([only, np.zeros(len(w.uv) - len(only), bool)])
        for a, b in _midpoint_candidates(w, only):
            w.collapse_to_midpoint(a, b)
        if not w.touched:
            break
        only = np.zeros(len(w.uv), dtype=bool)
        only[list(w.touched)] = True


# ---------------------------------------------------------------------------------------------
# Entry point
# ---------------------------------------------------------------------------------------------
def _check_input(mesh, frozen, face_data):
    nv, nf = len(mesh.uv), len(mesh.faces)
    if nf == 0 or mesh.faces.min() < 0 or mesh.faces.max() >= nv:
        raise ModelError("remesh needs faces that index existing vertices")
    if np.any(signed_material_areas(mesh.uv, mesh.faces) <= 0):
        raise ModelError("remesh needs every face counter-clockwise in material space with "
                         "area > 0; fix the input triangulation")
    if not (np.all(np.isfinite(mesh.uv)) and np.all(np.isfinite(mesh.x))
            and np.all(np.isfinite(mesh.v))):
        raise ModelError("remesh input has NaN/inf in uv, x or v: fix the step that made them")
    if frozen.shape != (nv,):
        raise ModelError(f"frozen_verts must be a bool mask of length {nv}")
    for name, arr in (face_data or {}).items():
        if len(arr) != nf:
            raise ModelError(f"face_data['{name}'] has {len(arr)} rows, the mesh {nf} faces")


def _export(w, mesh, face_data):
    """Compact the work mesh into MeshArrays (dead vertices and faces dropped)."""
    faces = w.faces_array()
    origin = np.array(w.origin)[[t is not None for t in w.faces]]
    alive_v = np.array(w.alive)
    new_id = -np.ones(len(alive_v), dtype=np.int64)
    new_id[alive_v] = np.arange(alive_v.sum())
    n0 = len(mesh.uv)

    def rows(orig, lst):
        # Rows of input vertices never change: only the new ones come from the Python lists.
        new = np.array(lst[n0:], dtype=orig.dtype).reshape((-1,) + orig.shape[1:])
        return np.concatenate([orig, new])[alive_v]

    out = MeshArrays(uv=w.snapshot()[4][alive_v], x=rows(mesh.x, w.x),
                     faces=new_id[faces], v=rows(mesh.v, w.v),
                     pinned=rows(mesh.pinned, w.pinned),
                     pin_target=rows(mesh.pin_target, w.pin_target),
                     grain=mesh.grain[origin], extras=dict(mesh.extras))
    data = {name: np.asarray(arr)[origin] for name, arr in (face_data or {}).items()}
    return out, data


def mesh_sizing(mesh, params, obstacle_distance=None, edges=None):
    """The vertex sizing metric (V, 2, 2) a remesh of ``mesh`` works with (``remesh`` takes it
    as ``sizing``). ``edges``: ``build_edges(mesh.faces)`` if the caller has it already."""
    face_M, area = _face_metric(mesh, params, obstacle_distance, edges)
    return _stacked(_vertex_sizing(face_M, area, mesh.faces, len(mesh.uv), params))


def pending_operations(mesh, Mv, frozen_verts=None, edges=None):
    """What a remesh of ``mesh`` in the sizing ``Mv`` would start from, counted over the whole
    mesh at once without making any operation (numpy, a few passes over the edges): the
    edges longer than 1 in the metric (not between two frozen vertices), which the split
    pass splits, plus the interior edges failing the anisotropic Delaunay test whose flip
    the stretch guard allows, which the flip pass flips (a refused flip counted here would
    be pending for ever: every frame's remesh made, then deferred). Collapses are not
    counted (the candidates' exact check is per edge).
    Measured on hanging (mapping, ~900 faces, frames 1-40): the split count equals the
    remesh's splits in every frame; the flips counted are 0.3-1 times its flips (splits set
    off more). ``Simulator._remesh`` defers a remesh by this count without making it."""
    ev, ef, eo = build_edges(mesh.faces) if edges is None else edges
    uv = mesh.uv
    M3 = np.stack([Mv[:, 0, 0], Mv[:, 0, 1], Mv[:, 1, 1]], axis=1)
    long = _edge_len2(uv, M3, ev[:, 0], ev[:, 1]) > 1.0
    if frozen_verts is not None:
        frozen = np.asarray(frozen_verts, bool)
        long &= ~(frozen[ev[:, 0]] & frozen[ev[:, 1]])
    inner = np.flatnonzero(ef[:, 1] >= 0)
    a, b, c, d = ev[inner, 0], ev[inner, 1], eo[inner, 0], eo[inner, 1]
    bad = _flip_wanted_np(uv, M3, a, b, c, d)
    bad[bad] &= _flip_allowed_np(uv, mesh.x, a[bad], b[bad], c[bad], d[bad])
    return int(np.count_nonzero(long)) + int(np.count_nonzero(bad))


def remesh(mesh: MeshArrays, params: RemeshParams = None, obstacle_distance=None,
           face_data=None, frozen_verts=None, max_splits=None, sizing=None, edges=None):
    """One remeshing pass. Returns (new MeshArrays, new face_data dict, stats dict).

    obstacle_distance: optional callable, (N, 3) world points -> (N,) signed distances.
    face_data: optional dict name -> (F, k) per-face arrays; each new face copies the row of
        the input face it was cut from.
    frozen_verts: optional (V,) bool; these vertices (and pinned ones) are never removed or
        moved, and an edge between two frozen vertices is never split (keeps seams intact).
    max_splits: safety cap on splits per call (default 4 x the input vertex count + 1000).
    sizing: the vertex metric (``mesh_sizing(mesh, params, obstacle_distance)``) if the caller has
        computed it already; edges: ``build_edges(mesh.faces)`` likewise.
    ``mesh.extras`` is passed through unchanged (it is not transferred per vertex).
    stats: counts ``splits``, ``flips``, ``collapses``, ``faces_in/out``, ``verts_in/out``
    and times ``ms_sizing``, ``ms_ops``, ``ms`` (wall clock) and ``ms_cpu`` (process time)."""
    t0, c0 = time.perf_counter(), time.process_time()
    params = params or RemeshParams()
    params.validate()
    nv = len(mesh.uv)
    frozen = np.zeros(nv, dtype=bool) if frozen_verts is None else \
        np.asarray(frozen_verts, dtype=bool)
    _check_input(mesh, frozen, face_data)

    edges = build_edges(mesh.faces) if edges is None else edges
    Mv = mesh_sizing(mesh, params, obstacle_distance, edges) if sizing is None else \
        np.asarray(sizing, np.float64)
    t1 = time.perf_counter()

    w = _Work(mesh, Mv, frozen, params, edges)
    _split_phase(w, max_splits if max_splits is not None else 4 * nv + 1000)
    _flip_phase(w)
    _collapse_phase(w)
    if w.n_collapse:              # otherwise the mesh is as the first flip pass left it
        _flip_phase(w)
    out, data = _export(w, mesh, face_data)
    t2 = time.perf_counter()
    stats = dict(splits=w.n_split, flips=w.n_flip, collapses=w.n_collapse,
                 faces_in=len(mesh.faces), faces_out=len(out.faces),
                 verts_in=nv, verts_out=len(out.uv),
                 ms_sizing=1e3 * (t1 - t0), ms_ops=1e3 * (t2 - t1), ms=1e3 * (t2 - t0),
                 ms_cpu=1e3 * (time.process_time() - c0))
    # Where each input vertex went (-1: collapsed away), so callers can remap vertex-indexed
    # data such as stitch pairs. Frozen and pinned vertices always survive.
    alive = np.array(w.alive)
    new_id = -np.ones(len(alive), dtype=np.int64)
    new_id[alive] = np.arange(alive.sum())
    stats["vertex_map"] = new_id[:nv]
    # What ``transfer_vertex_data`` needs: the parents of every split vertex (indices into
    # the input vertices followed by the split vertices in order) and, per output vertex, its
    # index there.
    stats["split_parents"] = np.array(w.split_parents, np.int64).reshape(-1, 2)
    stats["vertex_source"] = np.flatnonzero(alive)
    return out, data, stats


def transfer_vertex_data(values, stats):
    """Per-vertex data of a remesh's input (V_in, ...) carried to its output the way x and v
    are: unchanged on the vertices that survive, the mean of the edge's two ends at every
    vertex a split made (exact for data linear in material space). ``stats``: the remesh's."""
    values = np.asarray(values)
    parents, n_in = stats["split_parents"], int(stats["verts_in"])
    if len(values) != n_in:
        raise ModelError(f"vertex data has {len(values)} rows, the remeshed mesh had {n_in}")
    ext = np.empty((n_in + len(parents),) + values.shape[1:], np.result_type(values, 0.5))
    ext[:n_in] = values
    for k, (a, b) in enumerate(parents.tolist()):    # a split's ends may be earlier splits
        ext[n_in + k] = 0.5 * (ext[a] + ext[b])
    return ext[stats["vertex_source"]]
