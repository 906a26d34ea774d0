"""Implicit Euler dynamics: forces are energy gradients, Jacobians match finite differences,
free fall, pins, and a hanging cloth that comes to rest."""
import numpy as np
import pytest

from cloth.dynamics import STALE_SHARE, DynamicsSettings, ImplicitEuler
from cloth.model import Material

from .helpers import set_positions, set_velocities, sheet_model

MEMBRANE = Material(density=0.2, k_warp=30.0, k_weft=20.0, k_shear=7.0, k_bend=0.0,
                    damp_mass=0.0, damp_stiff=0.0)


def deformed(model, rng, scale=0.08):
    """A large, generic deformation: stretch, shear, rotation, bumps and noise."""
    uv = model.uv
    A = np.array([[1.1, 0.25], [-0.1, 0.93], [0.3, 0.2]])
    x = uv @ A.T + np.c_[np.zeros((len(uv), 2)), 0.05 * np.sin(6 * uv[:, 0]) * np.cos(5 * uv[:, 1])]
    return x + scale * 0.1 * rng.standard_normal(x.shape)


def energy_at(dyn, x):
    set_positions(dyn.model, x)
    return dyn.energy()


def fd_gradient(dyn, x, eps=1e-6):
    g = np.zeros_like(x)
    for i in range(x.shape[0]):
        for c in range(3):
            xp, xm = x.copy(), x.copy()
            xp[i, c] += eps
            xm[i, c] -= eps
            g[i, c] = (energy_at(dyn, xp) - energy_at(dyn, xm)) / (2 * eps)
    return g


def forces_at(dyn, x):
    set_positions(dyn.model, x)
    return dyn.forces()


@pytest.mark.parametrize("grain_angle", [0.0, 0.6])
def test_membrane_force_is_minus_energy_gradient(rng, grain_angle):
    from cloth.model import grain_from_angle
    m = sheet_model(n=4, size=0.3, pattern="random", material=MEMBRANE)
    if grain_angle:
        m.face_grain.from_numpy(np.resize(grain_from_angle(grain_angle, 1), (m.f_cap, 2, 2)))
    dyn = ImplicitEuler(m)
    x = deformed(m, rng)
    f = forces_at(dyn, x)
    g = fd_gradient(dyn, x)
    assert np.abs(f).max() > 1e-2
    assert np.allclose(f, -g, rtol=1e-6, atol=1e-7 * np.abs(g).max())


@pytest.mark.parametrize("bending", ["isotropic", "hinge"])
def test_bending_force_is_minus_energy_gradient(rng, bending):
    mat = Material(density=0.2, k_warp=1e-9, k_weft=1e-9, k_shear=0.0, k_bend=1e-3,
                   damp_mass=0.0, damp_stiff=0.0)
    m = sheet_model(n=4, size=0.3, pattern="alternating", material=mat, bending=bending)
    dyn = ImplicitEuler(m)
    x = deformed(m, rng, scale=0.3)
    x[:, 2] += 0.04 * rng.standard_normal(len(x))
    f = forces_at(dyn, x)
    g = fd_gradient(dyn, x)
    assert np.abs(f).max() > 1e-4
    assert np.allclose(f, -g, rtol=1e-5, atol=1e-6 * np.abs(g).max())


def jacobian_fd(dyn, x, p, eps=1e-6):
    return (forces_at(dyn, x + eps * p) - forces_at(dyn, x - eps * p)) / (2 * eps)


def assert_jacobian_matches_fd(dyn, x, p, exact, rtol, least):
    """force_jacobian_product at x along p against central differences of the forces, which
    must be at least ``least`` (so the check compares something)."""
    fd = jacobian_fd(dyn, x, p)
    set_positions(dyn.model, x)
    J = dyn.force_jacobian_product(p, exact=exact)
    assert np.abs(fd).max() > least
    assert np.allclose(J, fd, rtol=rtol, atol=rtol * np.abs(fd).max())


def test_membrane_jacobian_matches_finite_differences(rng):
    m = sheet_model(n=4, size=0.3, pattern="random", material=MEMBRANE)
    dyn = ImplicitEuler(m)
    x = deformed(m, rng)
    for _ in range(3):
        p = rng.standard_normal(x.shape)
        fd = jacobian_fd(dyn, x, p)
        set_positions(m, x)
        J = dyn.force_jacobian_product(p, exact=True)
        assert np.allclose(J, fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())


