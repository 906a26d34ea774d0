"""The augmented-Lagrangian projection with its loop on the host and exact Newton steps: each
inner step assembles the projected-Newton matrix as a 3x3-block sparse matrix and solves it by
a sparse Cholesky factorisation (``linalg.SparseCholesky``, reused as a CG preconditioner until
a step needs a fresh one), whose symbolic analysis is kept until the mesh changes.

Used where the one-kernel PCG solve (``al.solve_al``) is not: the exact solve of a cloth with
seams (the active-set step, ``active_set.py``, needs exact linear solves at the seams'
equalities) and the Vulkan and Metal back ends (the one long kernel crashed Debian's software
Vulkan driver). The AL itself is ``solve_al``'s: the same merit function, residual, line
search, multiplier step and stopping rule, from the kernels of ``al.py``.
"""
import os

import numpy as np
import taichi as ti

from .. import backend
from . import active_set
from . import al
from .al import (SVD, assemble_all, merit, metric_gradient,
                 newton_matrix, residual, update_multipliers, vertex_violation, violation_of)
from .buffers import (LAST_TRY, P_CONTACT_SCALE, P_MARGIN, P_SVD_DELTA,
                      PC_JACOBI, ST_CG, ST_COMP, ST_CONVERGED, ST_ITERS, ST_KKT, ST_NEWTON,
                      ST_START_VIOL, ST_VIOL, A, ConstraintPack, ContactPack, MeshPack,
                      MetricPack, T, VectorPack)

# LOOM_DEBUG_DIRECT=1 prints every Newton step (residual, step, line-search alpha).
_DEBUG = bool(os.environ.get("LOOM_DEBUG_DIRECT"))
# The active-set model raises the penalty only in a round whose violation did not fall below
# STALL times the last round's, and runs each round's Newton loop to INNER_FRACTION of the
# kkt tolerance: the kernels' rules (al.py), one definition.
STALL, INNER_FRACTION = al.PDAS_STALL, al.PDAS_INNER_FRACTION
# Rounds the active-set model gets before ``solve`` falls back on the margin model (converged
# projections took 2-8 rounds on hanging at resolutions 9 and 25, svd and warp-weft).
ACTIVE_SET_ROUNDS = 30
# Indices into the direct solver's ``info`` array (I_MERIT and I_LOOPS: the split kernels').
I_SLOPE, I_STEP, I_VIOL, I_COMP, I_ALPHA, I_MERIT, I_LOOPS = range(7)


@ti.kernel
def newton_system(method: ti.i32, mu: float, mesh: MeshPack, metric: MetricPack,
                  cons: ConstraintPack, contacts: ContactPack, vec: VectorPack):
    """vec.r = -grad L_A (via vec.Wdx = W (x - x_hat), a work vector) and the projected-Newton
    matrix H (``al.newton_matrix``: the matrix the PCG path's Newton steps solve with, in W's
    block pattern)."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        K, nv, nf, ns = cons.n_per_face, mesh.n_verts, mesh.n_faces, contacts.n_stitches
        metric_gradient(nv, vec.x, metric, vec)
        residual(K, nv, nf, ns, mu, vec.x, mesh, cons, contacts, vec)
        use_twist = mesh.params[P_SVD_DELTA] > 0.0 and method == SVD
        newton_matrix(K, nv, nf, ns, mu, mesh.params[P_MARGIN], mesh.params[P_CONTACT_SCALE],
                      use_twist, vec.x, mesh, metric, cons, contacts)


@ti.kernel
def line_search(method: ti.i32, mu: float, mesh: MeshPack, metric: MetricPack,
                cons: ConstraintPack, contacts: ContactPack, vec: VectorPack, info: A):
    """Backtracking (Armijo) along vec.d from vec.x (vec.r = -grad L_A there), as in
    ``solve_al``; leaves the constraints assembled at the new x. info: slope, largest vertex
    move, alpha (0: no step taken)."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        K, nv, nf, ns = cons.n_per_face, mesh.n_verts, mesh.n_faces, contacts.n_stitches
        slope = 0.0
        for n in range(nv):
            slope -= vec.r[n].dot(vec.d[n])
        L0 = merit(K, nv, nf, ns, mu, vec.x, vec.x_hat, metric, cons, contacts)
        alpha, step, tries, taken = 1.0, 0.0, 0, 0.0
        while tries <= LAST_TRY:
            a = alpha
            if tries == LAST_TRY or not slope < 0.0:
                a = 0.0
            for n in range(nv):
                vec.x_trial[n] = vec.x[n] + a * vec.d[n]
            assemble_all(method, nf, vec.x_trial, mesh, cons)
            if a == 0.0:
                break
            L = merit(K, nv, nf, ns, mu, vec.x_trial, vec.x_hat, metric, cons, contacts)
            if L <= L0 + 1e-4 * a * slope:
                for n in range(nv):
                    step = ti.max(step, (vec.x_trial[n] - vec.x[n]).norm())
                    vec.x[n] = vec.x_trial[n]
                taken = a
                break
            alpha *= 0.5
            tries += 1
        info[I_SLOPE] = slope
        info[I_STEP] = step
        info[I_ALPHA] = taken


