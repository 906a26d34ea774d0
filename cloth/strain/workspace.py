"""The Taichi side of strain limiting: work arrays and the solve kernels.

Design notes (measured on this 2-core CPU, Taichi 1.7.4, f64):
- Every array is a Taichi *ndarray* passed as a kernel argument, never a field captured by a
  kernel: kernels that capture fields are recompiled for every new field (every model, every
  reallocation), and compiling the mapping constraints plus the Newton kernels costs ~10-40 s.
  With ndarray arguments each kernel compiles once per process (and is then found in Taichi's
  offline cache by later processes).
- Launch overhead is ~15 us per kernel and ~50-60 us per parallel top-level loop, while one
  PCG iteration over 1k triangles costs ~50 us. So each solve phase (a whole PCG solve, a
  whole constraint assembly, a whole Jacobi / Gauss-Seidel run) is one kernel whose top-level
  loop is serialized; all face and vertex loops are then plain serial loops without atomics.
- The constraint loop inside the Newton kernels runs over c < K at run time (not unrolled with
  ti.static): unrolling 8 constraints x 9 gradient entries made one kernel take 30 s to compile.
"""
import taichi as ti

from .constraints import K_MAX, face_constraints

A = ti.types.ndarray()          # any ndarray; kernels compile once per dtype / dimension
T = ti.template()               # how a ti.func takes an array (by reference)

# Indices into the ``stats`` array (read back once per solve).
ST_ITERS, ST_VIOL, ST_CONVERGED, ST_CG, ST_NEWTON, ST_COMP = range(6)
# Indices into the ``params`` array.
P_WARP, P_WEFT, P_SHEAR, P_MARGIN, P_DELTA = 0, 2, 4, 6, 7


class Workspace:
    """Per-limiter arrays sized from the model's capacities (f_cap faces, v_cap vertices)."""

    def __init__(self, f_cap, v_cap):
        self.f_cap, self.v_cap = f_cap, v_cap
        F, V, K = f_cap, v_cap, K_MAX
        vec3, vec9 = ti.types.vector(3, float), ti.types.vector(9, float)
        # Copies of the model (refreshed by StrainLimiter when the mesh changes).
        self.face_verts = ti.ndarray(ti.types.vector(3, ti.i32), F)
        self.Dm_inv = ti.ndarray(ti.types.matrix(2, 2, float), F)
        self.grain = ti.ndarray(ti.types.matrix(2, 2, float), F)
        self.rest_area = ti.ndarray(float, F)
        self.mass = ti.ndarray(float, V)
        self.pinned = ti.ndarray(ti.i32, V)
        # Multipliers lambda >= 0, one per constraint (warm-started across calls).
        self.lam = ti.ndarray(float, (F, K))
        # Constraint data at the current iterate (see constraints.py for the meaning).
        self.g = ti.ndarray(float, (F, K))
        self.grad = ti.ndarray(vec9, (F, K))
        self.cm = ti.ndarray(vec3, (F, K))
        self.what = ti.ndarray(vec3, (F, K))
        self.kappa = ti.ndarray(float, (F, K))
        # Per-vertex vectors: positions (x), unconstrained x_hat, start of the call, line-search
        # trial, Newton direction and PCG vectors; Jacobi accumulators.
        names = ("x", "v", "x_hat", "x_start", "x_trial", "d", "r", "z", "p", "Ap", "acc")
        for name in names:
            setattr(self, name, ti.ndarray(vec3, V))
        self.P_inv = ti.ndarray(ti.types.matrix(3, 3, float), V)
        self.cnt = ti.ndarray(float, V)
        self.params = ti.ndarray(float, 8)     # bands (warp, weft, shear), margin, delta
        self.stats = ti.ndarray(float, 8)


# ---- copies between the model's fields and the work arrays -----------------------------------
@ti.kernel
def field_to_array(src: ti.template(), dst: A, n: int):
    for i in range(n):
        dst[i] = src[i]


@ti.kernel
def array_to_field(src: A, dst: ti.template(), n: int):
    for i in range(n):
        dst[i] = src[i]


