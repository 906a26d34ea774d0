"""Strain-limiting constraints of one triangle (docs/method.md §2 and §3) as Taichi funcs.

Every family returns a ``Constraints`` struct of K constraints, each ``g <= 0`` when satisfied
and scaled by ``sqrt(a)`` (docs/method.md §3: refining the mesh must not change how hard a region is
held). Per constraint c the struct holds

  g[c]         value (sqrt(a) * strain units, metres)
  grad[c, :]   dg/d(x_i, x_j, x_k), 9 numbers
  cm[c, :]     (M_i.e, M_j.e, M_k.e) and
  what[c, :]   unit world vector w^ and
  kappa[c]     >= 0, a positive semi-definite model of the curvature of g:
               d2g/dx_n dx_m ~= kappa (M_n.e)(M_m.e) (I - w^ w^T).

The curvature model is the exact Hessian of ``sqrt(a) ||F e||`` for the material direction e
(docs/method.md §4: plain Gauss-Newton cannot see that moving a row of vertices along u shears the
v edges; adding the curvature of ||w|| for constraints in tension makes the projection
converge). Constraints whose true curvature is negative (lower bounds: -||w||) get kappa = 0,
the "projected" part of projected Newton.

Families and their order (the order of ``tests/data/constraint_vectors.json``):
  svd (4)        eta1 lower/upper (warp band), eta2 lower/upper (weft band)     (paper eq. 7)
  warp-weft (6)  ||w_u|| lower/upper, ||w_v|| lower/upper, ||w_s|| lower/upper (eqs. 10-12)
  mapping (8)    (warp, v1) upper/lower, (warp, v2) upper/lower,
                 (weft, v1) upper/lower, (weft, v2) upper/lower               (eqs. 15, 23)
The mapping family can instead order its principal pairs by alignment with the warp
(``by_alignment=True``): pair "A" is the principal direction closer to the warp. The set of 8
constraints is the same, but indices no longer swap when eta1 and eta2 cross; they swap at
45 degrees instead, where the values jump, so the solver orders by magnitude
(families.MAPPING_PAIRS_BY_ALIGNMENT; docs/method.md §3.3).

Bands are passed as 2-vectors (min, max) of strains; the shear band of warp-weft is in
||w_s|| units (sqrt 2 at rest), see ``StrainLimiter`` for the conversion from bias strain.
"""
import numpy as np
import taichi as ti

from .families import (K_MAX, MAPPING_PAIRS_BY_ALIGNMENT, METHOD_IDS, METHODS,  # noqa: F401
                       N_CONSTRAINTS, SVD, WARP_WEFT)

# Regularisation of 1/(eta1 - eta2) in the svd family's principal-frame curvature (a Newton
# model term only: values and gradients do not depend on it). See svd_constraints.
SVD_DELTA = 1e-4
# Below this gap eta1 - eta2 the svd family's two stretch gradients are blended towards their
# mean, which they equal at eta1 = eta2 (the minimum-norm subgradient of max(eta1, eta2), as
# the mapping family takes sign(0) = 0). Why: at exactly isotropic stretch the principal
# frame is arbitrary, and eta1's own gradient shrinks the triangle along one direction only,
# which leaves max(eta1, eta2) where it was; the line search then never found a decrease and a
# uniformly pre-stretched sheet stayed 3 % over its band for 100 rounds (benchmarks.stability,
# "exactly isotropic 4 % stretch, free sheet (svd)"). Values are untouched. The gap, measured:
# with 1e-6 the stability case's start-up projection stalled again at 0.030 (its ties are
# near, not exact); with 1e-4 the resting svd sheet of tests/test_coupling.py gained energy
# (mean KE 2.0e-6 J over frames 120-150, rising): the blended gradient is not the gradient of
# the value, and a narrow blend switches on and off sharply. 1e-3 rests (1.5e-8 J at
# resolution 9) and passes the stability case.
SVD_ISO_GAP = 1e-3

