"""What the benchmarks share: the header every results page starts with (``header``: the
command, commit, date and CPU model), its JSON (``write_json``), a scene's configuration and
set-up (``configure``), a start moved by 1 nm (``nudge_start``) and a scene run for some
frames (``scene_run``). A new Simulator per run is cheap: every kernel compiles once per
process, so no benchmark keeps Simulators around. Sweeps of runs (each run a task in a worker
process that keeps its kernels, cached by what decides it): ``benchmarks.sweep``.

Every benchmark backs a page listed in docs/index.md and follows one protocol:
``python -m benchmarks.NAME --out DIR`` writes the page (NAME.md) and its JSON into DIR. Run from
the repository root, so they import ``cloth``, ``scenes`` and this module without editing
``sys.path``.
"""
import os
import platform
import shlex
import subprocess
import sys
import time

from cloth.provenance import commit


def command(module, argv=None):
    """The command line that ran a benchmark: ``python -m benchmarks.NAME ARGS`` (ARGS: this
    process's arguments unless given)."""
    argv = sys.argv[1:] if argv is None else argv
    return " ".join(["python -m " + module] + [shlex.quote(str(a)) for a in argv])


def header(cmd, seconds=None):
    """The lines under a results page's title: the command (and how long it took), the commit
    measured, the date and the machine (CPU model)."""
    took = f" ({seconds:.0f} s)" if seconds is not None else ""
    return (f"Command: `{cmd}`{took}  \n"
            f"Commit {commit()}, run {time.strftime('%Y-%m-%d')}; machine: {machine(date=False)}.")


def write_json(out, name, data, cmd, seconds=None):
    """NAME.json in ``out`` beside its page: ``data`` with the header's fields."""
    import json
    os.makedirs(out, exist_ok=True)
    path = os.path.join(out, name + ".json")
    with open(path, "w") as fh:
        json.dump({"command": cmd, "commit": commit(), "date": time.strftime("%Y-%m-%d"),
                   "machine": machine(date=False), "seconds": seconds, **data}, fh, indent=1,
                  default=_plain)
    return path


def _plain(v):
    """numpy scalars and arrays as JSON numbers and lists."""
    return v.tolist() if hasattr(v, "tolist") else str(v)


def nudge_start(setup, size=1e-9, seed=11):
    """Move the free vertices of a set-up's start by ``size`` m at random (1 nm: far below f32's
    resolution at 1 m), in place (``cloth.simulator.nudged_start``, which settings
    ``sim.nudge`` applies); returns the set-up."""
    from cloth.simulator import nudged_start
    setup.mesh = nudged_start(setup, seed, size).mesh
    return setup


def machine(date=True):
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
            f"Python {platform.python_version()}"
            + (f", run {time.strftime('%Y-%m-%d')}" if date else ""))


def run_drape_frames(sim, frames):
    """Step ``frames`` frames; each frame's strain-limiting ms and kinetic energy (J): what
    the drape benchmarks read of a landing."""
    from cloth import metrics
    ms, ke = [], []
    for _ in range(frames):
        sim.step_frame()
        ms.append(sim.stage("strain_limit").ms)
        ke.append(metrics.kinetic_energy(sim.model.velocities(), sim.model.mass))
    return ms, ke


def configure(scene, overrides):
    """(module, cfg, setup) of a scene with override dicts applied."""
    import scenes
    from scenes.common import resolve
    module = scenes.get(scene)
    cfg = resolve(module.DEFAULTS, overrides if isinstance(overrides, list) else [overrides])
    return module, cfg, module.build(cfg)


def scene_run(scene, overrides, frames, nudge_seed=None):
    """A scene run for ``frames`` frames in this process (a sweep's smallest run, e.g. for a
    test): the final positions, the kinetic energy a frame and the face count.
    ``nudge_seed``: the start moved by 1 nm (``nudge_start``)."""
    from cloth import backend
    backend.init("cpu", "f64")
    from cloth import metrics
    from cloth.simulator import Simulator
    _, cfg, setup = configure(scene, overrides)
    if nudge_seed is not None:
        nudge_start(setup, seed=nudge_seed)
    sim = Simulator(setup, cfg)
    ke = []
    for _ in range(frames):
        sim.step_frame()
        ke.append(metrics.kinetic_energy(sim.model.velocities(), sim.model.mass))
    return {"x": sim.model.positions().tolist(), "ke": ke, "faces": int(sim.model.n_faces)}
