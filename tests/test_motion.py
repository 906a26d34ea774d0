"""Motion through the strain projection: the fast solve stops once the limits hold, so it
answers near where it starts; started where each vertex was heading, a landing keeps its
motion as the exact solve does, and a sheet lying on an obstacle comes to rest.

A landing is chaotic (two CPUs' rounding lands it elsewhere), so each test runs a small
ensemble of starts 1 nm apart and asserts what holds for every member."""
import numpy as np
import pytest

from benchmarks.harness import configure
from cloth import metrics
from cloth.simulator import Simulator

SPHERE_TOP, EQUATOR = 0.85, 0.55      # the drape scene's sphere (m)
ENSEMBLE = (1, 2, 3)                  # seeds of the 1 nm moves


def _drop(seed, frames=12, preconditioners=None, **strain):
    """The drape scene at resolution 13 (landing in frames 5-6), its start moved by ~1 nm
    (seed): the kinetic energy per frame and the lowest vertex at the end. Appends each
    frame's (projection's, dynamics') preconditioner to ``preconditioners``."""
    _, cfg, setup = configure("drape", {"cloth": {"resolution": 13}, "strain": strain})
    sim = Simulator(setup, cfg)
    x = sim.model.positions()
    sim.model.set_positions(x + 1e-9 * np.random.default_rng(seed).standard_normal(x.shape))
    ke = []
    for _ in range(frames):
        sim.step_frame()
        ke.append(metrics.kinetic_energy(sim.model.velocities(), sim.model.mass))
        if preconditioners is not None:
            preconditioners.append((sim.strain.last_preconditioner,
                                    sim.dynamics.last_preconditioner))
    return np.array(ke), float(sim.model.positions()[:, 1].min())


@pytest.mark.slow
@pytest.mark.xdist_group("exact_solve")
@pytest.mark.parametrize("seed", ENSEMBLE)
def test_a_landing_keeps_its_motion_as_the_exact_solve_does(seed):
    """Through the landing (frame 4 to 9) the fast solve keeps a like share of the kinetic
    energy as the exact solve (each projection solved to its minimiser), within a factor of
    3 (measured on an AMD EPYC: fast 0.57-0.68 of the energy kept, exact 0.83-0.87; the fast
    model against exact Newton steps read 0.5-2.1 on two CPUs), and both slide down the sphere
    below its equator. Started where the vertices were instead of where they were heading,
    the fast solve kept 0.3 % of the energy and held the sheet on the sphere's top."""
    kept = lambda k: k[8] / k[3]                       # noqa: E731
    ke, low = _drop(seed)
    ke_exact, low_exact = _drop(seed, solve="exact")
    assert low < EQUATOR - 0.05 and low_exact < EQUATOR - 0.05, (low, low_exact)
    assert 1 / 3 < kept(ke) / kept(ke_exact) < 3, (kept(ke), kept(ke_exact))


@pytest.mark.parametrize("seed", ENSEMBLE)
def test_a_sheet_resting_on_the_sphere_comes_to_rest(seed):
    """After landing (peak kinetic energy ~0.1 J), the sheet lying on the sphere comes to
    rest: over frames 31-40 its kinetic energy is below 1 % of the peak (measured on an AMD
    EPYC: 1.3e-5 to 4.9e-4 J against a peak of 0.154 J). Through the landing the projection's
    PCG runs block Jacobi (with the factor of A a landing kept none of its motion); lying
    still, it takes the factor, and so does the dynamics' CG."""
    used = []
    ke, _ = _drop(seed, frames=70, preconditioners=used)
    assert ke[30:40].mean() < 1e-2 * ke.max(), (ke[30:40].mean(), ke.max())
    assert all(u == ("block Jacobi", "block Jacobi") for u in used[3:9]), used
    assert used[-1] == ("factor", "factor"), used


@pytest.mark.xdist_group("exact_solve")
def test_the_exact_solve_keeps_block_jacobi_under_contacts_at_rest():
    """The factor of A lacks the contacts' terms: at rest on the sphere the fast solve takes
    it, the exact solve does not (with it the drape's active-set rounds ran out, 31 rounds a
    frame where block Jacobi took 5-6)."""
    used = []
    _, cfg, setup = configure("drape", {"cloth": {"resolution": 13}})
    sim = Simulator(setup, cfg)
    for _ in range(70):
        sim.step_frame()
    used.append(sim.strain.last_preconditioner)
    sim.set_strain_solve("exact")
    sim.step_frame()
    used.append(sim.strain.last_preconditioner)
    assert used == ["factor", "block Jacobi"], used
