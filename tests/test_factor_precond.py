"""The strain solve's PCG preconditioned by a sparse Cholesky factor of the implicit step's
matrix (cloth/strain/factor_precond.py, al.precondition): the kernel's triangular solves
invert the factored matrix, the two preconditioners give the same projection, and the
factor is chosen, kept and refreshed as documented."""
import numpy as np
import pytest
import taichi as ti

from cloth import linalg
from cloth.strain import factor_precond
from cloth.strain import al
from cloth.strain.buffers import PC_FACTOR, PC_JACOBI, PC_MULTIGRID, A, PrecondPack
from cloth.strain.multigrid import MultigridPreconditioner, MultigridStub
from tests.test_coupling import _hanging, _tight_projection

pytestmark = pytest.mark.skipif(not linalg.HAVE_CHOLMOD,
                                reason="the factor preconditioner needs CHOLMOD")


@ti.kernel
def _apply(pc_mode: int, nv: int, pc: PrecondPack, r: A, z: A) -> float:
    rz = 0.0
    ti.loop_config(serialize=True)
    for _ in range(1):
        rz = al.precondition(pc_mode, nv, pc, r, z)
    return rz


def test_kernel_applies_the_inverse_of_the_factored_matrix():
    """z = P^-1 r from the kernel's two triangular solves equals a direct solve with the
    factored (lumped, pinned-masked) matrix, for a random r; r.z is returned."""
    sim = _hanging("mapping", res=6)
    sim.step_frame()
    sim.step_frame()
    lim = sim.strain
    fp = lim._pc
    assert fp is not None and fp.ready and lim.last_factorizations == 1
    values = factor_precond.pinned_values(fp.metric, sim.model.pinned)
    fp.refresh(values)
    factored = fp.chol._to_factor(fp.chol.matrix(values))
    nv, ws = sim.model.n_verts, lim._ws
    rng = np.random.default_rng(3)
    r = rng.standard_normal((ws.r.shape[0], 3))
    ws.r.from_numpy(r)
    mg = MultigridStub()
    rz = _apply(PC_FACTOR, nv, ws.precond_pack(fp, mg), ws.r, ws.z)
    z = ws.z.to_numpy()[:nv].ravel()
    want = np.linalg.solve(factored.toarray(), r[:nv].ravel())
    assert np.abs(z - want).max() < 1e-9 * np.abs(want).max()
    assert rz == pytest.approx(r[:nv].ravel() @ want, rel=1e-9)
    pinned = np.repeat(sim.model.pinned, 3)
    assert pinned.any() and np.allclose(z[pinned], r[:nv].ravel()[pinned])


def test_factor_and_block_jacobi_give_the_same_projection(monkeypatch):
    """From one saved state of hanging, the substep solved tightly with either preconditioner
    lands on the same constrained positions (within what the AL tolerance allows), and the
    factor is used only where it is meant to be."""
    sim = _hanging("mapping", res=9)
    lim = sim.strain
    for _ in range(12):
        sim.step_frame()
    state = sim.substep_state()
    out = {}
    for precondition in ("factor", "jacobi"):
        pc, _, out[precondition] = _tight_projection(sim, state, precondition, monkeypatch)
        assert (pc is None) == (precondition == "jacobi")
    edge = sim.model.typical_edge()
    assert np.abs(out["factor"] - out["jacobi"]).max() < 20 * lim.tol * edge


def test_factor_is_refreshed_every_few_solves_and_only_for_small_meshes(monkeypatch):
    """The first FIRST_AFTER solves on a mesh run block Jacobi, and the factor is made after
    them; it is remade every REFRESH_SOLVES solves, after a pin changes and on a mesh
    change; above FACTOR_MAX_FACES faces the multigrid is made instead, and for the masses'
    metric (a projection without a time step) neither."""
    from cloth.strain import solver
    sim = _hanging("mapping", res=6)
    lim = sim.strain
    made = []
    for _ in range(2 * factor_precond.REFRESH_SOLVES + factor_precond.FIRST_AFTER):
        sim.step_frame()                             # one substep a frame
        made.append(lim.last_factorizations)
    period, first = factor_precond.REFRESH_SOLVES, factor_precond.FIRST_AFTER - 1
    assert made[:first] == [0] * first and made[first] == 1
    assert made[first + period] == made[first + 2 * period] == 1 and sum(made) == 3
    free = int(np.flatnonzero(~sim.model.pinned)[0])
    sim.model.set_vertex_pin(free, True)             # e.g. held by the mouse
    assert not lim._pc.usable(sim.model.pinned)
    sim.step_frame()                                 # block Jacobi, then a new factor
    assert lim.last_factorizations == 1 and lim._pc.usable(sim.model.pinned)
    lim.on_mesh_changed()
    assert lim._pc is None
    monkeypatch.setattr(solver, "FACTOR_MAX_FACES", sim.model.n_faces - 1)
    assert isinstance(lim._pcg_preconditioner(lim.system_metric()), MultigridPreconditioner)
    monkeypatch.setattr(solver, "FACTOR_MAX_FACES", sim.model.n_faces)
    assert isinstance(lim._pcg_preconditioner(lim.system_metric()),
                      factor_precond.FactorPreconditioner)
    assert lim._pcg_preconditioner(lim._newton_metric(False)) is None