# Regularisation of 1/(eta1^2 - eta2^2) in the principal-direction derivative (docs/method.md §3.3).
# 1/D -> D/(D^2 + delta^2): bounded by 1/(2 delta), zero at D = 0 (where V is arbitrary and the
# exact value is 0 * inf). Error: the V-term is multiplied by D^2/(D^2 + delta^2), a relative
# error of exactly delta^2/(D^2 + delta^2) -- below 1e-6 wherever D > 1e-3 for delta = 1e-6,
# i.e. everywhere except within ~5e-4 stretch of exact isotropy, where the V-term is
# meaningless anyway (tests/test_constraints.py checks the bound and the error formula).
# Measured on a nearly isotropic projection (23x23 sheet stretched 3 %/3 %, mapping +-1 %,
# StrainLimiter defaults): delta = 1e-4 ... 1e-10 behave alike (38-40 AL rounds, final
# violation 0.6-4e-4); that problem is hard for every delta, the feasible set is not closed
# there (docs/method.md §3.3). delta = 1e-6 is chosen for accuracy, as small as f64 allows without
# letting round-off in D (~1e-16) matter.
MAPPING_DELTA = 1e-6

# Closure of the mapping family's feasible set at isotropy: ``defaults.MAPPING_ISO`` (settings
# strain.isotropy), why there.
from .defaults import MAPPING_ISO  # noqa: E402,F401


def _constraints_type(k):
    return ti.types.struct(g=ti.types.vector(k, float), grad=ti.types.matrix(k, 9, float),
                           cm=ti.types.matrix(k, 3, float), what=ti.types.matrix(k, 3, float),
                           kappa=ti.types.vector(k, float), twist=ti.types.matrix(k, 9, float))


Constraints4, Constraints6, Constraints8 = (_constraints_type(k) for k in (4, 6, 8))


# ---- kinematics (docs/method.md §2) -------------------------------------------------------
@ti.func
def shape_rows(Dm_inv):
    """Rows M_i, M_j, M_k of the paper's eq. 3 matrix as a 3x2 matrix: F = sum_n x_n M_n^T."""
    mj = ti.Vector([Dm_inv[0, 0], Dm_inv[0, 1]])
    mk = ti.Vector([Dm_inv[1, 0], Dm_inv[1, 1]])
    mi = -mj - mk
    return ti.Matrix.rows([mi, mj, mk])


@ti.func
def deformation_gradient(x0, x1, x2, Dm_inv):
    """F = Ds Dm^-1 (3x2), columns w_u, w_v along the material axes."""
    Ds = ti.Matrix.cols([x1 - x0, x2 - x0])
    return Ds @ Dm_inv


@ti.func
def sym_eig2(p, q, r):
    """Eigen-decomposition of the symmetric 2x2 [[p, q], [q, r]] = F^T F in closed form.

    Returns (lam1, lam2, V) with lam1 >= lam2 and V = [v1 v2] a rotation. Written to stay
    accurate in f32 and f64: the eigenvalue gap uses sqrt((p-r)^2/4 + q^2) (no subtraction of
    nearly equal eigenvalues), lam2 = det/lam1 (not mean - gap, which cancels for slivers), and
    the angle comes from atan2, which is continuous away from the isotropic point and returns
    a fixed direction (theta = 0) exactly at it. ti.sym_eig is not used: it is badly wrong in
    f32 for nearly isotropic C."""
    half_diff = 0.5 * (p - r)
    gap = ti.sqrt(half_diff * half_diff + q * q)
    lam1 = 0.5 * (p + r) + gap
    det = ti.max(p * r - q * q, 0.0)
    lam2 = 0.0
    if lam1 > 0.0:
        lam2 = ti.min(det / lam1, lam1)
    theta = 0.5 * ti.atan2(2.0 * q, p - r)
    c, s = ti.cos(theta), ti.sin(theta)
    V = ti.Matrix([[c, -s], [s, c]])
    return lam1, lam2, V


@ti.func
def stretch_svd(F):
    """Thin SVD of F (3x2): eta1 >= eta2 >= 0, V (2x2), U = [U_1 U_2] (3x2). det(F^T F) comes
    from the cross product of the columns so that slivers keep an accurate eta2."""
    w0 = ti.Vector([F[0, 0], F[1, 0], F[2, 0]])
    w1 = ti.Vector([F[0, 1], F[1, 1], F[2, 1]])
    p, q, r = w0.dot(w0), w0.dot(w1), w1.dot(w1)
    lam1, lam2, V = sym_eig2(p, q, r)
    # The cross product gives det(C) without cancellation (p r - q^2 cancels for slivers).
    n = w0.cross(w1)
    if lam1 > 0.0:
        lam2 = ti.min(n.dot(n) / lam1, lam1)
    eta1, eta2 = ti.sqrt(lam1), ti.sqrt(lam2)
    u1 = unit_or(F @ ti.Vector([V[0, 0], V[1, 0]]), ti.Vector([1.0, 0.0, 0.0]))
    u2 = unit_or(F @ ti.Vector([V[0, 1], V[1, 1]]), any_perpendicular(u1))
    return eta1, eta2, V, ti.Matrix.cols([u1, u2]), lam1 - lam2


