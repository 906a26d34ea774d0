"""Where a remeshed frame's time goes, per step, optionally beside an older tree's.

    python -m benchmarks.remesh_frame --out DIR                      # this tree only
    python -m benchmarks.remesh_frame --base /tmp/base --out docs/remesh --repeats 2

Each run is one subprocess per (tree, case, repeat), the trees alternating so that the load of
a shared machine falls on both alike. A run simulates ``hanging`` (mapping) remeshed every
frame and times every step a remesh sets off by wrapping the functions that do it (the probe
below wraps a function only where the tree has it, so an older tree is measured unchanged):

    remesh()            cloth.remesh.remesh: sizing and the split / flip / collapse passes
    model load          ClothModel.load: the arrays refilled (of which the bending matrix)
    on_mesh_changed     Simulator._mesh_changed: every solver told (dynamics, strain, collider)
    re-projection       the strain projection run again after the remesh
    block pattern       the implicit step's block pattern (system_matrix.pattern_of or its
                        incremental update), wherever it is built
    factor / multigrid  the preconditioners' symbolic analysis and (re)factorisations
    dynamics step       ImplicitEuler.step (its CG iterations reported beside it)
    system matrix fill  ImplicitEuler.system_matrix (the strain solve's metric)
    strain solve        StrainLimiter.project in the substep (pattern and preconditioner
                        time spent inside it also appear on their own rows)

Stage totals are the simulator's own ``Stage.ms``. After every frame (after its remesh) the
method's own constraint violation is recorded: the limits must hold to ``strain.tol``.
Medians over frames ``--skip``..end of every repeat.
"""
import argparse
import json
import os
import subprocess
import sys
import time

CASES = {
    "1k": {"label": "~1k faces (default sizes)", "set": {}},
    "4k": {"label": "~4k faces (remesh.size_max = 0.04)", "set": {"size_max": 0.04}},
    # The same sheet unremeshed at about the same face counts (the grid's), for the 1.5x
    # comparison: a remeshed frame against an unremeshed one of its size.
    "1k-grid": {"label": "882 faces, not remeshed (resolution 22)", "set": None,
                "resolution": 22},
    "4k-grid": {"label": "4050 faces, not remeshed (resolution 46)", "set": None,
                "resolution": 46},
}
# Rows of the table: (key, label, indent) in the order printed.
ROWS = [("frame", "**frame** (sum of stages)", 0),
        ("stage_remesh", "remesh stage", 0),
        ("remesh_call", "remesh() (sizing, split / flip / collapse)", 1),
        ("sizing", "sizing and pending count, before remesh()", 1),
        ("load", "model load (arrays refilled)", 1),
        ("bending", "bending matrix", 2),
        ("mesh_changed", "solvers' on_mesh_changed", 1),
        ("mc_dynamics", "dynamics", 2),
        ("mc_strain", "strain limiter", 2),
        ("reproject", "re-projection after the remesh", 1),
        ("stage_dynamics", "dynamics stage", 0),
        ("dyn_step", "implicit step (CG)", 1),
        ("sysfill", "system matrix fill", 1),
        ("stage_strain_limit", "strain limiting stage", 0),
        ("strain_solve", "strain solve (substep)", 1),
        ("pattern", "block pattern (anywhere)", 0),
        ("factor", "factor: analysis and factorisations (anywhere)", 0),
        ("multigrid", "multigrid hierarchy (anywhere)", 0)]
COUNTS = [("frame_mean", "frame, mean over frames (ms)"), ("faces", "faces"), ("cg_iters", "dynamics CG iterations"),
          ("cg_ms_per_iter", "dynamics ms per CG iteration"),
          ("ops", "remesh operations (split + flip + collapse)"),
          ("made", "remeshes made (share of frames)"),
          ("applied", "remeshes applied (share of frames)"),
          ("viol", "own violation after the frame (max over frames)")]