# ---- constraint evaluation ---------------------------------------------------------------------
@ti.func
def eval_face(method: ti.template(), f, pos: T, face_verts: T, Dm_inv: T, grain: T,
              rest_area: T, params: T):
    """All constraints of face f at positions ``pos``; mapping pairs ordered by alignment with
    the warp so that multipliers do not jump when eta1 and eta2 cross (METHOD 3.3)."""
    ids = face_verts[f]
    warp = ti.Vector([params[P_WARP], params[P_WARP + 1]])
    weft = ti.Vector([params[P_WEFT], params[P_WEFT + 1]])
    shear = ti.Vector([params[P_SHEAR], params[P_SHEAR + 1]])
    return face_constraints(method, pos[ids[0]], pos[ids[1]], pos[ids[2]], Dm_inv[f],
                            grain[f], ti.sqrt(rest_area[f]), warp, weft, shear,
                            params[P_DELTA], True)


@ti.func
def assemble_all(method: ti.template(), nf, pos: T, face_verts: T, Dm_inv: T, grain: T,
                 rest_area: T, params: T, g: T, grad: T, cm: T, what: T, kappa: T):
    """Values, gradients and curvature models of every constraint at ``pos``."""
    for f in range(nf):
        out = eval_face(method, f, pos, face_verts, Dm_inv, grain, rest_area, params)
        for c in ti.static(range(out.g.n)):
            g[f, c] = out.g[c]
            kappa[f, c] = out.kappa[c]
            grad_c = ti.Vector([0.0] * 9)
            cm_c, what_c = ti.Vector([0.0] * 3), ti.Vector([0.0] * 3)
            for m in ti.static(range(9)):
                grad_c[m] = out.grad[c, m]
            for m in ti.static(range(3)):
                cm_c[m] = out.cm[c, m]
                what_c[m] = out.what[c, m]
            grad[f, c] = grad_c
            cm[f, c] = cm_c
            what[f, c] = what_c


@ti.kernel
def assemble(method: ti.template(), nf: int, pos: A, face_verts: A, Dm_inv: A, grain: A,
             rest_area: A, params: A, g: A, grad: A, cm: A, what: A, kappa: A):
    ti.loop_config(serialize=True)
    for _ in range(1):
        assemble_all(method, nf, pos, face_verts, Dm_inv, grain, rest_area, params, g, grad,
                     cm, what, kappa)


# ---- augmented Lagrangian pieces (METHOD 4, paper eqs. 25-27) ----------------------------------
@ti.func
def scatter(vec: T, ids, val, scale):
    for n in ti.static(range(3)):
        vec[ids[n]] += scale * ti.Vector([val[3 * n], val[3 * n + 1], val[3 * n + 2]])


@ti.func
def dot(a: T, b: T, nv):
    s = 0.0
    for n in range(nv):
        s += a[n].dot(b[n])
    return s


@ti.func
def merit(K, nv, nf, mu, pos: T, x_hat: T, mass: T, lam: T, g: T):
    """L_A = 1/2 sum m |x - x_hat|^2 + sum (mu/2) max(0, g + lam/mu)^2 - lam^2/(2 mu), the
    slack variables of eq. 25 eliminated, with g as last assembled (at ``pos``)."""
    total = 0.0
    for n in range(nv):
        total += 0.5 * mass[n] * (pos[n] - x_hat[n]).norm_sqr()
    for f in range(nf):
        for c in range(K):
            t = ti.max(0.0, g[f, c] + lam[f, c] / mu)
            total += 0.5 * mu * t * t - 0.5 * lam[f, c] * lam[f, c] / mu
    return total


@ti.kernel
def merit_at(K: int, nv: int, nf: int, mu: float, pos: A, x_hat: A, mass: A, lam: A,
             g: A) -> float:
    total = 0.0
    ti.loop_config(serialize=True)
    for _ in range(1):
        total = merit(K, nv, nf, mu, pos, x_hat, mass, lam, g)
    return total


