"""Does the draped sheet's resting shape depend on the strain solve? The target: a cloth's
final draped shape must not depend on the solver's tolerance; the default and exact steps
give the same drape, the same fold count, within the chaos floor.

    python -m benchmarks.drape_shape --out docs/speed          # ~15 min, a run per core at a time
    python -m benchmarks.drape_shape --drops 0.95 --out /tmp/ds   # one height

The drape scene (resolution 25, the default settings otherwise) runs FRAMES frames from each
height in DROPS, once per solve (``strain.solve``: "fast", the default, and "exact", each
projection solved to its minimiser), and each again with every free vertex's start moved by 1 nm in a random direction. The sheet
rests from about frame 40; the shape it rests in is what a user sees. Per run: the final
positions, the lowest vertex, the hem's folds (``fold_count``) and the mean kinetic energy
over the last 30 frames.

The *chaos floor* of a solve at a height is the RMS distance between its resting sheet and
the same solve's from the start moved by 1 nm: the landing buckles the sheet, and a buckle's
side is decided by rounding, so no solve can be held to a closer answer than that. The
default gives the same drape as the exact solve when its distance to them is within that floor,
and the fold counts agree as a distribution over the heights (one height's count is one
draw of a chaotic outcome).

Writes drape_shape.md, drape_shape.json and drape_shape.png (the hems seen from above, per
height and solve) to --out; runs are cached in --out/drape_shape_runs/ by what decides them
(--fresh: run again). The runs are a sweep (``benchmarks.sweep``): a local cluster, one worker
per core, or ``--scheduler tcp://HOST:PORT`` (docs/sweeps.md); a run that fails is listed on
the page and its height left out.
"""
import argparse
import os
import sys

FRAMES = 90
REST_FRAMES = 30                    # the last frames, over which the resting KE is averaged
DROPS = (0.95, 0.951, 0.953, 0.957, 0.96, 0.965, 0.97)     # as benchmarks.motion_error
SOLVES = {"fast": {"solve": "fast"}, "exact": {"solve": "exact"}}     # strain settings
# A fold: an outward lobe of the hem, standing at least this far (m) out from the hem on both
# sides of it (about one edge of the resolution-25 sheet, 4.2 cm: smaller bumps are single
# triangles, not folds).
FOLD_PROMINENCE = 0.04


def hem_loop(faces):
    """The boundary vertices of a disc-like triangle mesh, in order around it."""
    from collections import Counter, defaultdict
    count = Counter()
    for a, b, c in faces:
        for e in ((a, b), (b, c), (c, a)):
            count[tuple(sorted(e))] += 1
    nbr = defaultdict(list)
    for (a, b), n in count.items():
        if n == 1:
            nbr[a].append(b)
            nbr[b].append(a)
    if not nbr or any(len(v) != 2 for v in nbr.values()):
        raise ValueError("the mesh's boundary is not one simple loop")
    start = min(nbr)
    loop, prev = [start], None
    while True:
        here = loop[-1]
        nxt = nbr[here][0] if nbr[here][0] != prev else nbr[here][1]
        if nxt == start:
            break
        loop.append(nxt)
        prev = here
    if len(loop) != len(nbr):
        raise ValueError("the mesh's boundary is more than one loop")
    return loop


def hem_folds(x, loop, axis_xz, prominence=FOLD_PROMINENCE):
    """The prominences (m) of the hem's folds: local maxima, along the closed hem, of its
    horizontal distance from the sphere's vertical axis that stand ``prominence`` above the
    minima on both sides (a fold hangs out from the sphere; between two folds the hem comes
    back in)."""
    import numpy as np
    from scipy.signal import find_peaks
    p = np.asarray(x)[loop]
    r = np.hypot(p[:, 0] - axis_xz[0], p[:, 2] - axis_xz[1])
    n = len(r)
    # Three copies so that a fold across the loop's start is seen whole; keep the middle one.
    peaks, props = find_peaks(np.concatenate([r, r, r]), prominence=prominence)
    return props["prominences"][(peaks >= n) & (peaks < 2 * n)]


def fold_count(x, loop, axis_xz, prominence=FOLD_PROMINENCE):
    """How many folds the hem has (``hem_folds``)."""
    return int(len(hem_folds(x, loop, axis_xz, prominence)))


