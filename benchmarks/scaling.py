"""Scaling: ms per frame of each stage and peak memory against triangle count, with the fitted
exponent k of cost ~ N^k per stage.

    python -m benchmarks.scaling --out docs/speed            # ~500 to ~100k triangles
    python -m benchmarks.scaling --quick --out results/scale  # ~500 to ~8k, a few minutes
    python -m benchmarks.scaling --there-and-back --resolutions 33 46 65 91 129 181 \
        --strain-frames 10 --out docs/speed   # 2k-64k, drift cancelled (~25 min)

Each size runs in its own child process (so its peak memory is its own):
  dynamics              the hanging scene (soft cloth, one 1/30 s substep per frame, CG to
                        1e-4), no strain limiting;
  strain_limit:METHOD   the same scene with the method on from the start (augmented
                        Lagrangian, the default budget of 50 rounds, warp +-1 % / weft +-5 %);
  collision             the same scene with a still sphere touching the sheet, the ground
                        plane and self-collision: ``collision`` is the obstacle pass (SDF and
                        continuous sampling per vertex), ``self_collision`` the spatial-hash
                        pass;
  remesh                ``cloth.remesh.remesh`` on the moving analytic sheet of the remesher's
                        own test sheet (``sheet_shape``, a gently curved swaying sheet), with
                        size_max 1.8 x the grid spacing so the count stays near N.
Every run starts from the scene's start; frame 1 is untimed (it compiles the kernels), then
the median over the next --frames frames (frames 2 to 4 by default: the start of the sheet's
fall, the same simulated time at every size; --strain-frames sets the strain-limit stages'
count apart: their 3-frame medians varied by up to 1.6x between runs, and above 2000 faces
frame 2 still runs block Jacobi while the multigrid is built). Memory: ``ru_maxrss`` (peak resident set) of
the child, which below ~8k triangles is mostly Python, Taichi and kernel compilation (a child
on an 8-triangle sheet is measured for comparison), and the bytes of every Taichi field and
ndarray the simulator holds (model, dynamics, strain work arrays, collider). A stage whose predicted time per frame at the next size (extrapolated
with the exponent of the last two sizes) exceeds --budget seconds is skipped, and the table
says so.
"""
import argparse
import json
import os
import resource
import subprocess
import sys
import time

import numpy as np

from benchmarks.harness import command, header, write_json

from cloth.strain.families import METHODS
STAGES = ("dynamics", "collision", "self_collision", "remesh") + tuple(
    f"strain_limit:{m}" for m in METHODS)
# Vertices per side: 2 (n - 1)^2 triangles, from 512 to 100352.
# 181: 64.8k triangles, the top of the scaling target's 2k-64k range.
FULL = [17, 33, 46, 65, 91, 129, 181, 225]
QUICK = [17, 33, 65]


def sheet_shape(uv, kind, t):
    """World positions and velocities of a 1 m sheet at time t (the remesh stage's moving
    test sheet): 'hanging' (gently curved, slowly swaying) or 'fold' (a sharp fold whose line
    drifts across the sheet)."""
    u, v = uv[:, 0], uv[:, 1]
    if kind == "hanging":
        # A generalised cylinder (isometric, like hanging drapes): the u-lines follow a plane
        # curve of curvature 4 sin(4 pi u + t) per metre, the v-lines hang straight down.
        s = np.linspace(0.0, 1.0, 2001)
        phi = -np.cos(4 * np.pi * s + t) / np.pi
        cx = np.concatenate([[0], np.cumsum(np.cos(phi[1:]) + np.cos(phi[:-1])) * 2.5e-4])
        cy = np.concatenate([[0], np.cumsum(np.sin(phi[1:]) + np.sin(phi[:-1])) * 2.5e-4])
        x = np.c_[np.interp(u, s, cx), np.interp(u, s, cy), -v]
        vel = np.c_[np.zeros_like(u), 0.05 * np.sin(np.pi * u) * v, np.zeros_like(u)]
        return x, vel
    at = 0.4 + 0.02 * t
    d = u - at
    x = np.c_[np.where(d < 0, u, at + d * np.cos(2.0)), v, np.where(d < 0, 0.0, d * np.sin(2.0))]
    return x, np.zeros_like(x)


