"""The augmented-Lagrangian solve of the strain limits in one kernel (docs/method.md §4, paper eqs.
25-27): constraint assembly, merit, residual, the PCG Newton direction with its
block-Jacobi preconditioner, multiplier updates, and the small bookkeeping kernels around it.
The funcs are in the order the kernel runs them; ``direct.py`` reuses them for its host loop.
Why one kernel and ndarray arguments: ``buffers.py``.
"""
import taichi as ti

from .buffers import (B_FROM_PREV, B_LATE_NEWTON, B_LATE_ROUND, B_MAX_CG, B_MAX_NEWTON,
                      B_MAX_ROUNDS, B_MU0, B_MU_GROW, B_MU_MAX, B_PC_MODE, B_RTOL, B_STEP_TOL,
                      B_TOL, CONTACT_SLOTS, CONVERGED, FEASIBLE_AS_GIVEN, LAST_TRY, N_STATS,
                      NO_CONTACT, NO_SKIP, P_CONTACT_SCALE, P_DELTA, P_INNER_RTOL, P_ISO, P_KKT_TOL,
                      P_MARGIN, P_PDAS, P_SHEAR, P_SVD_DELTA, P_WARP, P_WEFT, PC_FACTOR, PC_JACOBI,
                      PC_MULTIGRID, RUNNING, ST_CG, ST_COMP, ST_CONVERGED, ST_ITERS, ST_KKT,
                      ST_NEWTON, ST_START_VIOL, ST_TRIALS, ST_VIOL, A, T, ConstraintPack,
                      ContactPack, MeshPack, MetricPack, PrecondPack, StepPack, VectorPack)
from . import factor_precond, multigrid
from .constraints import MAPPING_PAIRS_BY_ALIGNMENT, face_constraints
from .families import MAPPING, SVD, WARP_WEFT
from .defaults import NEAR_POWER


# ---- constraint evaluation ---------------------------------------------------------------------
@ti.func
def eval_face(method: ti.template(), f, pos: T, mesh: T):
    """All constraints of face f at positions ``pos`` (mapping pairs ordered as
    families.MAPPING_PAIRS_BY_ALIGNMENT says)."""
    ids = mesh.face_verts[f]
    warp = ti.Vector([mesh.params[P_WARP], mesh.params[P_WARP + 1]])
    weft = ti.Vector([mesh.params[P_WEFT], mesh.params[P_WEFT + 1]])
    shear = ti.Vector([mesh.params[P_SHEAR], mesh.params[P_SHEAR + 1]])
    delta = mesh.params[P_SVD_DELTA] if ti.static(method == SVD) else mesh.params[P_DELTA]
    return face_constraints(method, pos[ids[0]], pos[ids[1]], pos[ids[2]], mesh.Dm_inv[f],
                            mesh.grain[f], ti.sqrt(mesh.rest_area[f]), warp, weft, shear,
                            delta, mesh.params[P_ISO], MAPPING_PAIRS_BY_ALIGNMENT)


@ti.func
def store_face(method: ti.template(), with_grad: ti.template(), f, pos: T, mesh: T, cons: T):
    """Face f's constraints under the family ``method`` (a compile-time id) at ``pos``: the
    values, and with ``with_grad`` their gradients and curvature models. The constraints come
    in bound pairs (c even, c + 1) with opposite gradients and the same cm and w^
    (constraints.py): only the even member's are stored (``pair_grad``). Why: writing the
    arrays, not computing them, was most of an assembly's cost (measured at 1.2k faces,
    mapping: 0.35 ms, of which 0.15 ms with the stores left out), and an assembly runs at
    every line-search trial."""
    out = eval_face(method, f, pos, mesh)
    for c in ti.static(range(out.g.n)):
        cons.g[f, c] = out.g[c]
        if ti.static(with_grad):
            cons.kappa[f, c] = out.kappa[c]
            if ti.static(c % 2 == 0):
                grad_c = ti.Vector([0.0] * 9)
                cm_c, what_c = ti.Vector([0.0] * 3), ti.Vector([0.0] * 3)
                for m in ti.static(range(9)):
                    grad_c[m] = out.grad[c, m]
                for m in ti.static(range(3)):
                    cm_c[m] = out.cm[c, m]
                    what_c[m] = out.what[c, m]
                cons.grad[f, c] = grad_c
                cons.cm[f, c] = cm_c
                cons.what[f, c] = what_c
            if ti.static(method == SVD):
                tw_c = ti.Vector([0.0] * 9)
                for m in ti.static(range(9)):
                    tw_c[m] = out.twist[c, m]
                cons.twist[f, c] = tw_c


@ti.func
def assemble_face(method, with_grad: ti.template(), f, pos: T, mesh: T, cons: T):
    """``store_face`` under the family whose id ``method`` is at run time. Why run time: one
    kernel serves the three families, so a switch of method compiles nothing, and a process
    that uses all three (the test suite, the comparison view) compiles the solve once, not
    three times. The price: every call site holds the three families, so a kernel with one
    call compiles longer than one family's did (``solve_al`` keeps two calls:
    docs/speed/first_run.md)."""
    if method == SVD:
        store_face(SVD, with_grad, f, pos, mesh, cons)
    elif method == WARP_WEFT:
        store_face(WARP_WEFT, with_grad, f, pos, mesh, cons)
    else:
        store_face(MAPPING, with_grad, f, pos, mesh, cons)


@ti.func
def assemble_all(method, nf, pos: T, mesh: T, cons: T):
    """Values, gradients and curvature models of every constraint at ``pos`` (``store_face``)."""
    for f in range(nf):
        assemble_face(method, True, f, pos, mesh, cons)


@ti.kernel
def assemble(method: ti.i32, pos: A, mesh: MeshPack, cons: ConstraintPack):
    ti.loop_config(serialize=True)
    for _ in range(1):
        assemble_all(method, mesh.n_faces, pos, mesh, cons)


@ti.kernel
def assemble_g(method: ti.i32, pos: A, mesh: MeshPack, cons: ConstraintPack):
    """The constraint values only (cons.g) at ``pos``: what the per-frame read-outs (the limits
    watch, metrics.csv) need, a fifth of ``assemble``'s work. A parallel loop: each face
    writes its own row, so the values do not depend on the thread count."""
    for f in range(mesh.n_faces):
        assemble_face(method, False, f, pos, mesh, cons)


# ---- augmented Lagrangian pieces (docs/method.md §4, paper eqs. 25-27) -------------------------
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
def max_norm(nv, a: T):
    """The largest |a_n| (a vertex vector's infinity norm over vertices)."""
    m = 0.0
    for n in range(nv):
        m = ti.max(m, a[n].norm())
    return m


@ti.func
def contact_normal(contact: T, n, j):
    c = contact[n, j]
    return ti.Vector([c[0], c[1], c[2]])


@ti.func
def contact_g(contact: T, pos: T, n, j):
    """Vertex n's contact constraint d - n.x <= 0 (metres, like g = strain x sqrt(a)): the
    vertex stays on the outer side of the obstacle's tangent plane at its contact point (the
    plane of the thickened surface, see ``Collider.contact_planes``). Linear in x, so it adds
    mu n n^T to the Newton matrix and no curvature."""
    return contact[n, j][3] - contact_normal(contact, n, j).dot(pos[n])


