"""The first run on a machine: the time to the first frame from an empty Taichi cache.

The first frame of ``python main.py`` with an empty (or a given) Taichi cache and, optionally,
what a method's first use and the window's stops cost.

    python -m benchmarks.first_run --out DIR [--cache DIR] [--keep] [--repo DIR] [--env K=V]
                                   [--method-switch] [--window] [-- ARGS...]

Writes ``first_run.md`` and ``first_run.json`` into DIR (the page docs/speed/first_run.md records
such runs). Sections:

- first frame: ``python main.py ARGS`` (default ``--headless --frames 3``) as a subprocess with
  ``TI_OFFLINE_CACHE_FILE_PATH`` set to --cache (default: a fresh empty temporary folder,
  removed afterwards unless --keep): the wall time to the first frame (the modification time of
  ``meshes/frame_0001.obj``, written as soon as frame 1 is done), the whole run's wall time,
  each frame's ``ms_total`` from ``metrics.csv`` (the warm speed: the median from frame
  WARM_FROM on, in a run that long, e.g. ``-- --headless --frames 60 --no-images``), the machine's
  load before and after, and the run's ``loom:`` notices. ``--repo DIR`` runs another copy of
  the code (e.g. an exported earlier commit) with the same Python; the run's environment is
  this one's plus ``--env`` pairs, LOOM_FAST_COMPILE removed unless given with ``--env``.
- ``--method-switch``: in a fresh process with an empty cache, the default scene (hanging,
  mapping) built and stepped one frame, then switched to svd, warp-weft and back to mapping,
  each first frame after the switch timed (what a live switch costs).
- ``--window``: the window (hanging, under ``xvfb-run``) in a fresh process from an empty cache
  (--cache keeps one instead): the longest window frame (the time the window could not
  respond) at start, while running and after each switch (to svd, to warp-weft; 20 window
  frames apart).
"""
import argparse
import csv
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# The warm speed is read from this frame on: the frames before it still compile what their
# first use needs (a 3-frame default run read 521.6 ms "a frame" from frames 2-3, against
# about 30 ms warm), so a run needs 2 x WARM_FROM - 1 frames or more to report it.
WARM_FROM = 11


def load():
    return f"{os.getloadavg()[0]:.2f}"


def run(args, cache, repo=ROOT, env_extra=(), out=None):
    """``python main.py ARGS`` with the Taichi cache ``cache``: its first frame and speed."""
    env = dict(os.environ)
    env.pop("LOOM_FAST_COMPILE", None)
    env["TI_OFFLINE_CACHE_FILE_PATH"] = cache
    for pair in env_extra:
        k, v = pair.split("=", 1)
        env[k] = v
    out = out or tempfile.mkdtemp(prefix="loom_first_run_out_")
    cmd = [sys.executable, "main.py", *args, "--out", out]
    load0 = load()
    t0 = time.time()
    p = subprocess.run(cmd, cwd=repo, env=env, capture_output=True, text=True)
    wall = time.time() - t0
    load1 = load()
    first = os.path.join(out, "meshes", "frame_0001.obj")
    t_first = os.path.getmtime(first) - t0 if os.path.exists(first) else None
    ms = []
    metrics = os.path.join(out, "metrics.csv")
    if os.path.exists(metrics):
        with open(metrics) as fh:
            ms = [float(r["ms_total"]) for r in csv.DictReader(fh)]
    notes = [l for l in p.stderr.splitlines() if l.startswith("loom:")]
    return dict(cmd=" ".join(["python main.py", *args]), rc=p.returncode, wall=wall,
                first=t_first, ms=ms, load0=load0, load1=load1, notes=notes,
                stderr=p.stderr[-3000:] if p.returncode else "")


