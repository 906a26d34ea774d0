"""The AL's Newton iteration descends on its merit: the residual the PCG and Cholesky paths
solve for is minus the gradient of the merit the line search tests (finite differences), in
the implicit step's metric, with active strain constraints. (Issue #13: an inconsistency here
would stall every inner loop.)"""
import numpy as np
import pytest
import taichi as ti

from cloth.ndarrays import A
from cloth.strain import al
from cloth.strain.constraints import METHOD_IDS, N_CONSTRAINTS


@ti.kernel
def _merit_at(method: ti.template(), K: int, nv: int, nf: int, ns: int, mu: float, pos: A,
              x_hat: A, w_ptr: A, w_col: A, w_val: A, w_diag: A, face_verts: A, Dm_inv: A,
              grain: A, rest_area: A, params: A, lam: A, g: A, grad: A, cm: A, what: A,
              kappa: A, twist: A, contact: A, lam_c: A, stitch: A, lam_s: A, fric: A,
              lam_t: A) -> float:
    total = 0.0
    ti.loop_config(serialize=True)
    for _ in range(1):
        al.assemble_all(method, nf, pos, face_verts, Dm_inv, grain, rest_area, params, g,
                        grad, cm, what, kappa, twist)
        total = al.merit(K, nv, nf, ns, mu, pos, x_hat, w_ptr, w_col, w_val, w_diag, lam, g,
                         contact, lam_c, stitch, lam_s, fric, lam_t)
    return total


@ti.kernel
def _residual_at(method: ti.template(), K: int, nv: int, nf: int, ns: int, mu: float, pos: A,
                 x_hat: A, w_ptr: A, w_col: A, w_val: A, w_diag: A, face_verts: A,
                 Dm_inv: A, grain: A, rest_area: A, params: A, lam: A, g: A, grad: A, cm: A,
                 what: A, kappa: A, twist: A, contact: A, lam_c: A, stitch: A, lam_s: A,
                 fric: A, lam_t: A, pinned: A, r: A):
    ti.loop_config(serialize=True)
    for _ in range(1):
        al.assemble_all(method, nf, pos, face_verts, Dm_inv, grain, rest_area, params, g,
                        grad, cm, what, kappa, twist)
        al.residual(K, nv, nf, ns, mu, pos, x_hat, w_ptr, w_col, w_val, w_diag, pinned,
                    face_verts, lam, g, grad, contact, lam_c, stitch, lam_s, fric, lam_t, r)


@pytest.mark.parametrize("method", ["mapping", "svd", "warp-weft"])
def test_residual_is_minus_the_merit_gradient(method):
    from tests.test_coupling import _hanging
    sim = _hanging(method, "implicit", res=6)
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

    def arrays():
        return (ws.face_verts, ws.Dm_inv, ws.grain, ws.rest_area, ws.params, ws.lam, ws.g,
                ws.grad, ws.cm, ws.what, ws.kappa, ws.twist, ws.contact, ws.lam_c, ws.stitch,
                ws.lam_s, ws.fric, ws.lam_t)

    pos = ws.x_trial

    def merit_at(xs):
        pos.from_numpy(xs)
        return _merit_at(mid, K, nv, nf, 0, mu, pos, ws.x_hat, W.ptr, W.col, W.val, W.diag,
                         *arrays())

    pos.from_numpy(x0)
    _residual_at(mid, K, nv, nf, 0, mu, pos, ws.x_hat, W.ptr, W.col, W.val, W.diag,
                 *arrays(), ws.pinned, ws.r)
    r = ws.r.to_numpy()[:nv]
    for trial in range(3):
        d = np.zeros_like(x0)
        d[:nv] = rng.standard_normal((nv, 3)) * (m.pinned == 0)[:, None]
        eps = 1e-7
        fd = (merit_at(x0 + eps * d) - merit_at(x0 - eps * d)) / (2 * eps)
        analytic = -np.sum(r * d[:nv])
        assert abs(fd - analytic) <= 1e-5 * max(abs(analytic), 1e-12), (trial, fd, analytic)