@ti.kernel
def multipliers(mu: float, mu_max: float, x: A, mesh: MeshPack, cons: ConstraintPack,
                contacts: ContactPack, info: A):
    ti.loop_config(serialize=True)
    for _ in range(1):
        K, nv, nf, ns = cons.n_per_face, mesh.n_verts, mesh.n_faces, contacts.n_stitches
        viol, comp = update_multipliers(K, nv, nf, ns, mu, mu_max, mesh.params[P_CONTACT_SCALE],
                                        x, mesh, cons, contacts)
        info[I_VIOL] = viol
        info[I_COMP] = comp


def packs(lim, metric, K):
    """The argument packs of the limiter ``lim``'s work arrays with the metric ``metric`` and
    K constraints a face: (mesh, metric, constraints, contacts, vectors), the direct kernels'
    arguments."""
    ws = lim._ws
    return (ws.mesh_pack(), ws.metric_pack(metric), ws.constraint_pack(K), ws.contact_pack(),
            ws.vector_pack())


def _multiplier_packs(ws, K):
    """The packs of the multiplier step (``multipliers``): mesh, constraints, contacts."""
    return ws.mesh_pack(), ws.constraint_pack(K), ws.contact_pack()


def fill_newton_system(lim, mid, K, mu, metric):
    """``newton_system`` on the limiter's work arrays at ws.x (constraints assembled there):
    the residual into ws.r, the Newton matrix values into ws.H."""
    m = lim.model
    if split_kernels():
        nv, nf = m.n_verts, m.n_faces
        pk, info = packs(lim, metric, K), lim._ws.info
        newton_rhs(mu, 2, *pk, info)
        check_loops(info.to_numpy(), "newton_rhs", nv, nf)
        newton_lhs(mid, mu, 2, *pk, info)
        check_loops(info.to_numpy(), "newton_lhs", nv, nf)
        return
    newton_system(mid, mu, *packs(lim, metric, K))


def solve(lim, mid, K, metric, chol, mu, mu_max, step_tol, margin_mu=None):
    """The AL loop of ``al.solve_al`` with exact Newton steps, for the StrainLimiter
    ``lim`` (its work arrays, settings and model). ``metric``: a BlockMatrix holding every face
    and seam pair; ``chol``: a ``linalg.SparseCholesky`` for that pattern. Returns (rounds,
    Newton steps, converged) and fills ``ws.stats`` like ``solve_al``.

    Under the exact solve (the active-set model) a projection that has not converged in
    ``ACTIVE_SET_ROUNDS`` rounds is solved again from its start with the margin model (initial
    penalty ``margin_mu``; ``lim.last_fallback`` says so). Why: the mapping family's
    constraints are not smooth (near isotropy its principal frame turns; measured on hanging
    at resolution 25, the merit rose by 4.9e-7 J over a 18 micrometre step where its quadratic
    model predicted -2.9e-8 J), Newton steps stall there, the penalty grows, and without the
    fallback the solve diverged (the sheet flew up)."""
    lim.last_fallback = False
    if not lim._exact():
        return _solve(lim, mid, K, metric, chol, mu, mu_max, step_tol, False, lim.max_rounds)
    multipliers_in = lim.multipliers()
    out = _solve(lim, mid, K, metric, chol, mu, mu_max, step_tol, True,
                 min(ACTIVE_SET_ROUNDS, lim.max_rounds))
    if out[2] or margin_mu is None:
        return out
    lim.restart_from(multipliers_in)
    lim._upload_params(margin_fallback=True)
    try:
        rounds, newton, converged = _solve(lim, mid, K, metric, chol, margin_mu, mu_max,
                                           step_tol, False, lim.max_rounds)
    finally:
        lim._upload_params()
    return out[0] + rounds, out[1] + newton, converged