@ti.func
def unit_or(w, fallback):
    """w / ||w||, or ``fallback`` when w has (numerically) vanished: a collapsed direction
    still needs some gradient direction so that compression limits can re-open it."""
    n = w.norm()
    out = fallback
    if n > 1e-12:
        out = w / n
    return out


@ti.func
def any_perpendicular(u):
    a = ti.Vector([1.0, 0.0, 0.0])
    if ti.abs(u[0]) > 0.7:
        a = ti.Vector([0.0, 1.0, 0.0])
    return (a - u * u.dot(a)).normalized()


@ti.func
def spread(coef, w):
    """The 9-vector (coef_i w, coef_j w, coef_k w): the gradient of phi(F e) with respect to
    the three vertex positions when coef = M e and w = dphi/d(F e)."""
    return ti.Vector([coef[0] * w[0], coef[0] * w[1], coef[0] * w[2],
                      coef[1] * w[0], coef[1] * w[1], coef[1] * w[2],
                      coef[2] * w[0], coef[2] * w[1], coef[2] * w[2]])


@ti.func
def set_one(out: ti.template(), c, value, grad, cm, what, kappa):
    """Store one constraint (value, gradient, curvature model) at index ``c``."""
    out.g[c] = value
    for m in ti.static(range(9)):
        out.grad[c, m] = grad[m]
    for m in ti.static(range(3)):
        out.cm[c, m] = cm[m]
        out.what[c, m] = what[m]
    out.kappa[c] = kappa


@ti.func
def set_band(out: ti.template(), c_lo: ti.template(), c_hi: ti.template(), sqa, stretch, band,
             grad_stretch, cm, what, kappa):
    """Lower and upper constraints of ``band[0] <= stretch - 1 <= band[1]`` (times sqrt(a)):
    g_lo = sqrt(a) (1 + band[0] - stretch), g_hi = sqrt(a) (stretch - 1 - band[1]).
    ``kappa`` is the curvature coefficient of the stretch itself (used for the upper one)."""
    # The lower bound's curvature (of -||w||) is concave: projected Newton drops it.
    set_one(out, c_lo, sqa * (1.0 + band[0] - stretch), -sqa * grad_stretch, cm, what, 0.0)
    set_one(out, c_hi, sqa * (stretch - 1.0 - band[1]), sqa * grad_stretch, cm, what,
             sqa * kappa)


