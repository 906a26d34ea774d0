"""The background warmer's work (started by cloth/warm.py, which decides when): compile, under
this process's compile configuration (optimised when started by a first run), one frame of a
small hanging sheet per strain method and of each other built-in scene, into the Taichi
offline cache, then write the marker that later runs read (cloth/warm.py).

    python -m scenes.warm [--arch cpu] [--precision f64] [--plan SCENE:METHOD,...] [--resolution N]
"""
import argparse
import json
import os
import sys
import time

from cloth.warm import LOCK_NAME, MARKER_NAME, PLAN, _read, _take_lock


def warm(plan, resolution, log=print):
    """Run one frame of each (scene, method) in ``plan``: every kernel they use compiles (or
    loads) under this process's compile configuration."""
    import scenes
    from scenes.common import resolve
    from cloth.simulator import Simulator
    for scene, method in plan:
        t0 = time.perf_counter()
        module = scenes.get(scene)
        over = {"sim": {"frames": 1}}
        if method:
            over["strain"] = {"method": method}
        if "resolution" in module.DEFAULTS.get("cloth", {}):
            over["cloth"] = {"resolution": resolution}
        cfg = resolve(module.DEFAULTS, [over])
        sim = Simulator(module.build(cfg), cfg)
        sim.step_frame()
        log(f"{time.strftime('%H:%M:%S')} {scene} {method or ''}: "
            f"{time.perf_counter() - t0:.1f} s", flush=True)


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m scenes.warm", description=__doc__.split("\n")[0])
    p.add_argument("--arch", default="cpu")
    p.add_argument("--precision", default="f64")
    p.add_argument("--plan", help="scene:method pairs, comma-separated (default: all)")
    p.add_argument("--resolution", type=int, default=7)
    a = p.parse_args(argv)
    plan = PLAN if not a.plan else [tuple((x.split(":") + [""])[:2]) for x in a.plan.split(",")]
    plan = [(s, m or None) for s, m in plan]
    try:
        os.nice(19)
    except OSError:
        pass
    from cloth import backend
    cache = backend.cache_dir()
    os.makedirs(cache, exist_ok=True)
    if not _take_lock(cache):
        print(f"{time.strftime('%F %T')} another warmer holds the lock; exiting", flush=True)
        return 0
    try:
        t0 = time.perf_counter()
        backend.init(a.arch, a.precision)
        from cloth import compile_notice
        done = compile_notice.fingerprint()
        print(f"{time.strftime('%F %T')} warming {cache} for {done} "
              f"({'fast' if backend.fast_compile() else 'optimised'})", flush=True)
        warm(plan, a.resolution)
        import taichi as ti
        ti.reset()               # writes the compiled kernels into the offline cache
        path = os.path.join(cache, MARKER_NAME)
        data = _read(path)
        data[done] = {"date": time.strftime("%F %T"),
                      "seconds": round(time.perf_counter() - t0, 1),
                      "plan": [f"{s}:{m or ''}" for s, m in plan]}
        tmp = f"{path}.{os.getpid()}.tmp"
        with open(tmp, "w") as fh:
            json.dump(data, fh, indent=1, sort_keys=True)
        os.replace(tmp, path)
        print(f"{time.strftime('%F %T')} done in {time.perf_counter() - t0:.0f} s", flush=True)
    finally:
        try:
            os.remove(os.path.join(cache, LOCK_NAME))
        except OSError:
            pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
