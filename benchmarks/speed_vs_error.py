"""Speed against error for the hanging scene (or drape): every run is a point (ms per frame,
error), for method x solver x iteration budget x substeps x resolution.

    python -m benchmarks.speed_vs_error --out docs/speed            # the full sweep
    python -m benchmarks.speed_vs_error --quick --out results/quick  # under two minutes

Errors (strain measures from cloth/metrics.py):
  band error      the active method's own constraint violation g / sqrt(a) (strain units, 0
                  inside the band): largest over the faces (``band_max``) and area-weighted RMS
                  (``band_rms``), each averaged over the frames of the run; plus the warp and
                  weft band violations at the last frame;
  energy drift    the largest rise of the total energy (kinetic + elastic + gravitational)
                  above its running minimum, over m |g| L (``cloth.metrics.energy_drift``): no
                  energy enters the scene, so any rise is numerical;
  solution error  RMS distance of the positions at 15 x 15 fixed material points (barycentric
                  lookup in material space) from a converged reference run of the same method
                  and resolution, divided by the cloth's diagonal, at simulated time
                  ``compare_frames`` / fps. The reference uses ``ref_substeps`` substeps, AL with
                  ``ref_iters`` rounds and tolerance ``ref_tol``.
Reference check (issue 7): the same reference with half the step and twice the iterations must
move by less than a tenth of the smallest solution error measured against it. It is recorded
for every reference and compare frame (``reference_checks``), together with the *chaos floor*
(``chaos_check``): how far the same reference run moves when its start is moved by 1 nm.

Why the first compare frame is 3: the hanging sheet buckles out of its plane during frames 3-4
(a symmetry-breaking instability). Before that, 1 nm at the start moves the run by 1e-9-1e-5
of the diagonal; from frame 4-5 on by 1e-4 and more (warp-weft at 288 triangles: 5e-10 at
frame 2, 4.7e-5 at frame 4, 3.4e-4 at frame 10). Halving the reference step changes the
run by about as much as an earlier perturbation does, so past the buckling no reference
can pass the check: the solution error there measures which way the sheet buckled, not how
accurate the run is. The errors at frame 3 are the accuracy numbers; later frames are kept
with their verdicts to show where that stops.

Timing: ms per frame is the wall time of ``Simulator.step_frame`` (every stage, plus the
per-frame bookkeeping), median over all timed frames of ``repeats`` runs, with the 10th and
90th percentiles as the spread; one untimed warm-up frame per configuration keeps kernel
compilation out (the kernels compile once per process; every run builds its own Simulator).

Writes speed_vs_error.md, speed_vs_error.json, pareto_band.png, pareto_solution.png.

The sweep measures the paper's split projection (``strain.coupling = "projection"``), the
solver its committed numbers in docs/speed were made with: its AL needs several rounds per
substep, which is what the budget axis studies. Under the default "implicit" coupling a warm
substep converges in one or two rounds (issue #13, benchmarks/solver.py), so budgets of 2 and
more give the same answer; re-running this sweep for it is left to do.
"""
import argparse
import copy
import itertools
import json
import os
import sys
import time

import numpy as np

from benchmarks.harness import commit, configure, machine
from cloth.strain.families import METHODS

FULL = dict(methods=list(METHODS), solvers=["al", "jacobi"],
            # Budgets per solver: an AL round (several Newton steps with PCG) does far more work
            # than a Jacobi sweep, so the two get different ranges of the same axis.
            iters={"al": [2, 8, 32], "jacobi": [20, 200, 2000]},
            substeps=[1, 2], resolutions=[9, 13, 21], frames=30, repeats=2,
            compare_frames=[3, 10], ref_substeps=64, ref_iters=100, ref_tol=1e-7,
            chaos_check=True)
QUICK = dict(methods=list(METHODS), solvers=["al", "jacobi"],
             iters={"al": [2, 32], "jacobi": [20, 2000]},
             substeps=[1], resolutions=[9, 13], frames=10, repeats=1,
             compare_frames=[3], ref_substeps=32, ref_iters=100, ref_tol=1e-7,
             chaos_check=False)
SAMPLES = 15        # material points per side for the solution error
# A solution error counts as measured only when it is at least this many times the reference's
# own change on halving its step (the "a tenth of the smallest error", applied per run).
RESOLUTION = 10.0


COUPLING = "projection"


