"""Remeshing every frame with each strain-limiting method, at the scene's default sizes (issue #4's
acceptance run): the mesh must stay finite, stay at a workable size, and meet the method's own
constraints after every frame's remesh and projection.

    python -m benchmarks.remesh_limits                 # hanging, 300 frames x 3 methods, ~25 min
    python -m benchmarks.remesh_limits --quick         # 30 frames each, ~2 min
    python -m benchmarks.remesh_limits --scene drape --frames 60
    python -m benchmarks.remesh_limits --methods svd --iters 50 --out results/svd_iters50

Per frame it records the face count, the method's own violation after the frame (the remesh stage
ends with a projection onto the new triangles, so this is the violation "after every frame's
remesh and projection"), NaN, whether that projection converged, the frame's wall time and the
kinetic energy. A run passes when every frame is finite and its own violation is under the
solver tolerance (``strain.tol``). Writes remesh_limits.md, remesh_limits.json and
remesh_limits.png (faces and violation against frame) under --out.
"""
import argparse
import json
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import numpy as np

from benchmarks import harness, speed_vs_error

from cloth.strain.families import METHODS


def log(*args):
    print(*args, file=sys.stderr, flush=True)


def run(scene, method, frames, extra=None):
    """One run with remeshing on at the scene's sizes; one dict per frame, and the config."""
    from cloth.simulator import Simulator
    overrides = {"remesh": {"enabled": True}, "strain": {"method": method}}
    for k, v in (extra or {}).items():
        overrides.setdefault(k, {}).update(v)
    module, cfg, setup = harness.configure(scene, overrides)
    sim = Simulator(setup, cfg)
    rows, t0 = [], time.perf_counter()
    for frame in range(1, frames + 1):
        t = time.perf_counter()
        sim.step_frame()
        row = sim.metrics_row()
        rows.append(dict(frame=frame, faces=int(row["faces"]), ms=1e3 * (time.perf_counter() - t),
                         violation=float(row["own_violation_max"]), nan=int(row["nan"]),
                         converged=bool(sim.strain.last_converged),
                         kinetic_energy=float(row["kinetic_energy"]),
                         splits=int(sim.remesh_stats["splits"]),
                         collapses=int(sim.remesh_stats["collapses"])))
        if frame % 25 == 0 or frame == frames:
            log(f"  {scene} {method}: frame {frame}/{frames}, {rows[-1]['faces']} faces, "
                f"violation {rows[-1]['violation']:.1e}, {time.perf_counter() - t0:.0f} s")
        if row["nan"]:
            log(f"  {scene} {method}: NaN at frame {frame}, run stopped")
            break
    return rows, cfg


