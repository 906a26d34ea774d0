"""What the whole teaching view adds to a running window frame, before and after a change
(docs/teaching.md, Cost): the hanging sheet (1152 triangles, mapping) in the real window
under Xvfb, ``LOOM_APP_FRAMES`` frames from the start, without and with
``--overlay axes,plot --color binding``, for this checkout and an earlier one, interleaved
(the order alternates every repeat, so a machine shared with other jobs loads both alike).
Prints each run's line and, per checkout, the medians and the added time per repeat:

    git worktree add --detach /tmp/before COMMIT
    python -m benchmarks.teaching_ab --before /tmp/before [--repeats 6] [--frames 300]
"""
import argparse
import os
import re
import subprocess
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONFIGS = {"base": [], "all": ["--overlay", "axes,plot", "--color", "binding"]}
LINE = re.compile(r"frame ([\d.]+) ms, render ([\d.]+) ms .*draw ([\d.]+), panel ([\d.]+), "
                  r"show ([\d.]+)\), simulation ([\d.]+) ms")
PARTS = ("frame", "render", "draw", "panel", "show", "simulation")


def run(tree, config, frames):
    env = dict(os.environ, LOOM_APP_FRAMES=str(frames), LOOM_APP_NO_VSYNC="1")
    proc = subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 1280x800x24", sys.executable,
                           "main.py", "hanging", *CONFIGS[config]], cwd=tree, env=env,
                          capture_output=True, text=True, timeout=900)
    line = next((x for x in proc.stderr.splitlines() if x.startswith("loom: ") and
                 "window frames" in x), None)
    if line is None:
        raise RuntimeError(f"{tree} {config}: no statistics line\n{proc.stderr[-2000:]}")
    return line, np.array([float(v) for v in LINE.search(line).groups()])


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--before", required=True, help="a checkout of the earlier commit")
    p.add_argument("--repeats", type=int, default=6)
    p.add_argument("--frames", type=int, default=300)
    args = p.parse_args(argv)
    trees = {"before": os.path.abspath(args.before), "after": ROOT}
    res = {name: {c: [] for c in CONFIGS} for name in trees}
    for r in range(args.repeats):
        order = list(trees) if r % 2 == 0 else list(trees)[::-1]
        for name in order:
            for config in CONFIGS:
                line, v = run(trees[name], config, args.frames)
                res[name][config].append(v)
                print(f"{r + 1} {name:6s} {config:4s} {line}", flush=True)
    for name in trees:
        base, full = np.array(res[name]["base"]), np.array(res[name]["all"])
        added = full - base
        share = added[:, 0] / base[:, 0]
        print(f"{name}: frame median {np.median(base[:, 0]):.1f} ms without, "
              f"{np.median(full[:, 0]):.1f} ms with the teaching view; added per repeat "
              f"{', '.join(f'{a:+.1f}' for a in added[:, 0])} ms, median {np.median(added[:, 0]):+.1f}"
              f" ms = {100 * np.median(share):.0f} % of the frame without (median of the "
              f"repeats); median added " + ", ".join(f"{k} {np.median(added[:, i]):+.1f}"
                                                      for i, k in enumerate(PARTS[1:], 1)))


if __name__ == "__main__":
    main()