def _solve(lim, mid, K, metric, chol, mu, mu_max, step_tol, active_set_model, max_rounds):
    """``solve``'s AL loop with one Newton model, at most ``max_rounds`` rounds."""
    ws, m = lim._ws, lim.model
    nv, nf = m.n_verts, m.n_faces
    info = ws.info
    from_prev = int(metric is lim._system)
    split = split_kernels()
    choose_start(lim, mid, K, mu, from_prev, metric)
    stats = ws.read_stats()
    if stats[ST_START_VIOL] < lim.tol:
        stats[ST_CONVERGED], stats[ST_VIOL] = 1, stats[ST_START_VIOL]
        ws.stats.from_numpy(stats)
        return 0, 0, True
    rounds = newton = cg_total = factorizations = solves = 0
    last_viol = np.inf
    if active_set_model:
        face_slot = metric.face_slot.to_numpy()[:nf]
        w_diag = metric.diag.to_numpy()[:nv]
    converged = False
    viol = comp = 0.0
    n3 = 3 * nv
    # The KKT stop, as in al.solve_al: a feasible round proposes convergence, the next
    # round's first Newton step must then move no vertex further than kkt_tol.
    kkt_tol = lim.kkt_length
    proposed, kkt = False, 0.0
    # A round's Newton loop ends when its step is below inner_tol: the kkt tolerance, or with
    # the active-set model a tenth of it, so each round's minimisation is finished before its
    # multiplier update (with the kkt tolerance itself the rounds ended after one Newton
    # step, the violation fell too slowly and the penalty grew until the line search stalled;
    # hanging at resolution 25, svd).
    inner_tol = kkt_tol * (INNER_FRACTION if active_set_model else 1.0)
    while rounds < max_rounds and not converged:
        for inner in range(lim.newton_budget(PC_JACOBI)):
            fill_newton_system(lim, mid, K, mu, metric)
            r0 = ws.r.to_numpy()[:nv]
            H0 = ws.H.to_numpy()[: metric.nnz]

            def solve_values(val, rhs):
                nonlocal cg_total, factorizations
                sol, iters, fresh = chol.solve_reusing(val, rhs.reshape(n3))
                cg_total += iters
                factorizations += int(fresh)
                return sol.reshape(nv, 3)

            if active_set_model:
                lc = active_set.LinearisedConstraints(lim, K, mu)
                d, resolves, _settled = active_set.step(lc, H0, r0, solve_values, face_slot,
                                                        w_diag)
                solves += resolves
            else:
                d = solve_values(H0, r0)
                solves += 1
            step = np.zeros((ws.d.shape[0], 3))
            step[:nv] = d
            newton += 1
            d_max = float(np.linalg.norm(step[:nv], axis=1).max()) if nv else 0.0
            if inner == 0:
                kkt = d_max
                if proposed and d_max <= kkt_tol:
                    converged = True            # stationary with these multipliers
                    break
                proposed = False
            ws.d.from_numpy(step)
            if split:
                out = line_search_split(lim, mid, K, mu, metric)
            else:
                line_search(mid, mu, *packs(lim, metric, K), info)
                out = info.to_numpy()
            if _DEBUG:
                print(f"  round {rounds} newton {newton}: |r| {np.linalg.norm(r0):.3e} alpha "
                      f"{out[I_ALPHA]:.3g} step {out[I_STEP]:.3e} slope {out[I_SLOPE]:.3e} mu {mu:.3g}")
            if out[I_ALPHA] == 0.0 or out[I_STEP] < step_tol or (kkt_tol > 0 and
                                                                  d_max <= inner_tol):
                break
        if converged:
            break
        if split:
            multipliers_checked(mu, mu_max, 2, ws.x, *_multiplier_packs(ws, K), info)
            out = info.to_numpy()
            check_loops(out, "multipliers", nv, nf)
        else:
            multipliers(mu, mu_max, ws.x, *_multiplier_packs(ws, K), info)
            out = info.to_numpy()
        viol, comp = float(out[I_VIOL]), float(out[I_COMP])
        rounds += 1
        if _DEBUG:
            print(f" round {rounds - 1} ends: violation {viol:.3e} complementarity {comp:.3e}")
        feasible = viol < lim.tol and comp < lim.tol
        if kkt_tol > 0:
            proposed = feasible
        else:
            converged = feasible
        if active_set_model:
            # The penalty grows only when the violation stalled (the textbook AL's rule:
            # multiplier updates alone converge while it falls by a factor each round). Grown
            # every round, as the margin model's is, it reached 1e4-1e5 x its start within a
            # projection on hanging at resolution 25, where the merit is so curved along the
            # Newton steps that the line search cut them to 1/256 and the solve diverged.
            if not viol < lim.tol and not viol <= STALL * last_viol:
                mu = min(mu * lim.mu_grow, mu_max)
            last_viol = viol
        elif not (kkt_tol > 0 and viol < lim.tol):
            mu = min(mu * lim.mu_grow, mu_max)
    stats[ST_ITERS], stats[ST_VIOL], stats[ST_COMP] = rounds, viol, comp
    stats[ST_CONVERGED], stats[ST_NEWTON] = float(converged), newton
    stats[ST_CG] = cg_total
    stats[ST_KKT] = kkt
    lim.last_factorizations = factorizations
    lim.last_solves = solves
    ws.stats.from_numpy(stats)
    return rounds, newton, converged