# ---------------------------------------------------------------------------------------------
# The probe: runs inside one tree (sys.path[0] = that tree) and prints one JSON line.
# ---------------------------------------------------------------------------------------------
def probe(case, frames, resolution):
    from cloth import backend
    backend.init("cpu", "f64")
    import importlib
    import numpy as np

    timers = {}
    depth = {"remesh": 0}

    def add(label, ms):
        timers[label] = timers.get(label, 0.0) + ms

    def wrap(owner, name, label, only_in_remesh=None):
        fn = getattr(owner, name, None)
        if fn is None:
            return

        def timed(*a, **k):
            if only_in_remesh is not None and bool(depth["remesh"]) != only_in_remesh:
                return fn(*a, **k)
            t0 = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                add(label, 1e3 * (time.perf_counter() - t0))
        setattr(owner, name, timed)

    def module(name):
        try:
            return importlib.import_module(name)
        except ImportError:
            return None

    sim_mod = module("cloth.simulator")
    Simulator = sim_mod.Simulator

    def inside_remesh(name):
        """Work inside Simulator.<name> counts as the remesh's (``only_in_remesh`` timers)."""
        orig = getattr(Simulator, name)

        def stage(self):
            depth["remesh"] += 1
            try:
                return orig(self)
            finally:
                depth["remesh"] -= 1
        setattr(Simulator, name, stage)
    inside_remesh("_remesh")
    if hasattr(Simulator, "_remesh_reproject"):      # a tree with the re-projection its own stage
        inside_remesh("_remesh_reproject")
    wrap(module("cloth.remesh"), "remesh", "remesh_call")
    for name in ("mesh_sizing", "pending_operations"):      # where a tree has them
        wrap(module("cloth.remesh"), name, "sizing", only_in_remesh=True)
    wrap(module("cloth.model").ClothModel, "load", "load")
    # Every name a tree may build the bending matrix by (the rebuild, or the local update).
    bend = module("cloth.bending")
    wrap(bend, "isotropic_matrix", "bending")
    if hasattr(bend, "IsotropicBending"):            # the per-face terms kept across remeshes
        wrap(bend.IsotropicBending, "matrix", "bending")
    wrap(Simulator, "_mesh_changed", "mesh_changed")
    wrap(module("cloth.dynamics").ImplicitEuler, "on_mesh_changed", "mc_dynamics")
    solver = module("cloth.strain.solver")
    wrap(solver.StrainLimiter, "on_mesh_changed", "mc_strain")
    wrap(Simulator, "_project_limits", "reproject", only_in_remesh=True)
    wrap(solver.StrainLimiter, "project", "strain_solve", only_in_remesh=False)
    sm = module("cloth.system_matrix")
    for name in ("pattern_of", "update_pattern"):
        wrap(sm, name, "pattern")
    wrap(module("cloth.dynamics").ImplicitEuler, "step", "dyn_step")
    wrap(module("cloth.dynamics").ImplicitEuler, "system_matrix", "sysfill")
    fp = module("cloth.strain.factor_precond")
    wrap(fp.FactorPreconditioner, "__init__", "factor")
    wrap(fp.FactorPreconditioner, "refresh", "factor")
    mg = module("cloth.strain.multigrid")
    wrap(mg.MultigridPreconditioner, "__init__", "multigrid")
    wrap(mg.MultigridPreconditioner, "refresh", "multigrid")

    from benchmarks.harness import configure
    from cloth.settings import Settings
    ov = {"cloth": {"resolution": CASES[case].get("resolution", resolution)},
          "strain": {"method": "mapping"}}
    if CASES[case]["set"] is not None:
        ov["remesh"] = dict(enabled=True, **CASES[case]["set"])
    _, cfg, setup = configure("hanging", [ov])
    sim = Simulator(setup, Settings(cfg))
    rows = []
    for f in range(frames):
        timers.clear()
        sim.step_frame()
        st = sim.remesh_stats
        row = {k: round(v, 4) for k, v in timers.items()}
        for s in sim.stages:
            row["stage_" + s.name] = round(s.ms, 4)
        row["frame"] = round(sum(s.ms for s in sim.stages), 4)
        row["faces"] = int(sim.model.n_faces)
        row["cg_iters"] = int(sim.dynamics.last_cg_iters)
        row["ops"] = int(st.get("splits", 0) + st.get("flips", 0) + st.get("collapses", 0))
        row["applied"] = int(st.get("applied", True)) if st else 0
        row["made"] = int(st.get("made", True)) if st else 0
        own = sim.own_violation()
        row["viol"] = float(np.max(own)) if own is not None and own.size else 0.0
        rows.append(row)
    print("PROBE " + json.dumps(rows))


