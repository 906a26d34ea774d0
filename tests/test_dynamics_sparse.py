"""The assembled sparse system (dynamics_sparse.py) is the matrix-free one: a sparse direct step
matches a tightly converged matrix-free PCG step, with pins, stitches, bending and damping."""
import numpy as np
import pytest

from cloth.dynamics import DynamicsSettings, ImplicitEuler
from cloth.dynamics_sparse import SparseImplicitEuler
from cloth.model import Material, MeshArrays

from .helpers import set_positions, set_velocities, sheet_model

MAT = Material(density=0.15, k_warp=300.0, k_weft=200.0, k_shear=20.0, k_bend=1e-4,
               damp_mass=0.1, damp_stiff=0.01)
STITCHES = [[1, 40], [3, 44]]


def pinned_sheet(rng):
    """A 7 x 7 random-triangulation sheet, stretched in x and compressed in y (both branches of
    the tension-only curvature terms), slightly bent, with three pins off their targets and
    random velocities."""
    m = sheet_model(n=7, size=0.5, pattern="random", material=MAT)
    x = m.positions() * np.array([1.03, 0.96, 1.0])
    x[:, 2] += 0.02 * np.sin(5 * x[:, 0]) * np.cos(4 * x[:, 1])
    pinned = np.zeros(m.n_verts, bool)
    pinned[[0, 6, 24]] = True
    m.load(MeshArrays(uv=m.uv, x=x, faces=m.faces, pinned=pinned, pin_target=x + 0.01))
    set_velocities(m, 0.1 * rng.standard_normal((m.n_verts, 3)))
    return m


def settings(**kw):
    return DynamicsSettings(stitch_stiffness=30.0, **kw)


@pytest.mark.parametrize("solver", ["llt"])   # ldlt: git log -- benchmarks/linear_solver.py
def test_sparse_direct_step_matches_tight_matrix_free_step(rng, solver):
    m = pinned_sheet(rng)
    x0, v0 = m.positions(), m.velocities()
    h = 1.0 / 60.0
    ref = ImplicitEuler(m, settings(cg_tol=1e-13, cg_max_iters=5000), stitches=STITCHES)
    sp = SparseImplicitEuler(m, settings(), stitches=STITCHES, linear_solver=solver)
    for _ in range(3):                       # three steps from the same states
        xs, vs = m.positions(), m.velocities()
        ref.step(h)
        assert ref.last_cg_residual < 1e-12
        x_ref, v_ref = m.positions(), m.velocities()
        set_positions(m, xs)
        set_velocities(m, vs)
        sp.step(h)
        x_sp, v_sp = m.positions(), m.velocities()
        dv = np.abs(v_ref - vs).max()
        assert dv > 1e-2                      # the step does something
        assert np.abs(v_sp - v_ref).max() < 1e-8 * max(dv, 1.0)
        assert np.abs(x_sp - x_ref).max() < 1e-10
        assert np.array_equal(x_sp[m.pinned], m.vert_pin_target.to_numpy()[: m.n_verts][m.pinned])
    assert np.abs(m.positions() - x0).max() > 1e-3 and np.abs(m.velocities() - v0).max() > 1e-2


def test_sparse_step_without_pins_free_fall():
    # No pins, no elastic force on a rigid translation: backward Euler free fall, exactly.
    mat = Material(density=0.2, k_warp=30.0, k_weft=30.0, k_shear=5.0, k_bend=1e-5,
                   damp_mass=0.0, damp_stiff=0.0)
    m = sheet_model(n=5, material=mat)
    dyn = SparseImplicitEuler(m, DynamicsSettings(gravity=(0.0, -9.81, 0.0)))
    x0 = m.positions()
    h, n = 1.0 / 60.0, 10
    for _ in range(n):
        dyn.step(h)
    drop = (m.positions() - x0)[:, 1]
    assert np.allclose(drop, -9.81 * h * h * n * (n + 1) / 2, rtol=1e-9, atol=1e-12)


def test_unknown_solver_is_refused():
    m = sheet_model(n=3)
    with pytest.raises(ValueError, match="unknown linear solver"):
        SparseImplicitEuler(m, linear_solver="qr")