@ti.func
def stitch_g(stitch: T, pos: T, s):
    """Seam s's equality constraint x_a - x_b = 0 (metres, a 3-vector). Linear, so in the AL
    it adds mu (e_a - e_b)(e_a - e_b)^T to the Newton matrix and no curvature. (Measured on
    tshirt: the inequality |x_a - x_b| <= 2 mm instead, with its curvature 1/|x_a - x_b|,
    needed 96-190 AL rounds where the contacts and seams met.)"""
    ab = stitch[s]
    return pos[ab[0]] - pos[ab[1]]


@ti.func
def friction_state(n, mu, x: T, contacts: T):
    """Coulomb friction of vertex n against its nearest contact plane, as an AL term: the
    tangential displacement over the substep c_t = P (x - x_prev) (P = I - n n^T) is held at
    zero by a multiplier inside the disc of radius mu_f (lam_c1 + lam_c2) (the cone: the
    normal multipliers are the normal impulses, times h). Returns (P, y, radius) with
    y = P (lam_t + mu c_t); the friction force is -clamp(y, radius) (sticking inside the
    disc, sliding on its rim). radius = 0 where there is no contact or no friction."""
    f = contacts.fric[n]
    radius = 0.0
    P = ti.Matrix.identity(float, 3)
    y = ti.Vector([0.0, 0.0, 0.0])
    if f[3] > 0.0 and contacts.contact[n, 0][3] > 0.5 * NO_CONTACT:
        cn = contact_normal(contacts.contact, n, 0)
        P = ti.Matrix.identity(float, 3) - cn.outer_product(cn)
        radius = f[3] * (contacts.lam_c[n, 0] + contacts.lam_c[n, 1])
        y = P @ (contacts.lam_t[n] + mu * (x[n] - ti.Vector([f[0], f[1], f[2]])))
    return P, y, radius


@ti.func
def clamp_disc(y, radius):
    out = y
    ny = y.norm()
    if ny > radius:
        out = y * (radius / ny) if ny > 0.0 else y
    return out


@ti.func
def metric_row(n, w_ptr: T, w_col: T, w_val: T, a: T, b: T):
    """Row n of W (a - b), W the projection's metric (system_matrix.py: the masses for the
    paper's projection, the implicit step's matrix for coupling "implicit")."""
    acc = ti.Vector([0.0, 0.0, 0.0])
    for k in range(w_ptr[n], w_ptr[n + 1]):
        j = w_col[k]
        acc += w_val[k] @ (a[j] - b[j])
    return acc


@ti.func
def pair_grad(grad: T, f, c):
    """The gradient of constraint c of face f: stored for the even member of each bound
    pair, the odd member's is its negative (``assemble_all``)."""
    gr = grad[f, c - c % 2]
    if c % 2 == 1:
        gr = -gr
    return gr


@ti.func
def assemble_values(method, nf, pos: T, mesh: T, cons: T):
    """The values only of every constraint at ``pos`` (a fifth of ``assemble_all``'s cost at
    1.2k faces, mapping: the gradients are not computed)."""
    for f in range(nf):
        assemble_face(method, False, f, pos, mesh, cons)


@ti.func
def metric_times(n, w_ptr: T, w_col: T, w_val: T, p: T):
    """Row n of B p, B a block matrix in W's pattern with values ``w_val`` (W itself, or the
    Newton matrix H)."""
    acc = ti.Vector([0.0, 0.0, 0.0])
    for k in range(w_ptr[n], w_ptr[n + 1]):
        acc += w_val[k] @ p[w_col[k]]
    return acc


@ti.func
def merit(K, nv, nf, ns, mu, pos: T, x_hat: T, metric: T, cons: T, contacts: T):
    """L_A = 1/2 (x - x_hat)^T W (x - x_hat) + sum (mu/2) max(0, g + lam/mu)^2 - lam^2/(2 mu),
    the slack variables of eq. 25 eliminated, with g as last assembled (at ``pos``), over the
    strain and contact constraints; plus lam_s.c + (mu/2)|c|^2 for the seams' equalities and
    the friction term (``merit_constraints``)."""
    quad = 0.0
    for n in range(nv):
        quad += 0.5 * (pos[n] - x_hat[n]).dot(metric_row(n, metric.w_ptr, metric.w_col,
                                                         metric.w_val, pos, x_hat))
    return quad + merit_constraints(K, nv, nf, ns, mu, pos, cons, contacts)


@ti.func
def merit_constraints(K, nv, nf, ns, mu, pos: T, cons: T, contacts: T):
    """The constraint terms of ``merit`` (all but the metric's quadratic), at ``pos``."""
    total = 0.0
    for n in range(nv):
        for j in ti.static(range(CONTACT_SLOTS)):
            lam_c = contacts.lam_c[n, j]
            t = ti.max(0.0, contact_g(contacts.contact, pos, n, j) + lam_c / mu)
            total += 0.5 * mu * t * t - 0.5 * lam_c * lam_c / mu
    for k in range(ns):
        cs = stitch_g(contacts.stitch, pos, k)
        total += contacts.lam_s[k].dot(cs) + 0.5 * mu * cs.norm_sqr()
    for n in range(nv):
        # Friction: max over the disc of lam'.c_t - |lam' - lam_t|^2 / (2 mu), up to a
        # constant; its gradient is clamp(y, radius).
        _P, y, radius = friction_state(n, mu, pos, contacts)
        if radius > 0.0:
            ny = y.norm()
            if ny <= radius:
                total += 0.5 * ny * ny / mu
            else:
                total += (radius * ny - 0.5 * radius * radius) / mu
    for f in range(nf):
        for c in range(K):
            lam = cons.lam[f, c]
            t = ti.max(0.0, cons.g[f, c] + lam / mu)
            total += 0.5 * mu * t * t - 0.5 * lam * lam / mu
    return total


@ti.func
def metric_gradient(nv, pos: T, metric: T, vec: T):
    """vec.Wdx = W (pos - x_hat), the gradient of the merit's quadratic term (``residual``
    reads it; solve_al's line search keeps it up to date along its steps)."""
    for n in range(nv):
        vec.Wdx[n] = metric_row(n, metric.w_ptr, metric.w_col, metric.w_val, pos, vec.x_hat)


@ti.func
def metric_along(nv, pos: T, metric: T, vec: T):
    """vec.Ap = W d (d = vec.d), and the coefficients (e.We, d.We, d.Wd) of the merit's
    quadratic term along pos + a d (e = pos - x_hat, We = W e from vec.Wdx): 1/2 (e + a d)^T
    W (e + a d) = 1/2 e.We + a d.We + a^2/2 d.Wd for symmetric W (``quad_at``)."""
    eWe, dWe, dWd = 0.0, 0.0, 0.0
    for n in range(nv):
        vec.Ap[n] = metric_times(n, metric.w_ptr, metric.w_col, metric.w_val, vec.d)
        eWe += (pos[n] - vec.x_hat[n]).dot(vec.Wdx[n])
        dWe += vec.d[n].dot(vec.Wdx[n])
        dWd += vec.d[n].dot(vec.Ap[n])
    return ti.Vector([eWe, dWe, dWd])


@ti.func
def quad_at(quad, a):
    """The merit's quadratic term at x + a d from ``metric_along``'s coefficients."""
    return 0.5 * quad[0] + a * quad[1] + 0.5 * a * a * quad[2]