# ---- a method's first use in a running simulator --------------------------------------------
def method_switch_child():
    """In this process (empty cache): build the default scene, step a frame, switch
    methods; prints one JSON line."""
    from cloth import backend
    backend.init("cpu", "f64")
    import scenes
    from cloth.simulator import Simulator
    from scenes.common import resolve
    m = scenes.get("hanging")
    cfg = resolve(m.DEFAULTS, [])
    r = {"fast": backend.fast_compile(), "load0": load()}
    t0 = time.perf_counter()
    sim = Simulator(m.build(cfg), cfg)
    sim.step_frame()
    r["build_and_first_frame_s"] = time.perf_counter() - t0
    r["switches"] = []
    for meth in ("svd", "warp-weft", "mapping"):
        sim.set_method(meth)
        t0 = time.perf_counter()
        sim.step_frame()
        r["switches"].append({"method": meth, "first_frame_s": time.perf_counter() - t0,
                              "load": load()})
    print(json.dumps(r))


def method_switch(cache):
    env = dict(os.environ, TI_OFFLINE_CACHE_FILE_PATH=cache)
    p = subprocess.run([sys.executable, "-m", "benchmarks.first_run", "--child-switch"],
                       cwd=ROOT, env=env, capture_output=True, text=True)
    if p.returncode != 0:
        return {"error": p.stderr[-1500:]}
    return json.loads(p.stdout.strip().splitlines()[-1])


# ---- the window's stops ---------------------------------------------------------------------
WINDOW_DRIVER = """
import json, sys, time
sys.path.insert(0, {root!r})
from cloth import backend
backend.init("cpu", "f64")
from ui.state import AppState
from ui.app import App
st = AppState.from_scene("hanging", [])
app = App(st, size=(1280, 800))
phases, t0 = {{}}, time.perf_counter()

def run(name, n):
    k0 = len(app.frame_times)
    for _ in range(n):
        app.frame()
    phases[name] = max(app.frame_times[k0:])

run("start", 3)
phases["start_total_s"] = time.perf_counter() - t0
run("running", {between})
for m in ("svd", "warp-weft"):
    st.switch_method(m)
    run("switch to " + m, {between})
print("RESULT", json.dumps({{"fast": backend.fast_compile(), "sim_frame": st.sim.frame,
                           **phases}}))
"""