# ---- the three families (docs/method.md §3.1-3.3) -------------------------------------------
@ti.func
def svd_constraints(x0, x1, x2, Dm_inv, sqa, warp, weft, delta):
    """docs/method.md §3.1 / paper eq. 7: eta1 in the warp band, eta2 in the weft band; the grain is
    ignored on purpose (isotropic limit). d eta_j / dx_n = (M_n . v_j) U_j (eq. 8/9).

    Curvature: ``kappa`` models eta_j as ||F v_j|| with v_j frozen. The exact second
    derivative (checked against finite differences of numpy's SVD) is, with
    a = U_1.dF v_2, b = U_2.dF v_1 (the in-plane twist) and n = U_1 x U_2,
        d2 eta_1 = (a + b)^2 / (2 (eta1 - eta2)) + (a - b)^2 / (2 (eta1 + eta2))
                   + (n.dF v_1)^2 / eta1,
        d2 eta_2 = -(a + b)^2 / (2 (eta1 - eta2)) + (a - b)^2 / (2 (eta1 + eta2))
                   + (n.dF v_2)^2 / eta2,
    so the upper eta_1 and the lower eta_2 constraints gain the positive semi-definite term
    T T^T / (2 (eta1 - eta2)), T_n = (M_n.v_2) U_1 + (M_n.v_1) U_2, stored as ``twist`` =
    sqrt(sqa / 2 * r) T with 1/(eta1 - eta2) regularised to r = D / (D^2 + delta^2) (bounded
    where eta1 = eta2, where eta_1 is not differentiable). Without it Newton cannot see that
    a triangle near eta1 = eta2 can shed its largest stretch by turning its frame."""
    out = Constraints4(0)
    F = deformation_gradient(x0, x1, x2, Dm_inv)
    eta1, eta2, V, U, _D = stretch_svd(F)
    Mr = shape_rows(Dm_inv)
    v1 = ti.Vector([V[0, 0], V[1, 0]])
    v2 = ti.Vector([V[0, 1], V[1, 1]])
    u1 = ti.Vector([U[0, 0], U[1, 0], U[2, 0]])
    u2 = ti.Vector([U[0, 1], U[1, 1], U[2, 1]])
    cm1, cm2 = Mr @ v1, Mr @ v2
    g1, g2 = spread(cm1, u1), spread(cm2, u2)
    # Near isotropy, each gradient moves towards the other (SVD_ISO_GAP): the mean at a tie.
    mix = 0.5 * ti.max(0.0, 1.0 - (eta1 - eta2) / SVD_ISO_GAP)
    set_band(out, 0, 1, sqa, eta1, warp, (1.0 - mix) * g1 + mix * g2, cm1, u1,
             1.0 / ti.max(eta1, 1e-2))
    set_band(out, 2, 3, sqa, eta2, weft, (1.0 - mix) * g2 + mix * g1, cm2, u2,
             1.0 / ti.max(eta2, 1e-2))
    gap = eta1 - eta2
    r = gap / (gap * gap + delta * delta)
    tw = ti.sqrt(0.5 * sqa * r) * (spread(cm2, u1) + spread(cm1, u2))
    for m in ti.static(range(9)):
        out.twist[1, m] = tw[m]        # eta_1 upper
        out.twist[2, m] = tw[m]        # eta_2 lower
    return out


@ti.func
def warp_weft_constraints(x0, x1, x2, Dm_inv, grain, sqa, warp, weft, shear):
    """docs/method.md §3.2 / paper eqs. 10-12: ||w_u||, ||w_v|| in the warp/weft bands and
    ||w_s|| = ||w_u + w_v|| in ``shear`` (||w_s|| units). w_u = F e_warp, w_v = F e_weft."""
    out = Constraints6(0)
    F = deformation_gradient(x0, x1, x2, Dm_inv)
    Mr = shape_rows(Dm_inv)
    e_warp = ti.Vector([grain[0, 0], grain[1, 0]])
    e_weft = ti.Vector([grain[0, 1], grain[1, 1]])
    for t in ti.static(range(3)):
        e = e_warp if t == 0 else (e_weft if t == 1 else e_warp + e_weft)
        w = F @ e
        n = w.norm()
        w_hat = unit_or(w, ti.Vector([1.0, 0.0, 0.0]))
        cm = Mr @ e
        grad = spread(cm, w_hat)
        if ti.static(t < 2):
            band = warp if t == 0 else weft
            set_band(out, 2 * t, 2 * t + 1, sqa, n, band, grad, cm, w_hat,
                     1.0 / ti.max(n, 1e-2))
        else:
            # The shear band is already a stretch range: write it as a strain band.
            set_band(out, 4, 5, sqa, n, shear - 1.0, grad, cm, w_hat, 1.0 / ti.max(n, 1e-2))
    return out


