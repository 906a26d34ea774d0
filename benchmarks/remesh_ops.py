"""Remeshing cost and operations per frame (issue #4's benchmark numbers).

    python -m benchmarks.remesh_ops          # ~4-5 min on 2 loaded cores -> docs/remesh/
    python -m benchmarks.remesh_ops --quick  # 0.5-2 min (less with Taichi's kernel cache warm)

Everything is read from what the simulator exposes: ``sim.remesh_stats`` (the last
``remesh()`` call: splits, flips, collapses, faces, ``ms``), ``Stage.ms`` (each stage's time in
the frame) and, where a scene limits strain, the limiter's ``last_iterations`` / ``last_ms`` /
``last_converged`` after the frame, which belong to the projection the remesh stage runs on the
new mesh (it is the stage's last action, and the remesh stage runs last in the frame).

1. Operations per frame: ``hanging`` and ``drape`` with remeshing on.
2. Cost against face count: ``hanging`` with remeshing on, the sizing bounds and the starting
   grid scaled together so the mesh works at about 1k to 20k faces (hanging limits no strain,
   so its frame is dynamics + remesh).
3. Warm or cold multipliers after a remesh: ``hanging`` with mapping (and warp-weft for
   comparison), remeshing on, with ``remesh.warm_multipliers`` on (``set_face_state`` carries
   the multipliers to the new faces and the projection after the remesh starts from them),
   off (it starts from zero), and on with that projection patched to solve cold
   (``warm=False``); compares the AL rounds and ms of that projection and of the next
   substep's.

Both scenes run at the default sizes. Before the curvature term was smoothed
(``RemeshParams.curvature_smoothing``), drape refined to ~15k faces by frame 10 at the default
size_min, where each mapping projection took 15-30 s, so this script ran it at twice that.
"""
import argparse
import contextlib
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import numpy as np

from benchmarks import harness

REMESH_ON = {"remesh": {"enabled": True}}
SCENES = {                                   # part 1: scene -> overrides besides REMESH_ON
    "hanging": {"strain": {"method": "none"}},   # the free sheet (the scene's default limits)
    "drape": {},
}
WARM_COLD = {"remesh": {"size_min": 0.03}}     # part 3: hanging, plus strain.method
DEFAULT_SIZE_MIN, DEFAULT_SIZE_MAX, DEFAULT_RES = 0.015, 0.08, 25

FULL = dict(frames=60, sweep_scales=(1.6, 1.0, 0.6, 0.375), sweep_frames=20, wc_frames=30,
            wc_methods=("mapping", "warp-weft"), wc_variants=("warm", "cold", "cold re-projection"))
QUICK = dict(frames=12, sweep_scales=(1.6, 0.6), sweep_frames=8, wc_frames=10,
             wc_methods=("mapping",), wc_variants=("warm", "cold"))


def log(*args):
    print(*args, file=sys.stderr, flush=True)


def sweep_overrides(scale):
    """Hanging at ``scale`` x the default sizing bounds, starting from a grid of the same
    relative fineness (scale 1 = the scene defaults)."""
    res = int(round((DEFAULT_RES - 1) / scale)) + 1
    return {"cloth": {"resolution": res}, "strain": {"method": "none"},
            "remesh": {"size_min": round(DEFAULT_SIZE_MIN * scale, 5),
                       "size_max": round(DEFAULT_SIZE_MAX * scale, 5)}}


def combine(*overrides):
    """Nested override dicts merged into one (later ones win)."""
    out = {}
    for ov in overrides:
        for k, v in ov.items():
            out[k] = combine(out.get(k, {}), v) if isinstance(v, dict) else v
    return out


def as_sets(overrides, prefix=""):
    """Override dict -> the equivalent ``--set key=value`` list (for the doc)."""
    out = []
    for k, v in overrides.items():
        if isinstance(v, dict):
            out += as_sets(v, f"{prefix}{k}.")
        else:
            val = str(v).lower() if isinstance(v, bool) else f'"{v}"' if isinstance(v, str) else v
            out.append(f"{prefix}{k}={val}")
    return out


