"""Kernel launches that replay their first call's arguments (cloth/launch.py): the same
results as Taichi's own launches, and new arguments always seen."""
import numpy as np
import pytest
import taichi as ti

from cloth import launch

A = ti.types.ndarray()
Pair = ti.types.argpack(src=A, dst=A, n=ti.i32)


@ti.kernel
def _scaled_copy(s: float, pair: Pair, k: ti.template()):
    for i in range(pair.n):
        pair.dst[i] = s * pair.src[i] + k


@ti.kernel
def _moved(a: A, R: ti.types.matrix(3, 3, float), c: ti.types.vector(3, float)):
    for i in range(a.shape[0]):
        a[i] = R @ a[i] + c


@ti.kernel
def _sum(n: ti.i32, a: A, weights: A) -> float:
    total = 0.0
    for i in range(n):
        total += a[i] * weights[i]
    return total


def _taichis_own(monkeypatch):
    from taichi.lang import kernel_impl
    monkeypatch.setattr(kernel_impl.Kernel, "__call__", launch._installed["original"])


def test_replays_take_each_calls_scalars_templates_arrays_and_return_value():
    assert launch._installed, "backend.init installs the replaying launches"
    src, dst = ti.ndarray(ti.f64, 8), ti.ndarray(ti.f64, 8)
    src.from_numpy(np.arange(8.0))
    pair = Pair(src=src, dst=dst, n=8)
    for s in (1.0, 2.5, -3.0):                      # one recording, replayed with new scalars
        for k in (0, 1):                            # a template value: a kernel variant each
            _scaled_copy(s, pair, k)
            assert np.array_equal(dst.to_numpy(), s * np.arange(8.0) + k)
    weights = np.ones(8)
    assert _sum(8, src, weights) == 28.0
    assert _sum(3, src, weights) == 3.0             # the count replayed
    weights[:] = 2.0                                # the same numpy array, changed in place
    assert _sum(8, src, weights) == 56.0
    other = ti.ndarray(ti.f64, 8)                   # another array: recorded anew
    other.from_numpy(np.full(8, 0.5))
    assert _sum(8, other, np.ones(8)) == 4.0
    points = ti.Vector.ndarray(3, ti.f64, 2)
    for c in ((1.0, 2.0, 3.0), (0.0, 0.0, -1.0), (1.0, 2.0, 3.0)):   # a pose's values
        points.from_numpy(np.eye(3)[:2])
        R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
        _moved(points, ti.Matrix(R), ti.Vector(c))
        assert np.allclose(points.to_numpy(), np.eye(3)[:2] @ R.T + np.array(c))
    for _ in range(3):                              # arrays made and dropped between calls
        fresh_src, fresh_dst = ti.ndarray(ti.f64, 8), ti.ndarray(ti.f64, 8)
        fresh_src.from_numpy(np.full(8, 7.0))
        _scaled_copy(1.0, Pair(src=fresh_src, dst=fresh_dst, n=8), 0)
        assert np.array_equal(fresh_dst.to_numpy(), np.full(8, 7.0))
        del fresh_src, fresh_dst


@pytest.mark.parametrize("scene", ["hanging", "drape"])
def test_a_scene_steps_as_with_taichis_own_launches(monkeypatch, scene):
    """Five frames with replayed launches end where Taichi's own launches end, bit for bit
    (the drape: contacts, friction and the obstacle passes)."""
    from benchmarks.harness import configure
    from cloth.simulator import Simulator

    def run():
        _, cfg, setup = configure(scene, {"cloth": {"resolution": 9}})
        sim = Simulator(setup, cfg)
        for _ in range(5):
            sim.step_frame()
        return sim.model.positions(), sim.model.velocities()

    replayed = run()
    _taichis_own(monkeypatch)
    own = run()
    assert all(np.array_equal(a, b) for a, b in zip(replayed, own))
