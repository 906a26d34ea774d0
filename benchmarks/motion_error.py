"""How far the strain-limited motion lands from exactly solved motion, per solve setting, with
the cost of each: speed against error on moving scenes.

    python -m benchmarks.motion_error --out docs/speed            # every case (~4 h of runs)
    python -m benchmarks.motion_error --cases hanging25 --out /tmp/me   # one case

Each case is a scene run from its start (one substep per frame). Each *solve* is a setting of
the strain solve (``SOLVES``); every (case, solve) runs in its own process and records the
positions at ``FRAMES_AT``, the strain-limiting time per frame and the kinetic energy. The
error of a run is the RMS vertex distance to the *reference* run at the same frame, divided by
the cloth's diagonal in material space. The reference solves each projection to its minimiser
(``strain.solve = "exact"``) with the limits held to 1e-7 strain (``strain.tol``). (The fast
solve's own tight solves do not converge to one answer: docs/history/motion.md section 4.) The
*chaos floor* is how far the reference itself moves when its start is moved
by 1 nm: past a buckling or a landing, no run can be nearer the reference than that, so an
error within a few floors is as right as the reference.

Drape is run from seven drop heights (``DROPS``; whether a sheet slides off the sphere's top
is a bifurcation, so one drop tells little): per solve, how many drape (the lowest vertex at
frame 30 below the sphere's equator), the lowest vertex against the reference's, and the
kinetic energy kept through the landing, KE(frame 8) / KE(frame 6).

Writes motion_error.md, motion_error.json and motion_error.png (ms a frame against the error
at frame 10, per case) to --out; the runs are cached in --out/motion_error_runs/ (delete it,
or pass --fresh, to measure again). The runs are a sweep (``benchmarks.sweep``): by default
on a local cluster, one worker process per core, each keeping its kernels between runs;
``--scheduler tcp://HOST:PORT`` runs them on a cluster (docs/sweeps.md). A run is cached by
what decides it (the code, the scene's configuration, the solve's settings), so an edited
``--extra`` solve reruns only its own runs.
"""
import argparse
import json
import os

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FRAMES = 30
FRAMES_AT = (5, 10, 30)
DROPS = (0.95, 0.951, 0.953, 0.957, 0.96, 0.965, 0.97)
DRAPED_BELOW = 0.55          # the drape sphere's equator (m)

# Cases: (scene, overrides). The drape runs from every height in DROPS.
CASES = {
    "hanging25": ("hanging", {"cloth": {"resolution": 25}, "strain": {"method": "mapping"}}),
    "hanging25-svd": ("hanging", {"cloth": {"resolution": 25}, "strain": {"method": "svd"}}),
    "hanging25-warp-weft": ("hanging", {"cloth": {"resolution": 25},
                                        "strain": {"method": "warp-weft"}}),
    "hanging46": ("hanging", {"cloth": {"resolution": 46}, "strain": {"method": "mapping"}}),
    "pull": ("pull", {}),
    "drape": ("drape", {}),
    "tshirt": ("tshirt", {}),
}
# Solves: overrides of the strain settings. "reference" and the "chaos" runs are the exact
# solve held to a tight tolerance, the chaos runs with the start moved by 1 nm in different
# random directions (one move's distance varied 6-36x between commits, so the floor is their
# median); the others are what a user can choose.
REFERENCE = {"solve": "exact", "tol": 1e-7}
SOLVES = {
    "reference": REFERENCE,
    "chaos": REFERENCE,
    "chaos 2": REFERENCE,
    "chaos 3": REFERENCE,
    "default": {"solve": "fast"},
    "exact": {"solve": "exact"},
}
DRAPE_SOLVES = ("reference", "default", "exact")