def window_run(cache, between=20):
    """One window run under xvfb-run: the longest window frame (ms) per phase."""
    env = dict(os.environ, LOOM_APP_NO_VSYNC="1", TI_OFFLINE_CACHE_FILE_PATH=cache)
    env.pop("LOOM_FAST_COMPILE", None)
    code = WINDOW_DRIVER.format(root=ROOT, between=between)
    proc = subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 1280x800x24", sys.executable,
                           "-c", code], capture_output=True, text=True, env=env)
    line = next((ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")), None)
    if line is None:
        return {"error": proc.stderr[-1500:]}
    return json.loads(line[len("RESULT "):])


# ---- the page ---------------------------------------------------------------------------------
def page(r, cmd, seconds):
    from benchmarks.harness import header
    L = ["# The first run on a machine", "", header(cmd, seconds), "",
         "## First frame", "",
         f"`{r['first_run']['cmd']}`, Taichi cache: {r['cache']}. Load (1-minute average) "
         f"{r['first_run']['load0']} before, {r['first_run']['load1']} after.", "",
         f"| first frame (s) | whole run (s) | ms a frame (median of frames {WARM_FROM}.., "
         "runs that long) | exit code |",
         "| --- | --- | --- | --- |"]
    f = r["first_run"]
    warm = sorted(f["ms"][WARM_FROM - 1:])
    warm_ms = f"{warm[len(warm) // 2]:.1f}" if len(warm) >= WARM_FROM else "-"
    L.append(f"| {f['first']:.1f} | {f['wall']:.1f} | {warm_ms} | {f['rc']} |"
             if f["first"] is not None else f"| - | {f['wall']:.1f} | - | {f['rc']} |")
    L += [""] + [f"    {n}" for n in f["notes"]] + ([""] if f["notes"] else [])
    if f["stderr"]:
        L += ["The run failed:", "", "```", f["stderr"], "```", ""]
    if "method_switch" in r:
        s = r["method_switch"]
        L += ["## A method's first use in a running simulator", ""]
        if "error" in s:
            L += ["The run failed:", "", "```", s["error"], "```", ""]
        else:
            L += [f"Empty cache, {'fast' if s['fast'] else 'optimised'} compile; "
                  f"build and first frame (mapping) "
                  f"{s['build_and_first_frame_s']:.1f} s.", "",
                  "| switch to | first frame after it (s) | load |", "| --- | --- | --- |"]
            L += [f"| {w['method']} | {w['first_frame_s']:.1f} | {w['load']} |"
                  for w in s["switches"]]
            L.append("")
    if "window" in r:
        L += ["## How long the window stops", "",
              "The longest window frame (s), i.e. the longest time the window could not "
              "respond, per phase.", "",
              "| compile | start: longest | start: total | running: longest | "
              "switch to svd | switch to warp-weft |",
              "| --- | --- | --- | --- | --- | --- |"]
        for w in r["window"]:
            if "error" in w:
                L.append(f"| failed: {w['error'][-200:]!r} | | | | | |")
                continue
            ms = 1e-3
            L.append(f"| {'fast' if w['fast'] else 'optimised'} | {w['start'] * ms:.1f} | "
                     f"{w['start_total_s']:.1f} | {w['running'] * ms:.2f} | "
                     f"{w['switch to svd'] * ms:.2f} | {w['switch to warp-weft'] * ms:.2f} |")
        L.append("")
    return "\n".join(L)


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m benchmarks.first_run",
                                description=__doc__.split("\n")[0])
    p.add_argument("--out", help="folder for first_run.md and first_run.json (default: print "
                   "the page)")
    p.add_argument("--cache", help="Taichi offline cache folder (default: a fresh empty one)")
    p.add_argument("--keep", action="store_true", help="keep the fresh cache folder")
    p.add_argument("--repo", default=ROOT, help="the code to run (default: this checkout)")
    p.add_argument("--env", action="append", default=[], metavar="K=V")
    p.add_argument("--method-switch", action="store_true",
                   help="also time a method's first use in a running simulator")
    p.add_argument("--window", action="store_true",
                   help="also time the window's stops at start and at a switch (xvfb-run)")
    p.add_argument("--child-switch", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("rest", nargs="*")
    a = p.parse_args(argv)
    if a.child_switch:
        method_switch_child()
        return 0
    from benchmarks.harness import command, write_json
    cmd = command("benchmarks.first_run", argv)
    t0 = time.time()
    args = a.rest or ["--headless", "--frames", "3"]

    def fresh():
        return a.cache or tempfile.mkdtemp(prefix="loom_ticache_")

    def done(cache):
        if not a.cache and not a.keep:
            shutil.rmtree(cache, ignore_errors=True)

    cache = fresh()
    try:
        r = {"cache": "given" if a.cache else "empty",
             "first_run": run(args, cache, a.repo, a.env)}
    finally:
        done(cache)
    if a.method_switch:
        cache = tempfile.mkdtemp(prefix="loom_ticache_")
        try:
            r["method_switch"] = method_switch(cache)
        finally:
            shutil.rmtree(cache, ignore_errors=True)
    if a.window:
        if shutil.which("xvfb-run") is None:
            sys.exit("xvfb-run is not installed (apt-get install xvfb)")
        cache = fresh()
        try:
            r["window"] = [window_run(cache)]
        finally:
            done(cache)
    text = page(r, cmd, time.time() - t0)
    if a.out:
        os.makedirs(a.out, exist_ok=True)
        with open(os.path.join(a.out, "first_run.md"), "w") as fh:
            fh.write(text + "\n")
        write_json(a.out, "first_run", r, cmd, time.time() - t0)
        print(f"wrote {os.path.join(a.out, 'first_run.md')}")
    else:
        print(text)
    return 0 if r["first_run"]["rc"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