@ti.func
def residual(K, nv, nf, ns, mu, x: T, mesh: T, cons: T, contacts: T, vec: T):
    """vec.r = -grad L_A at x = -W (x - x_hat) - sum max(0, lam + mu g) grad g; zero at pins.
    W (x - x_hat) is read from vec.Wdx (``metric_gradient``)."""
    for n in range(nv):
        vec.r[n] = -vec.Wdx[n]
        for j in ti.static(range(CONTACT_SLOTS)):
            s = contacts.lam_c[n, j] + mu * contact_g(contacts.contact, x, n, j)
            if s > 0.0:
                vec.r[n] += s * contact_normal(contacts.contact, n, j)  # grad (d - n.x) = -n
    for f in range(nf):
        ids = mesh.face_verts[f]
        for c in range(K):
            s = cons.lam[f, c] + mu * cons.g[f, c]
            if s > 0.0:
                scatter(vec.r, ids, pair_grad(cons.grad, f, c), -s)
    for k in range(ns):
        force = contacts.lam_s[k] + mu * stitch_g(contacts.stitch, x, k)
        vec.r[contacts.stitch[k][0]] -= force
        vec.r[contacts.stitch[k][1]] += force
    for n in range(nv):
        _P, y, radius = friction_state(n, mu, x, contacts)
        if radius > 0.0:
            vec.r[n] -= clamp_disc(y, radius)
    for n in range(nv):
        if mesh.pinned[n] == 1:
            vec.r[n] = ti.Vector([0.0, 0.0, 0.0])


@ti.func
def near_weight(s, near):
    """Weight of a constraint's Gauss-Newton term in the Newton model: 1 when active (s > 0),
    falling to 0 across the margin as the NEAR_POWER-th power of the closeness (s + near) /
    near. With the full weight on every constraint within the margin the model is stiffer
    than L_A, and at rest the inner loop stagnated (exact Cholesky steps lowered the residual
    by ~2 % each); ramped, the model changes continuously as a constraint approaches
    (measured on hanging, implicit coupling, mapping, mean KE over frames 120-150: resolution
    9 3.3e-7 -> 6.6e-8 J, resolution 25 7.2e-7 -> 1.1e-7 J). Ramped linearly, faces far inside
    their bands still stiffened it enough to hold a tight-band cloth where it was
    (defaults.NEAR_POWER says by how much)."""
    w = 1.0
    if s <= 0.0:
        w = ((s + near) / near) ** NEAR_POWER if near > 0.0 else 0.0
    return w


@ti.func
def newton_matrix(K, nv, nf, ns, mu, margin, c_scale, use_twist, x: T, mesh: T,
                  metric: T, cons: T, contacts: T):
    """The projected-Newton matrix of L_A at x, written out in W's block pattern (which
    must hold every face and seam pair: ``system_matrix.build_pattern``):

        H = W + sum_near w mu grad g grad g^T + sum_active (lam + mu g) curvature(g)
            + mu n n^T (contacts within the margin) + the seams' and friction's terms.

    "Near" includes constraints within ``margin`` (strain) of activating, with the weight w
    of ``near_weight``: a Newton step that ignores them runs straight into dozens of them
    (measured on a 10x10 sheet: 112 of 486 constraints switched on within 1e-3 of a step)
    and the line search then accepts only tiny steps; with the margin the same projection
    needs 6 instead of > 40 rounds. The curvature is the model of constraints.py (the
    curvature of ||F e|| with e frozen, plus svd's twist term). Pinned rows and columns
    become the identity (their step is zero).

    Why written out rather than applied face by face: one PCG iteration is then a single
    block-sparse product; measured at 4k faces (mapping, 8 constraints a face) the product
    costs 0.14 ms against 0.33-0.36 ms for the face-by-face operator, and the ~1 ms of
    assembly is repaid by the ~20 iterations of a Newton step."""
    I = ti.Matrix.identity(float, 3)
    copied = 0          # rows 0..copied-1 of H hold W's values (below)
    for f in range(nf):
        # H = W row by row, each row just before the first face that adds to it: the rows are
        # then in cache when the face's blocks land (measured at 64.8k faces, where H is 40
        # MB: 22 against 30 ms for the whole matrix, the same values).
        ids = mesh.face_verts[f]
        last = ti.max(ids[0], ti.max(ids[1], ids[2]))
        while copied <= last:
            for k in range(metric.w_ptr[copied], metric.w_ptr[copied + 1]):
                metric.H[k] = metric.w_val[k]
            copied += 1
        near = mu * margin * ti.sqrt(mesh.rest_area[f])
        # The face's constraint terms, summed first; symmetric, so only the blocks (a, b) with
        # a <= b are formed (Hf's lower block triangle stays unused).
        Hf = ti.Matrix.zero(float, 9, 9)
        any_near = False
        for c in range(K):
            s = cons.lam[f, c] + mu * cons.g[f, c]
            if s + near > 0.0:
                any_near = True
                # The pair's shared entries (the sign of grad drops out of grad grad^T).
                e = c - c % 2
                gr, cmv, w = cons.grad[f, e], cons.cm[f, e], cons.what[f, e]
                sc = ti.max(s, 0.0)
                wmu = near_weight(s, near) * mu
                for a in ti.static(range(3)):
                    for b in ti.static(range(a, 3)):
                        for i in ti.static(range(3)):
                            for j in ti.static(range(3)):
                                Hf[3 * a + i, 3 * b + j] += wmu * gr[3 * a + i] * gr[3 * b + j]
                if sc > 0.0:
                    # Curvature of ||F e||: (cm_a cm_b) kappa (I - w w^T) per block (a, b).
                    proj = sc * cons.kappa[f, c] * (I - w.outer_product(w))
                    for a in ti.static(range(3)):
                        for b in ti.static(range(a, 3)):
                            for i in ti.static(range(3)):
                                for j in ti.static(range(3)):
                                    Hf[3 * a + i, 3 * b + j] += cmv[a] * cmv[b] * proj[i, j]
                    if use_twist:
                        tw = cons.twist[f, c]
                        for a in ti.static(range(3)):
                            for b in ti.static(range(a, 3)):
                                for i in ti.static(range(3)):
                                    for j in ti.static(range(3)):
                                        Hf[3 * a + i, 3 * b + j] += sc * tw[3 * a + i] * \
                                            tw[3 * b + j]
        if any_near:
            for a in ti.static(range(3)):
                for b in ti.static(range(a, 3)):
                    blk = ti.Matrix([[Hf[3 * a + i, 3 * b + j] for j in ti.static(range(3))]
                                     for i in ti.static(range(3))])
                    metric.H[metric.face_slot[f, 3 * a + b]] += blk
                    if ti.static(a < b):
                        metric.H[metric.face_slot[f, 3 * b + a]] += blk.transpose()
    while copied < nv:
        for k in range(metric.w_ptr[copied], metric.w_ptr[copied + 1]):
            metric.H[k] = metric.w_val[k]
        copied += 1
    for n in range(nv):
        for j in ti.static(range(CONTACT_SLOTS)):
            gc = contact_g(contacts.contact, x, n, j)
            if contacts.lam_c[n, j] + mu * (gc + margin * c_scale) > 0.0:
                cn = contact_normal(contacts.contact, n, j)
                metric.H[metric.w_diag[n]] += mu * cn.outer_product(cn)
        # Friction: mu P sticking; on the rim, the curvature of radius |y| (mu radius / |y|
        # times P off the sliding direction).
        P, y, radius = friction_state(n, mu, x, contacts)
        if radius > 0.0:
            ny = y.norm()
            if ny <= radius:
                metric.H[metric.w_diag[n]] += mu * P
            else:
                yh = y / ny
                metric.H[metric.w_diag[n]] += (mu * radius / ny) * (P - yh.outer_product(yh))
    for k in range(ns):
        metric.H[metric.stitch_slot[k, 0]] += mu * I
        metric.H[metric.stitch_slot[k, 1]] += -mu * I
        metric.H[metric.stitch_slot[k, 2]] += -mu * I
        metric.H[metric.stitch_slot[k, 3]] += mu * I
    for i in range(nv):
        for k in range(metric.w_ptr[i], metric.w_ptr[i + 1]):
            j = metric.w_col[k]
            if mesh.pinned[i] == 1 or mesh.pinned[j] == 1:
                metric.H[k] = I if i == j else ti.Matrix.zero(float, 3, 3)


