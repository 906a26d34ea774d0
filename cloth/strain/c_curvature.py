"""The constraints' exact curvature in the Newton kernels, through C = F^T F (issue #13).

Every family's strains are functions G(p, q, r) of C = F^T F = [[p, q], [q, r]] alone, and
p, q, r are quadratic in the positions. So the weighted Hessian of a face's active constraints,
sum_c s_c d2 g_c / dx2 (s_c = max(0, lam_c + mu g_c), g_c = sqrt(a) G_c), splits exactly into
    S (x) I3  +  J^T H J,
    S = Mr T Mr^T,  T = [[2 G_p, G_q], [G_q, 2 G_r]],  H = d2G / dC2,  J = dC/dx (3 x 9),
with G_k, H the weighted derivatives of phi = sum_c s_c sqrt(a) G_c. T (2x2) and H (3x3) are
made positive semi-definite on their own (``exact_curvature.py`` checks on the host that this
converges as well as projecting the 9x9 sum; tests/test_exact_curvature.py that the split is
exact). The derivatives of phi in C come from central differences (19 evaluations of closed
forms per face with an active constraint, once per Newton step).

Why: the model of ``constraints.py`` (the curvature of ||F e|| with e frozen) misses the
rotating principal frame of the mapping family, ~35x along the Newton direction, and Newton
then needs 2-3 AL rounds of 5 steps where the exact matrix needs one (docs/speed/curvature.md).

Per face the kernels keep ``curv[f, 0..2]`` (9 numbers each): Mr (3x2) and T; H (6) and a flag;
w_u = F e_u and w_v = F e_v at the iterate.
"""
import taichi as ti

from .constraints import MAPPING_PAIRS_BY_ALIGNMENT, SVD, WARP_WEFT, sym_eig2, shape_rows

# Central-difference step in C (C ~ 1). f64: the mapping closure's curvature ~1/iso^2 = 1e4
# then has ~1e-5 relative error. f32 cannot resolve it; the step there keeps the round-off
# bounded and the matrix is projected anyway.
C_STEP_F64 = 1e-5
C_STEP_F32 = 3e-3


@ti.func
def mapping_strain(p, q, r, e, sigma, iso):
    """c~ (eta_sigma - 1) for material direction e and principal pair sigma (+-1):
    c~^2 = (1 + sigma w t / gap) / 2, w t / gap = 4 gap t / (4 gap^2 + iso^2) (iso = 0: t/gap),
    t = b cos 2phi + q sin 2phi, b = (p - r)/2, gap = sqrt(b^2 + q^2)."""
    b = 0.5 * (p - r)
    gap = ti.sqrt(b * b + q * q)
    t = b * (e[0] * e[0] - e[1] * e[1]) + 2.0 * q * e[0] * e[1]
    kappa = 0.0
    if iso > 0.0:
        kappa = 4.0 * gap * t / (4.0 * gap * gap + iso * iso)
    elif gap > 0.0:
        kappa = t / gap
    c = ti.sqrt(ti.max(0.5 * (1.0 + sigma * kappa), 0.0))
    eta = ti.sqrt(ti.max(0.5 * (p + r) + sigma * gap, 0.0))
    return c * (eta - 1.0)


@ti.func
def _stretch_along(p, q, r, e):
    """||F e|| from C."""
    return ti.sqrt(ti.max(e[0] * e[0] * p + 2.0 * e[0] * e[1] * q + e[1] * e[1] * r, 0.0))


@ti.func
def weighted_strain(method: ti.template(), p, q, r, grain, params_w, weights, sigma_a, iso):
    """phi(C) = sum_c weights[c] G_c(C), G_c the constraint values / sqrt(a) in the solver's
    order (constraints.py; mapping pair A is eta1, or frozen as ``sigma_a`` when pairs go by
    alignment: families.MAPPING_PAIRS_BY_ALIGNMENT).
    params_w = (warp lo, hi, weft lo, hi, shear lo, hi); a band's lower and upper constraints
    are lo - strain and strain - hi."""
    total = 0.0
    if ti.static(method == SVD):
        gap = ti.sqrt(0.25 * (p - r) * (p - r) + q * q)
        for j in ti.static(range(2)):
            sign = 1.0 if j == 0 else -1.0
            strain = ti.sqrt(ti.max(0.5 * (p + r) + sign * gap, 0.0)) - 1.0
            total += weights[2 * j] * (params_w[2 * j] - strain) \
                + weights[2 * j + 1] * (strain - params_w[2 * j + 1])
    elif ti.static(method == WARP_WEFT):
        e_warp = ti.Vector([grain[0, 0], grain[1, 0]])
        e_weft = ti.Vector([grain[0, 1], grain[1, 1]])
        for t in ti.static(range(3)):
            e = e_warp if t == 0 else (e_weft if t == 1 else e_warp + e_weft)
            strain = _stretch_along(p, q, r, e) - 1.0
            lo, hi = params_w[2 * t], params_w[2 * t + 1]
            if ti.static(t == 2):
                lo, hi = lo - 1.0, hi - 1.0          # the shear band is in ||w_s|| units
            total += weights[2 * t] * (lo - strain) + weights[2 * t + 1] * (strain - hi)
    else:
        for i in ti.static(range(2)):
            e = ti.Vector([grain[0, i], grain[1, i]])
            lo, hi = params_w[2 * i], params_w[2 * i + 1]
            for j in ti.static(range(2)):
                sigma = sigma_a if j == 0 else -sigma_a
                strain = mapping_strain(p, q, r, e, sigma, iso)
                total += weights[4 * i + 2 * j] * (strain - hi) \
                    + weights[4 * i + 2 * j + 1] * (lo - strain)
    return total