# ---- loop-capped back ends (Vulkan, Metal: backend.HOST_LOOP_AL) ----------------------------
# Mesa's llvmpipe, which runs Debian's software Vulkan (lavapipe), ends every loop of a shader
# invocation once that invocation has run 65535 loop iterations in all, its loops together
# (gallivm's LP_MAX_TGSI_LOOP_ITERATIONS, "shared between every loop"), and carries on after
# the loops: no error, just work left undone. The kernels above are one serial thread each. On
# the hanging scene at resolution 25 (625 vertices, 1152 faces, mapping) line_search ran into
# it from its fourth trial on (15.3k iterations before the first trial, 16.5k a trial): a step
# accepted at alpha 0.125 reported alpha 0.125 but never moved x (step 0), and the AL diverged:
# 100 rounds every frame, violation 0.07, 0.19, 0.33 over frames 1-3. newton_system reached the
# cap as well (25.7k iterations for the residual, 40.3k for the matrix), but only in the last
# ~500 iterations of its pass over pinned rows, on rows without pins: its r and H matched the
# split launches' below bit for bit there; at a few more vertices it would not. Resolution 20
# (400 vertices: newton_system 40.8k) held its limits. (Measured on lavapipe, Mesa 22.3.6,
# with a probe since removed, `git log -- benchmarks/loop_cap.py`: each phase once more,
# followed by a counting loop of 2^20 iterations, which stops at 65535 minus what the phase
# used.)
#
# Here the same work runs in launches that each stay below the cap at that size: the Newton
# system in two (the residual, the matrix), the line search's and the start choice's trials one
# launch each with their loops on the host; the arithmetic is the kernels' above, in the same
# order (forced onto the CPU, the split path follows the unsplit one to 1e-11 m over a frame in
# f64; fast-math rounding then lets the AL's branches drift apart). Every launch ends with
# ``loops_ran``, which notices the cap (a loop of ``two`` iterations then runs once), and the
# host stops with LoopCapError instead of returning a wrong projection: the matrix launch, ~65
# loop iterations a vertex, reaches the cap at ~1000 vertices (resolution 31 runs, 32 stops).
# Measured on hanging at resolution 25: 4, 4, 3 rounds and violation 1.3e-5, 3.7e-5, 9.1e-5
# over frames 1-3 (before: 100 rounds, 0.071, 0.19, 0.33), 2.5 and 1.7 s for frames 2 and 3
# (before: 17.9 and 16.6 s). GPU drivers have no such cap; the CPU never takes this path.
LOOP_CAP = backend.LOOP_CAP
TRIAL_STEP, TRIAL_X, TRIAL_START = 0, 1, 2
# What one ``trial`` launch does: where the trial point is (mode, TRIAL_*), and whether it
# assembles the constraints and evaluates the merit there. (Integers only: a float member's
# type would be fixed when the pack type is made, before ti.init chooses the precision.)
TrialPack = ti.types.argpack(mode=ti.i32, assemble=ti.i32, evaluate=ti.i32)


LoopCapError = backend.LoopCapError     # (one class for every kernel that probes the cap)


def split_kernels():
    """Whether the direct path runs in the split launches (``LOOP_CAP``)."""
    return backend.arch() in backend.HOST_LOOP_AL


def check_loops(out, kernel, nv, nf):
    """Raise LoopCapError unless ``out`` (an info array read back) says that every loop of
    ``kernel`` ran (``loops_ran``)."""
    backend.check_loop_probe(out[I_LOOPS], f"strain kernel {kernel}",
                             f"{nv} vertices, {nf} faces", 31)