@ti.func
def precondition(pc_mode, nv, pc: T, r: T, z: T):
    """z = P^-1 r; returns r.z. P by ``pc_mode``: PC_JACOBI, H's 3x3 diagonal blocks (their
    inverses in P_inv); PC_MULTIGRID, the aggregation multigrid of multigrid.py (arrays
    mg_int, mg_real, mg_block); PC_FACTOR, a sparse Cholesky factor P H~ P^T = L L^T of a
    matrix like H in 3x3 blocks over a vertex ordering (``factor_precond.apply``)."""
    if pc_mode == PC_FACTOR:
        factor_precond.apply(nv, pc.f_perm, pc.f_ptr, pc.f_idx, pc.f_val, pc.f_work, r, z)
    elif pc_mode == PC_MULTIGRID:
        multigrid.apply(nv, pc.mg_int, pc.mg_real, pc.mg_block, r, z)
    else:
        for n in range(nv):
            z[n] = pc.P_inv[n] @ r[n]
    rz = 0.0
    for n in range(nv):
        rz += r[n].dot(z[n])
    return rz


@ti.func
def newton_direction(pdas: ti.template(), K, nv, nf, ns, mu, max_cg, rtol, margin, use_twist, c_scale, pc_mode, mesh: T,
                     metric: T, cons: T, contacts: T, vec: T, pc: T):
    """pcg_direction's matrix and PCG solve at vec.x, with r = -grad L_A already in vec.r
    (and, in a kernel compiled with ``pdas``, the active-set re-solves when params[P_PDAS] is
    set; vec.x_trial is their scratch)."""
    newton_matrix(K, nv, nf, ns, mu, margin, c_scale, use_twist, vec.x, mesh, metric, cons,
                  contacts)
    rr = 0.0
    for n in range(nv):
        if pc_mode == PC_JACOBI:
            pc.P_inv[n] = metric.H[metric.w_diag[n]].inverse()   # pinned rows: the identity
        vec.b[n] = vec.r[n]
        vec.d[n] = ti.Vector([0.0, 0.0, 0.0])
        rr += vec.r[n].dot(vec.r[n])
    slope, it = 0.0, 0
    if ti.static(pdas):
        slope, it = pdas_resolves(K, nv, nf, mu, max_cg, rtol, rr, pc_mode, mesh, metric,
                                  cons, contacts, vec, pc, cons.kappa, vec.x_trial)
    else:
        it = pcg_loop(False, 0, K, nv, nf, mu, max_cg, rtol, rr, pc_mode, mesh, metric, cons,
                      contacts, vec, pc, vec.x_trial, cons.kappa)
        slope = -dot(vec.b, vec.d, nv)
    return slope, it


# ---- the primal-dual active-set step (strain.solve = "exact", PCG) -----------------------
# At most this many solves per Newton step while the predicted active set keeps changing
# (active_set.MAX_RESOLVES, the host version's).
PDAS_SOLVES = 6
# Each round's Newton loop runs to this fraction of the kkt tolerance before the multiplier
# update (with the kkt tolerance itself the rounds ended after one step), and the penalty
# grows only in a round whose violation did not fall below PDAS_STALL times the last
# round's (grown every round, it reached 1e4-1e5 x its start within one projection and the
# line search cut steps to 1/256: docs/history/motion.md section 5).
PDAS_INNER_FRACTION = 0.1
PDAS_STALL = 0.25


@ti.func
def face_step(face_verts: T, v: T, f):
    """The 9-vector of v at face f's three vertices."""
    ids = face_verts[f]
    a, b_, c = v[ids[0]], v[ids[1]], v[ids[2]]
    return ti.Vector([a[0], a[1], a[2], b_[0], b_[1], b_[2], c[0], c[1], c[2]])


@ti.func
def pdas_changes(K, nv, nf, mu, mesh: T, cons: T, contacts: T, vec: T, prev: T, first,
                 flip: T):
    """How many constraints the linearised step d = vec.d switches relative to the set the
    last solve used (the set active at x = vec.x when ``first``, else the one predicted from
    ``prev``); writes flip[f, c] = (active after d) - (active at x) in {-1, 0, 1} for the faces
    (the contacts' are recomputed where needed: ``pdas_contact_flip``)."""
    changes = 0
    for f in range(nf):
        jd = face_step(mesh.face_verts, vec.d, f)
        jp = face_step(mesh.face_verts, prev, f)
        for c in range(K):
            t = cons.g[f, c] + cons.lam[f, c] / mu
            gr = pair_grad(cons.grad, f, c)
            now = 1 if t > 0.0 else 0
            new = 1 if t + gr.dot(jd) > 0.0 else 0
            old = now
            if not first:
                old = 1 if t + gr.dot(jp) > 0.0 else 0
            if new != old:
                changes += 1
            flip[f, c] = float(new - now)
    for n in range(nv):
        if mesh.pinned[n] == 0:
            for j in ti.static(range(CONTACT_SLOTS)):
                cn = contact_normal(contacts.contact, n, j)
                t = (contacts.lam_c[n, j] + mu * contact_g(contacts.contact, vec.x, n, j)) / mu
                now = 1 if t > 0.0 else 0
                new = 1 if t - cn.dot(vec.d[n]) > 0.0 else 0
                old = now
                if not first:
                    old = 1 if t - cn.dot(prev[n]) > 0.0 else 0
                if new != old:
                    changes += 1
    return changes


@ti.func
def pdas_contact_flip(mu, contact: T, lam_c: T, x: T, prev: T, n, j):
    """(active after the step ``prev``) - (active at x) of vertex n's contact slot j, and t."""
    cn = contact_normal(contact, n, j)
    t = (lam_c[n, j] + mu * contact_g(contact, x, n, j)) / mu
    now = 1.0 if t > 0.0 else 0.0
    new = 1.0 if t - cn.dot(prev[n]) > 0.0 else 0.0
    return new - now, t


