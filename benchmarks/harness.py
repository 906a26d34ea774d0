"""What the benchmarks share: the machine and commit lines every report starts with, and the
building of scenes' Simulators (``configure``; ``SimulatorPool`` restarts a compiled one where
it can, so a sweep compiles each mesh's kernels once).

Benchmarks run as modules from the repository root (``python -m benchmarks.NAME``), so they
import ``cloth``, ``scenes`` and this module without editing ``sys.path``.
"""
import hashlib
import os
import platform
import subprocess

import numpy as np


def machine():
    model = platform.processor() or "unknown CPU"
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True).stdout
        model = next(l.split(":", 1)[1].strip() for l in out.splitlines()
                     if l.startswith("Model name"))
    except (OSError, StopIteration):
        pass
    import taichi as ti
    version = ".".join(str(v) for v in ti.__version__)
    return (f"{os.cpu_count()}-core CPU ({model}), Taichi {version} cpu backend, f64, "
            f"Python {platform.python_version()}")


def commit():
    """The git commit of the code measured (LOOM_COMMIT overrides it, for runs from an
    exported copy of a commit)."""
    if os.environ.get("LOOM_COMMIT"):
        return os.environ["LOOM_COMMIT"]
    try:
        root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        out = subprocess.run(["git", "-C", root, "rev-parse", "--short", "HEAD"],
                             capture_output=True, text=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", root, "status", "--porcelain", "cloth", "scenes"],
                               capture_output=True, text=True).stdout.strip()
        return (out + (" (cloth/ or scenes/ modified)" if dirty else "")) or "unknown"
    except OSError:
        return "unknown"


# ---- one Simulator per mesh, restarted between runs ---------------------------------------
class SimulatorPool:
    """Compiled Simulators keyed by scene, mesh and still obstacles; ``get`` restarts a
    matching one or builds a new one. Set-ups with moving obstacles, stitches,
    self-collision or remeshing always get a new Simulator (``Simulator.can_restart``)."""

    def __init__(self):
        self.sims = {}
        self.built = 0

    @staticmethod
    def obstacle_key(obstacles):
        """Type and parameters of still obstacles (the collider keeps no per-vertex state, so
        equal still obstacles can stay); None when one moves along a scripted path."""
        key = []
        for o in obstacles:
            if o.path is not None:
                return None
            key.append((type(o).__name__, repr(sorted(
                (k, np.asarray(v).tolist() if isinstance(v, np.ndarray) else v)
                for k, v in vars(o).items() if isinstance(v, (int, float, str, np.ndarray))))))
        return tuple(key)

    def reusable(self, setup, cfg):
        return (self.obstacle_key(setup.obstacles) is not None and setup.stitches is None
                and not setup.self_collision and not cfg.get("remesh", {}).get("enabled", False))

    def get(self, scene, setup, cfg):
        from cloth.simulator import Simulator
        key = (scene, hashlib.sha1(setup.mesh.faces.tobytes()).hexdigest(), len(setup.mesh.uv),
               self.obstacle_key(setup.obstacles), cfg.get("collision", {}).get("thickness"))
        if self.reusable(setup, cfg) and key in self.sims:
            sim = self.sims[key]
            setup.obstacles = sim.setup.obstacles     # equal ones, already compiled
            return sim.restart(setup, cfg)
        sim = Simulator(setup, cfg)
        self.built += 1
        if self.reusable(setup, cfg):
            self.sims[key] = sim
        return sim


def configure(scene, overrides):
    """(module, cfg, setup) of a scene with override dicts applied."""
    import scenes
    from scenes.common import resolve
    module = scenes.get(scene)
    cfg = resolve(module.DEFAULTS, overrides if isinstance(overrides, list) else [overrides])
    return module, cfg, module.build(cfg)
