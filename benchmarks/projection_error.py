"""How far one substep's strain projection lands from the exact projection, per solve setting.

The fast solve stops when every constraint is within ``strain.tol`` (1e-4 strain). That bounds
the violation, not the distance to the metric-nearest feasible point, which is what the
projection is meant to return. This benchmark runs a scene for some frames, keeps its state
(positions, velocities, the strain solve's state), and from that same state runs the next
substep through its projection once with each setting (``SETTINGS``) and once with the
reference (``strain.solve = "exact"`` held to 1e-8 strain).

    python -m benchmarks.projection_error --out docs/speed    # hanging, drape, tshirt (~15 min)
    python -m benchmarks.projection_error --scenes hanging --out /tmp/pe   # ~1 min

Scenes and their state (``SCENES``): hanging at resolution 9 after 10 frames, drape at 13
after 6 (the landing), tshirt after 8 (its seams closing; its own mesh and method). Drape's
contacts and tshirt's seams are constraints of the same projection. The page's table gives,
per method and setting, the largest and the RMS vertex distance to the reference, how far its
objective (x - x_hat)^T W (x - x_hat) / 2 lies above the reference's, the violation, AL rounds,
Newton steps and the one projection's time (rough: a single call on a shared machine; each
setting is timed on its second call from the same state, so without its compile). Each
(scene, method) is a run of a sweep (``benchmarks.sweep``: a local cluster, one worker process
per core, or ``--scheduler tcp://HOST:PORT``; cached in --out/projection_error_runs/, --fresh
runs them again): the ms are of one Taichi thread, beside another run on the other core.
"""
import argparse
import os
import time

import numpy as np

from benchmarks.harness import command, configure, header, write_json
from cloth.strain.families import METHODS

# The reference: the exact solve held to a tight tolerance.
REFERENCE = {"solve": "exact", "tol": 1e-8}
# What a user can choose (strain settings).
SETTINGS = {
    "fast (default)": {"solve": "fast"},
    "exact": {"solve": "exact"},
    "exact, tol 1e-5": {"solve": "exact", "tol": 1e-5},
}
# scene -> (resolution or None for the scene's own mesh, frames before the measured substep,
# methods or None for all three)
SCENES = {"hanging": (9, 10, None), "drape": (13, 6, None), "pull": (9, 10, None),
          "tshirt": (None, 8, ["mapping"])}


def _overrides(method, resolution):
    over = {"strain": {"method": method}}
    if resolution:
        over["cloth"] = {"resolution": resolution}
    return over


def objective(x, x_hat, W):
    """The projection's objective (x - x_hat)^T W (x - x_hat) / 2: the exact projection is the
    feasible point where it is least, so its excess is motion a solve takes out needlessly."""
    e = (np.asarray(x) - np.asarray(x_hat)).ravel()
    return 0.5 * e @ (W @ e)


def measure(scene, method, resolution, frames, reference=None, settings=None):
    """Rows (setting, largest distance, RMS distance, objective's excess, typical edge,
    violation, rounds, Newton steps, ms) of one method on one scene's saved state, for the
    ``settings`` (default ``SETTINGS``) against ``reference`` (default ``REFERENCE``)."""
    reference = REFERENCE if reference is None else reference
    settings = SETTINGS if settings is None else settings
    from cloth.simulator import Simulator
    over = _overrides(method, resolution)
    _, cfg, setup = configure(scene, over)
    base = Simulator(setup, cfg)
    for _ in range(frames):
        base.step_frame()
    state = base.substep_state()     # positions, velocities, the strain solve's state
    results = {}
    for name, strain in [("reference", reference)] + list(settings.items()):
        _, cfg, setup = configure(scene, [over, {"strain": strain}])
        sim = Simulator(setup, cfg)
        sim.time = base.time             # the saved state's clock (scripted pins follow it)

        def substep():
            """From the saved state: the substep's stages through the projection (pins, the
            implicit step, the obstacle passes, the projection with the contacts and seams)."""
            sim.set_substep_state(state)
            x_hat = sim.run_substep_through("strain_limit")
            return x_hat, sim.strain.system_metric().to_scipy()

        x_hat, W = substep()
        lim = sim.strain
        if name == "reference":
            if not lim.last_converged or lim.last_fallback:
                raise RuntimeError(f"{scene} {method}: the reference did not converge "
                                 f"({lim.last_iterations} rounds, fallback "
                                 f"{lim.last_fallback}): no distance to measure")
        else:
            x_hat, W = substep()         # timed without the first call's compile
        x = sim.model.positions()
        results[name] = (x, objective(x, x_hat, W), lim.last_violation_max, lim.last_iterations,
                         lim.last_newton, lim.last_ms)
    exact, f_exact = results.pop("reference")[:2]
    edge = base.model.typical_edge()
    return [(name, float(np.abs(xs - exact).max()),
             float(np.sqrt(np.mean(np.sum((xs - exact) ** 2, axis=1)))), f / f_exact - 1.0,
             edge, viol, rounds, newton, ms)
            for name, (xs, f, viol, rounds, newton, ms) in results.items()]