@ti.func
def mapping_constraints(x0, x1, x2, Dm_inv, grain, sqa, warp, weft, delta, iso,
                        by_alignment: ti.template()):
    """docs/method.md §3.3 / paper eqs. 13-15 and 23, multiplied form [fix]:
        c_ij = |e_i . v_j|,  g+_ij = sqrt(a)(c_ij (eta_j - 1) - eps_i^max),
                             g-_ij = sqrt(a)(eps_i^min - c_ij (eta_j - 1)).
    Gradient: sqrt(a)[c_ij d eta_j + (eta_j - 1) s_ij (e_i . d v_j)] with the rotation of the
    principal frame (eqs. 19-22, Papadopoulo & Lourakis) written through eta_1 U_1 = F v_1:
        d theta / dx_n = ((M_n.v2) F v1 + (M_n.v1) F v2) / (eta1^2 - eta2^2),
        e.dv1 = (e.v2) d theta,  e.dv2 = -(e.v1) d theta,
    and 1/D regularised to D/(D^2 + delta^2) (see MAPPING_DELTA for the error).

    ``iso`` > 0 closes the feasible set at isotropy (see MAPPING_ISO): c_ij is replaced by
        c~ = sqrt(w c^2 + (1 - w) / 2),  w = D^2 / (D^2 + iso^2),  D = eta1^2 - eta2^2,
    d c~ = (w c dc + (c^2 - 1/2) dw / 2) / c~,  dw = 2 D iso^2 / (D^2 + iso^2)^2 dD,
    dD = 2 eta1 d eta1 - 2 eta2 d eta2. iso = 0 is the paper's constraint exactly."""
    out = Constraints8(0)
    F = deformation_gradient(x0, x1, x2, Dm_inv)
    eta1, eta2, V, U, D = stretch_svd(F)
    Mr = shape_rows(Dm_inv)
    v1 = ti.Vector([V[0, 0], V[1, 0]])
    v2 = ti.Vector([V[0, 1], V[1, 1]])
    u1 = ti.Vector([U[0, 0], U[1, 0], U[2, 0]])
    u2 = ti.Vector([U[0, 1], U[1, 1], U[2, 1]])
    cm1, cm2 = Mr @ v1, Mr @ v2
    inv_D = D / (D * D + delta * delta)
    dtheta = (spread(cm2, F @ v1) + spread(cm1, F @ v2)) * inv_D
    e_warp = ti.Vector([grain[0, 0], grain[1, 0]])
    e_weft = ti.Vector([grain[0, 1], grain[1, 1]])
    # Isotropy closure weight w and its gradient (w = 1, dw = 0 when iso = 0).
    w_iso = 1.0
    dw = ti.Vector.zero(float, 9)
    if iso > 0.0:
        den = D * D + iso * iso
        w_iso = D * D / den
        dD = 2.0 * eta1 * spread(cm1, u1) - 2.0 * eta2 * spread(cm2, u2)
        dw = (2.0 * D * iso * iso / (den * den)) * dD
    # Principal pairs as (eta, v, U, M v, d v / d theta as a material vector).
    swap = False
    if ti.static(by_alignment):
        swap = ti.abs(e_warp.dot(v2)) > ti.abs(e_warp.dot(v1))
    etaA, etaB, vA, vB, uA, uB, cmA, cmB = eta1, eta2, v1, v2, u1, u2, cm1, cm2
    dvA, dvB = v2, -v1          # d v1 / d theta = v2, d v2 / d theta = -v1
    if swap:
        etaA, etaB, vA, vB, uA, uB, cmA, cmB = eta2, eta1, v2, v1, u2, u1, cm2, cm1
        dvA, dvB = -v1, v2
    for i in ti.static(range(2)):
        e = e_warp if i == 0 else e_weft
        band = warp if i == 0 else weft
        for j in ti.static(range(2)):
            eta = etaA if j == 0 else etaB
            v = vA if j == 0 else vB
            u = uA if j == 0 else uB
            cm = cmA if j == 0 else cmB
            dv = dvA if j == 0 else dvB
            ev = e.dot(v)
            c = ti.abs(ev)
            # sign(e.v) with sign(0) = 0: at e.v = 0 the |.| has a kink and 0 is the
            # minimum-norm subgradient (the reference data's convention). The threshold keeps
            # round-off of cos(pi/2) ~ 6e-17 from choosing a side at random.
            s = 0.0
            if ev > 1e-12:
                s = 1.0
            elif ev < -1e-12:
                s = -1.0
            dc = s * e.dot(dv) * dtheta
            if iso > 0.0:
                c_exact = c
                c = ti.sqrt(w_iso * c_exact * c_exact + 0.5 * (1.0 - w_iso))
                dc = (w_iso * c_exact * dc + 0.5 * (c_exact * c_exact - 0.5) * dw) / c
            strain = c * (eta - 1.0)
            grad = c * spread(cm, u) + (eta - 1.0) * dc
            k = 4 * i + 2 * j
            set_one(out, k, sqa * (strain - band[1]), sqa * grad, cm, u,
                     sqa * c / ti.max(eta, 1e-2))
            set_one(out, k + 1, sqa * (band[0] - strain), -sqa * grad, cm, u, 0.0)
    return out


@ti.func
def face_constraints(method: ti.template(), x0, x1, x2, Dm_inv, grain, sqa, warp, weft, shear,
                     delta, iso, by_alignment: ti.template()):
    """Dispatch on the (compile-time) method id of METHOD_IDS."""
    if ti.static(method == SVD):
        return svd_constraints(x0, x1, x2, Dm_inv, sqa, warp, weft, delta)
    elif ti.static(method == WARP_WEFT):
        return warp_weft_constraints(x0, x1, x2, Dm_inv, grain, sqa, warp, weft, shear)
    else:
        return mapping_constraints(x0, x1, x2, Dm_inv, grain, sqa, warp, weft, delta, iso,
                                   by_alignment)