@ti.kernel
def try_step(method: ti.template(), K: int, nv: int, nf: int, mu: float, alpha: float,
             x: A, d: A, x_trial: A, x_hat: A, mass: A, lam: A, face_verts: A, Dm_inv: A,
             grain: A, rest_area: A, params: A, g: A, grad: A, cm: A, what: A,
             kappa: A) -> float:
    """One line-search trial in one launch: x_trial = x + alpha d, assemble the constraints
    there, return L_A(x_trial)."""
    total = 0.0
    ti.loop_config(serialize=True)
    for _ in range(1):
        for n in range(nv):
            x_trial[n] = x[n] + alpha * d[n]
        assemble_all(method, nf, x_trial, face_verts, Dm_inv, grain, rest_area, params, g,
                     grad, cm, what, kappa)
        total = merit(K, nv, nf, mu, x_trial, x_hat, mass, lam, g)
    return total


@ti.func
def residual(K, nv, nf, mu, x: T, x_hat: T, mass: T, pinned: T, face_verts: T, lam: T, g: T,
             grad: T, r: T):
    """r = -grad L_A = -M (x - x_hat) - sum max(0, lam + mu g) grad g; zero at pins."""
    for n in range(nv):
        r[n] = -mass[n] * (x[n] - x_hat[n])
    for f in range(nf):
        ids = face_verts[f]
        for c in range(K):
            s = lam[f, c] + mu * g[f, c]
            if s > 0.0:
                scatter(r, ids, grad[f, c], -s)
    for n in range(nv):
        if pinned[n] == 1:
            r[n] = ti.Vector([0.0, 0.0, 0.0])


@ti.func
def build_preconditioner(K, nv, nf, mu, margin, mass: T, pinned: T, face_verts: T,
                         rest_area: T, lam: T, g: T,
                         grad: T, cm: T, what: T, kappa: T, P_inv: T):
    """3x3 block Jacobi of the projected-Newton matrix (see apply_hessian)."""
    for n in range(nv):
        P_inv[n] = mass[n] * ti.Matrix.identity(float, 3)
    for f in range(nf):
        ids = face_verts[f]
        near = mu * margin * ti.sqrt(rest_area[f])
        for c in range(K):
            s = lam[f, c] + mu * g[f, c]
            if s + near > 0.0:
                gr, w = grad[f, c], what[f, c]
                proj = ti.Matrix.identity(float, 3) - w.outer_product(w)
                for n in ti.static(range(3)):
                    gn = ti.Vector([gr[3 * n], gr[3 * n + 1], gr[3 * n + 2]])
                    P_inv[ids[n]] += mu * gn.outer_product(gn) \
                        + ti.max(s, 0.0) * kappa[f, c] * cm[f, c][n] ** 2 * proj
    for n in range(nv):
        if pinned[n] == 1:
            P_inv[n] = ti.Matrix.identity(float, 3)
        else:
            P_inv[n] = P_inv[n].inverse()


@ti.func
def apply_hessian(K, nv, nf, mu, margin, mass: T, pinned: T, face_verts: T, rest_area: T,
                  lam: T, g: T, grad: T,
                  cm: T, what: T, kappa: T, p: T, Ap: T):
    """Ap = (M + sum_near [mu grad g grad g^T] + sum_active (lam + mu g) curvature(g)) p, the
    projected-Newton matrix applied without forming it. "Near" includes constraints within
    ``margin`` (strain) of activating: a Newton step that ignores them runs straight into
    dozens of them (measured on a 10x10 sheet: 112 of 486 constraints switched on within
    1e-3 of a step) and the line search then accepts only tiny steps; with the margin the
    same projection needs 6 instead of > 40 rounds."""
    for n in range(nv):
        Ap[n] = mass[n] * p[n]
    for f in range(nf):
        ids = face_verts[f]
        pf = ti.Vector([0.0] * 9)
        for n in ti.static(range(3)):
            for k in ti.static(range(3)):
                pf[3 * n + k] = p[ids[n]][k]
        near = mu * margin * ti.sqrt(rest_area[f])
        for c in range(K):
            s = lam[f, c] + mu * g[f, c]
            if s + near > 0.0:
                gr = grad[f, c]
                scatter(Ap, ids, gr, mu * gr.dot(pf))
                if s > 0.0:
                    # Curvature of ||F e||: dw = sum_n (M_n.e) p_n, projected off w^.
                    cmv, w = cm[f, c], what[f, c]
                    dw = cmv[0] * p[ids[0]] + cmv[1] * p[ids[1]] + cmv[2] * p[ids[2]]
                    t = s * kappa[f, c] * (dw - w * w.dot(dw))
                    for n in ti.static(range(3)):
                        Ap[ids[n]] += cmv[n] * t
    for n in range(nv):
        if pinned[n] == 1:
            Ap[n] = ti.Vector([0.0, 0.0, 0.0])