def child(case, solve, drop=None, settings=None, frames=FRAMES):
    """One run: positions at FRAMES_AT, strain ms per frame, kinetic energy per frame.
    ``settings``: the solve's strain settings (default ``SOLVES[solve]``)."""
    from cloth import backend
    backend.init("cpu", "f64")
    import numpy as np
    from benchmarks.harness import configure
    from cloth import metrics
    from cloth.simulator import Simulator
    scene, overrides = overrides_of(case, solve, drop, settings)
    _, cfg, setup = configure(scene, overrides)
    if solve.startswith("chaos"):
        rng = np.random.default_rng(int(solve.split()[-1]) if solve != "chaos" else 1)
        free = ~setup.mesh.pinned
        step = rng.normal(size=setup.mesh.x.shape)
        step /= np.linalg.norm(step, axis=1, keepdims=True)
        setup.mesh.x[free] += 1e-9 * step[free]
    sim = Simulator(setup, cfg)
    out = {"x": {}, "ms": [], "ke": [], "converged": 0, "stationarity": [], "rounds": []}
    for frame in range(1, frames + 1):
        # AL rounds a frame, over every projection in it (the contact re-projections too).
        before = sim.strain.rounds_total
        sim.step_frame()
        out["rounds"].append(sim.strain.rounds_total - before)
        out["ms"].append(sim.stage("strain_limit").ms)
        out["ke"].append(metrics.kinetic_energy(sim.model.velocities(), sim.model.mass))
        out["converged"] += int(sim.strain.last_converged)
        out["stationarity"].append(sim.strain.last_stationarity)
        if frame in FRAMES_AT:
            out["x"][frame] = sim.model.positions().tolist()
    out["lowest"] = float(sim.model.positions()[:, 1].min())
    out["diagonal"] = float(np.linalg.norm(np.ptp(sim.model.uv, axis=0)))
    out["faces"] = int(sim.model.n_faces)
    return out


def overrides_of(case, solve, drop, settings=None):
    """The scene and overrides a run builds (``settings``: the solve's, default SOLVES')."""
    scene, overrides = CASES[case]
    overrides = json.loads(json.dumps(overrides))
    overrides.setdefault("strain", {}).update(SOLVES[solve] if settings is None else settings)
    if drop is not None:
        overrides.setdefault("cloth", {})["drop"] = drop
    return scene, overrides


def sweep_run(case, solve, drop):
    """The sweep's run of (case, solve, drop)."""
    from benchmarks.sweep import Run
    return Run("benchmarks.motion_error:child", [case, solve, drop, SOLVES[solve], FRAMES],
               f"{case} / {solve}" + ("" if drop is None else f" / drop {drop}"),
               scene=overrides_of(case, solve, drop))


def rms(a, b, diagonal):
    import numpy as np
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape:
        return float("nan")
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))) / diagonal)


def summarize(runs):
    """Rows per (case, solve): ms, errors at FRAMES_AT, the chaos floor."""
    import numpy as np
    rows = []
    for case, by_solve in runs.items():
        ref = by_solve.get("reference")
        if not ref or "error" in ref:
            continue
        diag = ref["diagonal"]
        chaos = [run for solve, run in by_solve.items()
                 if solve.startswith("chaos") and "error" not in run]
        spread = {f: [rms(c["x"][str(f)], ref["x"][str(f)], diag) for c in chaos]
                  for f in FRAMES_AT}
        floor = {f: float(np.median(v)) if v else float("nan") for f, v in spread.items()}
        for solve, run in by_solve.items():
            if solve == "reference" or solve.startswith("chaos") or "error" in run:
                continue
            err = {f: rms(run["x"][str(f)], ref["x"][str(f)], diag) for f in FRAMES_AT}
            rows.append(dict(case=case, solve=solve, faces=run["faces"],
                             ms=float(np.median(run["ms"][4:])),
                             ms_ref=float(np.median(ref["ms"][4:])),
                             converged=run["converged"], error=err, floor=floor,
                             floor_runs=spread))
    return rows


