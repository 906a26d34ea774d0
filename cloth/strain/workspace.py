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
  Launching from Python also costs ~0.1-0.4 ms per kernel in argument handling with ~20
  ndarray arguments (measured with cProfile: half of a 1k-triangle projection), so the whole
  augmented-Lagrangian solve is a single kernel (``solve_al``).
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
P_WARP, P_WEFT, P_SHEAR, P_MARGIN, P_DELTA, P_SVD_DELTA = 0, 2, 4, 6, 7, 8
N_PARAMS = 10


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
        self.twist = ti.ndarray(vec9, (F, K))     # extra rank-1 curvature (svd only)
        # Per-vertex vectors: positions (x), unconstrained x_hat, start of the call, line-search
        # trial, Newton direction and PCG vectors; Jacobi accumulators.
        names = ("x", "v", "x_hat", "x_start", "x_trial", "b", "d", "r", "z", "p", "Ap",
                 "acc")
        for name in names:
            setattr(self, name, ti.ndarray(vec3, V))
        self.P_inv = ti.ndarray(ti.types.matrix(3, 3, float), V)
        self.cnt = ti.ndarray(float, V)
        self.params = ti.ndarray(float, N_PARAMS)  # bands (warp, weft, shear), margin, deltas
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
    delta = params[P_SVD_DELTA] if ti.static(method == 0) else params[P_DELTA]
    return face_constraints(method, pos[ids[0]], pos[ids[1]], pos[ids[2]], Dm_inv[f],
                            grain[f], ti.sqrt(rest_area[f]), warp, weft, shear, delta, True)


@ti.func
def assemble_all(method: ti.template(), nf, pos: T, face_verts: T, Dm_inv: T, grain: T,
                 rest_area: T, params: T, g: T, grad: T, cm: T, what: T, kappa: T,
                 twist: T):
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
            if ti.static(method == 0):
                tw_c = ti.Vector([0.0] * 9)
                for m in ti.static(range(9)):
                    tw_c[m] = out.twist[c, m]
                twist[f, c] = tw_c


@ti.kernel
def assemble(method: ti.template(), nf: int, pos: A, face_verts: A, Dm_inv: A, grain: A,
             rest_area: A, params: A, g: A, grad: A, cm: A, what: A, kappa: A, twist: A):
    ti.loop_config(serialize=True)
    for _ in range(1):
        assemble_all(method, nf, pos, face_verts, Dm_inv, grain, rest_area, params, g, grad,
                     cm, what, kappa, twist)


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
def build_preconditioner(K, nv, nf, mu, margin, use_twist, mass: T, pinned: T,
                         face_verts: T, rest_area: T, lam: T, g: T,
                         grad: T, cm: T, what: T, kappa: T, twist: T, P_inv: T):
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
                if use_twist and s > 0.0:
                    tw = twist[f, c]
                    for n in ti.static(range(3)):
                        tn = ti.Vector([tw[3 * n], tw[3 * n + 1], tw[3 * n + 2]])
                        P_inv[ids[n]] += s * tn.outer_product(tn)
    for n in range(nv):
        if pinned[n] == 1:
            P_inv[n] = ti.Matrix.identity(float, 3)
        else:
            P_inv[n] = P_inv[n].inverse()


@ti.func
def apply_hessian(K, nv, nf, mu, margin, use_twist, mass: T, pinned: T, face_verts: T,
                  rest_area: T, lam: T, g: T, grad: T,
                  cm: T, what: T, kappa: T, twist: T, p: T, Ap: T):
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
                    if use_twist:
                        tw = twist[f, c]
                        scatter(Ap, ids, tw, s * tw.dot(pf))
    for n in range(nv):
        if pinned[n] == 1:
            Ap[n] = ti.Vector([0.0, 0.0, 0.0])


@ti.func
def pcg_direction(K, nv, nf, mu, max_cg, rtol, margin, use_twist, x: T, x_hat: T, mass: T,
                  pinned: T, face_verts: T, rest_area: T, lam: T, g: T, grad: T, cm: T,
                  what: T, kappa: T, twist: T, b: T, d: T, r: T, z: T, p: T, Ap: T, P_inv: T):
    """Projected-Newton direction: solve H d = -grad L_A by PCG (block Jacobi) from d = 0 to
    |r| <= rtol |grad L_A| (an inexact Newton step: measured on the hanging scene, rtol = 0.1
    needs as many Newton steps as 1e-3 with about half the CG iterations). Leaves
    b = -grad L_A; returns (slope grad L_A . d, CG iterations)."""
    residual(K, nv, nf, mu, x, x_hat, mass, pinned, face_verts, lam, g, grad, r)
    build_preconditioner(K, nv, nf, mu, margin, use_twist, mass, pinned, face_verts,
                         rest_area, lam, g, grad, cm, what, kappa, twist, P_inv)
    r0 = ti.sqrt(dot(r, r, nv))
    for n in range(nv):
        b[n] = r[n]
        d[n] = ti.Vector([0.0, 0.0, 0.0])
        z[n] = P_inv[n] @ r[n]
        p[n] = z[n]
    rz = dot(r, z, nv)
    it = 0
    while it < max_cg and ti.sqrt(dot(r, r, nv)) > rtol * r0:
        apply_hessian(K, nv, nf, mu, margin, use_twist, mass, pinned, face_verts, rest_area,
                      lam, g, grad, cm, what, kappa, twist, p, Ap)
        pAp = dot(p, Ap, nv)
        if pAp <= 0.0:
            break
        alpha = rz / pAp
        for n in range(nv):
            d[n] += alpha * p[n]
            r[n] -= alpha * Ap[n]
        it += 1
        for n in range(nv):
            z[n] = P_inv[n] @ r[n]
        rz_new = dot(r, z, nv)
        beta = rz_new / rz
        rz = rz_new
        for n in range(nv):
            p[n] = z[n] + beta * p[n]
    return -dot(b, d, nv), it


