"""Every kernel compiles once per process: the model, the solvers and the obstacles hand Taichi
their data as ndarray arguments, so a second Simulator of another mesh, other obstacles and
other parameters runs on the kernels the first one compiled.

Checked by counting the compiled kernel instances Taichi holds (``Kernel.compiled_kernels``,
one entry per specialisation), not by timing: a recompiling kernel adds an entry.
"""
import gc
import os

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

CUBE_OBJ = """v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1
f 1 3 2\nf 1 4 3\nf 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7
f 4 1 5\nf 4 5 8
"""


def compiled_kernels():
    """{kernel: (name, compiled specialisations)} of Loom's own kernels in this process.
    (Taichi's internal copy kernels, e.g. for ``to_numpy``, specialise per array kind: a run
    that reads another kind of array adds one without anything recompiling.)"""
    from taichi.lang.kernel_impl import Kernel
    return {id(k): (k.func.__name__, len(k.compiled_kernels)) for k in gc.get_objects()
            if isinstance(k, Kernel) and not k.func.__module__.startswith("taichi")}


def recompiled(before, after):
    """The kernels compiled before that hold more specialisations after: compiled again.
    (A kernel first used in the later run, e.g. self-collision impulses that one run's contacts
    need and the other's do not, is compiled for the first time, not again.)"""
    return sorted(name for key, (name, n) in after.items()
                  if before.get(key, ("", 0))[1] > 0 and n > before[key][1])


def scene_file(path, n, size):
    """A scene with an n x n vertex sheet hanging from a corner over every kind of obstacle,
    with self-collision and mapping strain limiting; ``size`` scales the obstacles (so their
    parameters differ)."""
    from cloth.io import write_obj
    from cloth.sheet import make_sheet
    uv, faces = make_sheet(1.0, 1.0, n, n)
    write_obj(f"{path}.sheet.obj", np.c_[uv[:, 0], 1.2 - uv[:, 1], np.zeros(len(uv))], uv, faces)
    s = size
    text = f"""
[cloth]
mesh = "{path}.sheet.obj"
pins = [[-0.001, -0.001, 0.001, 0.001]]
[[obstacles]]
kind = "sphere"
center = [0.0, 0.3, 0.0]
radius = {0.2 * s}
[[obstacles]]
kind = "plane"
normal = [0.0, 1.0, 0.0]
[[obstacles]]
kind = "capsule"
a = [-0.3, 0.2, 0.2]
b = [0.3, 0.2, 0.2]
radius = {0.05 * s}
[[obstacles]]
kind = "box"
center = [0.3, 0.1, -0.3]
extents = [{0.2 * s}, 0.1, 0.1]
angle = {20 * s}
[[obstacles]]
kind = "mesh"
path = "{path}.cube.obj"
scale = {0.1 * s}
offset = [-0.3, 0.1, -0.3]
resolution = {int(12 * s)}
[[obstacles]]
kind = "union"
path = "{os.path.join(ROOT, 'assets', 'mannequin.json')}"
[collision]
self_collision = true
thickness = {0.005 * s}
[strain]
method = "mapping"
[sim]
frames = 2
"""
    with open(f"{path}.cube.obj", "w") as fh:
        fh.write(CUBE_OBJ)
    with open(path, "w") as fh:
        fh.write(text)
    return path


def run_file(path, frames=2):
    import scenes
    from cloth.simulator import Simulator
    module = scenes.get(path)
    cfg = module.DEFAULTS
    sim = Simulator(module.build(cfg), cfg)
    for _ in range(frames):
        sim.step_frame()
    return sim


@pytest.mark.slow
def test_a_second_simulator_compiles_nothing(tmp_path):
    first = run_file(scene_file(str(tmp_path / "a.toml"), 9, 1.0))
    assert first.collider is not None and first.self_collision_on
    before = compiled_kernels()
    second = run_file(scene_file(str(tmp_path / "b.toml"), 12, 1.5))
    assert second.model.n_faces != first.model.n_faces
    assert second.collider.last_contacts >= 0 and np.all(np.isfinite(second.model.positions()))
    assert recompiled(before, compiled_kernels()) == []


def test_a_second_hanging_cloth_compiles_nothing():
    """The plainest case, in the quick subset: hanging at two resolutions."""
    from benchmarks.harness import configure
    from cloth.simulator import Simulator

    def run(res):
        _, cfg, setup = configure("hanging", [{"cloth": {"resolution": res}}])
        sim = Simulator(setup, cfg)
        sim.step_frame()
        return sim

    run(5)
    before = compiled_kernels()
    sim = run(6)
    assert sim.strain.last_converged
    assert recompiled(before, compiled_kernels()) == []
