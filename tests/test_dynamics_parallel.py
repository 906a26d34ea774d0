"""The parallel CG experiment (benchmarks/dynamics_parallel.py) does the serial step's
arithmetic: from the same state, the same CG iterations and the same positions and velocities
to round-off, with pins, stitches and both bending energies, on a mesh large enough for its
loops to be split between threads (Taichi's tasks are >= 512 vertices)."""
import numpy as np
import pytest

from benchmarks.dynamics_parallel import ParallelCG
from cloth.dynamics import ImplicitEuler
from cloth.model import Material, MeshArrays

from .helpers import sheet_model


def pinned_sheet(n, bending, material=None):
    m = sheet_model(n=n, size=1.0, bending=bending,
                    material=material or Material(k_warp=200, k_weft=150, k_shear=5,
                                                  k_bend=1e-5, damp_stiff=1e-3))
    pinned = np.zeros(m.n_verts, bool)
    pinned[[0, n - 1]] = True
    m.load(MeshArrays(uv=m.uv, x=m.positions(), faces=m.faces, pinned=pinned))
    return m


def stepper(dyn, parallel):
    """A function stepping ``dyn`` by h, serially (``ImplicitEuler.step``) or with the
    parallel CG; it returns the CG iterations."""
    if not parallel:
        return dyn.step
    cg = ParallelCG(dyn)
    return lambda h: cg.step(dyn, h)[1]


def run(parallel, n, bending, steps, stitches, material=None):
    m = pinned_sheet(n, bending, material)
    dyn = ImplicitEuler(m, stitches=stitches)
    step = stepper(dyn, parallel)
    iters = [step(1 / 30) for _ in range(steps)]
    return iters, m.positions(), m.velocities(), dyn.last_cg_residual


@pytest.mark.parametrize("bending", ["isotropic", "hinge"])
def test_parallel_cg_repeats_the_serial_step(bending):
    n = 36                                   # 1,296 vertices: two tasks of the vertex loops
    stitches = [[40, 3 * n + 7], [n * n - 2, n * (n - 3) + 5], [40, 500]]
    a = run(False, n, bending, 4, stitches)
    b = run(True, n, bending, 4, stitches)
    assert a[0] == b[0] and min(a[0]) > 5
    assert np.abs(a[1] - b[1]).max() < 1e-12 and np.abs(a[2] - b[2]).max() < 1e-10
    assert abs(a[3] - b[3]) <= 1e-9 * max(a[3], 1e-30)
    assert np.abs(a[2]).max() > 0.1          # the sheet fell: the update ran


def test_parallel_cg_stops_where_the_serial_one_does():
    """An iteration cap inside a launch's block, and a mesh change (remesh) rebuilding the
    vertex -> element lists."""
    runs = []
    for parallel in (False, True):
        m = pinned_sheet(12, "hinge")
        dyn = ImplicitEuler(m)
        dyn.settings.cg_max_iters = 5
        step = stepper(dyn, parallel)
        first = step(1 / 30)
        # A smaller mesh loaded into the same model: the lists follow it.
        small = sheet_model(n=9, size=1.0, bending="hinge")
        m.load(MeshArrays(uv=small.uv, x=small.positions(), faces=small.faces))
        dyn.on_mesh_changed()
        dyn.settings.cg_max_iters = 200
        runs.append((first, step(1 / 30), m.positions()))
    (f_a, it_a, x_a), (f_b, it_b, x_b) = runs
    assert f_a == f_b == 5 and it_a == it_b > 1
    assert np.abs(x_a - x_b).max() < 1e-12
