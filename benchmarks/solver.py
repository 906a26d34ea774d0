"""The constrained step, old and new side by side (issue #13): strain-limiting ms per frame, AL
rounds, Newton steps, converged fraction, and the kinetic energy of a cloth that should hang
still.

    python -m benchmarks.solver --out docs/speed                  # rest + speed, ~25 min
    python -m benchmarks.solver --quick --out /tmp/solver         # a few minutes
    python -m benchmarks.solver --probe 25 mapping --frames 150   # one row, printed as JSON

Variants (``strain.coupling`` / ``strain.linear_solver``):
  projection/pcg     the paper's split step (eq. 6: project x_hat in the mass metric) with the
                     one-kernel block-Jacobi PCG Newton solver and the curvature model
                     (strain.curvature = "model"): the solver before #13;
  implicit/pcg       the projection in the implicit step's metric A = (1 + h a) M + h (b + h) K
                     (one linearised backward-Euler step with the limits as constraints);
  implicit/cholesky  the same with exact Newton steps (CHOLMOD, analysis reused per mesh).
The implicit variants use ``--curvature`` (strain.curvature; default: the settings' default).

Rest: hanging, soft cloth, +-1 % / +-5 %, one substep per frame, mean kinetic energy over frames
120-150 (the issue's measure): resolution 9 for each method, 25 for mapping. Speed: hanging at
resolutions 46 and 91 from the start, frames 2..F (frame 1 compiles), median ms of the
strain_limit stage (the old solver for fewer frames: it takes seconds to a minute a frame).
Each configuration runs in its own child process (clean kernel caches and timings).
"""
import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

VARIANTS = (("projection", "pcg"), ("implicit", "pcg"), ("implicit", "cholesky"))
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# The solver before #13 (the split projection) had only the curvature model in its Newton
# matrix (strain.curvature, c_curvature.py).
OLD_CURVATURE = "model"


def child(res, method, coupling, linear_solver, curvature, frames, ke_from, overrides=None,
          bending=None, nudge_seed=None):
    """One configuration: ``overrides`` sets StrainLimiter attributes after the build (e.g.
    {"active_margin": 0.005}, a probe of a setting the scene files do not expose);
    ``bending``: sim.bending (default: the settings'). ``nudge_seed``: start from the scene's
    start moved by 1 nm with that seed (``speed_vs_error.nudge_start``; 0: not moved), and
    return the kinetic energy of every frame too (the rest ensemble)."""
    from cloth import backend
    backend.init("cpu", "f64")
    import scenes
    from scenes.common import resolve
    from cloth.simulator import Simulator
    from cloth import metrics
    mod = scenes.get("hanging")
    cfg = resolve(mod.DEFAULTS, [{"cloth": {"resolution": res},
                                  "strain": {"method": method, "coupling": coupling,
                                             "linear_solver": linear_solver,
                                             "curvature": curvature}}]
                  + ([{"sim": {"bending": bending}}] if bending else []))
    setup = mod.build(cfg)
    if nudge_seed:
        from benchmarks.speed_vs_error import nudge_start
        setup = nudge_start(setup, seed=nudge_seed)
    sim = Simulator(setup, cfg)
    for key, value in (overrides or {}).items():
        if not hasattr(sim.strain, key):
            raise SystemExit(f"--set: StrainLimiter has no setting '{key}'")
        setattr(sim.strain, key, value)
    sim.strain._upload_params()
    ke, ms, rounds, newton, conv, viol = [], [], [], [], [], []
    cg, factorizations, frame_ms, trials = [], [], [], []
    for _ in range(frames):
        sim.step_frame()
        m = sim.model
        ke.append(metrics.kinetic_energy(m.velocities(), m.mass))
        ms.append(sim.stage("strain_limit").ms)
        frame_ms.append(sum(s.ms for s in sim.stages if s.enabled))
        rounds.append(sim.strain.last_iterations)
        newton.append(sim.strain.last_newton)
        conv.append(bool(sim.strain.last_converged))
        viol.append(sim.strain.last_violation_max)
        cg.append(sim.strain.last_cg)
        trials.append(sim.strain.last_trials)
        factorizations.append(sim.strain.last_factorizations)
    ms, rounds = np.array(ms[1:]), np.array(rounds[1:])
    return dict(commit=_commit(), res=res, faces=sim.model.n_faces, method=method,
                bending=sim.model.bending,
                coupling=coupling, curvature=sim.strain.curvature,
                linear_solver=linear_solver, frames=frames,
                ke_mean=float(np.mean(ke[ke_from:])) if ke_from < frames else None,
                ms_median=float(np.median(ms)), ms_p90=float(np.percentile(ms, 90)),
                rounds_median=float(np.median(rounds)), rounds_max=int(rounds.max()),
                newton_median=float(np.median(newton[1:])),
                converged=float(np.mean(conv[1:])), viol_max=float(max(viol[1:])),
                cg_median=float(np.median(cg[1:])),
                trials_median=float(np.median(trials[1:])),
                frame_ms_median=float(np.median(frame_ms[1:])),
                factorizations_mean=float(np.mean(factorizations[1:])),
                overrides=overrides or {},
                **({"nudge_seed": nudge_seed, "ke_frames": [float(k) for k in ke]}
                   if nudge_seed is not None else {}))