def child(solve, drop, chaos, frames=FRAMES):
    """One run: the final positions and faces, the lowest vertex, KE and ms per frame."""
    from cloth import backend
    backend.init("cpu", "f64")
    import numpy as np
    from benchmarks.harness import configure, run_drape_frames
    from cloth.simulator import Simulator
    _, cfg, setup = configure("drape", overrides_of(solve, drop))
    if chaos:
        rng = np.random.default_rng(1)
        step = rng.normal(size=setup.mesh.x.shape)
        step /= np.linalg.norm(step, axis=1, keepdims=True)
        setup.mesh.x += 1e-9 * step
    sim = Simulator(setup, cfg)
    ms, ke = run_drape_frames(sim, frames)
    x = sim.model.positions()
    return {"x": x.tolist(), "faces": np.asarray(sim.model.faces).tolist(),
            "lowest": float(x[:, 1].min()), "ms": ms, "ke": ke,
            "diagonal": float(np.linalg.norm(np.ptp(sim.model.uv, axis=0))),
            "sphere": cfg["sphere"]["center"]}


def overrides_of(solve, drop):
    return {"cloth": {"drop": drop}, "strain": SOLVES[solve]}


def sweep_run(solve, drop, chaos):
    """The sweep's run of (solve, drop, chaos)."""
    from benchmarks.sweep import Run
    return Run("benchmarks.drape_shape:child", [solve, drop, chaos, FRAMES],
               f"{solve} / drop {drop}" + (" / 1 nm" if chaos else ""),
               scene=("drape", overrides_of(solve, drop)))


def summarize(runs, drops):
    """Per height: each solve's lowest vertex, folds, resting KE, its chaos floor, and the
    default's (fast) distance to the exact solve's."""
    import numpy as np
    from benchmarks.motion_error import rms
    rows = []
    for drop in drops:
        row = {"drop": drop}
        for solve in SOLVES:
            run, twin = runs[(solve, drop, False)], runs[(solve, drop, True)]
            loop = hem_loop(run["faces"])
            axis = (run["sphere"][0], run["sphere"][2])
            row[solve] = dict(
                lowest=run["lowest"], folds=fold_count(run["x"], loop, axis),
                folds_1nm=fold_count(twin["x"], loop, axis),
                ke_rest=float(np.mean(run["ke"][-REST_FRAMES:])),
                ms=float(np.median(run["ms"][5:])),
                floor=rms(run["x"], twin["x"], run["diagonal"]))
        d, e = runs[("fast", drop, False)], runs[("exact", drop, False)]
        row["default_vs_exact"] = rms(d["x"], e["x"], d["diagonal"])
        rows.append(row)
    return rows


def permutation_p(a, b, draws=20000):
    """Two-sided permutation test of a difference in means between two samples: the share of
    random relabellings whose difference is at least the observed one."""
    import numpy as np
    a, b = np.asarray(a, float), np.asarray(b, float)
    pooled, observed = np.concatenate([a, b]), abs(a.mean() - b.mean())
    rng = np.random.default_rng(0)
    hits = 0
    for _ in range(draws):
        rng.shuffle(pooled)
        hits += abs(pooled[: len(a)].mean() - pooled[len(a):].mean()) >= observed - 1e-12
    return hits / draws