def run(scene, method, resolution, frames, reference, settings):
    """``measure`` in a sweep's worker: {"rows": its rows}."""
    from cloth import backend
    backend.init("cpu", "f64")
    return {"rows": measure(scene, method, resolution, frames, reference, settings)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="docs/speed", help="folder for projection_error.md/.json")
    ap.add_argument("--scenes", nargs="+", default=["hanging", "drape", "tshirt"],
                    choices=list(SCENES))
    ap.add_argument("--resolution", type=int, default=None,
                    help="the sheets' resolution (default: per scene; tshirt has its own mesh)")
    ap.add_argument("--frames", type=int, default=None,
                    help="frames before the measured substep (default: per scene)")
    ap.add_argument("--methods", nargs="+", default=None, choices=METHODS,
                    help="default: all three (tshirt: its own, mapping)")
    from benchmarks.sweep import Run, add_arguments, failed_lines, run_sweep
    add_arguments(ap)
    args = ap.parse_args(argv)
    cmd = command("benchmarks.projection_error", argv)
    t0 = time.time()
    plan = []
    for scene in args.scenes:
        res, frames, methods = SCENES[scene]
        resolution = None if res is None else (args.resolution or res)
        frames = args.frames or frames
        for method in args.methods or methods or list(METHODS):
            plan.append((scene, method, resolution, frames))
    sweep = [Run("benchmarks.projection_error:run", [*p, REFERENCE, SETTINGS],
                 f"{p[0]} {p[1]}", scene=(p[0], _overrides(p[1], p[2]))) for p in plan]
    results = run_sweep(sweep, os.path.join(args.out, "projection_error_runs"),
                        args.scheduler, args.workers, args.fresh, name="projection_error")
    sections, data = [], []
    for scene in args.scenes:
        mine = [(p, r) for p, r in zip(plan, results) if p[0] == scene]
        resolution, frames = mine[0][0][2], mine[0][0][3]
        size = f"resolution {resolution}" if resolution else "its own mesh"
        L = [f"## {scene}, {size}, the projection of the first substep after frame {frames}",
             "", "| method | setting | distance to exact (mm) | of an edge | RMS (mm) | "
             "objective above exact | violation | rounds | Newton steps | ms (one solve) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
        for (_, method, _, _), r in mine:
            for name, dist, rms, gap, edge, viol, rounds, newton, ms in r.get("rows", []):
                L.append(f"| {method} | {name} | {1e3 * dist:.3f} | {100 * dist / edge:.2f} % | "
                         f"{1e3 * rms:.3f} | {100 * gap:.2g} % | {viol:.1e} | {rounds} | "
                         f"{newton} | {ms:.0f} |")
                data.append(dict(scene=scene, resolution=resolution, frames=frames,
                                 method=method, setting=name, distance_m=dist, rms_m=rms,
                                 objective_excess=gap, edge_m=edge, violation=viol,
                                 rounds=rounds, newton=newton, ms=ms))
                print(L[-1], flush=True)
        sections += L + [""]
    sections += failed_lines(sweep, results)
    seconds = time.time() - t0
    page = ["# One substep's projection against the exact projection", "",
            header(cmd, seconds), "",
            "Each row starts from the same state (positions, velocities and the strain solve's "
            "state, `Simulator.substep_state`) and runs the next substep through its projection "
            "(`Simulator.run_substep_through`): the pins, the implicit step, the obstacle "
            "passes, then the projection with drape's contacts and tshirt's seams as "
            "constraints. The reference is the same projection solved with `strain.solve = "
            "\"exact\"` to 1e-8 strain. Distance: the largest vertex distance to it, and the "
            "RMS over vertices. *Objective above exact*: the projection's objective "
            "(x - x_hat)^T W (x - x_hat) / 2 (W the implicit step's matrix) against the "
            "reference's: the exact projection takes out of the motion the least the limits "
            "allow, so an excess is damping the solve adds (an answer a little outside the "
            "limits can sit a little below it).", ""] + sections
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "projection_error.md"), "w") as fh:
        fh.write("\n".join(page))
    write_json(args.out, "projection_error", {"rows": data}, cmd, seconds)
    print(f"wrote {os.path.join(args.out, 'projection_error.md')}")


if __name__ == "__main__":
    main()