def _child_cmd(args):
    return [sys.executable, "-m", "benchmarks.solver", "--child", json.dumps(args)]


def _child_result(out, args):
    if out.returncode != 0:
        return {"error": out.stderr.strip().splitlines()[-1] if out.stderr.strip() else "?",
                "args": args}
    return json.loads(out.stdout.strip().splitlines()[-1])


def run_child(*args):
    out = subprocess.run(_child_cmd(args), capture_output=True, text=True, cwd=ROOT)
    return _child_result(out, args)


def run_children(arg_lists, jobs):
    """Children ``jobs`` at a time (each its own process); results in the order given."""
    results, running, pending = [None] * len(arg_lists), {}, list(enumerate(arg_lists))
    while pending or running:
        while pending and len(running) < jobs:
            i, args = pending.pop(0)
            running[i] = (subprocess.Popen(_child_cmd(args), stdout=subprocess.PIPE,
                                           stderr=subprocess.PIPE, text=True, cwd=ROOT), args)
        i = next(iter(running))
        proc, args = running.pop(i)
        stdout, stderr = proc.communicate()
        results[i] = _child_result(subprocess.CompletedProcess(proc.args, proc.returncode,
                                                                stdout, stderr), args)
        print(f"  [{sum(r is not None for r in results)}/{len(results)}] "
              f"{_row_text(results[i])}", file=sys.stderr, flush=True)
    return results


def _row_text(r):
    if "error" in r:
        return f"error: {r['error']}"
    ke = (f"KE {window_mean(r['ke_frames'], REST_WINDOW):.3g} J over frames "
          f"{REST_WINDOW[0]}-{REST_WINDOW[1]}" if r.get("ke_frames") else
          f"KE {r['ke_mean']:.3g} J")
    return (f"{r['faces']} faces {r['method']} {r['coupling']}/{r['linear_solver']} "
            f"seed {r.get('nudge_seed')}: {ke}, {r['ms_median']:.1f} ms")


def table(rows, keys, heads):
    lines = ["| " + " | ".join(heads) + " |", "|" + "---|" * len(heads)]
    for r in rows:
        cells = []
        for k in keys:
            v = r.get(k)
            cells.append(f"{v:.3g}" if isinstance(v, float) else str(v))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plan(quick, curvature):
    """(kind, (resolution, method, coupling, linear_solver, curvature, frames, ke_from)) per
    child; the old solver with OLD_CURVATURE, the implicit variants with ``curvature``."""
    old, new, chol = (v + (OLD_CURVATURE if v[0] == "projection" else curvature,)
                      for v in VARIANTS)
    if quick:
        return [("rest", (9, "mapping") + v + (40, 30)) for v in (old, new)] + \
            [("speed", (25, "mapping") + v + (10, 10)) for v in (old, new, chol)]
    jobs = [("rest", (9, m) + v + (150, 120)) for m in ("mapping", "svd", "warp-weft")
            for v in (old, new)]
    jobs += [("rest", (25, "mapping") + v + (150, 120)) for v in (old, new, chol)]
    for res, frames, old_frames in ((46, 40, 8), (91, 12, 3)):
        jobs.append(("speed", (res, "mapping") + old + (old_frames, old_frames)))
        jobs += [("speed", (res, "mapping") + v + (frames, frames)) for v in (new, chol)]
        jobs += [("speed", (res, m) + new + (frames, frames)) for m in ("svd", "warp-weft")]
    return jobs