def overrides_for(method, solver, iters, substeps, res, tol=1e-4, coupling=COUPLING):
    return {"cloth": {"resolution": res}, "sim": {"substeps": substeps},
            "strain": {"method": method, "solver": solver, "iters": iters, "tol": tol,
                       "coupling": coupling}}


def nudge_start(setup, size=1e-9, seed=11):
    """Move the free vertices of a set-up's start by ``size`` m at random (1 nm: far below f32's
    resolution at 1 m); returns the set-up."""
    noise = np.random.default_rng(seed).normal(0.0, size, setup.mesh.x.shape)
    noise[setup.mesh.pinned] = 0.0
    setup.mesh.x = setup.mesh.x + noise
    return setup


def snapshot(sim):
    m = sim.model
    return (m.positions(), m.uv.copy(), m.faces.copy())


def run(scene, overrides, frames, snap_frames=(), warmup=False, nudge=False):
    """One run. Returns dict: ``ms`` (wall ms of each frame), ``rows`` (metrics rows),
    ``snaps`` {frame: (x, uv, faces)} at ``snap_frames``, ``unconverged`` (substeps whose
    strain solve stopped on its budget; the last substep of each frame is sampled).
    ``nudge``: start from the scene's start moved by 1 nm (``nudge_start``)."""
    from cloth import metrics
    from cloth.simulator import Simulator
    _, cfg, setup = configure(scene, overrides)
    if warmup:                                   # compile this configuration's kernels
        Simulator(setup, cfg).step_frame()
        _, cfg, setup = configure(scene, overrides)
    if nudge:
        setup = nudge_start(setup)
    sim = Simulator(setup, cfg)
    out = {"ms": [], "rows": [], "snaps": {}, "unconverged": 0,
           "energy": [sim.metrics_row()["total_energy"]]}
    m = sim.model
    # Energy drift scale: the cloth's weight times its size (the energy of a fall through it).
    gravity = np.linalg.norm(cfg["sim"]["gravity"])
    out["energy_scale"] = float(m.mass.sum() * gravity * np.linalg.norm(np.ptp(m.uv, axis=0)))
    for k in range(1, frames + 1):
        t0 = time.perf_counter()
        sim.step_frame()
        out["ms"].append(1000.0 * (time.perf_counter() - t0))
        out["rows"].append(sim.metrics_row())
        out["energy"].append(out["rows"][-1]["total_energy"])
        if sim.strain is not None and sim.stage("strain_limit").enabled:
            out["unconverged"] += int(not sim.strain.last_converged)
        if k in snap_frames:
            out["snaps"][k] = snapshot(sim)
    out["faces"] = sim.model.n_faces
    # How far the warp and weft strains end outside their bands (not in metrics.csv: only
    # warp-weft bounds them directly).
    st, bands = sim.face_strains(), sim.bands()
    out["band_excess"] = {k: float(np.max(metrics.band_violation(st[k], bands[k])))
                          for k in ("warp", "weft")}
    return out


