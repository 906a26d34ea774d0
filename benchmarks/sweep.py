"""The sweep runner every benchmark with more than one run uses: each run a task on a
``dask.distributed`` cluster, its result cached by what decides it.

    from benchmarks.sweep import Run, add_arguments, run_sweep
    runs = [Run("benchmarks.drape_shape:child", [solve, drop, chaos, FRAMES], label)
            for ...]
    results = run_sweep(runs, folder, scheduler=a.scheduler, workers=a.workers)

- Where it runs: by default a local cluster of ``--workers`` worker processes (one per core),
  one thread each (Taichi holds the GIL while it compiles, so two threads in one process
  would only wait for each other); ``--scheduler tcp://HOST:PORT`` sends the runs to a running
  cluster instead (docs/sweeps.md). A worker imports the run's function and calls it in its
  own process, which keeps its Taichi runtime and compiled kernels from one run to the next;
  each run builds its own Simulator. A worker's Taichi runs its kernels on ``THREADS`` CPU
  threads (1: the sweep's parallelism is one run per core), unless the worker's environment
  sets ``TI_CPU_MAX_NUM_THREADS``: the thread count decides the order of a parallel sum, so a
  chaotic run (a drape's landing) ends differently with 1 or 2 threads, and a fixed count gives
  the same results on any machine and any number of workers.
- The cache: a run's result is kept in ``folder`` as ``LABEL.KEY.json``, KEY a hash of what
  decides the result: the code (``code_fingerprint``: every file under cloth/, scenes/ and
  assets/), the run function's source, its arguments, the compile mode and thread count set in
  the environment (``KEY_ENV``) and, for a run that names its scene and overrides, the scene's
  resolved configuration. A sweep that stopped resumes where it was; a
  changed setting reruns only the runs it changes; changed code reruns everything.
- Failures: a run that raises returns ``{"error": traceback}``, is not cached, and the sweep
  goes on (the benchmark's page lists it). A worker that dies (killed, out of memory) loses only
  its task, which the scheduler gives to another worker (up to
  ``distributed.scheduler.allowed-failures`` times, 3 by default; then the run is reported as
  an error). ``retries``: how often a task that raised outside the run itself is tried again.
- Progress: one line on stderr, runs done (of which cached), failed, left and the time to go.
- A worker checks that its code is the client's (the same fingerprint) before it runs
  anything, so a worker started from another checkout reports an error instead of a result.
- ``Run(..., own_process=True)``: the worker runs that one run in a fresh Python process of
  its own and returns its result (a run that needs what a worker's process cannot give
  it, e.g. f32 kernels: Taichi fixes the float type once per process).
"""
import hashlib
import importlib
import inspect
import json
import os
import re
import subprocess
import sys
import time
import traceback
from contextlib import contextmanager
from dataclasses import dataclass, field

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CODE_DIRS = ("cloth", "scenes", "assets")
RETRIES = 2
THREADS = 1             # Taichi's CPU threads in a worker (TI_CPU_MAX_NUM_THREADS overrides)
KEY_ENV = ("LOOM_FAST_COMPILE", "TI_CPU_MAX_NUM_THREADS")     # part of every run's cache key


@dataclass
class Run:
    """One run: ``fn`` ("package.module:function") called as ``fn(*args)`` in a worker, returning
    a JSON-able dict. ``scene``: (scene name, overrides) when the run builds a scene, so that
    its resolved configuration is part of the cache key. ``label``: what the progress and the
    page call it."""
    fn: str
    args: list
    label: str
    scene: tuple = None
    own_process: bool = False
    key: str = field(default=None, repr=False)


def code_fingerprint(root=ROOT, dirs=CODE_DIRS):
    """sha256 over the path and bytes of every file under ``dirs`` (compiled files left out):
    the code a run's result depends on, the same on every machine with the same checkout."""
    h = hashlib.sha256()
    for d in dirs:
        for base, subdirs, files in os.walk(os.path.join(root, d)):
            subdirs[:] = sorted(s for s in subdirs if s != "__pycache__")
            for name in sorted(files):
                if name.endswith((".pyc", ".pyo")):
                    continue
                path = os.path.join(base, name)
                h.update(os.path.relpath(path, root).encode() + b"\0")
                with open(path, "rb") as fh:
                    h.update(fh.read())
                h.update(b"\0")
    return h.hexdigest()


def module_hash(module):
    """sha256 of a module's source file: an argument that puts a benchmark's own code (its
    meshes, its measures: outside ``CODE_DIRS``) into a run's cache key."""
    if module == "__main__":
        raise ValueError("module_hash needs the module's own name, not __main__")
    path = importlib.import_module(module).__file__
    with open(path, "rb") as fh:
        return hashlib.sha256(fh.read()).hexdigest()


def _function(path):
    module, _, name = path.partition(":")
    return getattr(importlib.import_module(module), name)