# ---- child: one size -------------------------------------------------------------------------
def field_bytes(root):
    """Bytes of every Taichi field / ndarray reachable from ``root`` through attributes of
    objects defined in cloth/ (each counted once)."""
    from taichi.lang._ndarray import Ndarray
    from taichi.lang.field import Field
    seen, total, stack = set(), 0, [root]
    while stack:
        obj = stack.pop()
        if id(obj) in seen:
            continue
        seen.add(id(obj))
        if isinstance(obj, (Field, Ndarray)):
            total += obj.to_numpy().nbytes
            continue
        if isinstance(obj, (list, tuple)):
            stack.extend(obj)
        elif type(obj).__module__.startswith("cloth") and hasattr(obj, "__dict__"):
            stack.extend(vars(obj).values())
    return total


def timed_frames(sim, stage_names, frames, extra=None):
    """Step ``frames`` frames; the median ms per frame of each named stage (plus ``extra``:
    name -> f(sim) read after each frame)."""
    rows = {n: [] for n in stage_names}
    extra = extra or {}
    rows.update({n: [] for n in extra})
    for _ in range(frames):
        sim.step_frame()
        for n in stage_names:
            rows[n].append(sim.stage(n).ms)
        for n, f in extra.items():
            rows[n].append(f(sim))
    return {n: float(np.median(v)) for n, v in rows.items()}


def child(res, methods, frames, strain_frames=None):
    """Measure one size; returns a dict (printed as JSON by the child process). Each strain
    method and the collision run get their own Simulator from the scene's start (the kernels
    compile once per process, so only the first frame of each kind is slow)."""
    from cloth import backend
    backend.init("cpu", "f64")
    import scenes
    from cloth import remesh
    from cloth.collision import Plane, Sphere
    from cloth.model import MeshArrays
    from cloth.sheet import make_sheet
    from cloth.simulator import Simulator
    from scenes.common import resolve
    out = {"resolution": res, "ms": {}, "info": {}}
    module = scenes.get("hanging")

    def config(method="none"):
        cfg = resolve(module.DEFAULTS, [{"cloth": {"resolution": res},
                                         "strain": {"method": method}}])
        return cfg, module.build(cfg)

    t0 = time.perf_counter()
    cfg, setup = config()
    sim = Simulator(setup, cfg)
    out["faces"] = int(sim.model.n_faces)
    sim.step_frame()                                      # compiles the dynamics
    out["info"]["first_frame_s"] = time.perf_counter() - t0
    r = timed_frames(sim, ["dynamics"], frames,
                     {"cg_iterations": lambda s: s.dynamics.last_cg_iters})
    out["ms"]["dynamics"] = r["dynamics"]
    out["info"]["cg_iterations"] = r["cg_iterations"]
    for m in methods:
        cfg, setup = config(m)
        sim = Simulator(setup, cfg)
        sim.step_frame()                                  # frame 1, untimed (compiles if cold)
        r = timed_frames(sim, ["strain_limit"], strain_frames or frames,
                         {"rounds": lambda s: s.strain.last_iterations,
                          "newton": lambda s: s.strain.last_newton,
                          "cg": lambda s: s.strain.last_cg,
                          "converged": lambda s: float(s.strain.last_converged)})
        out["ms"][f"strain_limit:{m}"] = r["strain_limit"]
        for key in ("rounds", "newton", "cg", "converged"):
            out["info"][f"{key}:{m}"] = r[key]
    # Collision: a still sphere just touching the sheet's middle from behind, the ground, and
    # self-collision.
    cfg, setup = config()
    cfg["collision"] = {"thickness": 0.005}
    top = cfg["cloth"]["top"]
    setup.obstacles = [Sphere(center=(0.0, top - 0.5, -0.124), radius=0.12, mu=0.3),
                       Plane(point=(0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0), mu=0.3)]
    setup.self_collision = True
    sim = Simulator(setup, cfg)
    sim.step_frame()                                      # compiles the collider
    r = timed_frames(sim, [], frames, {"collision": lambda s: s.collider.last_ms_obstacles,
                                       "self_collision": lambda s: s.collider.last_ms_self})
    out["ms"].update(collision=r["collision"], self_collision=r["self_collision"])
    if sim.strain is None:
        # Allocate the strain limiter's work arrays (nothing runs) so that every size counts
        # the same fields, also where every method was skipped.
        sim.set_method("mapping")
        sim.set_method("none")
    out["field_bytes"] = field_bytes(sim)
    del sim
    # Remeshing: the remesher's own moving test sheet at this resolution.
    size_max = 1.8 / (res - 1)
    params = remesh.RemeshParams(size_min=size_max / 5, size_max=size_max)
    uv, faces = make_sheet(1.0, 1.0, res, res, pattern="alternating")
    mesh = MeshArrays(uv=uv, x=np.c_[uv, np.zeros(len(uv))], faces=faces)
    times, counts = [], []
    for frame in range(frames + 3):                       # 3 frames to settle the count
        mesh.x, mesh.v = sheet_shape(mesh.uv, "hanging", 0.1 * frame)
        t1 = time.perf_counter()
        mesh, _, st = remesh.remesh(mesh, params)
        if frame >= 3:
            times.append(1000.0 * (time.perf_counter() - t1))
            counts.append(st["faces_out"])
    out["ms"]["remesh"] = float(np.median(times))
    out["info"]["remesh_faces"] = float(np.median(counts))
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return out