def test_the_exact_solve_keeps_the_factor_up_to_its_own_size(monkeypatch):
    """Between FACTOR_MAX_FACES and EXACT_FACTOR_MAX_FACES faces the fast solve takes the
    multigrid and the exact solve the factor (its stop reads its Newton steps' length, which
    the factor gets right where the multigrid's short PCG does not); switching the solve
    live switches the preconditioner at the next solve."""
    from cloth.strain import solver
    sim = _hanging("mapping", res=6)
    lim = sim.strain
    monkeypatch.setattr(solver, "FACTOR_MAX_FACES", sim.model.n_faces - 1)
    monkeypatch.setattr(solver, "EXACT_FACTOR_MAX_FACES", sim.model.n_faces)
    assert isinstance(lim._pcg_preconditioner(lim.system_metric()), MultigridPreconditioner)
    sim._change("strain", solve="exact")
    assert isinstance(lim._pcg_preconditioner(lim.system_metric()),
                      factor_precond.FactorPreconditioner)
    sim._change("strain", solve="fast")
    assert isinstance(lim._pcg_preconditioner(lim.system_metric()), MultigridPreconditioner)
    monkeypatch.setattr(solver, "EXACT_FACTOR_MAX_FACES", sim.model.n_faces - 1)
    sim._change("strain", solve="exact")
    assert isinstance(lim._pcg_preconditioner(lim.system_metric()), MultigridPreconditioner)


def test_rounds_take_fewer_newton_steps_with_the_factor(monkeypatch):
    """FACTOR_NEWTON steps per round with the factor, MULTIGRID_NEWTON with the multigrid,
    MAX_NEWTON with block Jacobi. A solve with the factor stays within its budget (with the
    inner stop off every round runs it in full)."""
    from cloth.strain.defaults import FACTOR_NEWTON, MAX_NEWTON, MULTIGRID_NEWTON
    sim = _hanging("mapping", res=6)
    lim = sim.strain
    assert lim.newton_budget(PC_FACTOR) == FACTOR_NEWTON
    assert lim.newton_budget(PC_MULTIGRID) == MULTIGRID_NEWTON
    assert MULTIGRID_NEWTON < FACTOR_NEWTON < lim.newton_budget(PC_JACOBI) == MAX_NEWTON
    monkeypatch.setattr(lim, "inner_rtol", 0.0)
    lim._upload_params()
    for _ in range(4):
        sim.step_frame()
    assert lim._pc.usable(sim.model.pinned)
    sim.step_frame()
    assert lim.last_newton == FACTOR_NEWTON * lim.last_iterations


def test_long_multigrid_solves_take_more_newton_steps_a_round(monkeypatch):
    """With the multigrid a round takes MULTIGRID_NEWTON Newton steps up to LATE_ROUND rounds
    and MAX_NEWTON after (with the inner stop off every round runs its budget in full): one
    step a round left svd's projections on the pulled sheet at the round budget."""
    from cloth.strain import solver
    from cloth.strain.defaults import MAX_NEWTON, MULTIGRID_NEWTON
    sim = _hanging("svd", res=6)
    lim = sim.strain
    monkeypatch.setattr(solver, "FACTOR_MAX_FACES", sim.model.n_faces - 1)
    monkeypatch.setattr(solver, "LATE_ROUND", 2)
    monkeypatch.setattr(lim, "inner_rtol", 0.0)
    monkeypatch.setattr(lim, "tol", 1e-6)            # a few rounds in every solve
    lim._upload_params()
    seen = 0
    for _ in range(10):
        ready = isinstance(lim._pc, MultigridPreconditioner) and lim._pc.usable(sim.model.pinned)
        sim.step_frame()
        if ready:
            assert lim.last_converged and not lim.last_fallback
            rounds = lim.last_iterations
            early = min(rounds, 2)
            assert lim.last_newton == MULTIGRID_NEWTON * early + MAX_NEWTON * (rounds - early)
            seen += rounds > 2
    assert seen > 0


def test_an_unconverged_multigrid_solve_is_solved_again_with_more_newton_steps(monkeypatch):
    """A fast solve on the multigrid that ends unconverged is solved again from its start with
    MAX_NEWTON Newton steps in every round (``last_fallback``); one that converges is not.
    (Odd frames ask a tolerance of 1e-9 in one round: out of reach.)"""
    from cloth.strain import solver
    from cloth.strain.defaults import MAX_NEWTON, MULTIGRID_NEWTON
    sim = _hanging("svd", res=6)
    lim = sim.strain
    monkeypatch.setattr(solver, "FACTOR_MAX_FACES", sim.model.n_faces - 1)
    monkeypatch.setattr(lim, "inner_rtol", 0.0)
    lim._upload_params()
    tol = lim.tol
    retried = converged = 0
    for frame in range(10):
        ready = isinstance(lim._pc, MultigridPreconditioner) and lim._pc.usable(sim.model.pinned)
        hard = ready and frame % 2 == 1
        monkeypatch.setattr(lim, "max_rounds", 1 if hard else 100)
        monkeypatch.setattr(lim, "tol", 1e-9 if hard else tol)
        sim.step_frame()
        if not ready:
            continue
        if hard:
            retried += 1
            assert lim.last_fallback and lim.last_iterations == 2
            assert lim.last_newton == MULTIGRID_NEWTON + MAX_NEWTON
        else:
            converged += 1
            assert lim.last_converged and not lim.last_fallback
            assert lim.last_newton == MULTIGRID_NEWTON * lim.last_iterations
    assert retried > 0 and converged > 0