def resolved_config(scene, overrides):
    """The configuration a scene runs with after ``overrides`` (a dict or a list of dicts)."""
    import scenes
    from scenes.common import resolve
    return resolve(scenes.get(scene).DEFAULTS,
                   overrides if isinstance(overrides, list) else [overrides])


def run_key(run, code):
    """The hash of what decides a run's result (see the module's docstring)."""
    what = {"code": code, "fn": run.fn, "source": inspect.getsource(_function(run.fn)),
            "args": run.args, "threads": THREADS,
            # How the kernels are compiled and threaded (a local cluster's workers inherit
            # the client's environment): either can change a chaotic run's last bits.
            "env": {k: os.environ.get(k, "") for k in KEY_ENV}}
    if run.scene is not None:
        what["config"] = resolved_config(*run.scene)
    text = json.dumps(what, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def cache_path(folder, run):
    slug = re.sub(r"[^A-Za-z0-9.=+-]+", "_", run.label).strip("_")[:80] or "run"
    return os.path.join(folder, f"{slug}.{run.key[:16]}.json")


def cached_entries(folder, code=None):
    """Every run cached in ``folder`` under the current code (``code``: its fingerprint,
    computed when not given): a list of {"fn", "args", "label", "result", ...}."""
    code = code or code_fingerprint()
    out = []
    for name in sorted(os.listdir(folder)) if os.path.isdir(folder) else []:
        if not name.endswith(".json"):
            continue
        try:
            with open(os.path.join(folder, name)) as fh:
                entry = json.load(fh)
        except (OSError, ValueError):
            continue
        if isinstance(entry, dict) and entry.get("code") == code and "result" in entry:
            out.append(entry)
    return out


# ---- in the worker --------------------------------------------------------------------------
_worker = {"code": None}


def _execute(fn, args, code, own_process=False):
    """A task: run ``fn(*args)`` in this worker process (``own_process``: in a new process of
    its own, ``in_own_process``). A run that raises returns {"error": the traceback's end};
    the result gets ``wall_s`` and the worker's address."""
    if ROOT not in sys.path:
        sys.path.insert(0, ROOT)
    # Read by ti.init, which the run's first backend.init calls in this process.
    os.environ.setdefault("TI_CPU_MAX_NUM_THREADS", str(THREADS))
    if _worker["code"] is None:
        _worker["code"] = code_fingerprint()
    where = _where()
    if code is not None and _worker["code"] != code:
        return {"error": f"the worker {where} runs other code than the client (code "
                         f"fingerprint {_worker['code'][:12]}, the client's {code[:12]}): "
                         "start it from a checkout of the same commit", "worker": where}
    t0 = time.time()
    try:
        result = dict(in_own_process(fn, args) if own_process else _function(fn)(*args))
    except Exception:                       # the run's own failure: reported, not retried
        return {"error": traceback.format_exc()[-2000:], "worker": where,
                "wall_s": time.time() - t0}
    result["wall_s"] = time.time() - t0
    result["worker"] = where
    return result


def in_own_process(fn, args):
    """``fn(*args)`` in a fresh Python process (``python -m benchmarks.sweep FN OUT``, the
    arguments as JSON on its stdin, the result as JSON in the file OUT)."""
    import tempfile
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        p for p in (ROOT, os.environ.get("PYTHONPATH", "")) if p))
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "result.json")
        p = subprocess.run([sys.executable, "-m", "benchmarks.sweep", fn, out], cwd=ROOT,
                           env=env, input=json.dumps(args), capture_output=True, text=True)
        if p.returncode != 0 or not os.path.exists(out):
            raise RuntimeError(f"the run's own process exited with {p.returncode}:\n"
                               + p.stderr[-1500:])
        with open(out) as fh:
            return json.load(fh)


def _where():
    try:
        from distributed import get_worker
        return get_worker().address
    except (ImportError, ValueError):
        return f"pid {os.getpid()}"


# ---- the client -----------------------------------------------------------------------------
def add_arguments(parser):
    """The sweep options every benchmark takes: --scheduler, --workers, --fresh."""
    parser.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                        help="run on this running dask scheduler's workers (docs/sweeps.md); "
                             "default: a local cluster")
    parser.add_argument("--workers", type=int, default=None,
                        help="local worker processes (default: one per core)")
    parser.add_argument("--fresh", action="store_true",
                        help="run every run again, ignoring (and replacing) cached results")
    return parser


@contextmanager
def cluster(scheduler=None, workers=None):
    """A dask Client: on the running scheduler at ``scheduler``, else on a local cluster of
    ``workers`` processes (one per core by default), one thread each."""
    from distributed import Client, LocalCluster
    if scheduler:
        client = Client(scheduler)
        try:
            yield client
        finally:
            client.close()
        return
    import logging
    n = workers or os.cpu_count() or 1
    with LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                      dashboard_address=None, silence_logs=logging.ERROR) as lc, \
            Client(lc) as client:
        yield client