# ---- parent: the sweep over sizes --------------------------------------------------------------
def run_child(res, methods, frames, timeout, strain_frames=None):
    cmd = [sys.executable, "-m", "benchmarks.scaling", "--child", str(res), "--frames",
           str(frames), "--methods", *methods]
    if strain_frames:
        cmd += ["--strain-frames", str(strain_frames)]
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout,
                              cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    except subprocess.TimeoutExpired:
        return {"resolution": res, "error": f"timed out after {timeout} s"}
    if proc.returncode != 0:
        return {"resolution": res, "error": proc.stderr.strip().splitlines()[-1:]}
    line = [l for l in proc.stdout.splitlines() if l.startswith("{")][-1]
    out = json.loads(line)
    out["wall_s"] = time.perf_counter() - t0
    return out


def predict(points, n_next):
    """ms at n_next from the last two (N, ms) points (exponent 1.5 with one point)."""
    if not points:
        return 0.0
    if len(points) == 1:
        (n0, t0), k = points[0], 1.5
    else:
        (n1, t1), (n0, t0) = points[-2], points[-1]
        k = max(np.log(t0 / t1) / np.log(n0 / n1), 1.0) if t1 > 0 and t0 > 0 else 1.5
    return t0 * (n_next / n0) ** k


def stage_n(row, stage):
    """The triangle count a stage's time belongs to (the remesher's output varies a little)."""
    return row["info"]["remesh_faces"] if stage == "remesh" else row["faces"]


def fit_exponent(ns, ms):
    """Least-squares slope of log(ms) against log(N), or nan with fewer than 2 points."""
    ns, ms = np.asarray(ns, float), np.asarray(ms, float)
    ok = (ms > 0) & np.isfinite(ms)
    if ok.sum() < 2:
        return float("nan")
    return float(np.polyfit(np.log(ns[ok]), np.log(ms[ok]), 1)[0])


def sweep(resolutions, frames, budget_s, timeout, log=print, strain_frames=None, back=False):
    base = run_child(3, list(METHODS), 2, timeout)
    log(f"baseline (8 triangles): peak RSS {base.get('peak_rss_mb', float('nan')):.0f} MB")
    rows, skipped = [], []
    history = {s: [] for s in STAGES}
    for res in resolutions:
        n = 2 * (res - 1) ** 2
        # Every timed frame runs the dynamics, so a size whose dynamics alone is predicted
        # over budget ends the sweep; a strain method over budget is left out at this size.
        p = predict(history["dynamics"], n)
        if p > 1000 * budget_s:
            skipped.append(("all", n, p))
            break
        methods = []
        for m in METHODS:
            p = predict(history[f"strain_limit:{m}"], n)
            if p > 1000 * budget_s:
                skipped.append((f"strain_limit:{m}", n, p))
            else:
                methods.append(m)
        r = run_child(res, methods, frames, timeout, strain_frames)
        if "error" in r:
            log(f"{n} triangles: {r['error']}")
            rows.append(r)
            break
        r["faces"] = r.get("faces", n)
        for s, v in r["ms"].items():
            history[s].append((stage_n(r, s), v))
        rows.append(r)
        log(f"{r['faces']:6d} triangles: " + ", ".join(f"{s} {v:.1f}" for s, v in r["ms"].items())
            + f" ms/frame; peak RSS {r['peak_rss_mb']:.0f} MB; child {r['wall_s']:.0f} s")
    if back:
        there_and_back(rows, frames, timeout, log, strain_frames)
    return base, rows, skipped