def summarize_drape(drape):
    """Per solve: drapes, lowest vertices, KE kept, ms; and per drop the distance of the
    lowest vertex to the reference's."""
    import numpy as np
    out = []
    ref = drape.get("reference", {})
    for solve, by_drop in drape.items():
        ok = [r for r in by_drop.values() if "error" not in r]
        if not ok:
            continue
        low = [r["lowest"] for r in ok]
        kept = [r["ke"][7] / r["ke"][5] for r in ok]
        dlow = [abs(r["lowest"] - ref[d]["lowest"]) for d, r in by_drop.items()
                if "error" not in r and d in ref and "error" not in ref[d]]
        out.append(dict(solve=solve, draped=sum(v < DRAPED_BELOW for v in low), n=len(low),
                        lowest=low, ke_kept=float(np.median(kept)),
                        ke_kept_all=kept, lowest_vs_ref=float(max(dlow)) if dlow else None,
                        ms=float(np.median([np.median(r["ms"][4:]) for r in ok])),
                        rounds=float(np.median([np.median(r["rounds"][4:]) for r in ok
                                                if "rounds" in r] or [float("nan")]))))
    return out


def _run_minutes(runs, drape):
    """The runs' own wall time (min), summed: what the page cost, cached or not."""
    walls = [r.get("wall_s", 0.0) for by in runs.values() for r in by.values()]
    walls += [r.get("wall_s", 0.0) for by in drape.values() for r in by.values()]
    return sum(walls) / 60


def trade_off(rows, drows, runs):
    """The targets read off the runs: per moving case the default's error at frame 10 against
    the chaos floor, and the cheapest solve within 3 floors with its cost against the
    default's; for the drape, the default against the exact solve."""
    import numpy as np
    L = ["## The default on the speed-against-error curve\n",
         "Per case: the default's error at frame 10 in chaos floors (target: 3); the same for "
         "*exact*, the projection solved to its minimiser at the library's tolerance "
         "(1e-4 strain): what that tolerance itself costs in motion, stopping early aside; and "
         "the cheapest solve measured here within 3 floors, with its strain-limiting time over "
         "the default's.\n",
         "| case | default ms | default f10 / floor | exact f10 / floor | "
         "cheapest within 3 floors | its ms | x default's time |",
         "| --- | --- | --- | --- | --- | --- | --- |"]
    for case in sorted({r["case"] for r in rows}):
        sub = [r for r in rows if r["case"] == case]
        floor = sub[0]["floor"][10]
        dflt = next((r for r in sub if r["solve"] == "default"), None)
        if dflt is None or not floor > 0:
            continue
        within = sorted((r for r in sub if r["error"][10] <= 3 * floor), key=lambda r: r["ms"])
        head = f"| {case} | {dflt['ms']:.1f} | {dflt['error'][10] / floor:.1f} | "
        conv = next((r for r in sub if r["solve"] == "exact"), None)
        head += "- | " if conv is None else f"{conv['error'][10] / floor:.1f} | "
        if within:
            best = within[0]
            L.append(head + f"{best['solve']} | {best['ms']:.1f} | "
                     f"{best['ms'] / dflt['ms']:.1f} |")
        else:
            nearest = min(sub, key=lambda r: r["error"][10])
            L.append(head + f"none (nearest: {nearest['solve']}, "
                     f"{nearest['error'][10] / floor:.0f} floors) | {nearest['ms']:.1f} | "
                     f"{nearest['ms'] / dflt['ms']:.1f} |")
    by = {d["solve"]: d for d in drows}
    if "default" in by and "exact" in by:
        d, e = by["default"], by["exact"]
        gap = max(abs(a - b) for a, b in zip(d["lowest"], e["lowest"]))
        L += ["", f"Drape, default against the exact solve (targets: 7 of 7 drape, KE kept "
              f"0.75-1.33x exact's, lowest vertex within 2 cm): {d['draped']} of "
              f"{d['n']} drape (exact {e['draped']} of {e['n']}); KE kept "
              f"{d['ke_kept']:.3f} against {e['ke_kept']:.3f} "
              f"({d['ke_kept'] / e['ke_kept']:.2f}x); lowest vertex at most {100 * gap:.1f} cm "
              f"from exact's (per drop; medians {np.median(d['lowest']):.3f} and "
              f"{np.median(e['lowest']):.3f} m); {d['ms']:.0f} against {e['ms']:.0f} ms a "
              "frame."]
        twin = runs.get("drape", {})
        if all(k in twin and "error" not in twin[k] for k in ("reference", "chaos")):
            L[-1] += (" Whether a sheet slides off the top decides the lowest vertex: the "
                      "reference and its 1 nm twin (the scene's own drop) end "
                      f"{100 * abs(twin['reference']['lowest'] - twin['chaos']['lowest']):.1f}"
                      " cm apart.")
    return L