def summary(method, rows, tol, frames):
    faces = np.array([r["faces"] for r in rows])
    viol = np.array([r["violation"] for r in rows])
    ms = np.array([r["ms"] for r in rows[1:]])         # frame 1 compiles the kernels
    later = rows[len(rows) // 2:]
    return dict(method=method, frames=len(rows), frames_asked=frames,
                nan_frames=sum(r["nan"] > 0 for r in rows),
                violation_max=float(viol.max()), frames_over_tol=int((viol >= tol).sum()),
                unconverged=sum(not r["converged"] for r in rows),
                faces_first=int(faces[0]), faces_max=int(faces.max()),
                faces_second_half_median=float(np.median([r["faces"] for r in later])),
                faces_end=int(faces[-1]),
                ms_median=float(np.median(ms)) if len(ms) else float("nan"),
                ms_p90=float(np.percentile(ms, 90)) if len(ms) else float("nan"),
                kinetic_energy_end=float(rows[-1]["kinetic_energy"]),
                passed=bool(len(rows) == frames and all(r["nan"] == 0 for r in rows)
                            and viol.max() < tol))


def plot(runs, path, scene):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4))
    for method, (rows, tol) in runs.items():
        f = [r["frame"] for r in rows]
        a.plot(f, [r["faces"] for r in rows], label=method)
        b.semilogy(f, [max(r["violation"], 1e-12) for r in rows], label=method, lw=0.8)
    tol = next(iter(runs.values()))[1]
    b.axhline(tol, color="k", ls="--", lw=0.8, label=f"tolerance {tol:g}")
    a.set(xlabel="frame", ylabel="faces", title=f"{scene}: faces after each remesh")
    b.set(xlabel="frame", ylabel="own violation (strain)",
          title="violation after each frame's remesh + projection")
    a.legend(), b.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write(out, scene, summaries, cfg, command, seconds, where):
    cols = ["method", "passed", "frames", "nan_frames", "violation_max", "frames_over_tol",
            "unconverged", "faces_first", "faces_max", "faces_second_half_median", "faces_end",
            "ms_median", "ms_p90", "kinetic_energy_end"]
    heads = ["method", "passed", "frames", "NaN frames", "own violation max", "frames over tol",
             "unconverged projections", "faces frame 1", "faces max", "faces median (2nd half)",
             "faces end", "ms/frame median", "ms/frame p90", "KE end (J)"]
    r = cfg["remesh"]
    lines = [f"# Remeshing with each strain-limiting method: {scene} (issue #4)", "",
             f"Command: `{command}` ({seconds:.0f} s wall clock)  ",
             f"Commit: {where[0]}, {time.strftime('%Y-%m-%d')}  ",
             f"Machine: {where[1]}  ", "",
             f"Remeshing every frame at the scene's default sizes (size_min {r['size_min']} m, "
             f"size_max {r['size_max']} m, curvature_smoothing {r['curvature_smoothing']}); "
             f"strain tolerance {cfg['strain']['tol']:g}, AL budget {cfg['strain']['iters']} "
             "rounds per projection. *own violation*: the method's own "
             "constraint violation after the frame, i.e. after the remesh stage's projection "
             "onto the new triangles. *passed*: every frame finite and under the tolerance. "
             "ms/frame leaves out frame 1 (kernel compilation).", "",
             "| " + " | ".join(heads) + " |", "|" + "---|" * len(heads)]
    for s in summaries:
        lines.append("| " + " | ".join(speed_vs_error.fmt(s[c]) for c in cols) + " |")
    lines += ["", "![faces and violation per frame](remesh_limits.png)", ""]
    with open(os.path.join(out, "remesh_limits.md"), "w") as fh:
        fh.write("\n".join(lines))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="hanging")
    ap.add_argument("--frames", type=int, default=None, help="frames per method (default 300)")
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--quick", action="store_true", help="30 frames per method")
    ap.add_argument("--iters", type=int, default=None,
                    help="AL round budget per projection (default: the scene's strain.iters)")
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "remesh"))
    args = ap.parse_args(argv)
    frames = args.frames or (30 if args.quick else 300)
    from cloth import backend
    backend.init("cpu", "f64")
    os.makedirs(args.out, exist_ok=True)
    t0 = time.perf_counter()
    where = (harness.commit(), harness.machine())
    runs, summaries, cfg = {}, [], None
    for method in args.methods.split(","):
        log(f"{args.scene}, {method}, {frames} frames")
        rows, cfg = run(args.scene, method, frames,
                        {"strain": {"iters": args.iters}} if args.iters else None)
        tol = float(cfg["strain"]["tol"])
        runs[method] = (rows, tol)
        summaries.append(summary(method, rows, tol, frames))
        log("  " + ("passed" if summaries[-1]["passed"] else "FAILED"))
    argv = sys.argv[1:] if argv is None else argv
    command = " ".join(["python -m benchmarks.remesh_limits", *argv])
    seconds = time.perf_counter() - t0
    with open(os.path.join(args.out, "remesh_limits.json"), "w") as fh:
        json.dump({"scene": args.scene, "command": command, "commit": where[0],
                   "machine": where[1], "seconds": seconds, "summaries": summaries,
                   "frames": {m: rows for m, (rows, _) in runs.items()}}, fh, indent=1)
    plot(runs, os.path.join(args.out, "remesh_limits.png"), args.scene)
    write(args.out, args.scene, summaries, cfg, command, seconds, where)
    log(f"wrote {args.out}/remesh_limits.md in {seconds:.0f} s")
    return summaries


if __name__ == "__main__":
    main()