def there_and_back(rows, frames, timeout, log=print, strain_frames=None):
    """Run every size that ran again, largest first, with the same stages, and set each
    stage's ms to the geometric mean of its two runs (the runs themselves are kept as
    ``ms_up`` and ``ms_back``).

    Why: this machine's speed drifts within a sweep (by up to 1.5x over a quarter of an hour,
    seen as unchanged code fitting different exponents). Sizes run in rising order put any
    drift onto the exponent; in the mirrored sequence each size's two runs sit symmetrically
    about the sweep's middle in time, so a drift linear in time cancels in the mean's ratios
    (up to second order), and the two passes' exponents show how large the drift was."""
    for r in reversed([r for r in rows if "error" not in r]):
        methods = [s.split(":", 1)[1] for s in r["ms"] if s.startswith("strain_limit:")]
        b = run_child(r["resolution"], methods, frames, timeout, strain_frames)
        if "error" in b:
            log(f"{r['faces']} triangles, back: {b['error']}")
            continue
        r["ms_up"], r["ms_back"] = r["ms"], b["ms"]
        r["ms"] = {s: float(np.sqrt(v * b["ms"][s])) if s in b["ms"] and v > 0 else v
                   for s, v in r["ms_up"].items()}
        r["peak_rss_mb"] = max(r["peak_rss_mb"], b["peak_rss_mb"])
        log(f"{r['faces']:6d} triangles, back: " + ", ".join(
            f"{s} {v:.1f}" for s, v in b["ms"].items()) + f" ms/frame; child {b['wall_s']:.0f} s")