def run(scene, overrides, frames, label):
    """Run ``scene`` with remeshing on for ``frames`` frames; one dict per frame."""
    import scenes
    from cloth.simulator import Simulator
    from scenes.common import resolve
    module = scenes.get(scene)
    cfg = resolve(module.DEFAULTS, [REMESH_ON, overrides])
    sim = Simulator(module.build(cfg), cfg)
    substep_rounds = []                      # AL rounds of the per-substep projections
    if sim.strain is not None:
        stage = sim.stage("strain_limit")
        project = stage.run

        def counted():
            project()
            substep_rounds.append(sim.strain.last_iterations)
        stage.run = counted
    rows, t0 = [], time.perf_counter()
    for frame in range(1, frames + 1):
        substep_rounds.clear()
        sim.step_frame()
        st, ms = sim.remesh_stats, {s.name: s.ms for s in sim.stages}
        limited = sim.strain is not None and sim.stage("strain_limit").enabled
        rows.append(dict(
            frame=frame, faces=st["faces_out"],
            splits=st["splits"], flips=st["flips"], collapses=st["collapses"],
            remesh_ms=st["ms"], remesh_cpu_ms=st["ms_cpu"],
            stage_ms=ms["remesh"] + ms["remesh_reproject"],     # the remesh and its projection
            frame_ms=sum(ms.values()), top=float(sim.model.positions()[:, 1].max()),
            reproj_ms=sim.strain.last_ms if limited else 0.0,
            reproj_rounds=sim.strain.last_iterations if limited else 0,
            reproj_converged=sim.strain.last_converged if limited else True,
            substep_rounds=sum(substep_rounds), substep_ms=ms["strain_limit"]))
        if frame % 10 == 0 or frame == frames:
            log(f"  {label}: frame {frame}/{frames}, {rows[-1]['faces']} faces, "
                f"{time.perf_counter() - t0:.0f} s")
    return rows, cfg


# Part 3 variants: (what, overrides, whether the re-projection is forced cold).
WARM_COLD_VARIANTS = {
    "warm": ("`remesh.warm_multipliers=true`: multipliers transferred, the re-projection "
             "starts from them", {"remesh": {"warm_multipliers": True}}, False),
    "cold": ("`remesh.warm_multipliers=false`: no transfer, the re-projection starts from "
             "zero multipliers", {"remesh": {"warm_multipliers": False}}, False),
    "cold re-projection": ("`remesh.warm_multipliers=true`, but the re-projection solves from "
                           "zero (`project(warm=False)`, patched in; it puts the transferred "
                           "multipliers back for the next substep's projection)",
                           {"remesh": {"warm_multipliers": True}}, True),
}


@contextlib.contextmanager
def cold_reprojection(on=True):
    """Make the remesh stage's projection solve from zero multipliers (``warm=False``) in
    Simulators built inside (the stage list binds ``_remesh`` at construction)."""
    from cloth.simulator import Simulator
    saved = Simulator._remesh

    def remesh_stage(self):
        project = self._project_limits
        self._project_limits = lambda h, t, warm=True: project(h, t, warm=False)
        try:
            saved(self)
        finally:
            del self._project_limits
    if on:
        Simulator._remesh = remesh_stage
    try:
        yield
    finally:
        Simulator._remesh = saved


# ---- Markdown -------------------------------------------------------------------------------
def table(header, rows):
    return ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)] + \
        ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]


def col(rows, key):
    return np.array([r[key] for r in rows], dtype=float)


def share(rows, key):
    return col(rows, key) / col(rows, "frame_ms")


def ops_table(name, rows):
    """Frame 1 apart, then median and max over frames 2..N."""
    later = rows[1:]
    out = []
    for label, pick in (("frame 1", lambda a: a[0]),
                        (f"median, frames 2-{len(rows)}", lambda a: np.median(a[1:])),
                        (f"max, frames 2-{len(rows)}", lambda a: np.max(a[1:]))):
        if label != "frame 1" and not later:
            continue
        v = {k: pick(col(rows, k)) for k in ("faces", "splits", "flips", "collapses",
                                             "remesh_ms", "stage_ms", "reproj_ms", "frame_ms")}
        sh, sh_stage = pick(share(rows, "remesh_ms")), pick(share(rows, "stage_ms"))
        out.append([name, label, f"{v['faces']:.0f}", f"{v['splits']:.0f}", f"{v['flips']:.0f}",
                    f"{v['collapses']:.0f}", f"{v['remesh_ms']:.1f}", f"{v['stage_ms']:.1f}",
                    f"{v['reproj_ms']:.1f}", f"{v['frame_ms']:.0f}", f"{sh:.1%}",
                    f"{sh_stage:.1%}"])
    return out


