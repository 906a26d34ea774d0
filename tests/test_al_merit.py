"""The AL's Newton iteration descends on its merit: the residual the PCG and Cholesky paths
solve for is minus the gradient of the merit the line search tests (finite differences), in
the implicit step's metric, with active strain constraints. (An inconsistency here would stall
every inner loop.)"""
import numpy as np
import pytest
import taichi as ti

from cloth.ndarrays import A
from cloth.strain import al, direct
from cloth.strain.buffers import ConstraintPack, ContactPack, MeshPack, MetricPack, VectorPack
from cloth.strain.constraints import METHOD_IDS, N_CONSTRAINTS


MERIT, RESIDUAL, LINE = range(3)


@ti.kernel
def _probe(what: ti.i32, method: ti.i32, mu: float, a: float, pos: A, moved: A,
           mesh: MeshPack, metric: MetricPack, cons: ConstraintPack, contacts: ContactPack,
           vec: VectorPack) -> ti.types.vector(2, float):
    """MERIT: (the merit at pos, 0). RESIDUAL: the residual at pos into vec.r. LINE: the merit
    at pos + a d (d = vec.d) two ways: directly, and as solve_al's line search forms it (the
    quadratic from ``metric_along`` at pos, plus the constraint terms). (One kernel: each
    assembly call site compiles the three methods' constraints.)"""
    out = ti.Vector([0.0, 0.0])
    ti.loop_config(serialize=True)
    for _ in range(1):
        K, nv, nf, ns = cons.n_per_face, mesh.n_verts, mesh.n_faces, contacts.n_stitches
        al.metric_gradient(nv, pos, metric, vec)
        quad = al.metric_along(nv, pos, metric, vec)
        for n in range(nv):
            moved[n] = pos[n] + a * vec.d[n] if what == LINE else pos[n]
        al.assemble_all(method, nf, moved, mesh, cons)
        if what == RESIDUAL:
            al.residual(K, nv, nf, ns, mu, moved, mesh, cons, contacts, vec)
        else:
            out[0] = al.merit(K, nv, nf, ns, mu, moved, vec.x_hat, metric, cons, contacts)
            out[1] = al.quad_at(quad, a) + al.merit_constraints(K, nv, nf, ns, mu, moved, cons,
                                                                contacts)
    return out


@pytest.mark.parametrize("method", ["mapping", "svd", "warp-weft"])
def test_residual_is_minus_the_merit_gradient(method):
    from tests.test_coupling import _hanging
    sim = _hanging(method, res=6)
    for _ in range(3):
        sim.step_frame()                 # multipliers, x_hat, metric of a real substep
    lim, m = sim.strain, sim.model
    ws, W = lim._ws, lim._system
    nv, nf, mid, K = m.n_verts, m.n_faces, METHOD_IDS[method], N_CONSTRAINTS[method]
    mu = lim.mu_scale * lim._mean_mass(W) * 4.0
    x = ws.x.to_numpy()
    rng = np.random.default_rng(3)
    # A point near the solution but off it (some constraints active, some not).
    x0 = x.copy()
    x0[:nv] += 2e-4 * rng.standard_normal((nv, 3)) * (m.pinned == 0)[:, None]
    lam = ws.lam.to_numpy()
    assert np.count_nonzero(lam[:nf, :K]) > 0, "no active multipliers: the test sees nothing"

    packs = direct.packs(lim, W, K)  # (mesh, metric, constraints, contacts, vectors)
    pos = ws.x_trial

    def merit_at(xs):
        pos.from_numpy(xs)
        return _probe(MERIT, mid, mu, 0.0, pos, ws.z, *packs)[0]

    pos.from_numpy(x0)
    _probe(RESIDUAL, mid, mu, 0.0, pos, ws.z, *packs)
    r = ws.r.to_numpy()[:nv]
    for trial in range(3):
        d = np.zeros_like(x0)
        d[:nv] = rng.standard_normal((nv, 3)) * (m.pinned == 0)[:, None]
        eps = 1e-7
        fd = (merit_at(x0 + eps * d) - merit_at(x0 - eps * d)) / (2 * eps)
        analytic = -np.sum(r * d[:nv])
        # 1e-4: a wrong gradient is off by O(1). (Over starts 1 nm apart one svd state read
        # 6e-5: a face near eta1 = eta2, where the regularised frame term bends sharply
        # within the difference's 1e-7 step.)
        assert abs(fd - analytic) <= 1e-4 * max(abs(analytic), 1e-12), (trial, fd, analytic)
    # The line search's merit (quadratic term from W d once, solve_al) is the merit. Its
    # pieces do not depend on the method (assemble_all feeds both sides alike), so one
    # method checks it.
    if method != "mapping":
        return
    ws.d.from_numpy(d)
    for a in (1.0, 0.37):
        pos.from_numpy(x0)
        merit, along = _probe(LINE, mid, mu, a, pos, ws.z, *packs)
        assert abs(merit - along) <= 1e-12 * abs(merit), (a, merit, along)


