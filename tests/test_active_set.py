"""The active-set Newton model of the strain projection (strain.newton_model = "active-set",
cloth/strain/active_set.py): its Gauss-Newton blocks against a dense assembly, projections that
land on the tight solve where the margin model does not, and the fallback on the margin model
when it does not converge."""
import dataclasses

import numpy as np
import pytest

from benchmarks.projection_error import objective
from cloth.strain import active_set, direct
from cloth.strain.constraints import N_CONSTRAINTS
from cloth.strain.solver import StrainLimitError, StrainLimiter
from tests.test_coupling import _hanging, _redo_dynamics


def _settle(sim, model, **values):
    """Switch the limiter to ``model`` with the kkt stop and these values: the strain
    settings among them through the simulator's settings (their one owner), the limiter's own
    knobs (``max_newton``) on the limiter."""
    lim = sim.strain
    keys = {f.name for f in dataclasses.fields(sim.settings.strain)}
    settings = {"newton_model": model, "stop": "kkt"}
    settings.update({k: v for k, v in values.items() if k in keys})
    sim._change("strain", **settings)
    for k, v in values.items():
        if k not in keys:
            setattr(lim, k, v)
    lim._upload_params()
    return lim


def test_newton_model_setting_is_checked_and_sets_the_penalty():
    sim = _hanging("svd", "implicit", res=4)
    with pytest.raises(StrainLimitError, match="margin, active-set"):
        StrainLimiter(sim.model, newton_model="pdas")
    lim = sim.strain
    margin_mu = lim.mu_scale
    lim.set_newton_model("active-set")
    assert lim.mu_scale == pytest.approx(margin_mu * 1e-2)
    assert lim._ws.params.to_numpy()[direct.P_MARGIN] == 0.0     # the matrix is the Hessian
    lim.set_newton_model("margin")
    assert lim.mu_scale == margin_mu
    assert lim._ws.params.to_numpy()[direct.P_MARGIN] == lim.active_margin


def test_gauss_newton_blocks_equal_a_dense_assembly():
    """mu J_A^T J_A and mu J_A^T t_A written into the block pattern (face_slot, w_diag) equal
    the same products formed densely from the constraint gradients, for a random active set,
    with contacts, and with pinned vertices' rows and columns left out."""
    sim = _hanging("warp-weft", "implicit", "cholesky", res=5)
    sim.step_frame()
    lim = sim.strain
    m = sim.model
    nv, nf, K = m.n_verts, m.n_faces, N_CONSTRAINTS[lim.method]
    rng = np.random.default_rng(3)
    contact = lim._ws.contact.to_numpy()
    n = rng.normal(size=(nv, 3))
    contact[:nv, 0, :3] = n / np.linalg.norm(n, axis=1, keepdims=True)
    contact[:nv, 0, 3] = rng.normal(size=nv)
    lim._ws.contact.from_numpy(contact)
    metric, _chol = lim._direct_metric(True)
    mu = 2.5
    lc = active_set.LinearisedConstraints(lim, K, mu)
    active = (rng.random((nf, K)) < 0.5, rng.random((nv, 2)) < 0.5)
    blocks, force = lc.gauss_newton(active, metric.face_slot.to_numpy()[:nf],
                                    metric.diag.to_numpy()[:nv], metric.nnz)
    got = metric.to_scipy(_Values(blocks)).toarray()
    # Dense: one row of J per constraint.
    free = np.repeat(~m.pinned[:nv], 3).astype(float)
    rows, t = [], []
    grad = lim._ws.grad.to_numpy()[:nf, :K]
    for f in range(nf):
        for c in range(K):
            if active[0][f, c]:
                row = np.zeros(3 * nv)
                gr = grad[f, c - c % 2] * (1 if c % 2 == 0 else -1)
                for a, v in enumerate(m.faces[f]):
                    row[3 * v:3 * v + 3] += gr[3 * a:3 * a + 3]
                rows.append(row * free)
                t.append(lc.t[f, c])
    x = lim._ws.x.to_numpy()[:nv]
    lam_c = lim._ws.lam_c.to_numpy()[:nv]
    for v in range(nv):
        for j in range(2):
            if active[1][v, j]:
                row = np.zeros(3 * nv)
                row[3 * v:3 * v + 3] = -contact[v, j, :3]
                rows.append(row * free)
                t.append(contact[v, j, 3] - contact[v, j, :3] @ x[v] + lam_c[v, j] / mu)
    J, t = np.array(rows), np.array(t)
    assert np.abs(got - mu * J.T @ J).max() < 1e-9 * np.abs(got).max()
    assert np.allclose(force.reshape(-1), mu * J.T @ t, rtol=1e-9, atol=1e-12)