@ti.func
def pdas_times(K, nv, nf, mu, mesh: T, metric: T, cons: T, contacts: T, vec: T, prev: T,
               flip: T):
    """vec.Ap = (H + mu sum_c flip_c J_c^T J_c) vec.p: the Newton matrix with the Gauss-Newton
    terms of the predicted set in place of those of the set active at x (``flip``,
    ``prev``)."""
    for n in range(nv):
        vec.Ap[n] = metric_times(n, metric.w_ptr, metric.w_col, metric.H, vec.p)
    for f in range(nf):
        ids = mesh.face_verts[f]
        jp = face_step(mesh.face_verts, vec.p, f)
        for pair in range(K // 2):
            # A bound pair shares its gradient up to sign; at most one of the two is active.
            c = 2 * pair
            w = flip[f, c] + flip[f, c + 1]
            if w != 0.0:
                gr = cons.grad[f, c]
                scatter(vec.Ap, ids, gr, mu * w * gr.dot(jp))
    for n in range(nv):
        if mesh.pinned[n] == 1:
            vec.Ap[n] = ti.Vector([0.0, 0.0, 0.0])
        else:
            for j in ti.static(range(CONTACT_SLOTS)):
                fl, _t = pdas_contact_flip(mu, contacts.contact, contacts.lam_c, vec.x, prev,
                                           n, j)
                if fl != 0.0:
                    cn = contact_normal(contacts.contact, n, j)
                    vec.Ap[n] += (mu * fl * cn.dot(vec.p[n])) * cn


@ti.func
def pdas_resolves(K, nv, nf, mu, max_cg, rtol, rr, pc_mode, mesh: T, metric: T, cons: T,
                  contacts: T, vec: T, pc: T, flip: T, prev: T):
    """The Newton step's PCG solves in a kernel compiled with the active-set step
    (cloth/strain/active_set.py, here in the kernels with PCG). The first solves with the set
    active at x (H's own, margin 0) from d = 0, b = -grad L_A in r (|r|^2 = rr). When
    params[P_PDAS] is set, then, while the step switches constraints on or off, solve again
    with the Gauss-Newton terms and forces of the set it predicts, t + J d > 0 (t = g +
    lambda / mu), at most PDAS_SOLVES times; a re-solved step that is not a descent direction
    is replaced by the first solve's. ``flip`` (kappa's storage, free once H is assembled)
    and ``prev`` (x_trial's, free until the line search) are scratch. Every solve goes
    through one PCG call (a ti.func is inlined at each call site). Returns (slope, CG
    iterations)."""
    total = 0
    k = 0                    # solves made
    back = False             # solving the first solve's system again
    slope = 0.0
    while True:
        flipped = 0
        if k > 0:
            flipped = 1
            if not back:
                changed = 0
                if k < PDAS_SOLVES:
                    changed = pdas_changes(K, nv, nf, mu, mesh, cons, contacts, vec, prev,
                                           k == 1, flip)
                if changed == 0:
                    slope = -dot(vec.b, vec.d, nv)
                    if k > 1 and not slope < 0.0:
                        back = True
                    else:
                        break
            if back:
                # Back to the first solve: the set active at x (no flips).
                for f in range(nf):
                    for c in range(K):
                        flip[f, c] = 0.0
                for n in range(nv):
                    prev[n] = ti.Vector([0.0, 0.0, 0.0])
                    vec.r[n] = vec.b[n]
            else:
                for n in range(nv):
                    prev[n] = vec.d[n]
                # rhs = b - mu sum_c flip_c t_c J_c^T (faces; contacts' J = -n).
                for n in range(nv):
                    vec.r[n] = vec.b[n]
                for f in range(nf):
                    ids = mesh.face_verts[f]
                    for c in range(K):
                        if flip[f, c] != 0.0:
                            t = cons.g[f, c] + cons.lam[f, c] / mu
                            scatter(vec.r, ids, pair_grad(cons.grad, f, c),
                                    -mu * flip[f, c] * t)
                for n in range(nv):
                    if mesh.pinned[n] == 1:
                        vec.r[n] = ti.Vector([0.0, 0.0, 0.0])
                    else:
                        for j in ti.static(range(CONTACT_SLOTS)):
                            fl, t = pdas_contact_flip(mu, contacts.contact, contacts.lam_c,
                                                      vec.x, prev, n, j)
                            if fl != 0.0:
                                vec.r[n] += (mu * fl * t) * contact_normal(contacts.contact,
                                                                           n, j)
            # PCG from d = 0 on pdas_times' matrix with the rhs in r (H's preconditioner).
            rr = 0.0
            for n in range(nv):
                vec.d[n] = ti.Vector([0.0, 0.0, 0.0])
                rr += vec.r[n].dot(vec.r[n])
        total += pcg_loop(True, flipped, K, nv, nf, mu, max_cg, rtol, rr, pc_mode, mesh,
                          metric, cons, contacts, vec, pc, prev, flip)
        k += 1
        if k == 1:
            slope = -dot(vec.b, vec.d, nv)
            if not mesh.params[P_PDAS] > 0.0:
                break
        if back:
            slope = -dot(vec.b, vec.d, nv)
            break
    return slope, total


@ti.func
def pcg_loop(pdas: ti.template(), flipped, K, nv, nf, mu, max_cg, rtol, rr, pc_mode,
             mesh: T, metric: T, cons: T, contacts: T, vec: T, pc: T, prev: T, flip: T):
    """The PCG iterations of a Newton step, from d = 0 with the residual in r (|r|^2 = rr)
    to |r| <= rtol |r0| (d, r and the work vectors z, p, Ap in ``vec``): on H, or, with
    ``flipped`` = 1 in a kernel compiled with ``pdas``, on ``pdas_times``' matrix (H with the
    predicted set's Gauss-Newton terms; ``prev``, ``flip``). Returns the iterations."""
    # One call site of the preconditioner (it is inlined where it is called, and the
    # multigrid's cycle is large): z = P r at the top of every pass, the first pass's p = z.
    stop = rtol * rtol * rr
    it = -1
    rz = 0.0
    while True:
        rz_new = precondition(pc_mode, nv, pc, vec.r, vec.z)
        if it < 0:
            for n in range(nv):
                vec.p[n] = vec.z[n]
        else:
            beta = rz_new / rz
            for n in range(nv):
                vec.p[n] = vec.z[n] + beta * vec.p[n]
        rz = rz_new
        it += 1
        if not (it < max_cg and rr > stop):       # (a NaN residual stops too)
            break
        pAp = 0.0
        if ti.static(pdas):
            if flipped == 1:
                pdas_times(K, nv, nf, mu, mesh, metric, cons, contacts, vec, prev, flip)
            else:
                for n in range(nv):
                    vec.Ap[n] = metric_times(n, metric.w_ptr, metric.w_col, metric.H, vec.p)
        else:
            for n in range(nv):
                vec.Ap[n] = metric_times(n, metric.w_ptr, metric.w_col, metric.H, vec.p)
        for n in range(nv):
            pAp += vec.p[n].dot(vec.Ap[n])
        if pAp <= 0.0:
            break
        alpha = rz / pAp
        rr = 0.0
        for n in range(nv):
            vec.d[n] += alpha * vec.p[n]
            vec.r[n] -= alpha * vec.Ap[n]
            rr += vec.r[n].dot(vec.r[n])
    return it


@ti.func
def pcg_direction(pdas: ti.template(), K, nv, nf,
                  ns, mu, max_cg, rtol, margin, use_twist, c_scale, pc_mode, skip_rr, mesh: T,
                  metric: T, cons: T, contacts: T, vec: T, pc: T):
    """Projected-Newton direction at vec.x: solve H d = -grad L_A (H from ``newton_matrix``)
    by PCG with H's 3x3 diagonal blocks as preconditioner (block Jacobi), from d = 0 to
    |r| <= rtol |grad L_A| (an inexact Newton step: measured on the hanging scene, rtol = 0.1
    needs as many Newton steps as 1e-3 with about half the CG iterations). Leaves
    b = -grad L_A; returns (slope grad L_A . d, CG iterations, |grad L_A|^2). With
    |grad L_A|^2 <= skip_rr no step is computed (d = 0, slope 0)."""
    residual(K, nv, nf, ns, mu, vec.x, mesh, cons, contacts, vec)
    rr0 = dot(vec.r, vec.r, nv)
    slope, it = 0.0, 0
    if rr0 > skip_rr:
        slope, it = newton_direction(pdas, K, nv, nf, ns, mu, max_cg, rtol,
                                     margin, use_twist, c_scale, pc_mode, mesh, metric, cons,
                                     contacts, vec, pc)
    else:
        for n in range(nv):
            vec.d[n] = ti.Vector([0.0, 0.0, 0.0])
    return slope, it, rr0


@ti.func
def violation_of(K, nf, rest_area: T, g: T):
    viol = 0.0
    for f in range(nf):
        sqa = ti.sqrt(rest_area[f])
        for c in range(K):
            viol = ti.max(viol, g[f, c] / sqa)
    return viol


@ti.func
def vertex_violation(nv, ns, pos: T, contact: T, stitch: T, c_scale):
    """Largest contact or seam violation in strain-like units (metres / c_scale, the typical
    edge)."""
    viol = 0.0
    for n in range(nv):
        for j in ti.static(range(CONTACT_SLOTS)):
            viol = ti.max(viol, contact_g(contact, pos, n, j) / c_scale)
    for k in range(ns):
        viol = ti.max(viol, stitch_g(stitch, pos, k).norm() / c_scale)
    return viol


@ti.func
def update_multipliers(K, nv, nf, ns, mu, mu_max, c_scale, x: T, mesh: T, cons: T,
                       contacts: T):
    """The multiplier step of eq. 27, lam <- max(0, lam + mu g) (capped at mu_max sqrt(a), so
    an infeasible problem cannot grow it without bound across calls), for the strain,
    contact, seam and friction multipliers, with g as last assembled (at x). Returns the
    largest violation and the largest |delta lambda| / mu (complementarity), in strain
    units."""
    viol, comp = 0.0, 0.0
    for f in range(nf):
        sqa = ti.sqrt(mesh.rest_area[f])
        for c in range(K):
            new = ti.min(ti.max(0.0, cons.lam[f, c] + mu * cons.g[f, c]), mu_max * sqa)
            viol = ti.max(viol, cons.g[f, c] / sqa)
            comp = ti.max(comp, ti.abs(new - cons.lam[f, c]) / (mu * sqa))
            cons.lam[f, c] = new
    for n in range(nv):
        for j in ti.static(range(CONTACT_SLOTS)):
            gc = contact_g(contacts.contact, x, n, j)
            new = ti.min(ti.max(0.0, contacts.lam_c[n, j] + mu * gc), mu_max * c_scale)
            viol = ti.max(viol, gc / c_scale)
            comp = ti.max(comp, ti.abs(new - contacts.lam_c[n, j]) / (mu * c_scale))
            contacts.lam_c[n, j] = new
    for k in range(ns):
        cs = stitch_g(contacts.stitch, x, k)
        new = contacts.lam_s[k] + mu * cs               # equality: either sign
        cap = mu_max * c_scale
        if new.norm() > cap:
            new *= cap / new.norm()
        viol = ti.max(viol, cs.norm() / c_scale)
        contacts.lam_s[k] = new
    for n in range(nv):
        # Friction multipliers: the trial, clamped to the cone of the new normal
        # multipliers (zero where there is no contact).
        _P, y, radius = friction_state(n, mu, x, contacts)
        contacts.lam_t[n] = clamp_disc(y, radius)
    return viol, comp


# solve_al's start, in phases of its Newton loop (``first``). START_VALUES: the constraint
# values only at the given x (x_hat, on a projection's first call), by the line search's trial
# evaluation: they decide whether there is anything to do. Then, with ``from_prev``,
# START_CANDIDATE: x = the step's start x_prev = x_hat - h v, each vertex moved on at its last
# velocity when that is above the settle speed (``start_candidate``; pinned vertices stay),
# assembled, and kept when its merit is below the given x's; else, or without from_prev,
# START_GIVEN: the given x, assembled. NEWTON: the Newton steps. So the kernel has two
# constraint assemblies, not three: a ti.func is inlined at every call, and the kernel's
# compile time grows with its size (the three families at each call since the method is a
# run-time choice).
#
# Why x_prev: in the implicit step's metric a cloth at rest is a fixed point, so x_prev is
# then the solution itself (one round, one Newton step), while x_hat lies a whole sag away
# (12-17 % strain past the band on the soft cloth) and Newton has to travel back across the
# constraints' curvature. Why moved on: the default solve stops once the limits hold, so its
# answer lies near its start. A sheet landing on a sphere (its landing vertices stopped by the
# collision pass, the rest still falling: x_hat stretched, x_prev the lower merit) was held in
# the air from x_prev, keeping 0.3 % of its kinetic energy through the landing (exact Newton
# steps keep 72 %; docs/speed/motion_error.md). x_hat as the start drapes too, but costs a
# resting cloth 10x; a start halfway between, chosen by merit, was held like x_prev; running
# the first round's Newton loop to its end instead of to INNER_RTOL draped 5 of 7 drops.
NEWTON, START_VALUES, START_CANDIDATE, START_GIVEN = 0, 1, 2, 3


@ti.kernel
def solve_al(method: ti.i32, with_pdas: ti.template(), budget: A,
             mesh: MeshPack, metric: MetricPack, cons: ConstraintPack, contacts: ContactPack,
             vec: VectorPack, pc: PrecondPack, stats: A):
    """The whole AL projection (docs/method.md §4) in one launch (measured: with one launch per
    phase, Python's argument handling cost as much as the solve): rounds of inexact
    minimisation of L_A by projected Newton + PCG with a backtracking (Armijo) line search,
    then lambda <- max(0, lambda + mu g) (eq. 27, capped at mu_max sqrt(a) so that an
    infeasible problem cannot grow it without bound across calls) and mu <- min(grow mu,
    mu_max), until the largest violation and the largest |delta lambda| / mu
    (complementarity) are below tol (strain units). Stops early, with every multiplier kept,
    if x (= x_hat) is already feasible. Fills stats (rounds, violation, converged, CG,
    Newton steps, complementarity, line-search trials). The solve's controls (penalty,
    budgets, tolerances, preconditioner) are read from ``budget`` (buffers.B_*).

    ``with_pdas`` compiles the active-set re-solves in (strain.solve = "exact"
    under PCG). They are a template, not only a runtime switch, because inlined into every
    solve they tripled the optimised compile of the default solve (svd: 261 s with them,
    91 s before they were added, on the 2-core CPU); a kernel without them is the default's."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        K, nv, nf, ns = cons.n_per_face, mesh.n_verts, mesh.n_faces, contacts.n_stitches
        use_twist = mesh.params[P_SVD_DELTA] > 0.0 and method == SVD
        margin = mesh.params[P_MARGIN]
        c_scale = mesh.params[P_CONTACT_SCALE]
        mu_grow, mu_max = budget[B_MU_GROW], budget[B_MU_MAX]
        max_rounds = ti.cast(budget[B_MAX_ROUNDS], ti.i32)
        max_newton = ti.cast(budget[B_MAX_NEWTON], ti.i32)
        late_round = ti.cast(budget[B_LATE_ROUND], ti.i32)
        late_newton = ti.cast(budget[B_LATE_NEWTON], ti.i32)
        max_cg = ti.cast(budget[B_MAX_CG], ti.i32)
        rtol, tol, step_tol = budget[B_RTOL], budget[B_TOL], budget[B_STEP_TOL]
        from_prev = ti.cast(budget[B_FROM_PREV], ti.i32)
        pc_mode = ti.cast(budget[B_PC_MODE], ti.i32)
        mu = budget[B_MU0]
        rounds, newton, cg_total, trials = 0, 0, 0, 0
        viol, comp = 0.0, 0.0
        converged = RUNNING
        # The KKT stop (``kkt_tol`` > 0): a round that ends feasible (violation and multiplier
        # change below tol) only proposes convergence; the next round's first Newton step,
        # computed with the new multipliers, must then move no vertex further than kkt_tol.
        # That step is the distance to the minimiser as far as the Newton model sees it, so
        # the stop bounds stationarity, not only feasibility.
        kkt_tol = mesh.params[P_KKT_TOL]
        # The active-set step's matrix is the merit's Hessian: each round's Newton loop runs
        # to a tenth of the kkt tolerance before the multipliers move, and the penalty grows
        # only when the violation stalls (direct.py's INNER_FRACTION and STALL, measured there).
        pdas = mesh.params[P_PDAS] > 0.0
        inner_kkt = kkt_tol * (PDAS_INNER_FRACTION if pdas else 1.0)
        last_viol = 1e30
        proposed = 0
        kkt = 0.0
        for n in range(nv):
            vec.x_trial[n] = vec.x[n]
        first = START_VALUES
        L_hat = 0.0
        # The merit at x, kept from the line search that reached x until the multipliers or
        # the penalty change (saves one merit evaluation per Newton step).
        L_x, L_known = 0.0, 0
        while rounds < max_rounds and converged == RUNNING:
            inner = 0
            rr_first = 0.0
            d_max = 0.0
            newton_cap = max_newton
            if rounds >= late_round:
                newton_cap = late_newton
            while inner < newton_cap:
                slope, cg_it, step = 0.0, 0, 0.0
                L0 = 0.0
                if first == START_CANDIDATE or first == START_GIVEN:
                    # The start's choice (``START_VALUES``): the candidate, assembled at the
                    # end of the last pass, is kept when its merit is below the given x's.
                    if first == START_CANDIDATE and not merit(K, nv, nf, ns, mu, vec.x,
                                                              vec.x_hat, metric, cons,
                                                              contacts) < L_hat:
                        for n in range(nv):
                            vec.x[n] = vec.x_trial[n]   # the given x (START_VALUES' trial)
                        first = START_GIVEN         # assembled below
                    else:
                        first = NEWTON
                        metric_gradient(nv, vec.x, metric, vec)
                        continue
                else:
                    if first == NEWTON:
                        skip = NO_SKIP
                        if inner > 0:
                            skip = mesh.params[P_INNER_RTOL] ** 2 * rr_first
                        slope, cg_it, rr = pcg_direction(with_pdas, K, nv, nf, ns, mu, max_cg,
                                                         rtol, margin, use_twist, c_scale,
                                                         pc_mode, skip, mesh, metric, cons,
                                                         contacts, vec, pc)
                        if inner == 0:
                            rr_first = rr
                        cg_total += cg_it
                        newton += 1
                        inner += 1
                        d_max = max_norm(nv, vec.d)
                        if inner == 1:
                            kkt = d_max
                            if proposed == 1 and d_max <= kkt_tol:
                                converged = CONVERGED   # stationary with these multipliers
                                break
                            proposed = 0
                    if first == NEWTON and not slope < 0.0:
                        break
                    # The merit's quadratic term along x + a d from W d, computed once (into
                    # Ap, free after the PCG): a trial costs no product with W (17 blocks a
                    # vertex with bending: 40 MB at 64.8k faces). Wdx follows x along accepted
                    # steps.
                    quad = ti.Vector([0.0, 0.0, 0.0])
                    if first == NEWTON:
                        quad = metric_along(nv, vec.x, metric, vec)
                        if L_known == 1:
                            L0 = L_x
                        else:
                            L0 = quad_at(quad, 0.0) + merit_constraints(K, nv, nf, ns, mu,
                                                                        vec.x, cons, contacts)
                    # Trials assemble the constraint values only; the gradients and curvature
                    # are assembled once, at the point reached (measured at 64.8k faces: 5
                    # against 20 ms an assembly, and up to 2-3 trials a Newton step there).
                    alpha, tries = 1.0, 0
                    while tries <= LAST_TRY:
                        a = alpha
                        if tries == LAST_TRY or first == START_VALUES:
                            a = 0.0
                        for n in range(nv):
                            vec.x_trial[n] = vec.x[n]
                            if a > 0.0:
                                vec.x_trial[n] += a * vec.d[n]
                        if a == 0.0 and first == NEWTON:
                            break               # no step passed: x stays
                        # (START_VALUES: the given x's values decide whether there is anything to
                        # do and, with from_prev, where to start.)
                        assemble_values(method, nf, vec.x_trial, mesh, cons)
                        if a == 0.0:
                            break
                        trials += 1
                        L = quad_at(quad, a) + merit_constraints(K, nv, nf, ns, mu,
                                                                 vec.x_trial, cons, contacts)
                        if L <= L0 + 1e-4 * a * slope:
                            for n in range(nv):
                                step = ti.max(step, (vec.x_trial[n] - vec.x[n]).norm())
                                vec.x[n] = vec.x_trial[n]
                                vec.Wdx[n] += a * vec.Ap[n]
                            L_x, L_known = L, 1
                            break
                        alpha *= 0.5
                        tries += 1
                    if first == START_VALUES:
                        viol = ti.max(violation_of(K, nf, mesh.rest_area, cons.g),
                                      vertex_violation(nv, ns, vec.x, contacts.contact,
                                                       contacts.stitch, c_scale))
                        stats[ST_START_VIOL] = viol
                        if viol < tol:
                            converged = FEASIBLE_AS_GIVEN
                            break
                        first = START_GIVEN         # assembled below
                        if from_prev:
                            L_hat = merit(K, nv, nf, ns, mu, vec.x, vec.x_hat, metric, cons,
                                          contacts)
                            for n in range(nv):
                                if mesh.pinned[n] == 0:
                                    vec.x[n] = vec.Wdx[n]       # the start candidate
                            first = START_CANDIDATE     # assembled below
                # Gradients and curvature at x (the step's end, or x again after a failed
                # search, whose trials overwrote the values).
                assemble_all(method, nf, vec.x, mesh, cons)
                if first == NEWTON and (step < step_tol or
                                        (kkt_tol > 0.0 and d_max <= inner_kkt)):
                    break
            if converged != RUNNING:
                break
            viol, comp = update_multipliers(K, nv, nf, ns, mu, mu_max, c_scale, vec.x, mesh,
                                            cons, contacts)
            L_known = 0
            rounds += 1
            if viol < tol and comp < tol:
                if kkt_tol > 0.0:
                    proposed = 1
                else:
                    converged = CONVERGED
            # The penalty grows only while the limits are not met (under the KKT stop a
            # feasible round continues for stationarity, which a stiffer penalty only slows).
            grow = not (kkt_tol > 0.0 and viol < tol)
            if pdas and viol < PDAS_STALL * last_viol:
                grow = False
            last_viol = viol
            if grow:
                mu = ti.min(mu * mu_grow, mu_max)
        stats[ST_ITERS] = rounds
        stats[ST_VIOL] = viol
        stats[ST_CONVERGED] = 0 if converged == RUNNING else 1
        stats[ST_CG] = cg_total
        stats[ST_NEWTON] = newton
        stats[ST_COMP] = comp
        stats[ST_TRIALS] = trials
        stats[ST_KKT] = kkt


@ti.kernel
def max_violation(K: int, nf: int, rest_area: A, g: A) -> float:
    viol = 0.0
    ti.loop_config(serialize=True)
    for _ in range(1):
        viol = violation_of(K, nf, rest_area, g)
    return viol


@ti.func
def moving_share(v_last, extrapolate, settle):
    """How much of a vertex counts as moving, from its last projection's velocity: 0 below
    ``settle`` m/s, rising smoothly to 1 at 4 x settle (1 at every speed when settle is 0;
    0 without ``extrapolate``, when there is no last velocity)."""
    share = 0.0
    if extrapolate:
        share = 1.0
        if settle > 0.0:
            t = ti.min(ti.max((v_last.norm() - settle) / (3.0 * settle), 0.0), 1.0)
            share = t * t * (3.0 - 2.0 * t)
    return share


@ti.func
def near_obstacle(contacts: ti.template(), n):
    """Whether vertex n has a contact plane this projection (an obstacle within reach)."""
    return contacts.contact[n, 0][3] > 0.5 * NO_CONTACT


@ti.func
def start_candidate(n, xp, h, extrapolate, settle, step_start, io: ti.template(),
                    contacts: ti.template()):
    """solve_al's start candidate (START_CANDIDATE) for vertex n: x_prev = x_hat - h v
    (``xp``), moved on by h v_last in the vertex's ``moving_share``. With ``step_start``, a vertex near an
    obstacle starts instead, in the share that is not moving, where the substep truly began
    (io.x_step): the obstacle pass between the dynamics and the projection stopped it
    without the matching change of x, so its x_hat - h v lies where it never was (on the
    resting drape 0.10-0.17 strain past the limits, where x_step met them to 4e-6)."""
    share = moving_share(io.v_last[n], extrapolate, settle)
    out = xp + share * h * io.v_last[n]
    if step_start and near_obstacle(contacts, n):
        out = share * out + (1.0 - share) * io.x_step[n]
    return out


@ti.kernel
def reset_start(nv: int, h: float, extrapolate: int, settle: float, step_start: int,
                io: StepPack, vec: VectorPack, contacts: ContactPack):
    """``begin_solve``'s start candidates again (a projection solved again from its start:
    the first solve used their array, ``Wdx``, for W (x - x_hat))."""
    for n in range(nv):
        xp = io.x_in[n] - h * io.v_in[n]
        vec.Wdx[n] = start_candidate(n, xp, h, extrapolate, settle, step_start, io, contacts)


@ti.kernel
def begin_solve(nv: int, h: float, friction: int, clear: int, extrapolate: int,
                settle: float, step_start: int, io: StepPack, vec: VectorPack,
                contacts: ContactPack, stats: A):
    """Set up a projection from the model's state (x_in, v_in): x = x_hat = x_start = x_in,
    v = v_in; fric = (anchor, mu_f) per vertex, the anchor where the substep began (x_prev =
    x_hat - h v, or x_step near an obstacle), mu_f = 0 (no friction) unless ``friction``;
    vec.Wdx = the start candidates (``start_candidate``); with ``clear`` no contact half-spaces. One launch instead of five
    (each costs ~0.1 ms: a tenth of a resting 1.2k-face projection's host time)."""
    ti.loop_config(serialize=True)
    for n in range(nv):
        vec.x[n] = io.x_in[n]
        io.v[n] = io.v_in[n]
        vec.x_hat[n] = io.x_in[n]
        io.x_start[n] = io.x_in[n]
        xp = io.x_in[n] - h * io.v_in[n]
        if clear:
            for j in ti.static(range(CONTACT_SLOTS)):
                contacts.contact[n, j] = ti.Vector([0.0, 0.0, 0.0, NO_CONTACT])
        # (The start candidates live in Wdx until solve_al's start reads them there.)
        vec.Wdx[n] = start_candidate(n, xp, h, extrapolate, settle, step_start, io, contacts)
        # Friction holds the displacement over the substep, so its anchor is where the
        # substep began. Near an obstacle that is, in the share of the vertex that is not
        # moving (as in start_candidate and finish_solve), x_step: the obstacle pass moved x
        # without the matching v, so x_hat - h v lies where the vertex never was, and
        # friction pulled it there (measured: drape's strain limiting 20.5 -> 16.3 ms a frame
        # with x_step; with the x_hat start, a tabard's shoulders were held 24 % past their
        # limits until the penalty threw its chest 12 cm). A moving vertex keeps x_hat - h v:
        # its velocity after the pass is the impact's, friction included.
        anchor = xp
        if step_start and near_obstacle(contacts, n):
            still = 1.0 - moving_share(io.v_last[n], extrapolate, settle)
            anchor += still * (io.x_step[n] - xp)
        mu_f = contacts.contact_mu[n] if friction else 0.0
        contacts.fric[n] = ti.Vector([anchor[0], anchor[1], anchor[2], mu_f])
    for i in range(N_STATS):
        stats[i] = 0.0


@ti.kernel
def copy_vectors(n: int, src: A, dst: A):
    for i in range(n):
        dst[i] = src[i]


@ti.kernel
def finish_solve(nv: int, h: float, cap: float, extrapolate: int, settle: float,
                 step_start: int, x: A, io: StepPack, contacts: ContactPack):
    """v += dx / h (docs/method.md §4): the projection's correction becomes a velocity change, of at
    most ``cap`` (m/s) per vertex when cap > 0; x and v are copied to x_in and v_in (the
    model's state) and v to v_last (the next projection's start, ``begin_solve``).

    With ``step_start``, a vertex near an obstacle takes, in the share of it that is not
    moving (``moving_share``), the velocity of its whole substep, (x - x_step) / h, instead:
    v + dx / h counts the obstacle pass's stop as motion (it changed v, not x), and on a
    resting drape that left the sheet jittering (4e-5 J at resolution 25, where this rests
    at ~1e-6 J). Moving vertices keep v + dx / h: their velocity after the obstacle pass is
    the impact (the normal velocity removed), which (x - x_step) / h would undo, damping
    the landing (measured: 0.019 against 0.038 J a frame after it, docs/history/motion.md
    section 10)."""
    ti.loop_config(serialize=True)
    for n in range(nv):
        if h > 0.0:
            dv = (x[n] - io.x_start[n]) / h
            if step_start and near_obstacle(contacts, n):
                still = 1.0 - moving_share(io.v_last[n], extrapolate, settle)
                dv += still * ((x[n] - io.x_step[n]) / h - io.v[n] - dv)
            if cap > 0.0 and dv.norm() > cap:
                dv *= cap / dv.norm()
            io.v[n] += dv
        io.x_in[n] = x[n]
        io.v_in[n] = io.v[n]
        io.v_last[n] = io.v[n]
