"""Speed against error for the hanging scene (and drape): every run is a point (ms per frame,
error), for method x solver x iteration budget x substeps x resolution.

    python -m benchmarks.speed_vs_error --out results/speed           # the full sweep
    python -m benchmarks.speed_vs_error --quick --out results/quick   # under two minutes

Errors (definitions in cloth/metrics.py):
  band error      largest and area-weighted RMS violation of the method's own constraints and of
                  the warp/weft bands, at the final frame (strain units);
  solution error  RMS distance of the final positions at fixed material points from a converged
                  reference run of the same method (small step, many iterations, same
                  resolution), divided by the cloth's diagonal;
The reference is checked: halving its step and doubling its iterations must move it by less
than a tenth of the smallest solution error reported (written to the results).
Writes speed_vs_error.md, speed_vs_error.json, pareto_band.png, pareto_solution.png.
"""
import argparse
import itertools
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

FULL = dict(methods=["svd", "warp-weft", "mapping"], solvers=["al", "jacobi"],
            iters=[5, 20, 80], substeps=[1, 2], resolutions=[13, 25, 45], frames=90)
QUICK = dict(methods=["svd", "warp-weft", "mapping"], solvers=["al", "jacobi"],
             iters=[4, 40], substeps=[1], resolutions=[9, 13], frames=45)


def simulate(scene, overrides, frames):
    """Run a scene; returns (final (x, uv, faces), final metrics row, ms per frame list)."""
    import scenes
    from cloth.simulator import Simulator
    from scenes.common import resolve
    module = scenes.get(scene)
    cfg = resolve(module.DEFAULTS, [overrides])
    sim = Simulator(module.build(cfg), cfg)
    times = []
    for k in range(frames):
        t0 = time.perf_counter()
        sim.step_frame()
        if k:                                   # frame 0 includes compilation
            times.append(1000 * (time.perf_counter() - t0))
    m = sim.model
    row = sim.metrics_row()
    own = sim.strain.constraint_values() if sim.strain is not None else np.zeros((m.n_faces, 1))
    from cloth import metrics
    own_v = np.max(np.maximum(own, 0.0), axis=1)
    row["own_violation_rms"] = metrics.weighted_rms(own_v, m.rest_area)
    return (m.positions(), m.uv.copy(), m.faces.copy()), row, times


def overrides_for(method, solver, iters, substeps, res, tol=1e-4):
    return {"cloth": {"resolution": res}, "sim": {"substeps": substeps},
            "strain": {"method": method, "solver": solver, "iters": iters, "tol": tol}}


def sweep(grid, scene="hanging", log=print):
    from cloth import metrics
    frames = grid["frames"]
    results, references, checks = [], {}, {}
    for method, res in itertools.product(grid["methods"], grid["resolutions"]):
        # Converged reference for this method and resolution, and its self-check.
        ref_sub, ref_it = 4 * max(grid["substeps"]), 8 * max(grid["iters"])
        ref, _, _ = simulate(scene, overrides_for(method, "al", ref_it, ref_sub, res, 1e-7), frames)
        chk, _, _ = simulate(scene, overrides_for(method, "al", 2 * ref_it, 2 * ref_sub, res, 1e-7),
                             frames)
        points = metrics.material_sample_points(ref[1], 15)
        references[(method, res)] = (ref, points)
        checks[f"{method}/{res}"] = metrics.solution_error(chk, ref, points)
        log(f"reference {method} res {res}: self-check {checks[f'{method}/{res}']:.2e}")
        for solver, iters, sub in itertools.product(grid["solvers"], grid["iters"],
                                                    grid["substeps"]):
            final, row, times = simulate(scene, overrides_for(method, solver, iters, sub, res),
                                         frames)
            r = dict(method=method, solver=solver, iters=iters, substeps=sub, resolution=res,
                     faces=int(len(final[2])),
                     ms_median=float(np.median(times)),
                     ms_p10=float(np.percentile(times, 10)),
                     ms_p90=float(np.percentile(times, 90)),
                     own_violation_max=row["own_violation_max"],
                     own_violation_rms=row["own_violation_rms"],
                     warp_violation_max=row["warp_violation_max"],
                     weft_violation_max=row["weft_violation_max"],
                     solution_error=metrics.solution_error(final, ref, points),
                     nan=row["nan"])
            results.append(r)
            log(f"{method:9s} {solver:6s} iters {iters:3d} sub {sub} res {res:3d}: "
                f"{r['ms_median']:7.1f} ms/frame  viol {r['own_violation_max']:.2e}  "
                f"sol {r['solution_error']:.2e}")
    return results, checks