def write_report(out, runs, drape, cmd, failed=((), ())):
    """The page; ``failed``: (the sweep's runs, their results), whose errors it lists."""
    from benchmarks.harness import header, write_json
    from cloth import backend
    rows, drows = summarize(runs), summarize_drape(drape)
    seconds = 60 * _run_minutes(runs, drape)
    write_json(out, "motion_error", {"rows": rows, "drape": drows}, cmd, seconds)
    mode = backend.compile_mode()
    L = ["# Motion error against exactly solved motion\n",
         header(cmd, seconds) + f" (The seconds: the runs' own, summed; {mode} "
         "kernels.)\n",
         "Each case runs from its start, one substep per frame. Error: RMS vertex distance to "
         "the reference run at that frame over the cloth's diagonal. The reference solves each "
         "projection to its minimiser (`strain.solve = \"exact\"`) with the limits held to "
         "1e-7 strain; the chaos floor is how far the reference moves when its start moves by "
         "1 nm. Solves: *default* (`strain.solve = \"fast\"`: stopped once the limits hold, "
         "started where each vertex was going); *exact* (`strain.solve = \"exact\"` at the "
         "default tolerance, 1e-4 strain). ms: strain limiting per frame, median of frames "
         "5-30, two runs sharing the two cores. conv: frames whose strain solve converged (of "
         "30). One projection's distance and damping: projection_error.md.\n",
         "| case | faces | solve | ms | conv | error f5 | f10 | f30 | f10 / floor |",
         "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        e, fl = r["error"], r["floor"]
        L.append(f"| {r['case']} | {r['faces']} | {r['solve']} | {r['ms']:.1f} | "
                 f"{r['converged']} | {e[5]:.1e} | {e[10]:.1e} | {e[30]:.1e} | "
                 f"{e[10] / fl[10]:.1f} |" if fl[10] > 0 else
                 f"| {r['case']} | {r['faces']} | {r['solve']} | {r['ms']:.1f} | "
                 f"{r['converged']} | {e[5]:.1e} | {e[10]:.1e} | {e[30]:.1e} | - |")
    L.append("")
    L.append("Chaos floor (the reference against the reference started 1 nm away, median over "
             "the random moves; the range in brackets) and the reference's own cost:\n")
    L.append("| case | moves | floor f5 | f10 | f30 | reference ms |")
    L.append("| --- | --- | --- | --- | --- | --- |")
    seen = set()
    for r in rows:
        if r["case"] in seen:
            continue
        seen.add(r["case"])
        fl, sp = r["floor"], r["floor_runs"]
        cells = [f"{fl[f]:.1e}" + (f" ({min(sp[f]):.1e}-{max(sp[f]):.1e})" if len(sp[f]) > 1
                                   else "") for f in FRAMES_AT]
        L.append(f"| {r['case']} | {len(sp[10])} | " + " | ".join(cells)
                 + f" | {r['ms_ref']:.0f} |")
    if drows:
        L.append("")
        L.append(f"Drape from {len(DROPS)} heights ({DROPS[0]}-{DROPS[-1]} m), 30 frames. "
                 f"Draped: lowest vertex at frame 30 below the sphere's equator "
                 f"({DRAPED_BELOW} m). KE kept: KE(frame 8) / KE(frame 6), median. Lowest vs "
                 "reference: the largest difference over the drops (m). AL rounds a frame: "
                 "over every projection of the frame, median of frames 5-30 and the drops.\n")
        L.append("| solve | draped | lowest y per drop (m) | KE kept | lowest vs reference | "
                 "ms | AL rounds a frame |")
        L.append("| --- | --- | --- | --- | --- | --- | --- |")
        for d in drows:
            lv = "-" if d["lowest_vs_ref"] is None else f"{d['lowest_vs_ref']:.3f}"
            L.append(f"| {d['solve']} | {d['draped']} of {d['n']} | "
                     + ", ".join(f"{v:.2f}" for v in d["lowest"])
                     + f" | {d['ke_kept']:.3f} | {lv} | {d['ms']:.0f} | "
                     f"{d.get('rounds', float('nan')):.0f} |")
    L.append("")
    L += trade_off(rows, drows, runs)
    L.append("")
    L.append("![speed against error](motion_error.png)")
    from benchmarks.sweep import failed_lines
    L += failed_lines(*failed)
    L.append("")
    with open(os.path.join(out, "motion_error.md"), "w") as fh:
        fh.write("\n".join(L))
    plot(out, rows)


def plot(out, rows):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    cases = sorted({r["case"] for r in rows})
    if not cases:
        return
    cols = min(3, len(cases))
    nrows = (len(cases) + cols - 1) // cols
    fig, axes = plt.subplots(nrows, cols, figsize=(4.6 * cols, 3.8 * nrows), squeeze=False)
    for ax in axes.ravel()[len(cases):]:
        ax.set_visible(False)
    for ax, case in zip(axes.ravel(), cases):
        sub = [r for r in rows if r["case"] == case]
        for r in sub:
            ax.loglog(r["ms"], max(r["error"][10], 1e-12), "o")
            ax.annotate(r["solve"], (r["ms"], max(r["error"][10], 1e-12)), fontsize=7,
                        xytext=(3, 3), textcoords="offset points")
        floor = sub[0]["floor"][10]
        if floor > 0:
            ax.axhline(floor, color="grey", ls="--", lw=0.8)
            ax.axhline(3 * floor, color="grey", ls=":", lw=0.8)
        ax.set_title(f"{case} ({sub[0]['faces']} faces)", fontsize=9)
        ax.set_xlabel("strain limiting, ms a frame")
        ax.set_ylabel("RMS error / diagonal at frame 10")
    fig.suptitle("speed against motion error (dashed: chaos floor, dotted: 3x floor)",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "motion_error.png"), dpi=110)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "speed"))
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--solves", nargs="+", default=list(SOLVES))
    ap.add_argument("--extra", nargs="+", default=[], metavar="NAME=JSON",
                    help="more solves: a name and strain settings, e.g. "
                         "'tol5={\"solve\": \"exact\", \"tol\": 1e-5}'")
    from benchmarks.sweep import add_arguments
    add_arguments(ap)
    a = ap.parse_args(argv)
    drape_solves = list(DRAPE_SOLVES)
    for item in a.extra:
        name, _, value = item.partition("=")
        SOLVES[name] = json.loads(value)
        a.solves.append(name)
        drape_solves.append(name)        # an extra solve runs every drop
    folder = os.path.join(a.out, "motion_error_runs")
    os.makedirs(folder, exist_ok=True)
    plan = []
    for case in a.cases:
        if case == "drape":
            plan += [(case, s, d) for s in drape_solves if s in a.solves for d in DROPS]
            plan += [(case, s, None) for s in a.solves]
        else:
            plan += [(case, s, None) for s in a.solves]
    # Every case and solve cached under the current code is read back, so a report always
    # covers what has been measured, not only this invocation's cases.
    from benchmarks.sweep import cached_entries, run_sweep
    sweep = [sweep_run(*p) for p in plan]
    results = run_sweep(sweep, folder, a.scheduler, a.workers, a.fresh, name="motion_error")
    runs, drape = {}, {}
    for entry in cached_entries(folder):
        case, solve, drop = entry["args"][:3]
        run = entry["result"]
        if drop is not None:
            drape.setdefault(solve, {})[float(drop)] = run
        else:
            runs.setdefault(case, {})[solve] = run
    from benchmarks.harness import command
    write_report(a.out, runs, drape, command("benchmarks.motion_error", argv),
                 failed=(sweep, results))
    print(f"wrote {os.path.join(a.out, 'motion_error.md')}")


if __name__ == "__main__":
    main()