def test_bending_jacobian_matches_finite_differences_at_the_rest_angle(rng):
    # The solver keeps the Gauss-Newton part k w grad(theta) grad(theta)^T of the bending
    # Hessian, which is the exact Jacobian wherever theta = theta_0: test it there, on a
    # curved rest shape so theta_0 != 0.
    mat = Material(density=0.2, k_warp=1e-9, k_weft=1e-9, k_shear=0.0, k_bend=1e-3,
                   damp_mass=0.0, damp_stiff=0.0)
    base = sheet_model(n=4, size=0.3)
    rest = np.c_[base.uv, 0.3 * (base.uv[:, 0] - 0.15) ** 2 + 0.2 * base.uv[:, 0] * base.uv[:, 1]]
    m = sheet_model(n=4, size=0.3, material=mat, x=rest, rest_x=rest)
    assert np.abs(m.edge_rest_angle.to_numpy()).max() > 1e-3
    dyn = ImplicitEuler(m)
    for _ in range(3):
        assert_jacobian_matches_fd(dyn, rest, rng.standard_normal(rest.shape), exact=True,
                                   rtol=1e-5, least=1e-5)


def test_isotropic_bending_jacobian_is_exact_and_constant(rng):
    # The isotropic energy is quadratic in x: its force Jacobian, the one the solver uses
    # (exact=False) included, equals finite differences of the forces at any state.
    mat = Material(density=0.2, k_warp=1e-9, k_weft=1e-9, k_shear=0.0, k_bend=1e-3,
                   damp_mass=0.0, damp_stiff=0.0)
    m = sheet_model(n=5, size=0.3, pattern="random", material=mat)
    assert m.bending == "isotropic" and m.n_bend > 0
    dyn = ImplicitEuler(m)
    x = deformed(m, rng, scale=0.3)
    x[:, 2] += 0.04 * rng.standard_normal(len(x))
    for exact in (True, False):
        assert_jacobian_matches_fd(dyn, x, rng.standard_normal(x.shape), exact=exact,
                                   rtol=1e-6, least=1e-4)


def test_flat_sheet_moved_rigidly_has_no_isotropic_bending_energy(rng):
    mat = Material(density=0.2, k_warp=1e-9, k_weft=1e-9, k_shear=0.0, k_bend=1.0,
                   damp_mass=0.0, damp_stiff=0.0)
    m = sheet_model(n=6, size=0.3, pattern="random", material=mat)
    R, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    x = np.c_[m.uv, np.zeros(m.n_verts)] @ R.T + [0.3, -1.0, 2.0]
    set_positions(m, x)
    dyn = ImplicitEuler(m)
    rigid_energy, rigid_force = dyn.energy(), np.abs(dyn.forces()).max()
    x[7, 2] += 0.001                                    # a 1 mm bump costs energy
    set_positions(m, x)
    bump_energy, bump_force = dyn.energy(), np.abs(dyn.forces()).max()
    assert bump_energy > 1e-3
    # Zero up to round-off (the sum x.Qx of a sheet 2 m from the origin).
    assert abs(rigid_energy) < 1e-9 * bump_energy
    assert rigid_force < 1e-9 * bump_force


def assemble_stiffness(dyn, n, exact):
    K = np.zeros((3 * n, 3 * n))
    for j in range(3 * n):
        e = np.zeros(3 * n)
        e[j] = 1.0
        K[:, j] = -dyn.force_jacobian_product(e.reshape(n, 3), exact=exact).ravel()
    return K


def test_solver_stiffness_is_positive_semidefinite_under_compression(rng):
    m = sheet_model(n=4, size=0.3, pattern="random",
                    material=Material(k_warp=30, k_weft=20, k_shear=7, k_bend=1e-3))
    dyn = ImplicitEuler(m)
    x = m.uv @ np.array([[0.8, 0.3], [-0.2, 0.85], [0.1, 0.2]]).T
    x += 0.01 * rng.standard_normal((m.n_verts, 3))
    set_positions(m, x)
    K_psd = assemble_stiffness(dyn, m.n_verts, exact=False)
    K_exact = assemble_stiffness(dyn, m.n_verts, exact=True)
    assert np.allclose(K_psd, K_psd.T, atol=1e-9) and np.allclose(K_exact, K_exact.T, atol=1e-9)
    scale = np.abs(K_exact).max()
    assert np.linalg.eigvalsh(K_psd).min() > -1e-10 * scale
    # The exact membrane stiffness is indefinite here (compression buckles), which is why the
    # solver projects it.
    assert np.linalg.eigvalsh(K_exact).min() < -1e-4 * scale


