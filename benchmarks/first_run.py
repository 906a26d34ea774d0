"""Time to the first frame of ``python main.py`` with an empty (or a given) Taichi cache.

    python -m benchmarks.first_run [--cache DIR] [--keep] [--repo DIR] [--env K=V] -- ARGS...

Runs ``python main.py ARGS`` (default ``--headless --frames 3``) as a subprocess with
``TI_OFFLINE_CACHE_FILE_PATH`` set to DIR (default: a fresh empty temporary folder, removed
afterwards unless --keep), and reports

- the wall time to the first frame (the modification time of ``meshes/frame_0001.obj``,
  which the headless run writes as soon as frame 1 is done, against the start),
- the whole run's wall time,
- each frame's ``ms_total`` from ``metrics.csv`` (frames 2.. are the warm speed),
- the machine's load (``uptime``) before and after, since the numbers are noisy on a
  shared machine,
- the run's stderr lines that start with ``loom:`` (the compile notices).

``--repo DIR`` runs another copy of the code (e.g. an exported earlier commit) with the same
Python. The run's environment is this one's plus ``--env`` pairs; LOOM_FAST_COMPILE is
removed unless given with ``--env``.
"""
import argparse
import csv
import os
import shutil
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def uptime():
    try:
        return subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    except OSError:
        return "?"


def run(args, cache, repo=ROOT, env_extra=(), out=None):
    env = dict(os.environ)
    env.pop("LOOM_FAST_COMPILE", None)
    env["TI_OFFLINE_CACHE_FILE_PATH"] = cache
    for pair in env_extra:
        k, v = pair.split("=", 1)
        env[k] = v
    out = out or tempfile.mkdtemp(prefix="loom_first_run_out_")
    cmd = [sys.executable, "main.py", *args, "--out", out]
    load0 = uptime()
    t0 = time.time()
    p = subprocess.run(cmd, cwd=repo, env=env, capture_output=True, text=True)
    wall = time.time() - t0
    load1 = uptime()
    first = os.path.join(out, "meshes", "frame_0001.obj")
    t_first = os.path.getmtime(first) - t0 if os.path.exists(first) else None
    ms = []
    metrics = os.path.join(out, "metrics.csv")
    if os.path.exists(metrics):
        with open(metrics) as fh:
            ms = [float(r["ms_total"]) for r in csv.DictReader(fh)]
    notes = [l for l in p.stderr.splitlines() if l.startswith("loom:")]
    return dict(cmd=" ".join(cmd), rc=p.returncode, wall=wall, first=t_first, ms=ms,
                load0=load0, load1=load1, notes=notes, stderr=p.stderr, stdout=p.stdout)


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("--cache", help="Taichi offline cache folder (default: a fresh empty one)")
    p.add_argument("--keep", action="store_true", help="keep the fresh cache folder")
    p.add_argument("--repo", default=ROOT, help="the code to run (default: this checkout)")
    p.add_argument("--env", action="append", default=[], metavar="K=V")
    p.add_argument("rest", nargs="*")
    a = p.parse_args(argv)
    args = a.rest or ["--headless", "--frames", "3"]
    cache = a.cache or tempfile.mkdtemp(prefix="loom_ticache_")
    try:
        r = run(args, cache, a.repo, a.env)
    finally:
        if not a.cache and not a.keep:
            shutil.rmtree(cache, ignore_errors=True)
    print(f"command: {r['cmd']}  (cache {cache}{', kept' if a.keep or a.cache else ''})")
    print(f"load before: {r['load0']}")
    print(f"load after:  {r['load1']}")
    print(f"exit code {r['rc']}; first frame after "
          + (f"{r['first']:.1f} s" if r["first"] is not None else "-")
          + f"; whole run {r['wall']:.1f} s")
    print("ms a frame: " + ", ".join(f"{m:.0f}" for m in r["ms"]))
    for line in r["notes"]:
        print("  " + line)
    if r["rc"] != 0:
        print(r["stderr"][-3000:])
    return 0 if r["rc"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