class _Values:
    """A numpy block array posing as a Taichi ndarray for ``BlockMatrix.to_scipy``."""

    def __init__(self, blocks):
        self.blocks = blocks

    def to_numpy(self):
        return self.blocks


@pytest.mark.parametrize("method", ["svd", "warp-weft", "mapping"])
def test_active_set_projection_lands_on_the_tight_solve(method):
    """From one saved substep of hanging (resolution 9, after 6 frames), the active-set
    projection (kkt stop at 1 cm/s, tol 1e-5) lands within 0.2 mm of the same projection
    solved tightly (tol 1e-8, 1e-6 m/s), while the margin model's (the default) lands 1-4 mm
    from it. Measured: warp-weft 0.105 mm here (frame 6); from frame 10
    (benchmarks.projection_error) svd 0.0003 mm, warp-weft 0.0006 mm, and at tol 1e-4 0.01-0.25
    mm, where the violation left decides the distance; mapping 0.006 mm since its principal
    pairs are ordered by magnitude (0.34 mm before, whatever the tolerance: ordered by
    alignment, its constraint values jumped where the principal axes crossed 45 degrees,
    strain/families.py)."""
    sim = _hanging(method, "implicit", res=9)
    for _ in range(6):
        sim.step_frame()
    state = sim.substep_state()
    lim = _settle(sim, "active-set", tol=1e-8, kkt_velocity=1e-6, max_newton=30,
                  curvature="exact", linear_solver="cholesky")
    _redo_dynamics(sim, state)
    lim.project(sim.h)
    assert lim.last_converged and not lim.last_fallback
    tight = sim.model.positions()
    # As a user switches it on: the kernels' active-set step (PCG).
    _settle(sim, "active-set", tol=1e-5, kkt_velocity=1e-2, max_newton=None,
            linear_solver="pcg")
    _redo_dynamics(sim, state)
    lim.project(sim.h)
    assert lim.last_converged and lim.last_violation_max < 1e-5
    assert lim.last_stationarity <= 1e-2
    assert lim.last_solves == 0 and not lim.last_fallback    # in the kernels, no host solve
    assert np.abs(sim.model.positions() - tight).max() < 2e-4
    _settle(sim, "margin", stop="violation", curvature="model", tol=1e-4)
    _redo_dynamics(sim, state)
    lim.project(sim.h)
    assert lim.last_converged
    assert np.abs(sim.model.positions() - tight).max() > 5e-4     # the default stops short


@pytest.mark.parametrize("linear_solver", ["pcg", "cholesky"])
def test_active_set_falls_back_on_the_margin_model(monkeypatch, linear_solver):
    """A projection the active-set model does not finish within ACTIVE_SET_ROUNDS is solved
    again from its start with the margin model, in the kernels (pcg) as in the host loop
    (cholesky): it converges, holds the limits, and says so (``last_fallback``)."""
    sim = _hanging("svd", "implicit", res=9)
    sim.step_frame()
    lim = _settle(sim, "active-set", linear_solver=linear_solver)
    monkeypatch.setattr(direct, "ACTIVE_SET_ROUNDS", 1)
    sim.step_frame()
    assert lim.last_fallback
    assert lim.last_converged and lim.last_violation_max < lim.tol
    assert np.isfinite(sim.model.positions()).all()
    monkeypatch.setattr(direct, "ACTIVE_SET_ROUNDS", 30)
    sim.step_frame()
    assert lim.last_converged and not lim.last_fallback


def _scene_at(scene, frames, **cloth):
    """``scene`` (cloth settings ``cloth``) after ``frames`` default frames, and its state."""
    from benchmarks.harness import configure
    from cloth.simulator import Simulator
    _, cfg, setup = configure(scene, {"cloth": cloth} if cloth else {})
    sim = Simulator(setup, cfg)
    for _ in range(frames):
        sim.step_frame()
    return sim, sim.substep_state()