@ti.func
def clamp_psd2(T):
    """The symmetric 2x2 T with its negative eigenvalues set to zero."""
    l1, l2, V = sym_eig2(T[0, 0], T[0, 1], T[1, 1])
    # sym_eig2 returns the smaller one as det / l1 (for C, which is PSD); recompute it here.
    l2 = T[0, 0] + T[1, 1] - l1
    v1 = ti.Vector([V[0, 0], V[1, 0]])
    v2 = ti.Vector([V[0, 1], V[1, 1]])
    return ti.max(l1, 0.0) * v1.outer_product(v1) + ti.max(l2, 0.0) * v2.outer_product(v2)


@ti.func
def clamp_psd3(H):
    """The symmetric 3x3 H with its negative eigenvalues set to zero (cyclic Jacobi)."""
    A = H
    V = ti.Matrix.identity(float, 3)
    for _sweep in range(6):
        for k in ti.static(range(3)):
            i, j = ti.static((0, 1, 0)[k], (1, 2, 2)[k])
            if ti.abs(A[i, j]) > 1e-300:
                theta = (A[j, j] - A[i, i]) / (2.0 * A[i, j])
                sgn = 1.0 if theta >= 0.0 else -1.0
                t = sgn / (ti.abs(theta) + ti.sqrt(theta * theta + 1.0))
                c = 1.0 / ti.sqrt(t * t + 1.0)
                s = t * c
                R = ti.Matrix.identity(float, 3)
                R[i, i], R[j, j], R[i, j], R[j, i] = c, c, s, -s
                A = R.transpose() @ A @ R
                V = V @ R
    out = ti.Matrix.zero(float, 3, 3)
    for k in ti.static(range(3)):
        vk = ti.Vector([V[0, k], V[1, k], V[2, k]])
        out += ti.max(A[k, k], 0.0) * vk.outer_product(vk)
    return out