def write_report(out, rows, seconds, cmd, failed=((), ())):
    """The page; ``failed``: (the sweep's runs, their results), whose errors it lists."""
    import numpy as np
    from benchmarks.harness import header, write_json
    solves = list(SOLVES)
    lines = [
        "# Does the resting drape depend on the strain solve?", "",
        header(cmd, seconds) + " (The seconds: the runs' own, summed.)", "",
        f"The drape scene (resolution 25, 1152 faces) for {FRAMES} frames from each height, "
        "once per solve and once more with every vertex's start moved by 1 nm. *floor*: the "
        "RMS distance between a run's resting sheet and its 1 nm twin's, over the sheet's "
        "diagonal (the chaos floor: how far the same solve's rest moves when rounding decides "
        "a buckle differently). *default vs exact*: the same distance between the default's "
        "(`strain.solve = \"fast\"`) and the exact solve's resting sheets from the same height. *folds*: outward lobes of the "
        f"hem at least {100 * FOLD_PROMINENCE:.0f} cm deep (`fold_count`), the 1 nm twin's "
        f"after the slash. KE: mean over the last {REST_FRAMES} frames. ms: strain limiting a "
        "frame, median of frames 6 on.", "",
        "| drop (m) | default vs exact | floor, default | floor, exact | folds, default | "
        "folds, exact | lowest (m), default / exact | resting KE (J), default / exact |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        d, e = r["fast"], r["exact"]
        lines.append(
            f"| {r['drop']:.3f} | {r['default_vs_exact']:.3f} | {d['floor']:.3f} | "
            f"{e['floor']:.3f} | {d['folds']} / {d['folds_1nm']} | {e['folds']} / "
            f"{e['folds_1nm']} | {d['lowest']:.3f} / {e['lowest']:.3f} | "
            f"{d['ke_rest']:.1e} / {e['ke_rest']:.1e} |")
    dve = np.array([r["default_vs_exact"] for r in rows])
    floors = np.array([[r[s]["floor"] for s in solves] for r in rows])
    folds = {s: sorted([r[s]["folds"] for r in rows] + [r[s]["folds_1nm"] for r in rows])
             for s in solves}
    ms = {s: float(np.median([r[s]["ms"] for r in rows])) for s in solves}
    p_folds = permutation_p(*(folds[s] for s in solves))
    lines += ["", "Summary over the heights:", "",
              f"- default vs exact: median {np.median(dve):.3f}, largest {dve.max():.3f} of "
              f"the diagonal; the chaos floors: median {np.median(floors):.3f}, largest "
              f"{floors.max():.3f}.",
              "- folds (every run, twins included): " + "; ".join(
                  f"{s} {', '.join(map(str, folds[s]))} (median {np.median(folds[s]):g})"
                  for s in solves) + f"; the means differ by "
              f"{abs(np.mean(folds[solves[0]]) - np.mean(folds[solves[1]])):.2f} fold, and a "
              f"random split of the same counts differs as much or more with probability "
              f"{p_folds:.2f} (two-sided permutation test).",
              "- strain limiting ms a frame (median over the heights): " + ", ".join(
                  f"{s} {ms[s]:.0f}" for s in solves) + ".",
              "", "![the hems from above](drape_shape.png)"]
    from benchmarks.sweep import failed_lines
    lines += failed_lines(*failed) + [""]
    with open(os.path.join(out, "drape_shape.md"), "w") as fh:
        fh.write("\n".join(lines))
    write_json(out, "drape_shape", {"rows": rows}, cmd, seconds)


def plot(out, runs, drops):
    """The resting hems seen from above: a panel per height, the fast and exact solves (and
    their 1 nm twins, thin), over the sphere's outline."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    cols = min(len(drops), 4)
    rows = -(-len(drops) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(2.7 * cols, 2.8 * rows + 0.4), squeeze=False)
    for ax in axes.flat[len(drops):]:
        ax.axis("off")
    colors = {"fast": "tab:blue", "exact": "tab:orange"}
    for ax, drop in zip(axes.flat, drops):
        for solve, color in colors.items():
            for chaos in (False, True):
                run = runs[(solve, drop, chaos)]
                loop = hem_loop(run["faces"])
                p = np.asarray(run["x"])[loop + loop[:1]]
                ax.plot(p[:, 0], p[:, 2], color=color, lw=0.6 if chaos else 1.6,
                        alpha=0.6 if chaos else 1.0,
                        label=None if chaos else solve)
        c = runs[("fast", drop, False)]["sphere"]
        t = np.linspace(0, 2 * np.pi, 100)
        ax.plot(c[0] + 0.3 * np.cos(t), c[2] + 0.3 * np.sin(t), color="0.6", lw=0.8, ls=":")
        ax.set_aspect("equal")
        ax.set_title(f"drop {drop:.3f} m", fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    axes[0][0].legend(fontsize=7, loc="lower left")
    fig.suptitle("Resting hems from above\n(thin: the same solve from a start moved by 1 nm; "
                 "dotted: the sphere)", fontsize=9)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "drape_shape.png"), dpi=110)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="docs/speed")
    p.add_argument("--drops", type=float, nargs="+", default=list(DROPS))
    from benchmarks.sweep import add_arguments, run_sweep
    add_arguments(p)
    a = p.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    folder = os.path.join(a.out, "drape_shape_runs")
    plan = [(s, d, c) for d in a.drops for s in SOLVES for c in (False, True)]
    sweep = [sweep_run(*r) for r in plan]
    print(f"drape_shape: {len(plan)} runs of {FRAMES} frames", file=sys.stderr)
    results = run_sweep(sweep, folder, a.scheduler, a.workers, a.fresh, name="drape_shape")
    runs = dict(zip(plan, results))
    # A height is summarized when its four runs finished.
    drops = [d for d in a.drops if all("error" not in runs[(s, d, c)]
                                       for s in SOLVES for c in (False, True))]
    if not drops:
        raise SystemExit("drape_shape: no height has all its runs: "
                         + next(r["error"] for r in results if "error" in r)[-600:])
    rows = summarize(runs, drops)
    # The runs' own time, summed (cached runs count what they took when they ran).
    from benchmarks.harness import command
    write_report(a.out, rows, sum(r.get("wall_s", 0.0) for r in results),
                 command("benchmarks.drape_shape", argv), failed=(sweep, results))
    plot(a.out, runs, drops)
    print(open(os.path.join(a.out, "drape_shape.md")).read())


if __name__ == "__main__":
    main()