# ---- the sweep ---------------------------------------------------------------------------------
def sweep(grid, scene="hanging", log=print):
    """Runs the grid; returns (results: list of dicts, checks: list of dicts)."""
    from cloth import metrics
    cf = sorted(grid["compare_frames"])
    results, checks = [], []
    for res, method in itertools.product(grid["resolutions"], grid["methods"]):
        # Converged reference for this method and resolution, and its check run.
        t0 = time.perf_counter()
        rs, ri, rt = grid["ref_substeps"], grid["ref_iters"], grid["ref_tol"]
        ref_ov = overrides_for(method, "al", ri, rs, res, rt)
        ref = run(scene, ref_ov, cf[-1], cf)
        chk = run(scene, overrides_for(method, "al", 2 * ri, 2 * rs, res, rt), cf[-1], cf)
        nudged = run(scene, ref_ov, cf[-1], cf, nudge=True) \
            if grid.get("chaos_check") else None
        points = metrics.material_sample_points(ref["snaps"][cf[0]][1], SAMPLES)
        check = {"method": method, "resolution": res, "seconds": time.perf_counter() - t0,
                 "unconverged_substeps": ref["unconverged"] + chk["unconverged"]}
        for f in cf:
            check[f"change_f{f}"] = metrics.solution_error(chk["snaps"][f], ref["snaps"][f], points)
            # None (JSON null) where the chaos run was not made (--quick): "not measured".
            check[f"chaos_f{f}"] = metrics.solution_error(
                nudged["snaps"][f], ref["snaps"][f], points) if nudged else None
        checks.append(check)
        log(f"reference {method} res {res}: change on halving the step "
            + ", ".join(f"{check[f'change_f{f}']:.2e} (frame {f}, 1 nm: "
                        f"{chaos_text(check[f'chaos_f{f}'])})" for f in cf)
            + f"  [{check['seconds']:.0f} s]")
        for solver, sub in itertools.product(grid["solvers"], grid["substeps"]):
            for iters in grid["iters"][solver]:
                ov = overrides_for(method, solver, iters, sub, res)
                reps = [run(scene, ov, grid["frames"], cf, warmup=(k == 0))
                        for k in range(grid["repeats"])]
                ms = np.concatenate([r["ms"] for r in reps])
                last = reps[0]
                rows = last["rows"]
                r = dict(method=method, solver=solver, iters=iters, substeps=sub, resolution=res,
                         faces=int(last["faces"]),
                         ms_median=float(np.median(ms)), ms_p10=float(np.percentile(ms, 10)),
                         ms_p90=float(np.percentile(ms, 90)),
                         ms_strain=float(np.median([w["ms_strain_limit"] for w in rows])),
                         band_max=float(np.mean([w["own_violation_max"] for w in rows])),
                         band_rms=float(np.mean([w["own_violation_rms"] for w in rows])),
                         band_max_end=float(rows[-1]["own_violation_max"]),
                         warp_violation_end=last["band_excess"]["warp"],
                         weft_violation_end=last["band_excess"]["weft"],
                         sl_iterations=float(np.mean([w["sl_iterations"] for w in rows])),
                         unconverged_frames=int(last["unconverged"]),
                         energy_drift=metrics.energy_drift(last["energy"],
                                                           last["energy_scale"]),
                         finite=bool(all(w["nan"] == 0 for w in rows)),
                         # Repeats of one configuration must agree exactly (determinism).
                         repeats_identical=bool(all(
                             np.array_equal(q["snaps"][cf[-1]][0], last["snaps"][cf[-1]][0])
                             for q in reps)))
                for f in cf:
                    r[f"solution_error_f{f}"] = metrics.solution_error(
                        last["snaps"][f], ref["snaps"][f], points)
                results.append(r)
                log(f"{method:9s} {solver:6s} iters {iters:4d} sub {sub} res {res:3d}: "
                    f"{r['ms_median']:7.1f} ms/frame  band {r['band_max']:.2e}  "
                    f"sol {r[f'solution_error_f{cf[0]}']:.2e}")
    judge_references(results, checks, cf)
    return results, checks


def judge_references(results, checks, cf):
    """Fill in each reference check's verdicts and each run's resolved flags, per frame."""
    for c in checks:
        # The smallest error this reference had to resolve, and the verdict, per frame. An
        # error under RESOLUTION x the reference's own change is below what the reference can
        # measure: it is reported as "< that floor" (``resolved_fN`` False), not as a number.
        mine = [r for r in results if r["method"] == c["method"] and
                r["resolution"] == c["resolution"]]
        for f in cf:
            smallest = min(r[f"solution_error_f{f}"] for r in mine) if mine else float("nan")
            c[f"smallest_f{f}"] = smallest
            c[f"converged_f{f}"] = bool(c[f"change_f{f}"] < 0.1 * smallest)
            floor = RESOLUTION * c[f"change_f{f}"]
            for r in mine:
                r[f"solution_floor_f{f}"] = floor
                r[f"resolved_f{f}"] = bool(r[f"solution_error_f{f}"] >= floor)
            c[f"unresolved_f{f}"] = sum(not r[f"resolved_f{f}"] for r in mine)
            c[f"runs_f{f}"] = len(mine)


# ---- output ------------------------------------------------------------------------------------
def fmt(v):
    if isinstance(v, bool):
        return "yes" if v else "NO"
    if isinstance(v, float):
        return f"{v:.3g}"
    return str(v)


def chaos_text(v):
    """The chaos floor as printed: a number, or "not measured" where no nudged run was made
    (``--quick`` skips it; earlier JSON files stored NaN there)."""
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "not measured"
    return f"{v:.3g}"