def plot(rest, speed, path):
    """Two panels: rest kinetic energy per method and coupling (log), strain-limiting ms per
    frame against faces for mapping (log-log)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2))
    rows = [r for r in rest if "error" not in r]
    labels = [f"{r['method']}\n{r['faces']} tri\n{r['coupling']}/{r['linear_solver']}"
              for r in rows]
    colors = ["tab:red" if r["coupling"] == "projection" else "tab:blue" for r in rows]
    a.bar(range(len(rows)), [r["ke_mean"] for r in rows], color=colors)
    a.set_yscale("log")
    a.set_xticks(range(len(rows)), labels, fontsize=6)
    a.axhline(1e-6, color="k", ls=":", lw=1)
    a.set_ylabel("mean kinetic energy, frames 120-150 (J)")
    a.set_title("hanging at rest (red: split projection, blue: implicit)")
    for (c, ls_), marker in zip(VARIANTS, "osD"):
        pts = sorted((r["faces"], r["ms_median"]) for r in speed + rest
                     if "error" not in r and r["method"] == "mapping" and
                     (r["coupling"], r["linear_solver"]) == (c, ls_) and r["faces"] > 200)
        if pts:
            b.loglog(*zip(*pts), marker=marker, label=f"{c} / {ls_}")
    b.set_xlabel("triangles")
    b.set_ylabel("strain limiting, median ms per frame")
    b.set_title("hanging, mapping, from the start")
    b.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--child")
    ap.add_argument("--out", default="docs/speed")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--rerun-rest", metavar="COUPLING/SOLVER",
                    help="re-measure only those rest rows in OUT/solver.json, e.g. implicit/pcg")
    ap.add_argument("--with-speed", action="store_true",
                    help="with --rerun-rest: re-run that variant's speed rows too")
    ap.add_argument("--probe", nargs=2, metavar=("RES", "METHOD"),
                    help="measure one configuration and print its row (JSON), e.g. "
                         "--probe 25 mapping --frames 150 --ke-from 120")
    ap.add_argument("--coupling", default="implicit")
    ap.add_argument("--linear-solver", default="pcg")
    ap.add_argument("--curvature", default=None, choices=("exact", "model"),
                    help="strain.curvature of the implicit variants and --probe (default: the "
                         "settings' default)")
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--ke-from", type=int, default=120)
    ap.add_argument("--budget-sweep", action="store_true",
                    help="the PCG budget (StrainLimiter.max_cg) against speed and rest: writes "
                         "OUT/cg_budget.md and .json (~10 min)")
    ap.add_argument("--bending", choices=("isotropic", "hinge"),
                    help="sim.bending for --probe (default: the settings')")
    ap.add_argument("--rest-ensemble", type=int, metavar="SEEDS",
                    help="the rest measure from the start and SEEDS starts moved by 1 nm, per "
                         "variant (rest_ensemble.md/png)")
    ap.add_argument("--ensemble-res", type=int, default=25)
    ap.add_argument("--ensemble-variants", default=",".join(ENSEMBLE_VARIANTS),
                    help="variants of the ensemble (ENSEMBLE_VARIANTS; --set applies to each)")
    ap.add_argument("--jobs", type=int, default=2, help="children side by side (ensemble)")
    ap.add_argument("--set", action="append", default=[], metavar="ATTR=JSON",
                    help="StrainLimiter attribute for --probe, e.g. --set active_margin=0.005")
    args = ap.parse_args()
    curvature = args.curvature or _default_curvature()
    overrides = {}
    for item in args.set:
        key, _, value = item.partition("=")
        overrides[key] = json.loads(value)
    if args.rest_ensemble:
        os.makedirs(args.out, exist_ok=True)
        rest_ensemble(args.out, args.ensemble_res, "mapping", args.rest_ensemble, args.jobs,
                      curvature, overrides, args.ensemble_variants.split(","))
        return
    if args.probe:
        print(json.dumps(child(int(args.probe[0]), args.probe[1], args.coupling,
                               args.linear_solver, curvature, args.frames, args.ke_from,
                               overrides, args.bending)))
        return
    if args.child:
        print(json.dumps(child(*json.loads(args.child))))
        return
    os.makedirs(args.out, exist_ok=True)
    if args.budget_sweep:
        budget_sweep(args.out, curvature)
        return
    if args.rerun_rest:
        # Re-measure the rest rows of one coupling / Newton solver (after a solver change),
        # keep every other row, and rewrite the docs.
        with open(os.path.join(args.out, "solver.json")) as fh:
            data = json.load(fh)
        coupling, linear_solver = args.rerun_rest.split("/")
        kinds = ("rest", "speed") if args.with_speed else ("rest",)
        for kind in kinds:
            for i, r in enumerate(data[kind]):
                if (r.get("coupling"), r.get("linear_solver")) == (coupling, linear_solver):
                    data[kind][i] = run_child(r["res"], r["method"], coupling, linear_solver,
                                              r.get("curvature", OLD_CURVATURE), r["frames"],
                                              120 if kind == "rest" else r["frames"])
                    print(json.dumps(data[kind][i]), file=sys.stderr, flush=True)
        what = " and speed" if args.with_speed else ""
        write_docs(data["rest"], data["speed"], args.out,
                   f"`python -m benchmarks.solver` (rest{what} rows of {args.rerun_rest} "
                   f"re-run with `--rerun-rest {args.rerun_rest}"
                   f"{' --with-speed' if args.with_speed else ''}`)")
        return
    t0 = time.time()
    rest, speed = [], []
    jobs = plan(args.quick, curvature)
    for i, (kind, a) in enumerate(jobs):
        print(f"[{i + 1}/{len(jobs)}] {kind} {a} ({time.time() - t0:.0f} s)", file=sys.stderr,
              flush=True)
        (rest if kind == "rest" else speed).append(run_child(*a))
        print(json.dumps((rest if kind == "rest" else speed)[-1]), file=sys.stderr, flush=True)
    write_docs(rest, speed, args.out, f"`python -m benchmarks.solver"
               f"{' --quick' if args.quick else ''}`")


# PCG iterations per Newton step (per 1000 faces: the budget grows like sqrt(faces / 1000)).
BUDGETS = (4, 8, 15, 25, 50)


def budget_sweep(out, curvature):
    """Speed (each method from the start at resolution 46, mapping at 91) and rest (each
    method at resolution 9, mapping at 25) per PCG budget, every row in its own process."""
    rows = []
    jobs = [(b, (46, m, 30, 100)) for m in ("mapping", "svd", "warp-weft") for b in BUDGETS]
    jobs += [(b, (91, "mapping", 12, 100)) for b in (15, 50)]
    jobs += [(b, (25, "mapping", 150, 120)) for b in BUDGETS]
    jobs += [(b, (9, m, 150, 120)) for b in BUDGETS for m in ("mapping", "svd", "warp-weft")]
    t0 = time.time()
    for i, (budget, (res, method, frames, ke_from)) in enumerate(jobs):
        print(f"[{i + 1}/{len(jobs)}] max_cg {budget}: {method} res {res} "
              f"({time.time() - t0:.0f} s)", file=sys.stderr, flush=True)
        row = run_child(res, method, "implicit", "pcg", curvature, frames, ke_from,
                        {"max_cg": budget})
        row["max_cg"] = budget
        rows.append(row)
    with open(os.path.join(out, "cg_budget.json"), "w") as fh:
        json.dump(rows, fh, indent=1)
    keys = ["faces", "method", "max_cg", "frames", "ms_median", "ms_p90", "rounds_median",
            "rounds_max", "newton_median", "cg_median", "converged", "viol_max", "ke_mean",
            "commit"]
    heads = ["faces", "method", "max_cg", "frames", "SL ms median", "p90", "rounds", "max",
             "Newton", "CG", "converged", "max viol", "KE 120-150 (J)", "commit"]
    md = ["# The PCG budget of the strain solve: speed against rest (issue #13)", "",
          f"`python -m benchmarks.solver --budget-sweep` ({time.time() - t0:.0f} s), "
          f"{time.strftime('%Y-%m-%d')}, 2-core CPU, f64, full optimisation. hanging, "
          "coupling implicit, one substep per frame; `max_cg` is the PCG budget per Newton "
          "step at 1000 faces (it grows like sqrt(faces / 1000)). Speed rows: from the start, "
          "median over frames 2-F. Rest rows: KE = mean kinetic energy over frames 120-150 "
          "(targets: <= 1e-6 J at resolution 9, <= 3e-7 J for mapping at 25).", "",
          table(sorted(rows, key=lambda r: (r.get("faces", 0), r.get("method", ""),
                                            r["max_cg"])), keys, heads), ""]
    with open(os.path.join(out, "cg_budget.md"), "w") as fh:
        fh.write("\n".join(md) + "\n")
    print("\n".join(md))


ENSEMBLE_FRAMES = 240
# The windows of the ensemble's kinetic energy: the (frames 121-150) and a later one.
REST_WINDOW, LATE_WINDOW = (121, 150), (181, 240)
REST_TARGET = 3e-7         # J, issue #13, mapping at resolution 25


def window_mean(ke_frames, window):
    """Mean of the per-frame kinetic energies over frames ``window`` = (first, last), counted
    from 1 (ke_frames[k] belongs to frame k + 1)."""
    first, last = window
    if len(ke_frames) < last:
        raise ValueError(f"{len(ke_frames)} frames, the window needs {last}")
    return float(np.mean(ke_frames[first - 1:last]))


def ensemble_summary(rows, variants):
    """One row per variant (label, Newton solve, settings) of the ensemble's runs (each run
    carries its variant's label): the median, range and count under REST_TARGET of the mean
    kinetic energy over REST_WINDOW, the median over LATE_WINDOW and the median
    strain-limiting ms. Failed runs ({"error": ...}) are counted as failed."""
    summary = []
    for label, solver, ov in variants:
        mine = [r for r in rows if r.get("variant") == label]
        runs = [r for r in mine if "error" not in r]
        if not runs:
            continue
        ke = np.array([window_mean(r["ke_frames"], REST_WINDOW) for r in runs])
        late = np.array([window_mean(r["ke_frames"], LATE_WINDOW) for r in runs])
        summary.append(dict(
            variant=label, solver=solver, overrides=json.dumps(ov) if ov else "",
            runs=len(runs), failed=len(mine) - len(runs), ke_median=float(np.median(ke)),
            ke_min=float(ke.min()), ke_max=float(ke.max()),
            under_target=f"{int((ke <= REST_TARGET).sum())} of {len(ke)}",
            late_median=float(np.median(late)),
            ms_median=float(np.median([r["ms_median"] for r in runs])),
            commit=runs[0]["commit"]))
    return summary


# The ensemble's variants by name: (Newton solve, StrainLimiter settings).
ENSEMBLE_VARIANTS = {"pcg": ("pcg", {}), "pcg-jacobi": ("pcg", {"precondition": "jacobi"}),
                     "cholesky": ("cholesky", {})}


def rest_ensemble(out, res, method, seeds, jobs, curvature, overrides,
                  names=("pcg", "pcg-jacobi", "cholesky")):
    """The rest measure over an ensemble: the same hanging run from its start and from ``seeds``
    starts moved by 1 nm, for each variant in ``names`` (ENSEMBLE_VARIANTS; ``overrides`` are
    added to each). Why: the mean kinetic energy over frames 121-150 of one run moved by 2-3x
    with changes that only move round-off (docs/speed/solver.md), so one run cannot say
    whether a change helps. Writes rest_ensemble.{md,png,json}: per variant the median and
    range of the mean kinetic energy over REST_WINDOW and LATE_WINDOW
    (``ensemble_summary``), and every run's kinetic energy per frame."""
    t0 = time.time()
    variants = [(name,) + (ENSEMBLE_VARIANTS[name][0],
                           {**ENSEMBLE_VARIANTS[name][1], **overrides}) for name in names]
    # Seed 0: the scene's own start (not moved; a seed makes the child return ke_frames).
    args = [(res, method, "implicit", solver, curvature, ENSEMBLE_FRAMES, 120, ov, None, seed)
            for _label, solver, ov in variants for seed in range(seeds + 1)]
    rows = run_children(args, jobs)
    for i, r in enumerate(rows):
        r["variant"] = variants[i // (seeds + 1)][0]
    summary = ensemble_summary(rows, variants)
    with open(os.path.join(out, "rest_ensemble.json"), "w") as fh:
        json.dump(rows, fh)
    _plot_ensemble(rows, os.path.join(out, "rest_ensemble.png"), res, method)
    faces = next((r["faces"] for r in rows if "error" not in r), "?")
    md = [f"# The rest at resolution {res} is chaotic: an ensemble (issue #13)", "",
          f"`python -m benchmarks.solver --rest-ensemble {seeds} --ensemble-res {res}` "
          f"({time.time() - t0:.0f} s, {jobs} at a time), {time.strftime('%Y-%m-%d')}, 2-core "
          f"CPU, f64. hanging, {method}, {faces} faces, coupling implicit, one substep per "
          "frame; each variant runs from the scene's start and from "
          f"{seeds} starts moved by 1 nm at random (seeds 1-{seeds}). KE 121-150: the mean "
          "kinetic energy over frames 121-150 (the issue's measure, target <= 3e-7 J); "
          "181-240: the same later. ms: the median over runs of each run's median "
          "strain-limiting ms per frame (children run side by side, so slower than alone). "
          "pcg: the default (PCG preconditioned by the factor of the implicit step's matrix); "
          "pcg-jacobi: PCG with block Jacobi (the solver before); cholesky: exact Newton steps.",
          "",
          table(summary, ["variant", "overrides", "runs", "failed", "ke_median", "ke_min",
                          "ke_max", "under_target", "late_median", "ms_median", "commit"],
                ["variant", "settings", "runs", "failed", "KE 121-150 median (J)", "min",
                 "max", "<= 3e-7 J", "KE 181-240 median (J)", "SL ms", "commit"]), "",
          "![kinetic energy of every run](rest_ensemble.png)"]
    with open(os.path.join(out, "rest_ensemble.md"), "w") as fh:
        fh.write("\n".join(md) + "\n")
    print("\n".join(md))


def _plot_ensemble(rows, path, res, method):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(9, 4.5))
    colors = {"pcg": "tab:blue", "pcg-jacobi": "tab:red", "cholesky": "tab:orange"}
    for r in rows:
        if "error" in r or not r.get("ke_frames"):
            continue
        first = r["nudge_seed"] == 0
        ax.semilogy(range(1, len(r["ke_frames"]) + 1), r["ke_frames"],
                    color=colors.get(r["variant"], "tab:gray"), lw=1.6 if first else 0.7,
                    alpha=1.0 if first else 0.6,
                    label=r["variant"] + (" (from the scene's start)" if first else
                                          " (starts moved by 1 nm)"))
    ax.axhline(REST_TARGET, color="k", ls=":", lw=1)
    ax.axvspan(*REST_WINDOW, color="0.9")
    handles, labels = ax.get_legend_handles_labels()
    keep = {l: h for h, l in zip(handles, labels)}
    ax.legend(keep.values(), keep.keys(), fontsize=8)
    ax.set_xlabel("frame (1/60 s)")
    ax.set_ylabel("kinetic energy (J)")
    ax.set_title(f"hanging, {method}, resolution {res}: every run of the ensemble "
                 "(grey: frames 121-150; dotted: 3e-7 J)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def write_docs(rest, speed, out, how):
    """solver.json, solver.md (tables) and solver.png from the rows."""
    with open(os.path.join(out, "solver.json"), "w") as fh:
        json.dump({"rest": rest, "speed": speed}, fh, indent=1)
    md = ["# The constrained step: split projection vs implicit coupling (issue #13)", "",
          f"{how}, {time.strftime('%Y-%m-%d')}, 2-core CPU, f64, machine shared with other "
          "jobs (timings are indicative; compare within a table).", "",
          "## Rest: hanging, mean kinetic energy over frames 120-150 (J); strain-limiting "
          "ms per frame: median over frames 2-150", "",
          table(rest, ["faces", "method", "coupling", "linear_solver", "curvature", "ke_mean",
                       "ms_median", "rounds_median", "newton_median", "converged", "commit"],
                ["faces", "method", "coupling", "Newton solve", "curvature", "KE (J)",
                 "SL ms/frame", "AL rounds", "Newton steps", "converged", "commit"]), "",
          "## Speed: hanging from its start (the sheet falls and settles), median over frames "
          "2-F", "",
          table(speed, ["faces", "method", "frames", "coupling", "linear_solver", "curvature",
                        "ms_median", "ms_p90", "rounds_median", "rounds_max", "newton_median",
                        "converged", "viol_max", "commit"],
                ["faces", "method", "F", "coupling", "Newton solve", "curvature",
                 "SL ms median", "p90", "rounds", "max", "Newton", "converged", "max viol",
                 "commit"]), ""]
    plot(rest, speed, os.path.join(out, "solver.png"))
    md.append("![rest and speed](solver.png)")
    with open(os.path.join(out, "solver.md"), "w") as fh:
        fh.write("\n".join(md) + "\n")
    print("\n".join(md))


def _default_curvature():
    from cloth.settings import COMMON_DEFAULTS
    return COMMON_DEFAULTS["strain"]["curvature"]


def _commit():
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True).stdout.strip()
    except OSError:
        return "?"


if __name__ == "__main__":
    main()