def write_outputs(base, rows, skipped, out, cmd, seconds, budget_s):
    os.makedirs(out, exist_ok=True)
    good = [r for r in rows if "error" not in r]
    fits = {}
    for s in STAGES + ("peak_rss", "field_bytes"):
        pts = []
        for r in good:
            if s in r["ms"]:
                pts.append((stage_n(r, s), r["ms"][s]))
            elif s == "peak_rss":
                pts.append((r["faces"], r["peak_rss_mb"]))
            elif s == "field_bytes":
                pts.append((r["faces"], r["field_bytes"]))
        big = [p for p in pts if p[0] >= 8000]
        issue = [p for p in pts if 2000 <= p[0] <= 70000]       # the scaling target's 2k-64k
        fits[s] = {"k_all": fit_exponent(*zip(*pts)) if len(pts) > 1 else float("nan"),
                   "k_8k": fit_exponent(*zip(*big)) if len(big) > 1 else float("nan"),
                   "k_2k_64k": fit_exponent(*zip(*issue)) if len(issue) > 1 else float("nan"),
                   "n_points": len(pts), "largest": int(max((p[0] for p in pts), default=0))}
        for key in ("ms_up", "ms_back"):               # the two passes of --there-and-back
            one = [(stage_n(r, s), r[key][s]) for r in good
                   if key in r and s in r[key] and 2000 <= stage_n(r, s) <= 70000]
            if len(one) > 1:
                fits[s][f"k_2k_64k_{key[3:]}"] = fit_exponent(*zip(*one))
    write_json(out, "scaling", {"budget": budget_s, "baseline": base, "rows": rows,
                                "fits": fits, "skipped": skipped}, cmd, seconds)
    names = {"dynamics": "dynamics", "collision": "collision (obstacles)",
             "self_collision": "self-collision", "remesh": "remesh",
             **{f"strain_limit:{m}": f"strain limit {m}" for m in METHODS}}
    lines = ["# Scaling with triangle count", "", header(cmd, seconds), "",
             "On a machine shared with other jobs, times carry noise of tens of percent.", "",
             "Hanging soft sheet, one 1/30 s substep per frame; ms per frame of each stage, "
             "median over the timed frames (see `benchmarks/scaling.py` for the set-up of each "
             "stage; remesh runs on its own test sheet, whose triangle count after remeshing is "
             "in brackets and is the N of its fit). `CG iters`: the dynamics' CG iterations per "
             "step (capped at 500). Peak RSS is the child process's `ru_maxrss` (one process "
             "per size): up to about 8k triangles it is set by Python, Taichi and LLVM compiling "
             f"the kernels (the same run on 8 triangles peaks at "
             f"{base.get('peak_rss_mb', float('nan')):.0f} MB, and the figure varies by some "
             "100 MB with what had to be compiled), so its exponent means something only over "
             "the larger sizes. `Taichi MB` counts the bytes of the fields and ndarrays the "
             "simulator holds, spare capacity included (model, dynamics, strain work arrays, "
             "collider).", "",
             "| triangles | " + " | ".join(names[s] for s in STAGES) +
             " | CG iters | peak RSS MB | Taichi MB |",
             "|---" * (len(STAGES) + 4) + "|"]
    for r in good:
        cells = [f"{r['ms'][s]:.3g}" if s in r["ms"] else "skipped" for s in STAGES]
        cells[STAGES.index("remesh")] += f" ({r['info']['remesh_faces']:.0f})"
        lines.append(f"| {r['faces']} | " + " | ".join(cells) +
                     f" | {r['info'].get('cg_iterations', float('nan')):.0f}"
                     f" | {r['peak_rss_mb']:.0f}"
                     f" | {r['field_bytes'] / 2**20:.1f} |")
    lines += ["", "Fitted exponent k of cost ~ N^k (least squares in log-log), over every "
              "measured size, over sizes of 8k triangles and more, and over 2k-64k (the "
              "range of the solver's scaling target):", "",
              "| stage | k (all sizes) | k (>= 8k) | k (2k-64k) | sizes | largest N |",
              "|---|---|---|---|---|---|"]
    for s in STAGES:
        f = fits[s]
        lines.append(f"| {names[s]} | {f['k_all']:.2f} | {f['k_8k']:.2f} | "
                     f"{f['k_2k_64k']:.2f} | {f['n_points']} | "
                     f"{f['largest']} |")
    for s, label in (("peak_rss", "peak RSS"), ("field_bytes", "Taichi field bytes")):
        f = fits[s]
        lines.append(f"| {label} | {f['k_all']:.2f} | {f['k_8k']:.2f} | "
                     f"{f['k_2k_64k']:.2f} | {f['n_points']} | "
                     f"{f['largest']} |")
    passes = [s for s in STAGES if "k_2k_64k_up" in fits[s]]
    if passes:
        lines += ["", "Run there and back (`--there-and-back`): every size ran twice, in rising "
                  "and then in falling order, and each time above is the geometric mean of its "
                  "two runs, which cancels a drift of the machine's speed that is linear in "
                  "time. The exponent over 2k-64k from each pass alone (the spread is the "
                  "drift):", "", "| stage | k rising | k falling | k of the means |",
                  "|---|---|---|---|"]
        lines += [f"| {names[s]} | {fits[s]['k_2k_64k_up']:.2f} | "
                  f"{fits[s]['k_2k_64k_back']:.2f} | {fits[s]['k_2k_64k']:.2f} |"
                  for s in passes]
    if skipped:
        lines += ["", "Skipped (predicted time per frame above the --budget of "
                  f"{budget_s:g} s, from the exponent of the two sizes before):", ""]
        for s, n, p in skipped:
            what = "every stage (the dynamics runs in every frame)" if s == "all" else names[s]
            lines.append(f"- {what} at {n} triangles: predicted {p / 1000:.0f} s per frame"
                         if np.isfinite(p) else f"- {what} at {n} triangles: failed")
    for r in rows:
        if "error" in r:
            lines.append(f"- resolution {r['resolution']}: {r['error']}")
    for key, what in (("rounds", "AL rounds"), ("newton", "Newton steps"),
                      ("cg", "PCG iterations")):
        per = [(r["faces"], {m: r["info"].get(f"{key}:{m}") for m in METHODS}) for r in good]
        lines += ["", f"{what} per substep (median) by size: " + "; ".join(
            f"{n}: " + ", ".join(f"{m} {v:.0f}" for m, v in d.items() if v is not None)
            for n, d in per if any(v is not None for v in d.values())) + "."]
    lines += ["", "Plot: `scaling.png`."]
    with open(os.path.join(out, "scaling.md"), "w") as fh:
        fh.write("\n".join(lines) + "\n")
    plot(good, base, fits, out, names)