def write_outputs(results, checks, out, grid, scene, command, seconds):
    os.makedirs(out, exist_ok=True)
    cf = sorted(grid["compare_frames"])
    fps = 30.0
    with open(os.path.join(out, "speed_vs_error.json"), "w") as fh:
        json.dump({"scene": scene, "grid": grid, "command": command, "machine": machine(),
                   "commit": commit(), "seconds": seconds, "results": results,
                   "reference_checks": checks}, fh, indent=1)
    lines = [f"# Speed against error: {scene}", "",
             f"Command: `{command}` ({seconds:.0f} s). Machine: {machine()}; commit "
             f"{commit()}. Other jobs shared the two cores while this ran, so times carry "
             "noise of tens of percent; compare them within one table.", "",
             f"Each run: {grid['frames']} frames at {fps:.0f} fps from the scene's start; ms per "
             f"frame = median (p10-p90) over the timed frames of {grid['repeats']} repeat(s). "
             "band = the method's own violation (strain), largest over faces (max) or "
             "area-weighted RMS, averaged over the frames. energy drift = largest rise of the "
             "total energy above its running minimum / (m g L) (cloth.metrics.energy_drift; no "
             "energy enters this scene). sol fN = solution error at frame N "
             f"against the reference ({grid['ref_substeps']} substeps, AL {grid['ref_iters']} "
             f"rounds, tol {grid['ref_tol']:g}), RMS over {SAMPLES}x{SAMPLES} material points "
             "/ cloth diagonal. Budgets: AL rounds or Jacobi sweeps per substep "
             "(stopping earlier at a violation of 1e-4).", "",
             "## Reference check", "",
             "Halving the reference step and doubling its iterations changes it by `change`; "
             "the reference is converged where that is under a tenth of the smallest solution "
             "error measured against it. `1 nm` (the chaos floor, where measured): how far the "
             "same reference moves when its start is moved by 1 nm. The sheet buckles out of "
             "its plane during frames 3-4; from then on any difference, the halved step's "
             "included, is amplified, so where the check fails and the chaos floor has grown "
             "to the same order as `change`, the solution errors at that frame measure "
             "which way the sheet buckled, not accuracy (see the module docstring).", "",
             f"So that every error reported is at least {RESOLUTION:g} x its reference's "
             "change, an error below that floor is not reported as a number: the runs table "
             "shows it as `< floor`, the solution plot as a hollow marker at the floor, and "
             "`unresolved` counts those runs. `converged` is the issue's check on the raw "
             "smallest error.", "",
             "| method | resolution | " + " | ".join(
                 f"change f{f} | 1 nm f{f} | smallest f{f} | converged f{f} | unresolved f{f}"
                 for f in cf) + " |",
             "|---|---|" + "---|---|---|---|---|" * len(cf)]
    for c in checks:
        lines.append(f"| {c['method']} | {c['resolution']} | " + " | ".join(
            f"{fmt(c[f'change_f{f}'])} | {chaos_text(c.get(f'chaos_f{f}'))} | "
            f"{fmt(c[f'smallest_f{f}'])} | {fmt(c[f'converged_f{f}'])} | "
            f"{c[f'unresolved_f{f}']} of {c[f'runs_f{f}']}" for f in cf) + " |")
    cols = ["method", "solver", "iters", "substeps", "resolution", "faces", "ms_median",
            "ms_p10", "ms_p90", "band_max", "band_rms", "warp_violation_end",
            "weft_violation_end", "unconverged_frames", "energy_drift"] + \
        [f"solution_error_f{f}" for f in cf]
    heads = ["method", "solver", "budget", "sub", "res", "faces", "ms/frame", "p10", "p90",
             "band max", "band rms", "warp viol end", "weft viol end", "frames unconv.",
             "energy drift"] + [f"sol f{f}" for f in cf]
    lines += ["", "## Runs", "", "| " + " | ".join(heads) + " |", "|" + "---|" * len(heads)]
    def cell(r, c):
        if c.startswith("solution_error_f") and not r.get(f"resolved_{c[15:]}", True):
            return f"< {r[f'solution_floor_{c[15:]}']:.3g}"
        return fmt(r[c])
    for r in results:
        lines.append("| " + " | ".join(cell(r, c) for c in cols) + " |")
    lines += ["", "Plots: `pareto_band.png` (ms per frame against band max), "
              f"`pareto_solution.png` (against the solution error at frame {cf[0]})."]
    with open(os.path.join(out, "speed_vs_error.md"), "w") as fh:
        fh.write("\n".join(lines) + "\n")
    plot(results, out, grid, scene)