@ti.func
def loops_ran(two, info: T):
    """info[I_LOOPS] = 2 when a loop of ``two`` (= 2, a run-time value: a constant count is
    unrolled and escapes the cap) iterations runs in full, 1 once the driver's loop cap was hit
    (llvmpipe runs a capped loop's body once)."""
    info[I_LOOPS] = backend.loop_probe(two)


@ti.kernel
def start_values(method: ti.i32, two: int, mesh: MeshPack, cons: ConstraintPack,
                 contacts: ContactPack, vec: VectorPack, stats: A, info: A):
    """``choose_start``'s first part: the constraints at x (= x_hat) and the start violation."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        K, nv, nf, ns = cons.n_per_face, mesh.n_verts, mesh.n_faces, contacts.n_stitches
        assemble_all(method, nf, vec.x, mesh, cons)
        stats[ST_START_VIOL] = ti.max(violation_of(K, nf, mesh.rest_area, cons.g),
                                      vertex_violation(nv, ns, vec.x, contacts.contact,
                                                       contacts.stitch,
                                                       mesh.params[P_CONTACT_SCALE]))
        loops_ran(two, info)


@ti.kernel
def line_start(mu: float, two: int, mesh: MeshPack, metric: MetricPack, cons: ConstraintPack,
               contacts: ContactPack, vec: VectorPack, info: A):
    """``line_search``'s start: the slope along vec.d and the merit at x."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        K, nv, nf, ns = cons.n_per_face, mesh.n_verts, mesh.n_faces, contacts.n_stitches
        slope = 0.0
        for n in range(nv):
            slope -= vec.r[n].dot(vec.d[n])
        info[I_SLOPE] = slope
        info[I_MERIT] = merit(K, nv, nf, ns, mu, vec.x, vec.x_hat, metric, cons, contacts)
        loops_ran(two, info)


@ti.kernel
def trial(method: ti.i32, mu: float, a: float, two: int, what: TrialPack,
          mesh: MeshPack, metric: MetricPack, cons: ConstraintPack, contacts: ContactPack,
          vec: VectorPack, info: A):
    """One trial point of ``line_search`` or ``choose_start``: vec.x_trial = x + a d
    (what.mode TRIAL_STEP), x (TRIAL_X) or the start candidate vec.Wdx at unpinned vertices
    (TRIAL_START); with ``what.assemble`` the constraints there, with ``what.evaluate`` the
    merit there into info[I_MERIT]."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        K, nv, nf, ns = cons.n_per_face, mesh.n_verts, mesh.n_faces, contacts.n_stitches
        for n in range(nv):
            if what.mode == TRIAL_STEP:
                vec.x_trial[n] = vec.x[n] + a * vec.d[n]
            else:
                vec.x_trial[n] = vec.x[n]
                if what.mode == TRIAL_START and mesh.pinned[n] == 0:
                    vec.x_trial[n] = vec.Wdx[n]
        if what.assemble:
            assemble_all(method, nf, vec.x_trial, mesh, cons)
        if what.evaluate:
            info[I_MERIT] = merit(K, nv, nf, ns, mu, vec.x_trial, vec.x_hat, metric, cons,
                                  contacts)
        loops_ran(two, info)


@ti.kernel
def accept(nv: int, two: int, vec: VectorPack, info: A):
    """x = x_trial; info[I_STEP] = the largest vertex move."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        step = 0.0
        for n in range(nv):
            step = ti.max(step, (vec.x_trial[n] - vec.x[n]).norm())
            vec.x[n] = vec.x_trial[n]
        info[I_STEP] = step
        loops_ran(two, info)


@ti.kernel
def newton_rhs(mu: float, two: int, mesh: MeshPack, metric: MetricPack, cons: ConstraintPack,
               contacts: ContactPack, vec: VectorPack, info: A):
    """``newton_system``'s first part: vec.Wdx and the residual vec.r."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        K, nv, nf, ns = cons.n_per_face, mesh.n_verts, mesh.n_faces, contacts.n_stitches
        metric_gradient(nv, vec.x, metric, vec)
        residual(K, nv, nf, ns, mu, vec.x, mesh, cons, contacts, vec)
        loops_ran(two, info)


@ti.kernel
def newton_lhs(method: ti.i32, mu: float, two: int, mesh: MeshPack, metric: MetricPack,
               cons: ConstraintPack, contacts: ContactPack, vec: VectorPack, info: A):
    """``newton_system``'s second part: the Newton matrix."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        K, nv, nf, ns = cons.n_per_face, mesh.n_verts, mesh.n_faces, contacts.n_stitches
        use_twist = mesh.params[P_SVD_DELTA] > 0.0 and method == SVD
        newton_matrix(K, nv, nf, ns, mu, mesh.params[P_MARGIN], mesh.params[P_CONTACT_SCALE],
                      use_twist, vec.x, mesh, metric, cons, contacts)
        loops_ran(two, info)


