"""What the benchmarks share: the machine and commit lines every report starts with, and a
scene's configuration and set-up (``configure``). A new Simulator per run is cheap: every
kernel compiles once per process (issue #15), so no benchmark keeps Simulators around.

Benchmarks run as modules from the repository root (``python -m benchmarks.NAME``), so they
import ``cloth``, ``scenes`` and this module without editing ``sys.path``.
"""
import os
import platform
import subprocess


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
    import time
    # The date goes with the machine into every results page's header (with the command and
    # the commit: docs/index.md lists them).
    return (f"{os.cpu_count()}-core CPU ({model}), Taichi {version} cpu backend, f64, "
            f"Python {platform.python_version()}, run {time.strftime('%Y-%m-%d')}")


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


def configure(scene, overrides):
    """(module, cfg, setup) of a scene with override dicts applied."""
    import scenes
    from scenes.common import resolve
    module = scenes.get(scene)
    cfg = resolve(module.DEFAULTS, overrides if isinstance(overrides, list) else [overrides])
    return module, cfg, module.build(cfg)


def cached_run(path, module, args, label, fresh=False, error_chars=300):
    """One benchmark run in its own process, cached as JSON at ``path``: ``python -m module
    --child JSON(args)``, whose last stdout line is the result's JSON. A failed run returns
    {"error": the end of its stderr} and is not cached; a finished one gets ``wall_s``.
    Prints ``label`` and the time (or the error) to stderr."""
    import json
    import sys
    import time
    if os.path.exists(path) and not fresh:
        with open(path) as fh:
            return json.load(fh)
    t0 = time.time()
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    proc = subprocess.run([sys.executable, "-m", module, "--child", json.dumps(args)],
                          capture_output=True, text=True, cwd=root)
    if proc.returncode != 0:
        result = {"error": proc.stderr[-600:]}
    else:
        result = json.loads(proc.stdout.strip().splitlines()[-1])
        result["wall_s"] = time.time() - t0
        with open(path, "w") as fh:
            json.dump(result, fh)
    print(f"  {label}" + (f": error {result['error'][-error_chars:]}" if "error" in result
                          else f" ({result['wall_s']:.0f} s)"), file=sys.stderr, flush=True)
    return result