def _substep_through_projection(sim, state):
    """Put ``state`` back and run the next substep's stages through the strain projection:
    pins, dynamics, the obstacle passes, then the projection with the contacts as
    constraints (and the seams, where the scene has stitches). Returns (the positions, the
    projection's start x_hat, the metric W as scipy): the projection minimises
    (x - x_hat)^T W (x - x_hat) / 2 over the constraints."""
    sim.set_substep_state(state)
    x_hat = sim.run_substep_through("strain_limit")
    return sim.model.positions(), x_hat, sim.strain.system_metric().to_scipy()


@pytest.mark.parametrize("method", ["svd", "warp-weft", "mapping"])
def test_active_set_projection_with_contacts_lands_on_the_tight_solve(method):
    """drape at resolution 13 in its landing (frame 6, the sheet pressed onto the sphere): the
    kernels' active-set projection (PCG, block Jacobi with the contacts, kkt stop, tol 1e-5)
    lands within 0.1 mm of the projection solved tightly in the host loop, with the contacts
    as constraints of both (measured 0.01-0.07 mm); the default stops several mm short
    (mapping: 5.2 mm) at a higher objective. Each in the same substep from the same state."""
    sim, state = _scene_at("drape", 6, resolution=13)
    sim._change("strain", method=method)
    lim = _settle(sim, "active-set", tol=1e-8, kkt_velocity=1e-6, max_newton=30,
                  curvature="exact", linear_solver="cholesky")
    tight, x_hat, W = _substep_through_projection(sim, state)
    assert lim.last_converged and not lim.last_fallback
    assert (sim.strain.contact_planes.to_numpy()[:, 0, 3] > -1e29).sum() > 10  # contacts there
    _settle(sim, "active-set", tol=1e-5, kkt_velocity=1e-2, max_newton=None,
            curvature="exact", linear_solver="pcg")
    x, _, _ = _substep_through_projection(sim, state)
    assert lim.last_converged and not lim.last_fallback and lim.last_solves == 0
    assert np.abs(x - tight).max() < 1e-4, np.abs(x - tight).max()
    _settle(sim, "margin", stop="violation", curvature="model", tol=1e-4,
            linear_solver="pcg")
    x, _, _ = _substep_through_projection(sim, state)
    assert lim.last_converged
    assert np.abs(x - tight).max() > 1e-3                          # the default stops short
    assert objective(x, x_hat, W) > objective(tight, x_hat, W)


@pytest.mark.slow
def test_active_set_projection_with_seams_lands_on_the_tight_solve():
    """tshirt at frame 8, its seams closing (74 stitches, equality constraints of the
    projection) on the mannequin: the active-set projection at the default tolerances lands
    within 0.2 mm of the tight one (measured 0.07-0.08 mm), while the margin model, even run
    to 100 rounds at tol 1e-8, stops on a feasible point 14 mm from it at a seam vertex whose
    objective is 3.6 % higher: its Newton matrix, stiff along every constraint near its band,
    makes its steps vanish short of the minimiser (docs/history/motion.md section 14). The
    default lands 15 mm away."""
    sim, state = _scene_at("tshirt", 8)
    assert len(sim.dynamics.stitches_np) > 0
    lim = _settle(sim, "active-set", tol=1e-8, kkt_velocity=1e-6, max_newton=30,
                  curvature="exact", linear_solver="cholesky")
    tight, x_hat, W = _substep_through_projection(sim, state)
    assert lim.last_converged and not lim.last_fallback
    f_min = objective(tight, x_hat, W)
    _settle(sim, "active-set", tol=1e-4, kkt_velocity=1e-2, max_newton=None,
            curvature="exact", linear_solver="cholesky")
    x, _, _ = _substep_through_projection(sim, state)
    assert lim.last_converged and not lim.last_fallback
    assert np.abs(x - tight).max() < 2e-4, np.abs(x - tight).max()
    assert objective(x, x_hat, W) < 1.001 * f_min
    _settle(sim, "margin", stop="violation", curvature="model", tol=1e-4,
            linear_solver="pcg")
    x, _, _ = _substep_through_projection(sim, state)
    assert lim.last_converged
    assert np.abs(x - tight).max() > 5e-3                          # the default stops short
    assert objective(x, x_hat, W) > 1.02 * f_min