@ti.func
def violation_of(K, nf, rest_area: T, g: T):
    viol = 0.0
    for f in range(nf):
        sqa = ti.sqrt(rest_area[f])
        for c in range(K):
            viol = ti.max(viol, g[f, c] / sqa)
    return viol


@ti.kernel
def solve_al(method: ti.template(), K: int, nv: int, nf: int, mu0: float, mu_grow: float,
             mu_max: float, max_rounds: int, max_newton: int, max_cg: int, rtol: float,
             tol: float, step_tol: float, adaptive: int, params: A, x: A, x_hat: A,
             x_trial: A, mass: A, pinned: A, face_verts: A, Dm_inv: A, grain: A,
             rest_area: A, lam: A, g: A, grad: A, cm: A, what: A, kappa: A, twist: A, b: A,
             d: A, r: A, z: A, p: A, Ap: A, P_inv: A, stats: A):
    """The whole AL projection (METHOD 4) in one launch (measured: with one launch per
    phase, Python's argument handling cost as much as the solve): rounds of inexact
    minimisation of L_A by projected Newton + PCG with a backtracking (Armijo) line search,
    then lambda <- max(0, lambda + mu g) (eq. 27, capped at mu_max sqrt(a) so that an
    infeasible problem cannot grow it without bound across calls) and mu <- min(grow mu,
    mu_max), until the largest violation and the largest |delta lambda| / mu
    (complementarity) are below tol (strain units). Stops early, with every multiplier kept,
    if x (= x_hat) is already feasible. Fills stats (rounds, violation, converged, CG,
    Newton steps, complementarity)."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        use_twist = params[P_SVD_DELTA] > 0.0 and K == 4
        margin = params[P_MARGIN]
        mu = mu0
        rounds, newton, cg_total = 0, 0, 0
        viol, comp = 0.0, 0.0
        converged = 0
        # Line-search trials; the last one (alpha = 0) re-assembles at x when none passes, so
        # the constraints are always assembled at x after it (one inlined assembly only).
        for n in range(nv):
            x_trial[n] = x[n]
        first = 1
        while rounds < max_rounds and converged == 0:
            inner = 0
            while inner < max_newton:
                slope, cg_it = 0.0, 0
                L0 = 0.0
                if first == 0:
                    slope, cg_it = pcg_direction(K, nv, nf, mu, max_cg, rtol, margin,
                                                 use_twist, x, x_hat, mass, pinned,
                                                 face_verts, rest_area, lam, g, grad, cm,
                                                 what, kappa, twist, b, d, r, z, p, Ap,
                                                 P_inv)
                    cg_total += cg_it
                    newton += 1
                    inner += 1
                    L0 = merit(K, nv, nf, mu, x, x_hat, mass, lam, g)
                if first == 0 and not slope < 0.0:
                    break
                alpha, step, tries = 1.0, 0.0, 0
                while tries < 13:
                    a = alpha
                    if tries == 12 or first == 1:
                        a = 0.0
                    for n in range(nv):
                        x_trial[n] = x[n]
                        if a > 0.0:
                            x_trial[n] += a * d[n]
                    assemble_all(method, nf, x_trial, face_verts, Dm_inv, grain, rest_area,
                                 params, g, grad, cm, what, kappa, twist)
                    if a == 0.0:
                        break
                    L = merit(K, nv, nf, mu, x_trial, x_hat, mass, lam, g)
                    if L <= L0 + 1e-4 * a * slope:
                        for n in range(nv):
                            step = ti.max(step, (x_trial[n] - x[n]).norm())
                            x[n] = x_trial[n]
                        break
                    alpha *= 0.5
                    tries += 1
                if first == 1:
                    first = 0
                    viol = violation_of(K, nf, rest_area, g)
                    if viol < tol:
                        converged = 2       # feasible as given: nothing to do
                        break
                    continue
                if adaptive:
                    # Trust the exact active set more after a full step, widen it after a
                    # short one (``adaptive_margin``).
                    if alpha >= 1.0 and tries == 0:
                        margin *= 0.25
                    elif alpha < 0.25 or tries == 12:
                        margin = ti.min(ti.max(4.0 * margin, 1e-4), 0.1)
                if step < step_tol:
                    break
            if converged == 2:
                break
            viol, comp = 0.0, 0.0
            for f in range(nf):
                sqa = ti.sqrt(rest_area[f])
                for c in range(K):
                    new = ti.min(ti.max(0.0, lam[f, c] + mu * g[f, c]), mu_max * sqa)
                    viol = ti.max(viol, g[f, c] / sqa)
                    comp = ti.max(comp, ti.abs(new - lam[f, c]) / (mu * sqa))
                    lam[f, c] = new
            rounds += 1
            if viol < tol and comp < tol:
                converged = 1
            mu = ti.min(mu * mu_grow, mu_max)
        stats[ST_ITERS] = rounds
        stats[ST_VIOL] = viol
        stats[ST_CONVERGED] = ti.min(converged, 1)
        stats[ST_CG] = cg_total
        stats[ST_NEWTON] = newton
        stats[ST_COMP] = comp


@ti.kernel
def max_violation(K: int, nf: int, rest_area: A, g: A) -> float:
    viol = 0.0
    ti.loop_config(serialize=True)
    for _ in range(1):
        viol = violation_of(K, nf, rest_area, g)
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