@ti.func
def face_c_curvature(method: ti.template(), K, f, x: ti.template(), mesh: ti.template(),
                     params_w, iso, step, cons: ti.template(), mu):
    """Fill cons.curv[f, 0..2] for face f at positions x (see the module doc; ``mesh`` and
    ``cons`` are buffers.MeshPack and ConstraintPack). Leaves a zero flag
    (curv[f, 1][6] = 0) when no constraint of the face is active."""
    sqa = ti.sqrt(mesh.rest_area[f])
    weights = ti.Vector([0.0] * 8)
    any_active = 0
    for c in ti.static(range(8)):
        if c < K:
            s = cons.lam[f, c] + mu * cons.g[f, c]
            if s > 0.0:
                weights[c] = s * sqa
                any_active = 1
    cons.curv[f, 1][6] = 0.0
    if any_active == 1:
        ids = mesh.face_verts[f]
        Mr = shape_rows(mesh.Dm_inv[f])
        w0 = Mr[0, 0] * x[ids[0]] + Mr[1, 0] * x[ids[1]] + Mr[2, 0] * x[ids[2]]
        w1 = Mr[0, 1] * x[ids[0]] + Mr[1, 1] * x[ids[1]] + Mr[2, 1] * x[ids[2]]
        p, q, r = w0.dot(w0), w0.dot(w1), w1.dot(w1)
        G = mesh.grain[f]
        # Pair A of the mapping family (eta1, or the principal direction closer to the warp
        # under MAPPING_PAIRS_BY_ALIGNMENT), frozen.
        sigma_a = 1.0
        if ti.static(MAPPING_PAIRS_BY_ALIGNMENT):
            t_warp = 0.5 * (p - r) * (G[0, 0] * G[0, 0] - G[1, 0] * G[1, 0]) \
                + 2.0 * q * G[0, 0] * G[1, 0]
            sigma_a = -1.0 if t_warp < 0.0 else 1.0
        # Central differences of phi in (p, q, r): gradient and Hessian.
        h = step
        phi0 = weighted_strain(method, p, q, r, G, params_w, weights, sigma_a, iso)
        grad = ti.Vector([0.0, 0.0, 0.0])
        Hc = ti.Matrix.zero(float, 3, 3)
        for i in ti.static(range(3)):
            ei = ti.Vector([1.0 if k == i else 0.0 for k in ti.static(range(3))]) * h
            fp = weighted_strain(method, p + ei[0], q + ei[1], r + ei[2], G, params_w,
                                 weights, sigma_a, iso)
            fm = weighted_strain(method, p - ei[0], q - ei[1], r - ei[2], G, params_w,
                                 weights, sigma_a, iso)
            grad[i] = (fp - fm) / (2.0 * h)
            Hc[i, i] = (fp - 2.0 * phi0 + fm) / (h * h)
        for k in ti.static(range(3)):
            i, j = ti.static((0, 0, 1)[k], (1, 2, 2)[k])
            ei = ti.Vector([1.0 if m == i else 0.0 for m in ti.static(range(3))]) * h
            ej = ti.Vector([1.0 if m == j else 0.0 for m in ti.static(range(3))]) * h
            d = ti.Vector([0.0, 0.0, 0.0, 0.0])
            for n in ti.static(range(4)):
                si = 1.0 if n < 2 else -1.0
                sj = 1.0 if n % 2 == 0 else -1.0
                dd = si * ei + sj * ej
                d[n] = weighted_strain(method, p + dd[0], q + dd[1], r + dd[2], G, params_w,
                                       weights, sigma_a, iso)
            Hc[i, j] = (d[0] - d[1] - d[2] + d[3]) / (4.0 * h * h)
            Hc[j, i] = Hc[i, j]
        T = clamp_psd2(ti.Matrix([[2.0 * grad[0], grad[1]], [grad[1], 2.0 * grad[2]]]))
        # A new name for the clamped matrix: in Taichi 1.7.4 ``Hc = clamp_psd3(Hc)`` left Hc
        # as it was (the clamp's result was lost; tests/test_exact_curvature.py), and the
        # Newton matrix built from the unclamped Hc was indefinite (smallest eigenvalue -2.0
        # on hanging at resolution 9, docs/speed/motion.md).
        Hc_psd = clamp_psd3(Hc)
        cons.curv[f, 0] = ti.Vector([Mr[0, 0], Mr[0, 1], Mr[1, 0], Mr[1, 1], Mr[2, 0],
                                     Mr[2, 1], T[0, 0], T[0, 1], T[1, 1]])
        cons.curv[f, 1] = ti.Vector([Hc_psd[0, 0], Hc_psd[0, 1], Hc_psd[0, 2], Hc_psd[1, 1],
                                     Hc_psd[1, 2], Hc_psd[2, 2],
                                     1.0, 0.0, 0.0])
        cons.curv[f, 2] = ti.Vector([w0[0], w0[1], w0[2], w1[0], w1[1], w1[2], 0.0, 0.0,
                                     0.0])


@ti.func
def _unpack(curv: ti.template(), f):
    c0, c1, c2 = curv[f, 0], curv[f, 1], curv[f, 2]
    Mr = ti.Matrix([[c0[0], c0[1]], [c0[2], c0[3]], [c0[4], c0[5]]])
    T = ti.Matrix([[c0[6], c0[7]], [c0[7], c0[8]]])
    Hc = ti.Matrix([[c1[0], c1[1], c1[2]], [c1[1], c1[3], c1[4]], [c1[2], c1[4], c1[5]]])
    w0 = ti.Vector([c2[0], c2[1], c2[2]])
    w1 = ti.Vector([c2[3], c2[4], c2[5]])
    return Mr, T, Hc, w0, w1


@ti.func
def dC_row(Mr, w0, w1, n):
    """dC / dx_n as a 3x3 matrix whose rows are dp, dq, dr with respect to x_n."""
    a, b = Mr[n, 0], Mr[n, 1]
    return ti.Matrix.rows([2.0 * a * w0, a * w1 + b * w0, 2.0 * b * w1])


@ti.func
def c_curvature_block(curv: ti.template(), f, a, b):
    """The 3x3 block (vertex a, vertex b) of face f's S (x) I3 + J^T H J (zero if inactive)."""
    out = ti.Matrix.zero(float, 3, 3)
    if curv[f, 1][6] > 0.0:
        Mr, T, Hc, w0, w1 = _unpack(curv, f)
        ma = ti.Vector([Mr[a, 0], Mr[a, 1]])
        mb = ti.Vector([Mr[b, 0], Mr[b, 1]])
        out = ma.dot(T @ mb) * ti.Matrix.identity(float, 3) \
            + dC_row(Mr, w0, w1, a).transpose() @ Hc @ dC_row(Mr, w0, w1, b)
    return out