def test_free_fall_matches_backward_euler_and_half_g_t_squared():
    mat = Material(density=0.2, k_warp=30.0, k_weft=30.0, k_shear=5.0, k_bend=1e-5,
                   damp_mass=0.0, damp_stiff=0.0)
    m = sheet_model(n=5, material=mat)
    dyn = ImplicitEuler(m, DynamicsSettings(gravity=(0.0, -9.81, 0.0), cg_tol=1e-13))
    x0 = m.positions()
    h, n = 1.0 / 60.0, 30
    for _ in range(n):
        dyn.step(h)
    drop = (m.positions() - x0)[:, 1]
    # Backward Euler: v_k = -g k h, x_n = x_0 - g h^2 n (n + 1) / 2 (no elastic force acts on
    # a rigid translation) ...
    assert np.allclose(drop, -9.81 * h * h * n * (n + 1) / 2, rtol=1e-9, atol=1e-12)
    # ... which is 1/2 g t^2 up to the integrator's first-order error 1/2 g h t.
    t = n * h
    assert abs(drop.mean() + 0.5 * 9.81 * t * t) <= 0.5 * 9.81 * h * t + 1e-12
    assert np.allclose(m.positions()[:, [0, 2]], x0[:, [0, 2]], atol=1e-12)


def test_pinned_vertices_stay_exactly_on_their_targets():
    m = sheet_model(n=6, material=Material(k_warp=20, k_weft=20, k_shear=4, k_bend=1e-6))
    pinned = np.zeros(m.n_verts, bool)
    pinned[[0, 5]] = True
    from cloth.model import MeshArrays
    mesh = MeshArrays(uv=m.uv, x=m.positions(), faces=m.faces, pinned=pinned)
    m.load(mesh)
    dyn = ImplicitEuler(m)
    target = m.positions()[pinned]
    for _ in range(20):
        dyn.step(1 / 30)
    assert np.array_equal(m.positions()[pinned], target)
    assert m.positions()[~pinned, 1].min() < -0.05


def test_stitch_springs_pull_seams_together():
    m = sheet_model(n=5, material=Material(k_warp=20, k_weft=20, k_shear=4, k_bend=1e-6,
                                           damp_mass=1.0))
    pairs = np.array([[0, 24], [4, 20]])
    dyn = ImplicitEuler(m, DynamicsSettings(gravity=(0, 0, 0), stitch_stiffness=50.0),
                        stitches=pairs)
    d0 = np.linalg.norm(np.diff(m.positions()[pairs], axis=1), axis=2).max()
    for _ in range(60):
        dyn.step(1 / 30)
    x = m.positions()
    d1 = np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1).max()
    assert d1 < 0.1 * d0 and np.all(np.isfinite(x))


def test_host_loop_step_repeats_the_one_launch_step():
    """The CG loop on the host (what Vulkan and Metal run: one launch per iteration) does the
    one-launch kernel's arithmetic: same iterations, same positions and velocities."""
    runs = []
    for host_loop in (False, True):
        m = sheet_model(n=8, material=Material(k_warp=200, k_weft=150, k_shear=5, k_bend=1e-5))
        pinned = np.zeros(m.n_verts, bool)
        pinned[[0, 7]] = True
        from cloth.model import MeshArrays
        m.load(MeshArrays(uv=m.uv, x=m.positions(), faces=m.faces, pinned=pinned))
        dyn = ImplicitEuler(m)
        dyn.host_loop = host_loop
        iters = [dyn.step(1 / 30) for _ in range(5)]
        runs.append((iters, m.positions(), m.velocities()))
    (it_a, x_a, v_a), (it_b, x_b, v_b) = runs
    assert it_a == it_b and min(it_a) > 1
    assert np.abs(x_a - x_b).max() < 1e-12 and np.abs(v_a - v_b).max() < 1e-10
    assert np.abs(v_a).max() > 0.1            # the sheet fell: the update ran