def run_probe(tree, case, frames, resolution):
    """One probe in a subprocess with ``tree`` first on the path; returns its per-frame rows."""
    code = (f"import sys; sys.path.insert(0, {tree!r}); sys.argv = ['probe']; "
            f"exec(open({os.path.abspath(__file__)!r}).read().replace("
            f"'if __name__ == \"__main__\":', 'if False:')); "
            f"probe({case!r}, {frames}, {resolution})")
    env = dict(os.environ, PYTHONPATH=tree)
    out = subprocess.run([sys.executable, "-c", code], cwd=tree, env=env, capture_output=True,
                         text=True)
    line = next((l for l in out.stdout.splitlines() if l.startswith("PROBE ")), None)
    if line is None:
        raise RuntimeError(f"probe in {tree} failed:\n{out.stderr[-3000:]}")
    return json.loads(line[6:])


def summarise(runs, skip):
    """Median of every key over frames skip.. of all runs (missing keys count as 0)."""
    import numpy as np
    frames = [r for run in runs for r in run[skip:]]
    keys = {k for r in frames for k in r}
    out = {k: float(np.median([r.get(k, 0.0) for r in frames])) for k in keys}
    out["viol"] = max(r["viol"] for run in runs for r in run[1:])
    out["applied"] = float(np.mean([r.get("applied", 1) for r in frames]))
    out["made"] = float(np.mean([r.get("made", 1) for r in frames]))
    it = np.array([r.get("cg_iters", 0) for r in frames], float)
    ms = np.array([r.get("dyn_step", 0.0) for r in frames])
    out["cg_ms_per_iter"] = float(np.median(ms[it > 0] / it[it > 0])) if np.any(it > 0) else 0.0
    out["frame_mean"] = float(np.mean([r["frame"] for r in frames]))
    # A deferred remesh leaves most steps at zero, so the medians above describe deferred
    # frames once most are: the same steps over the frames whose remesh was applied.
    applied = [r for r in frames if r.get("applied", 1)]
    out["when_applied"] = {k: float(np.median([r.get(k, 0.0) for r in applied]))
                           for k in keys} if applied else {}
    return out


def _step_rows(cols, summary):
    """The table rows of ROWS, one cell per (case, tree) from ``summary(case, tree)``."""
    lines = []
    for key, label, indent in ROWS:
        cells = []
        for case, name in cols:
            v = summary(case, name).get(key)
            cells.append("-" if v is None else f"{v:.1f}")
        lines.append("| " + "&nbsp;&nbsp;" * 2 * indent + label + " | " + " | ".join(cells) + " |")
    return lines


def write_report(path, results, trees, args, header):
    import numpy as np
    cols = [(case, name) for case in args.cases for name in trees]
    lines = header + ["",
                      "| step (ms per frame, median) | " +
                      " | ".join(f"{name} {case}" for case, name in cols) + " |",
                      "|---|" + "---|" * len(cols)]
    lines += _step_rows(cols, lambda case, name: results[case][name])
    for key, label in COUNTS:
        cells = []
        for case, name in cols:
            v = results[case][name].get(key)
            if v is None:
                cells.append("-")
            elif key == "viol":
                cells.append(f"{v:.1e}")
            elif key == "frame_mean":
                cells.append(f"{v:.1f}")
            elif key in ("cg_ms_per_iter", "applied", "made"):
                cells.append(f"{v:.3f}" if key == "cg_ms_per_iter" else f"{100 * v:.0f} %")
            else:
                cells.append(f"{v:.0f}")
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    lines += ["", "The same steps, medians over the frames whose remesh was applied only (a deferred "
              "remesh sets off nothing):", "",
              "| step (ms per frame, median over applied remeshes) | " +
              " | ".join(f"{name} {case}" for case, name in cols) + " |",
              "|---|" + "---|" * len(cols)]
    lines += _step_rows(cols, lambda case, name: results[case][name].get("when_applied", {}))
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")
    del np