class Progress:
    """The sweep's progress line on stderr (rewritten in place on a terminal)."""

    def __init__(self, total, cached, stream=None, name="sweep"):
        self.total, self.cached, self.done, self.failed = total, cached, cached, 0
        self.stream = stream or sys.stderr
        self.name, self.t0 = name, time.time()
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()

    def line(self):
        left = self.total - self.done - self.failed
        ran = self.done + self.failed - self.cached
        if left and ran:
            togo = (time.time() - self.t0) / ran * left
            eta = f"~{togo / 60:.0f} min" if togo >= 90 else f"~{togo:.0f} s"
        else:
            eta = "-" if left else "0 s"
        return (f"{self.name}: {self.done} of {self.total} done ({self.cached} cached), "
                f"{self.failed} failed, {left} left, {eta} to go "
                f"[{time.time() - self.t0:.0f} s]")

    def update(self, note=None):
        if note:
            self.stream.write(("\r\033[K" if self.tty else "") + note + "\n")
        self.stream.write(("\r\033[K" + self.line()) if self.tty else self.line() + "\n")
        self.stream.flush()

    def close(self):
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()


def run_sweep(runs, folder, scheduler=None, workers=None, fresh=False, client=None,
              retries=RETRIES, name="sweep", stream=None):
    """Run every ``Run`` (cached in ``folder``); returns their results in order, a failed run's
    as {"error": ...}. ``client``: a dask Client to use (else one from ``cluster``)."""
    os.makedirs(folder, exist_ok=True)
    code = code_fingerprint()
    results = [None] * len(runs)
    for run in runs:
        run.key = run_key(run, code)
    todo = []
    for i, run in enumerate(runs):
        path = cache_path(folder, run)
        if not fresh and os.path.exists(path):
            with open(path) as fh:
                results[i] = json.load(fh)["result"]
        else:
            todo.append(i)
    progress = Progress(len(runs), len(runs) - len(todo), stream, name)
    progress.update()
    if todo:
        if client is not None:
            _submit_all(client, runs, todo, results, folder, code, retries, progress)
        else:
            with cluster(scheduler, workers) as c:
                _submit_all(c, runs, todo, results, folder, code, retries, progress)
    progress.close()
    return results


def _submit_all(client, runs, todo, results, folder, code, retries, progress):
    from distributed import as_completed
    futures = {}
    for i in todo:
        run = runs[i]
        # One key prefix for every run: the runs form one task group, which the scheduler
        # queues and hands out as workers free up (a key per label would be a group per run,
        # each sent at once to a worker that may be busy with a long run).
        f = client.submit(_execute, run.fn, run.args, code, run.own_process,
                          key=f"loom-run-{run.key[:32]}", pure=False, retries=retries)
        futures[f] = i
    for f in as_completed(futures):
        i, run = futures[f], runs[futures[f]]
        try:
            # As JSON, so a fresh result is the same as the cached one read back (str keys).
            result = json.loads(json.dumps(f.result(), default=_plain))
        except Exception as exc:       # the task's workers died too often, or it could not run
            result = {"error": f"{type(exc).__name__}: {exc}"}
            if "deserializ" in str(exc):
                result["error"] += (" (the scheduler and every worker import benchmarks.sweep: "
                                    "start them from the repository's root with "
                                    "PYTHONPATH=$PWD, docs/sweeps.md)")
        results[i] = result
        if "error" in result:
            progress.failed += 1
            last = [l for l in result["error"].strip().splitlines() if l.strip()][-1:] or ["?"]
            progress.update(f"  {run.label}: failed: {last[0].strip()[:300]}")
            continue
        with open(cache_path(folder, run) + ".part", "w") as fh:
            json.dump({"key": run.key, "code": code, "fn": run.fn, "args": run.args,
                       "label": run.label, "date": time.strftime("%Y-%m-%d %H:%M"),
                       "result": result}, fh)
        os.replace(cache_path(folder, run) + ".part", cache_path(folder, run))
        progress.done += 1
        progress.update(f"  {run.label} ({result['wall_s']:.0f} s, {result.get('worker')})")


def _plain(v):
    """numpy scalars and arrays as JSON numbers and lists."""
    return v.tolist() if hasattr(v, "tolist") else str(v)


def failed_lines(runs, results):
    """Markdown lines listing the runs that failed and their errors' last line (none: [])."""
    bad = [(r, res) for r, res in zip(runs, results) if "error" in res]
    if not bad:
        return []
    lines = ["", f"Failed runs ({len(bad)} of {len(runs)}; not in the tables above):", ""]
    for run, res in bad:
        last = [l for l in res["error"].strip().splitlines() if l.strip()][-1:] or ["?"]
        lines.append(f"- {run.label}: `{last[0].strip()[:300]}`")
    return lines


if __name__ == "__main__":
    # A run in its own process (``in_own_process``): FN OUT, the arguments on stdin.
    os.environ.setdefault("TI_CPU_MAX_NUM_THREADS", str(THREADS))
    _result = dict(_function(sys.argv[1])(*json.load(sys.stdin)))
    with open(sys.argv[2], "w") as _fh:
        json.dump(_result, _fh, default=_plain)
