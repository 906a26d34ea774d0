"""The constraints' exact curvature in the Newton matrix, on the host (an experiment of #13).

The Newton matrix of the AL (``al.newton_matrix``, used by both Newton paths) models the
curvature of each active constraint as that of ``sqrt(a) ||F e||`` with the direction e frozen
(``constraints.py``: kappa, cm, what; svd adds its twist term). For the mapping family that
misses the terms of the rotating principal frame (c_ij = |e_i . v_j| turns with F as
1 / (eta1^2 - eta2^2), and the isotropy closure adds 1 / iso^2 terms). Measured on ``hanging``
res 25 after 60 frames (``python -m benchmarks.curvature``): along the Newton direction the
residual's finite difference is ~70x the model's H d for mapping, within 1 % for svd.

This module replaces the model by the exact curvature, made positive semi-definite per face:
    H_f = PSD( sum_c s_c  d2 g_c / dx2 ),   s_c = max(0, lam_c + mu g_c),
with d2 g_c from central differences of the analytic gradients (``constraints.evaluate``) and
PSD by clamping the 9x9 eigenvalues at zero. It runs in numpy on the faces with an active
constraint, for the Cholesky path only (``StrainLimiter.exact_curvature``), and is slow (18
gradient evaluations of every active face per Newton step): it measures what an exact Newton
matrix buys, before anyone writes the analytic Hessian into the kernels.
"""
import numpy as np

from . import constraints
from .c_curvature import C_STEP_F64

# Central-difference step of the gradients (m): the positions are O(1 m) and the gradients'
# round-off ~1e-16, so 1e-6 m leaves ~1e-10 relative error from round-off and ~1e-12 from the
# third derivative on 1 cm triangles; it does not cross kinks of |e.v| except within 1e-6 m.
FD_STEP = 1e-6