# ---- host-side evaluation (tests, tools) ---------------------------------------------------
@ti.kernel
def _eval_batch(method: ti.template(), by_alignment: ti.template(), x: ti.types.ndarray(),
                Dm_inv: ti.types.ndarray(), grain: ti.types.ndarray(),
                area: ti.types.ndarray(), bands: ti.types.ndarray(), delta: float,
                iso: float, g: ti.types.ndarray(), grad: ti.types.ndarray()):
    for f in range(x.shape[0]):
        xs = ti.Matrix.zero(float, 3, 3)
        Dm = ti.Matrix.zero(float, 2, 2)
        G = ti.Matrix.zero(float, 2, 2)
        for a, b in ti.static(ti.ndrange(3, 3)):
            xs[a, b] = x[f, a, b]
        for a, b in ti.static(ti.ndrange(2, 2)):
            Dm[a, b] = Dm_inv[f, a, b]
            G[a, b] = grain[f, a, b]
        warp = ti.Vector([bands[0], bands[1]])
        weft = ti.Vector([bands[2], bands[3]])
        shear = ti.Vector([bands[4], bands[5]])
        out = face_constraints(method, ti.Vector([xs[0, 0], xs[0, 1], xs[0, 2]]),
                               ti.Vector([xs[1, 0], xs[1, 1], xs[1, 2]]),
                               ti.Vector([xs[2, 0], xs[2, 1], xs[2, 2]]),
                               Dm, G, ti.sqrt(area[f]), warp, weft, shear, delta, iso,
                               by_alignment)
        for c in ti.static(range(out.g.n)):
            g[f, c] = out.g[c]
            for m in ti.static(range(9)):
                grad[f, c, m] = out.grad[c, m]


def evaluate(method, x, Dm_inv, grain, area, warp, weft, shear, delta=MAPPING_DELTA,
             by_alignment=False, iso=0.0):
    """Constraint values (n, K) and gradients (n, K, 9) of ``n`` triangles on the host.

    x (n, 3, 3) rows x_i, x_j, x_k; Dm_inv, grain (n, 2, 2); area (n,); bands as (min, max)
    strain pairs, ``shear`` in ||w_s|| units. Uses Taichi's default float."""
    if method not in METHODS:
        raise ValueError(f"unknown strain-limiting method '{method}': use one of "
                         f"{', '.join(METHODS)}")
    dt = np.float64 if ti.lang.impl.get_runtime().default_fp == ti.f64 else np.float32
    x = np.ascontiguousarray(x, dtype=dt)
    n, k = len(x), N_CONSTRAINTS[method]
    g, grad = np.zeros((n, k), dt), np.zeros((n, k, 9), dt)
    bands = np.array([*warp, *weft, *shear], dtype=dt)
    _eval_batch(METHOD_IDS[method], bool(by_alignment), x,
                np.ascontiguousarray(Dm_inv, dtype=dt), np.ascontiguousarray(grain, dtype=dt),
                np.ascontiguousarray(area, dtype=dt), bands, delta, float(iso), g, grad)
    return g.astype(np.float64), grad.astype(np.float64)


@ti.kernel
def _eig_batch(C: ti.types.ndarray(), out: ti.types.ndarray()):
    for f in range(C.shape[0]):
        lam1, lam2, V = sym_eig2(C[f, 0], C[f, 1], C[f, 2])
        out[f, 0], out[f, 1] = lam1, lam2
        out[f, 2], out[f, 3], out[f, 4], out[f, 5] = V[0, 0], V[1, 0], V[0, 1], V[1, 1]


def sym_eig2_numpy(p, q, r):
    """The closed-form 2x2 eigen-solver run in Taichi on arrays (for tests): returns
    (n, 6) rows lam1, lam2, v1 (2), v2 (2)."""
    dt = np.float64 if ti.lang.impl.get_runtime().default_fp == ti.f64 else np.float32
    C = np.ascontiguousarray(np.stack([p, q, r], axis=1), dtype=dt)
    out = np.zeros((len(C), 6), dt)
    _eig_batch(C, out)
    return out
