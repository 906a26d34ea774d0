"""How long the window stops drawing at start and at a live method switch, from an empty cache.

    python -m benchmarks.window_switch [--cache DIR] [--frames-between 20]

Runs the window (hanging, the default scene, under ``xvfb-run``) twice in fresh processes, with
the other methods prepared after the first step (the default) and without
(``LOOM_PREPARE_METHODS=0``), each with a fresh empty Taichi cache (``--cache DIR`` keeps one
instead, for a warm run) and the background warmer off. Each run shows the window, lets it run
``--frames-between`` window frames, switches to svd, runs, switches to warp-weft, runs, and
reports the longest window frame (the time the window could not respond) in each phase:
start (up to the end of preparing), running, and after each switch. (docs/speed/first_run.md)
"""
import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

DRIVER = """
import json, sys, time
sys.path.insert(0, {root!r})
from cloth import backend
backend.init("cpu", "f64", first_run_fast=True)
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

run("start", 2 + 2 * len(st.methods_to_prepare()) + 1)
phases["start_total_s"] = time.perf_counter() - t0
run("running", {between})
for m in ("svd", "warp-weft"):
    st.switch_method(m)
    run("switch to " + m, {between})
print("RESULT", json.dumps({{"compile": backend.compile_reason(), "fast": backend.fast_compile(),
                           "sim_frame": st.sim.frame, **phases}}))
"""


def one(prepare, cache, between):
    env = dict(os.environ, LOOM_BACKGROUND_COMPILE="0", LOOM_APP_NO_VSYNC="1",
               LOOM_PREPARE_METHODS="1" if prepare else "0",
               TI_OFFLINE_CACHE_FILE_PATH=cache)
    env.pop("LOOM_FAST_COMPILE", None)
    code = DRIVER.format(root=ROOT, between=between)
    proc = subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 1280x800x24", sys.executable,
                           "-c", code], capture_output=True, text=True, env=env)
    line = next((ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")), None)
    if line is None:
        sys.exit(f"the window run failed:\n{proc.stderr[-3000:]}")
    return json.loads(line[len("RESULT "):])


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m benchmarks.window_switch",
                                description=__doc__.split("\n")[0])
    p.add_argument("--cache", help="a Taichi cache folder to use (default: a fresh empty one)")
    p.add_argument("--frames-between", type=int, default=20)
    a = p.parse_args(argv)
    if shutil.which("xvfb-run") is None:
        sys.exit("xvfb-run is not installed (apt-get install xvfb)")
    print(f"load {os.getloadavg()[0]:.2f}")
    print("| prepare | compile | start: longest frame (s) | start: total (s) | running: longest "
          "(s) | switch to svd: longest (s) | switch to warp-weft: longest (s) |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for prepare in (True, False):
        cache = a.cache or tempfile.mkdtemp(prefix="loom_cache_")
        try:
            r = one(prepare, cache, a.frames_between)
        finally:
            if not a.cache:
                shutil.rmtree(cache, ignore_errors=True)
        ms = 1e-3
        print(f"| {'on' if prepare else 'off'} | {'fast' if r['fast'] else 'optimised'} | "
              f"{r['start'] * ms:.1f} | {r['start_total_s']:.1f} | {r['running'] * ms:.2f} | "
              f"{r['switch to svd'] * ms:.2f} | {r['switch to warp-weft'] * ms:.2f} |",
              flush=True)
    print(f"load {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