@ti.kernel
def multipliers_checked(mu: float, mu_max: float, two: int, x: A, mesh: MeshPack,
                        cons: ConstraintPack, contacts: ContactPack, info: A):
    """``multipliers`` with ``loops_ran``."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        K, nv, nf, ns = cons.n_per_face, mesh.n_verts, mesh.n_faces, contacts.n_stitches
        viol, comp = update_multipliers(K, nv, nf, ns, mu, mu_max, mesh.params[P_CONTACT_SCALE],
                                        x, mesh, cons, contacts)
        info[I_VIOL] = viol
        info[I_COMP] = comp
        loops_ran(two, info)


def _trial(lim, mid, K, mu, metric, a, mode, assemble, evaluate):
    """Launch ``trial`` and return the info array read back."""
    ws, m = lim._ws, lim.model
    what = ws.pack("trial", TrialPack, mode=mode, assemble=assemble, evaluate=evaluate)
    trial(mid, mu, a, 2, what, *packs(lim, metric, K), ws.info)
    out = ws.info.to_numpy()
    check_loops(out, "trial", m.n_verts, m.n_faces)
    return out


def _accept(lim):
    m, info = lim.model, lim._ws.info
    accept(m.n_verts, 2, lim._ws.vector_pack(), info)
    out = info.to_numpy()
    check_loops(out, "accept", m.n_verts, m.n_faces)
    return out


def choose_start(lim, mid, K, mu, from_prev, metric):
    """The constraints at x_hat and the start violation (``start_values``); then, unless x_hat
    is feasible, the start point as ``al.solve_al`` chooses it (al.START_VALUES): with
    ``from_prev`` the start candidate (in vec.Wdx) when its merit is below x_hat's. A few
    launches (each ~0.1 ms), against a host loop's factorisations."""
    ws, m = lim._ws, lim.model
    mesh, _met, cons, contacts, vec = packs(lim, metric, K)
    start_values(mid, 2, mesh, cons, contacts, vec, ws.stats, ws.info)
    check_loops(ws.info.to_numpy(), "start_values", m.n_verts, m.n_faces)
    if not (from_prev and ws.read_stats()[ST_START_VIOL] >= lim.tol):
        return
    L_hat = _trial(lim, mid, K, mu, metric, 0.0, TRIAL_X, 0, 1)[I_MERIT]
    L = _trial(lim, mid, K, mu, metric, 0.0, TRIAL_START, 1, 1)[I_MERIT]
    if L < L_hat:
        _accept(lim)
    else:
        _trial(lim, mid, K, mu, metric, 0.0, TRIAL_X, 1, 0)


def line_search_split(lim, mid, K, mu, metric):
    """``line_search`` with its loop on the host (``LOOP_CAP``); returns its info values."""
    ws, m = lim._ws, lim.model
    line_start(mu, 2, *packs(lim, metric, K), ws.info)
    out = ws.info.to_numpy()
    check_loops(out, "line_start", m.n_verts, m.n_faces)
    f32 = np.float32 if out.dtype == np.float32 else np.float64
    slope, L0 = f32(out[I_SLOPE]), f32(out[I_MERIT])
    alpha, step, tries, taken = f32(1.0), 0.0, 0, 0.0
    while tries <= LAST_TRY:
        a = alpha
        if tries == LAST_TRY or not slope < 0.0:
            a = f32(0.0)
        out = _trial(lim, mid, K, mu, metric, float(a), TRIAL_STEP, 1, int(a != 0.0))
        if a == 0.0:
            break
        # The kernel's test, in its precision: L <= L0 + 1e-4 a slope.
        if f32(out[I_MERIT]) <= L0 + f32(1e-4) * a * slope:
            step = float(_accept(lim)[I_STEP])
            taken = float(a)
            break
        alpha = alpha * f32(0.5)
        tries += 1
    result = np.zeros(8)
    result[I_SLOPE], result[I_STEP], result[I_ALPHA] = slope, step, taken
    return result