def phases_table(name, rows, width=10):
    """Mean operations per frame in blocks of frames, to show refining and settling."""
    blocks = [rows[:1]] + [rows[a:a + width] for a in range(1, len(rows), width)]
    return [[name, f"{b[0]['frame']}-{b[-1]['frame']}" if len(b) > 1 else f"{b[0]['frame']}",
             b[-1]["faces"], f"{b[-1]['top']:.3f}"]
            + [f"{col(b, k).mean():.0f}" for k in ("splits", "flips", "collapses")]
            for b in blocks]


def sweep_row(scale, rows, cfg):
    """Statistics over the second half of a run (after the mesh has grown to its size)."""
    late = rows[len(rows) // 2:]
    r = cfg["remesh"]
    med = lambda k: np.median(col(late, k))
    return [f"{scale:g}", cfg["cloth"]["resolution"], f"{r['size_min']:g} / {r['size_max']:g}",
            f"{med('faces'):.0f}", f"{med('remesh_ms'):.1f}", f"{med('remesh_cpu_ms'):.1f}",
            f"{med('stage_ms'):.1f}", f"{med('frame_ms'):.0f}",
            f"{np.median(share(late, 'stage_ms')):.0%}",
            f"{med('splits'):.0f} / {med('flips'):.0f} / {med('collapses'):.0f}",
            f"{late[0]['frame']}-{late[-1]['frame']}"]


def warm_cold_row(name, rows):
    """Part 3: the re-projection after each remesh and the next substep's projection."""
    later = rows[1:]
    rounds, ms = col(later, "reproj_rounds"), col(later, "reproj_ms")
    sub = col(later, "substep_rounds")
    stat = lambda a: f"{np.median(a):.0f} / {a.mean():.1f} / {a.max():.0f}"
    return [name, f"{np.median(col(later, 'faces')):.0f}", stat(rounds),
            f"{np.median(ms):.0f} / {ms.mean():.0f} / {ms.max():.0f}",
            sum(not r["reproj_converged"] for r in later), stat(sub),
            f"{(rounds + sub).mean():.1f}", f"{(ms + col(later, 'substep_ms')).mean():.0f}"]


def machine():
    """The sweep's machine line plus the load average when the run started."""
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return f"{harness.machine()} (load average {load:.1f} at start)"


def write_doc(path, cmd, seconds, where, p, part1, sweep, wc):
    """``where``: (commit, machine) lines, taken when the run started."""
    hdr = ["scene", "frames", "faces", "splits", "flips", "collapses", "remesh() ms",
           "remesh stage ms", "of which re-projection ms", "frame ms", "remesh() share",
           "stage share"]
    doc = [
        "# Remeshing: operations and cost per frame (issue #4)",
        "",
        f"Command: `{cmd}` ({seconds:.0f} s wall clock)  ",
        f"Commit: {where[0]}, {time.strftime('%Y-%m-%d')}  ",
        f"Machine: {where[1]}  ",
        "Times are wall clock on a machine shared with other jobs: expect ±30 % between runs.",
        "",
        "Definitions. *remesh() ms*: the `cloth.remesh.remesh` call (`sim.remesh_stats['ms']`). "
        "*remesh stage ms*: the whole `remesh` stage (`Stage.ms`): the call, loading the new "
        "mesh into the fields, the solvers' updates and, where a scene limits strain, the "
        "projection run again on the new triangles (*of which re-projection ms*, the "
        "limiter's `last_ms`). *frame ms*: the sum of all stages' `Stage.ms`. *share*: of the "
        "frame. Operation counts are per `remesh()` call (one per frame). Frame 1 turns the "
        "scene's starting grid into the adaptive mesh and includes the kernels' compilation "
        "in its frame ms, so it is shown apart.",
        "",
        "## 1. Operations per frame, scenes with remeshing on",
        "",
        "Scene defaults plus " + ", ".join(
            f"`{name}`: `" + " ".join(as_sets(combine(REMESH_ON, SCENES[name]))) + "`"
            for name in part1) + ". drape limits strain (mapping, the scene default), "
        "hanging does not.",
        "",
        *table(hdr, [r for name, rows in part1.items() for r in ops_table(name, rows)]),
        "",
        "Mean operations per frame over blocks of frames; *faces* and *top* (the cloth's "
        "highest point, m) at the block's end. hanging's top is its pins (2 m). drape's is "
        "the sphere's top plus the thickness (0.855 m) while the sheet lies over the sphere.",
        "",
        *table(["scene", "frames", "faces", "top (m)", "splits", "flips", "collapses"],
               [r for name, rows in part1.items() for r in phases_table(name, rows)]),
        "",
        "## 2. Remeshing cost against face count",
        "",
        "`hanging` with remeshing on, `size_min` and `size_max` scaled by *scale* from the "
        f"defaults ({DEFAULT_SIZE_MIN} / {DEFAULT_SIZE_MAX} m) and the starting grid "
        f"(*resolution* vertices a side) with them; {p['sweep_frames']} frames each, medians "
        "over the second half of each run, when the mesh has grown to its working size. "
        "hanging limits no strain, so its frame is dynamics plus remesh; in a scene that "
        "limits strain the projection dominates the frame and the remesh share is far "
        "smaller (part 1, drape).",
        "",
        *table(["scale", "resolution", "size_min / size_max (m)", "faces", "remesh() ms",
                "remesh() CPU ms", "remesh stage ms", "frame ms", "stage share",
                "splits / flips / collapses", "frames"], sweep),
        "",
        "## 3. Multipliers through a remesh: warm transfer against cold",
        "",
        f"`hanging`, `{' '.join(as_sets(combine(REMESH_ON, WARM_COLD)))}` and "
        f"`strain.method` {' or '.join(p['wc_methods'])}"
        + (" (mapping is the question asked, the others for comparison)"
           if len(p["wc_methods"]) > 1 else "")
        + f", {p['wc_frames']} frames each, statistics over frames 2 to the end. "
        "After each remesh `Simulator._remesh` projects the new mesh onto the limits (the "
        "*re-projection*, in the same substep as the strain_limit stage's projection); with "
        "`remesh.warm_multipliers` it first carries each face's multipliers to the faces cut "
        "from it (`StrainLimiter.set_face_state`, scaled by sqrt of the area ratio). "
        "Variants:",
        "",
        *[f"- *{name}*: {what}" for name, (what, _, _) in WARM_COLD_VARIANTS.items()
          if name in p["wc_variants"]],
        "",
        "Only the remesh stage differs; the runs then drift apart, so compare distributions, "
        "not frames. Rounds and ms are median / mean / max over frames. *substep projection*: "
        "the strain_limit stage's (one substep per frame, so it is the first projection "
        "after the previous frame's remesh and starts from the multipliers the "
        "re-projection left). The last two columns add both projections of a frame.",
        "",
        *table(["method", "variant", "faces (median)", "re-projection AL rounds",
                "re-projection ms", "unconverged re-projections", "substep projection AL rounds",
                "all AL rounds per frame (mean)", "all projection ms per frame (mean)"], wc),
        "",
    ]
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w") as f:
        f.write("\n".join(doc))


def measure(p):
    """Run the three parts with settings ``p`` (FULL or QUICK); returns their table rows."""
    part1 = {}
    for name, ov in SCENES.items():
        log(f"part 1: {name}")
        part1[name], _ = run(name, ov, p["frames"], name)
    sweep = []
    for scale in p["sweep_scales"]:
        log(f"part 2: hanging at scale {scale}")
        rows, cfg = run("hanging", sweep_overrides(scale), p["sweep_frames"], f"scale {scale}")
        sweep.append(sweep_row(scale, rows, cfg))
    wc = []
    for method in p["wc_methods"]:
        for variant in p["wc_variants"]:
            log(f"part 3: hanging, {method}, {variant}")
            _, overrides, cold = WARM_COLD_VARIANTS[variant]
            with cold_reprojection(cold):
                rows, _ = run("hanging", combine(WARM_COLD, overrides,
                                                 {"strain": {"method": method}}),
                              p["wc_frames"], f"{method}, {variant}")
            wc.append([method] + warm_cold_row(variant, rows))
    return part1, sweep, wc


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer frames and sizes")
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "remesh", "remesh_ops.md"))
    args = ap.parse_args(argv)
    p = QUICK if args.quick else FULL
    from cloth import backend
    backend.init("cpu", "f64")
    t0, where = time.perf_counter(), (harness.commit(), machine())
    part1, sweep, wc = measure(p)
    argv = sys.argv[1:] if argv is None else argv
    cmd = " ".join(["python -m benchmarks.remesh_ops", *argv])
    write_doc(args.out, cmd, time.perf_counter() - t0, where, p, part1, sweep, wc)
    log(f"wrote {args.out} in {time.perf_counter() - t0:.0f} s")
    return args.out


if __name__ == "__main__":
    main()