def plot(rows, base, fits, out, names):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax, axm) = plt.subplots(1, 2, figsize=(12, 4.8), gridspec_kw={"width_ratios": [3, 2]})
    styles = {"dynamics": ("k", "o"), "collision": ("tab:gray", "s"),
              "self_collision": ("tab:brown", "D"), "remesh": ("tab:purple", "v"),
              "strain_limit:svd": ("tab:blue", "^"), "strain_limit:warp-weft": ("tab:orange", "^"),
              "strain_limit:mapping": ("tab:green", "^")}
    for s in STAGES:
        pts = [(stage_n(r, s), r["ms"][s]) for r in rows if s in r["ms"]]
        if not pts:
            continue
        c, mk = styles[s]
        ax.plot(*zip(*pts), color=c, marker=mk, lw=1.3,
                label=f"{names[s]} (k = {fits[s]['k_all']:.2f})")
    ax.set_xscale("log")
    ax.set_yscale("log")
    lo, hi = ax.get_ylim()
    ax.set_ylim(lo, hi * 30)                       # headroom: the legend sits above the lines
    ax.set_xlabel("triangles (log)")
    ax.set_ylabel("ms per frame (one substep; log)")
    ax.set_title("Cost of each stage against mesh size")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7.5, loc="upper left", ncol=2)
    n = [r["faces"] for r in rows]
    axm.plot(n, [r["peak_rss_mb"] for r in rows], "o-", color="tab:red",
             label=f"peak RSS of the process (k = {fits['peak_rss']['k_8k']:.2f} above 8k)")
    axm.plot(n, [r["field_bytes"] / 2**20 for r in rows], "s--", color="tab:blue",
             label=f"Taichi fields + ndarrays (k = {fits['field_bytes']['k_all']:.2f})")
    axm.set_xscale("log")
    axm.set_yscale("log")
    axm.set_xlabel("triangles (log)")
    axm.set_ylabel("MB (log)")
    axm.set_title(f"Memory (8 triangles: peak RSS {base.get('peak_rss_mb', float('nan')):.0f} MB)")
    axm.grid(True, which="both", alpha=0.3)
    axm.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "scaling.png"), dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join("results", "scaling"))
    ap.add_argument("--quick", action="store_true", help="~500 to ~8k triangles")
    ap.add_argument("--frames", type=int, default=None, help="timed frames per stage")
    ap.add_argument("--strain-frames", type=int, default=None,
                    help="timed frames of the strain-limit stages (default: --frames); "
                    "their medians over 3 frames varied by up to 1.6x between runs")
    ap.add_argument("--budget", type=float, default=40.0,
                    help="skip a stage predicted slower than this many seconds per frame")
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per size")
    ap.add_argument("--there-and-back", action="store_true",
                    help="run the sizes again in falling order and average each size's two "
                    "runs (cancels a linear drift of the machine's speed; twice the time)")
    ap.add_argument("--resolutions", type=int, nargs="+", default=None,
                    help=f"vertices per side of the sizes to run (default {FULL})")
    ap.add_argument("--child", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--methods", nargs="*", default=list(METHODS), help=argparse.SUPPRESS)
    ap.add_argument("--replot", action="store_true",
                    help="rewrite scaling.md and scaling.png from OUT/scaling.json")
    args = ap.parse_args(argv)
    if args.replot:
        d = json.load(open(os.path.join(args.out, "scaling.json")))
        write_outputs(d["baseline"], d["rows"], [tuple(x) for x in d["skipped"]], args.out,
                      d["command"], d["seconds"], d.get("budget", args.budget))
        return 0
    if args.child:
        print(json.dumps(child(args.child, args.methods, args.frames or 3,
                               args.strain_frames)))
        return 0
    argv = sys.argv[1:] if argv is None else argv
    frames = args.frames or (2 if args.quick else 3)
    t0 = time.perf_counter()
    sizes = args.resolutions or (QUICK if args.quick else FULL)
    base, rows, skipped = sweep(sorted(sizes), frames, args.budget, args.timeout,
                                strain_frames=args.strain_frames, back=args.there_and_back)
    seconds = time.perf_counter() - t0
    write_outputs(base, rows, skipped, args.out, command("benchmarks.scaling", argv),
                  seconds, args.budget)
    print(f"wrote {args.out}/scaling.md in {seconds:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