@pytest.mark.parametrize("resolution, kind", [(25, "factor"), (46, "multigrid")])
def test_the_step_preconditioned_by_the_strain_solves_matrix_is_the_block_jacobi_step_in_fewer_iterations(
        resolution, kind):
    """On a hanging sheet, where the strain solve keeps a factor (1.2k faces) or a multigrid
    (4k faces) of the implicit matrix, the dynamics' CG preconditioned by it stops, by the
    same block-Jacobi residual test, as close to a tight solve as block Jacobi's CG does, in
    under half its iterations; and the simulator hands it over."""
    from benchmarks.harness import configure
    from cloth.simulator import Simulator
    _, cfg, setup = configure("hanging", {"cloth": {"resolution": resolution}})
    sim = Simulator(setup, cfg)
    for _ in range(3):                 # the strain solve makes its own after two solves
        sim.step_frame()
    dyn, m = sim.dynamics, sim.model
    assert dyn.last_preconditioner == kind
    pc = sim.strain.implicit_preconditioner()
    x0, v0, dv0 = m.positions(), m.velocities(), dyn.warm_start()

    def step(preconditioner, tol):
        set_positions(m, x0)
        set_velocities(m, v0)
        dyn.set_warm_start(dv0)
        dyn.settings.cg_tol = tol
        dyn.set_preconditioner(preconditioner)
        iters = dyn.step(sim.h)
        return dyn.warm_start(), iters, dyn.last_preconditioner

    tight, _, _ = step(None, 1e-12)
    dv_j, it_j, pc_j = step(None, 1e-4)
    dv_p, it_p, pc_p = step(pc, 1e-4)
    assert (pc_j, pc_p) == ("block Jacobi", kind)
    err_j, err_p = np.abs(dv_j - tight).max(), np.abs(dv_p - tight).max()
    print(kind, it_j, it_p, err_j, err_p)
    assert err_p < 2.0 * err_j and err_j < 1e-3 * np.abs(tight).max()
    assert it_p < 0.5 * it_j


def test_a_stale_factor_gives_way_to_block_jacobi_until_it_is_made_again():
    """A factor of A made on the hanging sheet, used on the sheet turned a quarter turn about
    the vertical (its stiff in-plane directions where the factor's were soft; with it alone
    CG did not converge in 500 iterations), runs its share of block Jacobi's iterations and
    then CG goes on with block Jacobi, converged; the next steps run block Jacobi, until the
    factor is made again."""
    from benchmarks.harness import configure
    from cloth.simulator import Simulator
    _, cfg, setup = configure("hanging", {"cloth": {"resolution": 25}})
    sim = Simulator(setup, cfg)
    for _ in range(3):
        sim.step_frame()
    dyn, m = sim.dynamics, sim.model
    pc = sim.strain.implicit_preconditioner()
    x0, v0, dv0 = m.positions(), m.velocities(), dyn.warm_start()
    centre = x0.mean(axis=0)
    quarter = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])   # about y

    def step(turn, preconditioner=pc):
        set_positions(m, centre + (x0 - centre) @ turn.T)
        set_velocities(m, v0)
        dyn.set_warm_start(dv0)
        dyn.set_preconditioner(preconditioner)
        dyn.step(sim.h)
        return dyn.last_preconditioner, dyn.last_cg_iters, dyn.last_cg_residual

    jacobi = step(quarter, None)
    fresh = step(np.eye(3))
    stale = step(quarter)
    after = step(np.eye(3))
    pc._make(m.pinned)
    remade = step(np.eye(3))
    assert jacobi[0] == "block Jacobi" and fresh[0] == stale[0] == remade[0] == "factor"
    assert after[0] == "block Jacobi"
    assert fresh[1] < 0.5 * after[1]
    # The budget was half of the block-Jacobi step before it (``jacobi``); then block Jacobi
    # from where the factor got to.
    assert stale[1] <= STALE_SHARE * jacobi[1] + 1.5 * jacobi[1]
    assert max(r[2] for r in (jacobi, fresh, stale, after, remade)) <= dyn.settings.cg_tol
