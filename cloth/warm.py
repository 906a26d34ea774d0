"""Optimised kernels built in the background, for the next run.

Cold, on a 2-core machine, full optimisation compiles the strain solve (strain/al.py
``solve_al``, one kernel for the three methods) in about 8 minutes; fast compilation (Taichi's
advanced optimisation off) in about 20 s, and the solve then runs up to 1.4x slower. So main.py's
first run on a machine (no marker below for this code) compiles fast and starts this module
as a detached, low-priority process:

    python -m scenes.warm --arch cpu --precision f64     (scenes/warm.py: it runs scenes)

It compiles, with full optimisation, what the scenes use: a small hanging sheet (the strain
solve, one kernel for the three methods) and a frame of each other built-in scene (dynamics,
obstacles, self-collision, exact steps), into the same Taichi offline cache (Taichi's cache key holds the
compile configuration, so fast and optimised kernels sit side by side), and then writes the
marker ``loom_optimised.json`` there, keyed by ``compile_notice.fingerprint`` (Taichi version,
arch, precision, optimisation, the cloth source). Runs that find it compile nothing and run at
full speed. One warmer at a time (a lock file ``loom_warm.lock`` with its pid); its output goes
to ``loom_warm.log`` in the cache folder.

Never started under pytest (PYTEST_CURRENT_TEST set), when LOOM_FAST_COMPILE is given, or with
LOOM_BACKGROUND_COMPILE=0.
"""
import json
import os
import subprocess
import sys
import time

MARKER_NAME = "loom_optimised.json"
LOCK_NAME = "loom_warm.lock"
LOG_NAME = "loom_warm.log"
BACKGROUND_ENV = "LOOM_BACKGROUND_COMPILE"
STALE_LOCK_S = 3 * 3600
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# What the warmer runs: (scene, strain method or None for the scene's own). One hanging sheet
# builds the strain solve of all three methods (one kernel: strain/al.py ``assemble_face``).
PLAN = [("hanging", None), ("pull", None), ("drape", None), ("tshirt", None)]


def _read(path):
    try:
        with open(path) as fh:
            data = json.load(fh)
        return data if isinstance(data, dict) else {}
    except (OSError, ValueError):
        return {}


def optimised_fingerprint(arch, precision):
    from . import compile_notice
    return compile_notice.fingerprint(arch, precision, fast=False)


def marker_state(cache, arch, precision):
    """'done' (optimised kernels of this code are built), 'other code' (built for other
    code only) or 'none'."""
    data = _read(os.path.join(cache, MARKER_NAME))
    if optimised_fingerprint(arch, precision) in data:
        return "done"
    return "other code" if data else "none"


def _pid_alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def running(cache):
    """The pid of a warmer that holds the lock, else None (a stale lock is ignored)."""
    path = os.path.join(cache, LOCK_NAME)
    try:
        with open(path) as fh:
            pid = int(fh.read().split()[0])
        age = time.time() - os.path.getmtime(path)
    except (OSError, ValueError, IndexError):
        return None
    return pid if _pid_alive(pid) and age < STALE_LOCK_S else None


def _take_lock(cache):
    path = os.path.join(cache, LOCK_NAME)
    if running(cache) is None and os.path.exists(path):
        try:
            os.remove(path)          # stale: its process is gone
        except OSError:
            pass
    try:
        fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:
        return False
    with os.fdopen(fd, "w") as fh:
        fh.write(f"{os.getpid()}\n")
    return True


def allowed(env=None):
    """Whether a run may start the background warmer: not under pytest (unless
    LOOM_BACKGROUND_COMPILE=1), not switched off with LOOM_BACKGROUND_COMPILE=0."""
    env = os.environ if env is None else env
    flag = env.get(BACKGROUND_ENV, "").strip()
    if flag == "0":
        return False
    if flag == "1":
        return True
    return "PYTEST_CURRENT_TEST" not in env


def command(arch, precision, plan=None, resolution=None):
    cmd = [sys.executable, "-m", "scenes.warm", "--arch", arch, "--precision", precision]
    if plan:
        cmd += ["--plan", ",".join(f"{s}:{m or ''}" for s, m in plan)]
    if resolution:
        cmd += ["--resolution", str(resolution)]
    return cmd


def start(cache, arch, precision, plan=None, resolution=None):
    """Start the warmer detached (own session, niced, output to the log). Returns 'started',
    'running' (another one holds the lock) or 'failed'."""
    if running(cache) is not None:
        return "running"
    env = dict(os.environ)
    env["LOOM_FAST_COMPILE"] = "0"
    env["TI_OFFLINE_CACHE_FILE_PATH"] = cache
    try:
        os.makedirs(cache, exist_ok=True)
        log = open(os.path.join(cache, LOG_NAME), "a")
        subprocess.Popen(command(arch, precision, plan, resolution), cwd=ROOT, env=env,
                         stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                         start_new_session=True, close_fds=True)
        log.close()
    except OSError:
        return "failed"
    return "started"


def first_run_line(reason, started, log_path):
    """The one line a fast-compiling run prints (main.py)."""
    why = ("first run on this machine" if reason == "first run"
           else "the code changed since the optimised kernels were built")
    where = {"started": "are being built in the background for the next run",
             "running": "are being built by another Loom process in the background",
             "failed": "could not be started in the background "
                       "(LOOM_FAST_COMPILE=0 builds them in this run)",
             "off": "are not built in the background (LOOM_BACKGROUND_COMPILE=0)"}[started]
    tail = f" (log: {log_path})" if started in ("started", "running") else ""
    return (f"loom: {why}: kernels compiled quickly (up to 1.4x slower); optimised ones "
            f"{where}{tail}")


def after_init():
    """main.py, after backend.init(..., first_run_fast=True): when this run compiles fast for
    want of optimised kernels, start the warmer (if allowed) and return the line to print;
    else None."""
    from . import backend
    reason = backend.compile_reason()
    if reason not in ("first run", "code changed"):
        return None
    cache = backend.cache_dir()
    started = (start(cache, backend.arch(), backend.precision()) if allowed() else "off")
    return first_run_line(reason, started, os.path.join(cache, LOG_NAME))
