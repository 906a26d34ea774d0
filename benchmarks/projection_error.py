"""How far one substep's strain projection lands from the exact projection (issue #13).

The AL stops when every constraint is within ``strain.tol`` (1e-4 strain). That bounds the
violation, not the distance to the metric-nearest feasible point, which is what the projection
is meant to return. This benchmark runs ``hanging`` for some frames, keeps the state (positions,
velocities, multipliers), and from that same state projects once with each solver setting, then
once more with an "exact" setting (tol 1e-8, tight inner solves) as the reference.

    python -m benchmarks.projection_error [--resolution 9] [--frames 10] [--methods svd mapping]

Prints a Markdown table: per method and setting, the largest vertex distance to the exact
projection (m), the violation, AL rounds and Newton steps. Times are left out: one projection
per setting is too short to time on a shared machine (the first call also compiles).
"""
import argparse

import numpy as np

from benchmarks.harness import commit, configure, machine
from cloth.strain.families import METHODS

EXACT = dict(max_newton=40, cg_rtol=1e-9, max_cg=2000, tol=1e-8, inner_rtol=0.0)
SETTINGS = {
    "default": {},
    "inner_rtol 0 (every round runs max_newton steps)": dict(inner_rtol=0.0),
    "cg_rtol 0.01": dict(cg_rtol=0.01),
    "max_newton 10": dict(max_newton=10),
    "max_newton 10, inner_rtol 0": dict(max_newton=10, inner_rtol=0.0),
    "tight inner (max_newton 30, cg_rtol 1e-6, inner_rtol 0)": dict(max_newton=30, cg_rtol=1e-6,
                                                                   max_cg=400, inner_rtol=0.0),
}
KEYS = ("max_newton", "cg_rtol", "max_cg", "tol", "inner_rtol")


def measure(method, resolution, frames):
    from cloth.simulator import Simulator
    _, cfg, setup = configure("hanging", {"cloth": {"resolution": resolution},
                                          "strain": {"method": method}})
    sim = Simulator(setup, cfg)
    for _ in range(frames):
        sim.step_frame()
    lim = sim.strain
    x, v, faces = sim.model.positions(), sim.model.velocities(), lim.face_state()
    base = {k: getattr(lim, k) for k in KEYS}
    results = {}
    for name, over in [("exact", EXACT)] + list(SETTINGS.items()):
        for k, val in {**base, **over}.items():
            setattr(lim, k, val)
        lim._upload_params()                # inner_rtol lives in the kernels' params
        sim.model.set_positions(x)
        sim.model.set_velocities(v)
        lim.set_face_state(faces)           # the multipliers (same faces: scale 1)
        sim._update_pins(sim.time + sim.h)
        sim.dynamics.step(sim.h)
        sim.dynamics.system_matrix(sim.h, lim.system_metric())
        lim.project(sim.h)
        results[name] = (sim.model.positions(), lim.last_violation_max, lim.last_iterations,
                         lim.last_newton)
    exact = results.pop("exact")[0]
    edge = sim.model.typical_edge()
    return [(name, float(np.abs(xs - exact).max()), edge, viol, rounds, newton)
            for name, (xs, viol, rounds, newton) in results.items()]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--resolution", type=int, default=9)
    ap.add_argument("--frames", type=int, default=10, help="frames before the measured substep")
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    args = ap.parse_args(argv)
    from cloth import backend
    backend.init("cpu", "f64")
    print(f"hanging, resolution {args.resolution}, the projection of substep "
          f"{args.frames + 1}; commit {commit()}; {machine()}\n")
    print("| method | setting | distance to exact (mm) | of an edge | violation | rounds | "
          "Newton steps |")
    print("|---|---|---|---|---|---|---|")
    for method in args.methods:
        for name, dist, edge, viol, rounds, newton in measure(method, args.resolution,
                                                              args.frames):
            print(f"| {method} | {name} | {1e3 * dist:.2f} | {100 * dist / edge:.1f} % | "
                  f"{viol:.1e} | {rounds} | {newton} |")


if __name__ == "__main__":
    main()