@ti.kernel
def newton_direction(K: int, nv: int, nf: int, mu: float, max_cg: int, rtol: float,
                     params: A, x: A, x_hat: A, mass: A, pinned: A, face_verts: A,
                     rest_area: A, lam: A, g: A, grad: A, cm: A, what: A, kappa: A, d: A,
                     r: A, z: A, p: A, Ap: A, P_inv: A, stats: A) -> float:
    """Projected-Newton direction: solve H d = -grad L_A by PCG (block Jacobi) from d = 0.
    Returns the slope grad L_A . d (< 0 for descent); adds the CG iterations to stats."""
    slope = 0.0
    ti.loop_config(serialize=True)
    for _ in range(1):
        margin = params[P_MARGIN]
        residual(K, nv, nf, mu, x, x_hat, mass, pinned, face_verts, lam, g, grad, r)
        build_preconditioner(K, nv, nf, mu, margin, mass, pinned, face_verts, rest_area, lam,
                             g, grad, cm, what, kappa, P_inv)
        for n in range(nv):
            d[n] = ti.Vector([0.0, 0.0, 0.0])
            z[n] = P_inv[n] @ r[n]
            p[n] = z[n]
        rz = dot(r, z, nv)
        r0 = ti.sqrt(dot(r, r, nv))
        it = 0
        while it < max_cg:
            apply_hessian(K, nv, nf, mu, margin, mass, pinned, face_verts, rest_area, lam, g,
                          grad, cm, what, kappa, p, Ap)
            pAp = dot(p, Ap, nv)
            if pAp <= 0.0:
                break
            alpha = rz / pAp
            for n in range(nv):
                d[n] += alpha * p[n]
                r[n] -= alpha * Ap[n]
            it += 1
            if ti.sqrt(dot(r, r, nv)) <= rtol * r0:
                break
            for n in range(nv):
                z[n] = P_inv[n] @ r[n]
            rz_new = dot(r, z, nv)
            beta = rz_new / rz
            rz = rz_new
            for n in range(nv):
                p[n] = z[n] + beta * p[n]
        stats[ST_CG] += it
        residual(K, nv, nf, mu, x, x_hat, mass, pinned, face_verts, lam, g, grad, r)
        slope = -dot(r, d, nv)
    return slope


@ti.kernel
def accept_trial(nv: int, x: A, x_trial: A) -> float:
    """x <- x_trial; returns the largest vertex move."""
    step = 0.0
    ti.loop_config(serialize=True)
    for n in range(nv):
        step = ti.max(step, (x_trial[n] - x[n]).norm())
        x[n] = x_trial[n]
    return step


@ti.kernel
def update_multipliers(K: int, nf: int, mu: float, lam_cap: float, rest_area: A, lam: A,
                       g: A, stats: A):
    """lambda <- max(0, lambda + mu g) (eq. 27, inequality form). Stores the largest violation
    and the largest |delta lambda| / mu (violation plus complementarity), both in strain
    units. lambda is capped at lam_cap sqrt(a) so that an infeasible problem (pins pulled
    apart) cannot grow it without bound across calls."""
    viol, comp = 0.0, 0.0
    ti.loop_config(serialize=True)
    for f in range(nf):
        sqa = ti.sqrt(rest_area[f])
        for c in range(K):
            new = ti.min(ti.max(0.0, lam[f, c] + mu * g[f, c]), lam_cap * sqa)
            viol = ti.max(viol, g[f, c] / sqa)
            comp = ti.max(comp, ti.abs(new - lam[f, c]) / (mu * sqa))
            lam[f, c] = new
    stats[ST_VIOL] = viol
    stats[ST_COMP] = comp