def plot(results, out, grid, scene):
    """One panel per resolution; colour = method, marker/line = solver, dashes = substeps;
    lines join the iteration budgets of one (method, solver, substeps), labels give the budget."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    colors = {"svd": "tab:blue", "warp-weft": "tab:orange", "mapping": "tab:green"}
    markers = {"al": "o", "jacobi": "x"}
    dashes = {1: "-", 2: "--", 4: ":"}
    cf = sorted(grid["compare_frames"])[0]
    res_list = sorted({r["resolution"] for r in results})
    for key, name, label in (
            ("band_max", "pareto_band.png", "band error: own violation, max over faces\n"
             "(strain, mean over frames)"),
            (f"solution_error_f{cf}", "pareto_solution.png",
             f"solution error at frame {cf}\n(RMS distance / cloth diagonal)")):
        fig, axes = plt.subplots(1, len(res_list), figsize=(4.6 * len(res_list) + 0.8, 4.4),
                                 sharey=True, squeeze=False)
        for ax, res in zip(axes[0], res_list):
            rows = [r for r in results if r["resolution"] == res]
            groups = sorted({(r["method"], r["solver"], r["substeps"]) for r in rows})
            for m, s, sub in groups:
                # An error below its reference's resolution is drawn at that floor, hollow.
                pts = sorted((r["iters"], r["ms_median"], max(r[key], 1e-9),
                              r.get(f"resolved_f{cf}", True) or key == "band_max",
                              r.get(f"solution_floor_f{cf}", 0.0)) for r in rows
                             if (r["method"], r["solver"], r["substeps"]) == (m, s, sub))
                pts = [(it, x, y if ok else fl, ok) for it, x, y, ok, fl in pts]
                xs, ys = [p[1] for p in pts], [p[2] for p in pts]
                ax.plot(xs, ys, dashes.get(sub, "-."), color=colors[m], marker=markers[s],
                        ms=6, lw=1.2, alpha=0.85)
                hollow = [(x, y) for _, x, y, ok in pts if not ok]
                if hollow:
                    ax.plot(*zip(*hollow), ls="", marker="o", ms=7, mfc="white",
                            color=colors[m])
                for it, x, y, _ in pts:
                    ax.annotate(str(it), (x, y), textcoords="offset points", xytext=(4, 3),
                                fontsize=6.5, color=colors[m])
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_title(f"{scene}, resolution {res} ({rows[0]['faces']} triangles)", fontsize=10)
            ax.set_xlabel("ms per frame (median, log)")
            ax.grid(True, which="both", alpha=0.3)
        axes[0][0].set_ylabel(label + " (log)")
        handles = [Line2D([], [], color=c, lw=2, label=m) for m, c in colors.items()]
        handles += [Line2D([], [], color="gray", marker=mk, ls="", label=f"solver {s}")
                    for s, mk in markers.items()]
        handles += [Line2D([], [], color="gray", ls=dashes.get(sub, "-."),
                           label=f"{sub} substep{'s' if sub > 1 else ''}")
                    for sub in sorted({r["substeps"] for r in results})]
        if key != "band_max" and not all(r.get(f"resolved_f{cf}", True) for r in results):
            handles.append(Line2D([], [], color="gray", marker="o", mfc="white", ls="",
                                  label=f"< {RESOLUTION:g} x the reference's change"))
        axes[0][-1].legend(handles=handles, fontsize=8, loc="best",
                           title="numbers: iteration budget", title_fontsize=7.5)
        fig.suptitle("Speed against error (down and left is better)", fontsize=11)
        fig.tight_layout()
        fig.savefig(os.path.join(out, name), dpi=110)
        plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join("results", "speed"))
    ap.add_argument("--quick", action="store_true", help="a small sweep, under two minutes")
    ap.add_argument("--scene", default="hanging", help="hanging or drape")
    args = ap.parse_args(argv)
    from cloth import backend
    backend.init("cpu", "f64")
    grid = copy.deepcopy(QUICK if args.quick else FULL)
    command = "python -m benchmarks.speed_vs_error " + " ".join(argv if argv is not None
                                                                 else sys.argv[1:])
    t0 = time.perf_counter()
    results, checks = sweep(grid, args.scene)
    seconds = time.perf_counter() - t0
    write_outputs(results, checks, args.out, grid, args.scene, command, seconds)
    print(f"wrote {args.out}/ in {seconds:.0f} s")


if __name__ == "__main__":
    main()