def face_hessians(method, X, Dm_inv, grain, area, weights, bands, delta, iso, step=FD_STEP):
    """sum_c weights[n, c] d2 g_c / dx2 for each face n, (n, 9, 9), symmetrised. X (n, 3, 3)
    rows x_i, x_j, x_k; bands = (warp, weft, shear) as the solver passes them."""
    n = len(X)
    out = np.zeros((n, 9, 9))
    warp, weft, shear = bands
    for k in range(9):
        plus, minus = X.copy(), X.copy()
        plus[:, k // 3, k % 3] += step
        minus[:, k // 3, k % 3] -= step
        _, g_plus = constraints.evaluate(method, plus, Dm_inv, grain, area, warp, weft, shear,
                                         delta=delta, by_alignment=constraints.MAPPING_PAIRS_BY_ALIGNMENT, iso=iso)
        _, g_minus = constraints.evaluate(method, minus, Dm_inv, grain, area, warp, weft,
                                          shear, delta=delta, by_alignment=constraints.MAPPING_PAIRS_BY_ALIGNMENT, iso=iso)
        out[:, :, k] = np.einsum("nc,ncm->nm", weights, (g_plus - g_minus) / (2.0 * step))
    return 0.5 * (out + out.transpose(0, 2, 1))


def psd(H):
    """Each symmetric block of H (n, k, k) with its negative eigenvalues set to zero."""
    w, Q = np.linalg.eigh(H)
    return np.einsum("nij,nj,nkj->nik", Q, np.maximum(w, 0.0), Q)


def add_to_newton_matrix(lim, method, K, mu, metric, mode="split"):
    """Add the PSD exact curvature of the active constraints to the Newton matrix ``ws.H``
    that ``direct.newton_system`` filled with the curvature model switched off (kappa and
    twist zero). ``mode`` "full": the 9x9 sum made PSD (``face_hessians``); "split": its two
    parts through C made PSD each (``split_face_hessians``). Pinned rows and columns stay as
    newton_system left them. Returns the number of faces that carry an active constraint."""
    ws, m = lim._ws, lim.model
    nv, nf = m.n_verts, m.n_faces
    lam, g = ws.lam.to_numpy()[:nf, :K], ws.g.to_numpy()[:nf, :K]
    s = np.maximum(lam + mu * g, 0.0)
    faces = np.flatnonzero((s > 0.0).any(axis=1))
    if len(faces) == 0:
        return 0
    fv = m.faces[faces]
    X = ws.x.to_numpy()[:nv][fv]
    bands = (lim.warp, lim.weft, lim.shear_band())
    Dm_inv, grain = ws.Dm_inv.to_numpy()[faces], ws.grain.to_numpy()[faces]
    area = ws.rest_area.to_numpy()[faces]
    if mode == "full":
        blocks = psd(face_hessians(method, X, Dm_inv, grain, area, s[faces], bands,
                                   lim.mapping_delta, lim.mapping_iso))
    else:
        blocks = split_face_hessians(method, X, Dm_inv, grain, area, s[faces], bands,
                                     lim.mapping_iso)
    H = ws.H.to_numpy()
    slot = metric.face_slot.to_numpy()[faces]
    free = ws.pinned.to_numpy()[:nv] == 0
    for a in range(3):
        for b in range(3):
            ok = free[fv[:, a]] & free[fv[:, b]]
            np.add.at(H, slot[ok, 3 * a + b], blocks[ok, 3 * a:3 * a + 3, 3 * b:3 * b + 3])
    ws.H.from_numpy(H)
    return len(faces)


# ---- the same curvature through C = F^T F -------------------------------------------------
# Every family's strains are functions of C = F^T F = [[p, q], [q, r]] alone (they do not see
# rotations), and p, q, r are quadratic in the positions. So with G(p, q, r) a constraint's
# strain, its Hessian splits exactly into
#     d2G/dx2 = sum_k G_k d2C_k/dx2  +  J^T (d2G/dC2) J,       J = dC/dx (3 x 9),
# a 2x2 coefficient matrix [[2 G_p, G_q], [G_q, 2 G_r]] in material space (times I3) and a 3x3
# one, each of which can be made positive semi-definite on its own in closed form. This is the
# form a kernel can afford (no 9x9 eigen-solve); ``split_face_hessians`` computes it.
# The step of the differences in (p, q, r): the kernels' (c_curvature.py).
C_STEP = C_STEP_F64


def mapping_strain_of_c(p, q, r, e, sigma, iso):
    """c~ (eta_sigma - 1) of the mapping family for the material direction e and principal
    pair sigma (+1: v1, -1: v2), from C (constraints.mapping_constraints, written through
    C): with b = (p - r)/2, gap = sqrt(b^2 + q^2) and t = b cos 2phi + q sin 2phi (phi the
    angle of e), c^2 = (1 + sigma t / gap) / 2 and the closure's w t / gap is
    4 gap t / (4 gap^2 + iso^2)."""
    b = 0.5 * (p - r)
    gap = np.sqrt(b * b + q * q)
    t = b * (e[..., 0] ** 2 - e[..., 1] ** 2) + q * 2.0 * e[..., 0] * e[..., 1]
    if iso > 0.0:
        kappa = 4.0 * gap * t / (4.0 * gap * gap + iso * iso)
    else:
        kappa = np.where(gap > 0.0, t / np.where(gap > 0.0, gap, 1.0), 0.0)
    c = np.sqrt(np.maximum(0.5 * (1.0 + sigma * kappa), 0.0))
    eta = np.sqrt(np.maximum(0.5 * (p + r) + sigma * gap, 0.0))
    return c * (eta - 1.0)


def strains_of_c(method, C, grain, bands, iso, C_pairs=None):
    """The K constraint values g / sqrt(a) of each face in the solver's order (mapping pairs
    by alignment with the warp), from C = (p, q, r) of shape (..., 3) and the grain (..., 2, 2).
    ``C_pairs``: the C whose pairing the mapping family keeps (default C itself), so that
    differences around a C do not cross the relabelling."""
    p, q, r = C[..., 0], C[..., 1], C[..., 2]
    warp, weft, shear = bands
    out = []

    def band(value, lo_hi):
        out.extend([lo_hi[0] - value, value - lo_hi[1]])      # lower, upper

    if method == "svd":
        gap = np.sqrt(0.25 * (p - r) ** 2 + q * q)
        band(np.sqrt(np.maximum(0.5 * (p + r) + gap, 0.0)) - 1.0, warp)
        band(np.sqrt(np.maximum(0.5 * (p + r) - gap, 0.0)) - 1.0, weft)
    elif method == "warp-weft":
        e_warp, e_weft = grain[..., :, 0], grain[..., :, 1]
        for e, lo_hi in ((e_warp, warp), (e_weft, weft),
                         (e_warp + e_weft, (shear[0] - 1.0, shear[1] - 1.0))):
            n = np.sqrt(e[..., 0] ** 2 * p + 2.0 * e[..., 0] * e[..., 1] * q + e[..., 1] ** 2 * r)
            band(n - 1.0, lo_hi)
    else:
        e_warp, e_weft = grain[..., :, 0], grain[..., :, 1]
        # Pair A is the principal direction closer to the warp: v1 unless |e_warp.v2| is larger.
        Cp = C if C_pairs is None else C_pairs
        t_warp = 0.5 * (Cp[..., 0] - Cp[..., 2]) * (e_warp[..., 0] ** 2 - e_warp[..., 1] ** 2) \
            + Cp[..., 1] * 2.0 * e_warp[..., 0] * e_warp[..., 1]
        sigma_a = np.where((t_warp < 0.0) & constraints.MAPPING_PAIRS_BY_ALIGNMENT, -1.0, 1.0)
        for e, lo_hi in ((e_warp, warp), (e_weft, weft)):
            for sigma in (sigma_a, -sigma_a):
                s = mapping_strain_of_c(p, q, r, e, sigma, iso)
                out.extend([s - lo_hi[1], lo_hi[0] - s])      # upper, lower
    return np.stack(out, axis=-1)


def c_derivatives(method, C, grain, bands, iso, step=C_STEP):
    """Gradient (n, K, 3) and Hessian (n, K, 3, 3) of ``strains_of_c`` in (p, q, r) by central
    differences (the pairing of the mapping family is frozen at C)."""
    n = len(C)
    K = strains_of_c(method, C[:1], grain[:1], bands, iso).shape[-1]
    grad, hess = np.zeros((n, K, 3)), np.zeros((n, K, 3, 3))
    eye = np.eye(3) * step

    def at(delta):
        return strains_of_c(method, C + delta, grain, bands, iso, C_pairs=C)

    g0 = at(np.zeros(3))
    for i in range(3):
        gp, gm = at(eye[i]), at(-eye[i])
        grad[:, :, i] = (gp - gm) / (2 * step)
        hess[:, :, i, i] = (gp - 2 * g0 + gm) / step ** 2
        for j in range(i + 1, 3):
            pp, pm = at(eye[i] + eye[j]), at(eye[i] - eye[j])
            mp, mm = at(-eye[i] + eye[j]), at(-eye[i] - eye[j])
            hess[:, :, i, j] = hess[:, :, j, i] = (pp - pm - mp + mm) / (4 * step ** 2)
    return grad, hess


def c_and_jacobian(X, Dm_inv):
    """C = (p, q, r) (n, 3), the material rows Mr (n, 3, 2) and J = dC/dx (n, 3, 9)."""
    mj, mk = Dm_inv[:, 0, :], Dm_inv[:, 1, :]
    Mr = np.stack([-mj - mk, mj, mk], axis=1)                 # (n, 3, 2)
    w = np.einsum("nva,nvc->nac", Mr, X)                      # rows w_u, w_v (n, 2, 3)
    w0, w1 = w[:, 0], w[:, 1]
    C = np.stack([(w0 * w0).sum(-1), (w0 * w1).sum(-1), (w1 * w1).sum(-1)], axis=1)

    def spread(coef, vec):                                    # (n, 3) x (n, 3) -> (n, 9)
        return (coef[:, :, None] * vec[:, None, :]).reshape(len(coef), 9)

    m0, m1 = Mr[:, :, 0], Mr[:, :, 1]
    J = np.stack([2.0 * spread(m0, w0), spread(m0, w1) + spread(m1, w0),
                  2.0 * spread(m1, w1)], axis=1)
    return C, Mr, J


def split_face_hessians(method, X, Dm_inv, grain, area, weights, bands, iso, project=True):
    """sum_c weights[n, c] d2 g_c / dx2 per face (n, 9, 9) through C (see above), with
    g = sqrt(a) G(C); ``project`` makes the 2x2 and the 3x3 part each positive
    semi-definite."""
    C, Mr, J = c_and_jacobian(X, Dm_inv)
    dG, d2G = c_derivatives(method, C, grain, bands, iso)
    w = weights * np.sqrt(area)[:, None]
    Gk = np.einsum("nc,nck->nk", w, dG)                       # (n, 3)
    HC = np.einsum("nc,ncij->nij", w, d2G)                    # (n, 3, 3)
    T = np.stack([np.stack([2 * Gk[:, 0], Gk[:, 1]], -1),
                  np.stack([Gk[:, 1], 2 * Gk[:, 2]], -1)], 1)  # (n, 2, 2)
    if project:
        T, HC = psd(T), psd(HC)
    S = np.einsum("nia,nab,njb->nij", Mr, T, Mr)              # (n, 3, 3) over the vertices
    return _kron_i3(S) + np.einsum("nki,nkl,nlj->nij", J, HC, J)


def _kron_i3(S):
    """S (n, 3, 3) over the vertices -> S (x) I3 (n, 9, 9) over the coordinates."""
    return np.einsum("nij,ab->niajb", S, np.eye(3)).reshape(len(S), 9, 9)