def plot(path, results, trees, cases):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    parts = [("remesh_call", "remesh()"), ("load", "model load"),
             ("mesh_changed", "on_mesh_changed"), ("reproject", "re-projection"),
             ("stage_dynamics", "dynamics"), ("stage_strain_limit", "strain limiting")]
    fig, axes = plt.subplots(1, len(cases), figsize=(5 * len(cases), 4), squeeze=False)
    for ax, case in zip(axes[0], cases):
        bottom = [0.0] * len(trees)
        for key, label in parts:
            vals = [results[case][t].get(key, 0.0) for t in trees]
            ax.bar(trees, vals, bottom=bottom, label=label)
            bottom = [b + v for b, v in zip(bottom, vals)]
        other = [results[case][t]["frame"] - b for t, b in zip(trees, bottom)]
        ax.bar(trees, [max(o, 0.0) for o in other], bottom=bottom, label="other",
               color="lightgrey")
        ax.set_title(CASES[case]["label"])
        ax.set_ylabel("ms per frame (median)")
    axes[0][-1].legend(fontsize=8)
    fig.suptitle("hanging, mapping, remeshed every frame: where a frame's time goes")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", help="an older source tree to measure beside this one")
    ap.add_argument("--base-name", default="base")
    ap.add_argument("--name", default="new")
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--skip", type=int, default=10, help="frames left out of the medians")
    ap.add_argument("--resolution", type=int, default=46)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--out", default=None, help="folder for remesh_frame.md/.json/.png")
    ap.add_argument("--from-json", help="rewrite the report and plot from a saved "
                    "remesh_frame.json (no runs)")
    args = ap.parse_args()
    if args.from_json:
        return _from_json(args)
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    trees = {args.name: here}
    if args.base:
        trees = {args.base_name: os.path.abspath(args.base), args.name: here}
    from benchmarks.harness import command, header
    t0 = time.time()
    raw = {case: {name: [] for name in trees} for case in args.cases}
    for rep in range(args.repeats):
        for case in args.cases:
            order = list(trees) if rep % 2 == 0 else list(trees)[::-1]
            for name in order:
                rows = run_probe(trees[name], case, args.frames, args.resolution)
                raw[case][name].append(rows)
                s = summarise([rows], args.skip)
                print(f"{case} {name:5s} rep {rep}: frame {s['frame']:.1f} ms, faces "
                      f"{s['faces']:.0f}, remesh stage {s.get('stage_remesh', 0):.1f}, "
                      f"dynamics {s.get('stage_dynamics', 0):.1f}, strain "
                      f"{s.get('stage_strain_limit', 0):.1f}, max violation {s['viol']:.1e}",
                      flush=True)
    results = {case: {name: summarise(raw[case][name], args.skip) for name in trees}
               for case in args.cases}
    cmd = command("benchmarks.remesh_frame")
    base_line = (f"Base tree `{args.base}` (commit as exported), named *{args.base_name}*; "
                 if args.base else "")
    head = ["# Remeshed frames: where the time goes", "",
            header(cmd, time.time() - t0) + "  ",
            f"{base_line}this tree named *{args.name}*.  ",
            f"Scene: `hanging`, mapping, `--resolution {args.resolution}`, remeshed every "
            f"frame (the *grid* columns: the sheet not remeshed, at the resolution "
            f"named), {args.frames} frames; medians over frames {args.skip}-{args.frames} of "
            f"{args.repeats} runs per tree, the trees alternating. Rows are indented under "
            "the stage they belong to; *anywhere* rows count their work in whichever stage "
            "it happens. Wall clock, on a machine that may be shared with other jobs."]
    if args.out:
        os.makedirs(args.out, exist_ok=True)
        write_report(os.path.join(args.out, "remesh_frame.md"), results, list(trees), args,
                     head)
        with open(os.path.join(args.out, "remesh_frame.json"), "w") as fh:
            json.dump({"results": results, "raw": raw, "command": cmd, "header": head}, fh)
        plot(os.path.join(args.out, "remesh_frame.png"), results, list(trees), args.cases)
        print(f"wrote {args.out}/remesh_frame.md")
    else:
        import tempfile
        path = os.path.join(tempfile.gettempdir(), "remesh_frame.md")
        write_report(path, results, list(trees), args, head)
        print(open(path).read())


def _from_json(args):
    """The report of a saved run, summarised again (its header lines are kept)."""
    with open(args.from_json) as fh:
        saved = json.load(fh)
    raw, header = saved["raw"], saved["header"]
    cases = list(raw)
    trees = list(raw[cases[0]])
    args.cases = cases
    results = {c: {t: summarise(raw[c][t], args.skip) for t in trees} for c in cases}
    out = args.out or os.path.dirname(args.from_json)
    write_report(os.path.join(out, "remesh_frame.md"), results, trees, args, header)
    plot(os.path.join(out, "remesh_frame.png"), results, trees, cases)
    print(f"wrote {out}/remesh_frame.md")


if __name__ == "__main__":
    main()