@ti.kernel
def max_violation(K: int, nf: int, rest_area: A, g: A) -> float:
    viol = 0.0
    ti.loop_config(serialize=True)
    for f in range(nf):
        sqa = ti.sqrt(rest_area[f])
        for c in range(K):
            viol = ti.max(viol, g[f, c] / sqa)
    return viol


@ti.kernel
def begin_solve(nv: int, x: A, x_hat: A, x_start: A, stats: A):
    ti.loop_config(serialize=True)
    for n in range(nv):
        x_hat[n] = x[n]
        x_start[n] = x[n]
    for i in range(8):
        stats[i] = 0.0


@ti.kernel
def finish_solve(nv: int, h: float, x: A, x_start: A, v: A):
    """v += dx / h (METHOD 4): the projection's correction becomes a velocity change."""
    ti.loop_config(serialize=True)
    for n in range(nv):
        if h > 0.0:
            v[n] += (x[n] - x_start[n]) / h


# ---- the per-triangle projection baseline (PBD style) ------------------------------------
@ti.func
def project_face(method: ti.template(), f, jacobi, x: T, face_verts: T, Dm_inv: T, grain: T,
                 rest_area: T,
                 params: T, mass: T, pinned: T, acc: T, cnt: T):
    """Move the face's vertices along the gradient of its most violated constraint so that
    its linearisation is satisfied, weighted by inverse mass (pins have none); Jacobi
    accumulates the moves, Gauss-Seidel applies them at once. Returns the violation found
    (strain units)."""
    out = eval_face(method, f, x, face_verts, Dm_inv, grain, rest_area, params)
    worst = 0.0
    gr = ti.Vector([0.0] * 9)
    for c in ti.static(range(out.g.n)):
        if out.g[c] > worst:
            worst = out.g[c]
            for m in ti.static(range(9)):
                gr[m] = out.grad[c, m]
    if worst > 0.0:
        ids = face_verts[f]
        wn = ti.Vector([0.0, 0.0, 0.0])
        denom = 0.0
        for n in ti.static(range(3)):
            if pinned[ids[n]] == 0:
                wn[n] = 1.0 / mass[ids[n]]
            denom += wn[n] * (gr[3 * n] ** 2 + gr[3 * n + 1] ** 2 + gr[3 * n + 2] ** 2)
        if denom > 0.0:
            for n in ti.static(range(3)):
                dx = -worst * wn[n] / denom * ti.Vector([gr[3 * n], gr[3 * n + 1],
                                                         gr[3 * n + 2]])
                if jacobi:
                    acc[ids[n]] += dx
                    cnt[ids[n]] += 1.0
                else:
                    x[ids[n]] += dx
    return worst / ti.sqrt(rest_area[f])


@ti.kernel
def pbd_solve(method: ti.template(), jacobi: int, nv: int, nf: int, tol: float,
              max_iters: int, omega: float, x: A, face_verts: A, Dm_inv: A, grain: A,
              rest_area: A, params: A, mass: A, pinned: A, acc: A, cnt: A, stats: A):
    """Jacobi (averaged, relaxed by omega) or Gauss-Seidel (in place, serial order) sweeps of
    per-triangle projections until the worst violation seen in a sweep is below tol."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        it = 0
        while it < max_iters:
            if jacobi:
                for n in range(nv):
                    acc[n] = ti.Vector([0.0, 0.0, 0.0])
                    cnt[n] = 0.0
            viol = 0.0
            for f in range(nf):
                viol = ti.max(viol, project_face(method, f, jacobi, x, face_verts, Dm_inv,
                                                 grain, rest_area, params, mass, pinned, acc,
                                                 cnt))
            if viol < tol:
                break
            it += 1
            if jacobi:
                for n in range(nv):
                    if cnt[n] > 0.0:
                        x[n] += omega * acc[n] / cnt[n]
        stats[ST_ITERS] = it