def _newton_system_at(lim, mid, K, mu, metric):
    """A function x -> (r, H) at positions x (numpy, the work array's shape): the residual
    -grad L_A (flattened) and the Newton matrix (scipy CSR) as ``direct.newton_system``
    assembles them for the limiter ``lim`` with penalty ``mu``."""
    from cloth.strain import direct
    ws, nv = lim._ws, lim.model.n_verts

    def residual_and_matrix(xs):
        ws.x.from_numpy(xs)
        lim._assemble(mid, ws.x)
        direct.fill_newton_system(lim, mid, K, mu, metric)
        return ws.r.to_numpy()[:nv].ravel().copy(), metric.to_scipy(ws.H)
    return residual_and_matrix


def _directional_errors(residual_and_matrix, x0, nv, free, rng, directions, eps=1e-7, H=None):
    """Along random directions d (zero where ``free`` is False): the relative error
    |H d - H_true d| / |H_true d| and the Rayleigh ratio d.H.d / d.H_true.d, with H_true d
    the central difference of the residual (H: the matrix at x0, if the caller has it).
    Returns (errors, ratios) per direction."""
    if H is None:
        _, H = residual_and_matrix(x0)
    rel, ratio = [], []
    for _ in range(directions):
        d = np.zeros_like(x0)
        d[:nv] = rng.standard_normal((nv, 3)) * free
        rp, _ = residual_and_matrix(x0 + eps * d)
        rm, _ = residual_and_matrix(x0 - eps * d)
        true_d = -(rp - rm) / (2 * eps)
        model_d = H @ d[:nv].ravel()
        rel.append(np.linalg.norm(model_d - true_d) / np.linalg.norm(true_d))
        ratio.append(d[:nv].ravel() @ model_d / (d[:nv].ravel() @ true_d))
    return rel, ratio


@pytest.mark.parametrize("method", ["mapping", "svd", "warp-weft"])
def test_newton_matrix_is_the_merit_hessian_without_the_margin(method):
    """``al.newton_matrix`` (the matrix both Newton paths solve with) against the central
    difference of the residual: with active_margin 0 it is the merit's Hessian up to the
    curvature model's error (measured here: relative error of H d 2.6 % for mapping, 5e-4 for
    svd, 1e-9 for warp-weft); with the default margin it is stiffer along every
    direction tried (the near constraints enter; docs/history/inner_solver.md; 1.6-3.6 times
    since their weight is cubic in their closeness, defaults.NEAR_POWER).
    It is symmetric, and the identity on pinned rows."""
    from tests.test_coupling import _hanging
    sim = _hanging(method, res=6)
    for _ in range(3):
        sim.step_frame()
    lim, m = sim.strain, sim.model
    ws = lim._ws
    nv, mid, K = m.n_verts, METHOD_IDS[method], N_CONSTRAINTS[method]
    W = lim._newton_metric(True)
    assert W is lim._system
    mu = lim.mu_scale * lim._mean_mass(W) * 4.0
    rng = np.random.default_rng(5)
    free = (m.pinned == 0)[:, None]
    x0 = ws.x.to_numpy()
    x0[:nv] += 2e-4 * rng.standard_normal((nv, 3)) * free
    residual_and_matrix = _newton_system_at(lim, mid, K, mu, W)
    errors, ratios = [], []
    for margin in (0.0, lim.active_margin):
        lim.active_margin = margin
        lim._upload_params()
        _, H = residual_and_matrix(x0)
        assert abs(H - H.T).max() <= 1e-12 * abs(H).max()
        pinned = np.repeat(m.pinned, 3)
        assert np.array_equal(H[pinned].toarray(), np.eye(3 * nv)[pinned])
        err, ratio = _directional_errors(residual_and_matrix, x0, nv, free, rng, 3, H=H)
        errors.append(max(err))
        ratios.append(min(ratio))
    assert errors[0] < 0.1
    assert ratios[0] > 0.9
    assert ratios[1] > 1.5