def write_outputs(results, checks, out, grid, scene):
    os.makedirs(out, exist_ok=True)
    smallest = min((r["solution_error"] for r in results if r["solution_error"] > 0), default=0.0)
    ref_ok = all(v < 0.1 * smallest for v in checks.values()) if smallest > 0 else True
    with open(os.path.join(out, "speed_vs_error.json"), "w") as fh:
        json.dump({"scene": scene, "grid": grid, "results": results,
                   "reference_self_check": checks, "smallest_solution_error": smallest,
                   "reference_converged": ref_ok}, fh, indent=1)
    cols = ["method", "solver", "iters", "substeps", "resolution", "faces", "ms_median", "ms_p10",
            "ms_p90", "own_violation_max", "own_violation_rms", "warp_violation_max",
            "weft_violation_max", "solution_error"]
    lines = [f"# Speed against error: {scene}", "",
             f"Machine: {os.cpu_count()} CPU cores, Taichi cpu backend, f64. Final frame after "
             f"{grid['frames']} frames at 30 fps. ms per frame: median (p10-p90) over frames.", "",
             f"Reference self-check (halve step, double iterations), largest: "
             f"{max(checks.values()):.2e}; smallest solution error reported: {smallest:.2e}; "
             f"converged enough: {'yes' if ref_ok else 'NO'}.", "",
             "| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in results:
        lines.append("| " + " | ".join(f"{r[c]:.3g}" if isinstance(r[c], float) else str(r[c])
                                       for c in cols) + " |")
    with open(os.path.join(out, "speed_vs_error.md"), "w") as fh:
        fh.write("\n".join(lines) + "\n")
    plot(results, out)


def plot(results, out):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    markers = {"svd": "o", "warp-weft": "s", "mapping": "^"}
    colors = {"al": "tab:blue", "jacobi": "tab:red"}
    for key, name, label in (("own_violation_max", "pareto_band.png", "own band violation, max (strain)"),
                             ("solution_error", "pareto_solution.png", "solution error / cloth size")):
        fig, ax = plt.subplots(figsize=(6.4, 4.4))
        for r in results:
            ax.scatter(r["ms_median"], max(r[key], 1e-12), marker=markers[r["method"]],
                       color=colors[r["solver"]], s=14 + 2 * r["resolution"], alpha=0.75)
        for m, mk in markers.items():
            ax.scatter([], [], marker=mk, color="gray", label=m)
        for s, c in colors.items():
            ax.scatter([], [], marker="o", color=c, label=f"solver {s}")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("ms per frame (median)")
        ax.set_ylabel(label)
        ax.set_title("hanging: speed against error (marker size = resolution)")
        ax.legend(fontsize=8)
        ax.grid(True, which="both", alpha=0.3)
        fig.tight_layout()
        fig.savefig(os.path.join(out, name), dpi=110)
        plt.close(fig)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join("results", "speed"))
    ap.add_argument("--quick", action="store_true", help="a small sweep, under two minutes")
    ap.add_argument("--scene", default="hanging")
    args = ap.parse_args()
    from cloth import backend
    backend.init("cpu", "f64")
    grid = QUICK if args.quick else FULL
    t0 = time.perf_counter()
    results, checks = sweep(grid, args.scene)
    write_outputs(results, checks, args.out, grid, args.scene)
    print(f"wrote {args.out}/ in {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
