"""How far one substep's strain projection lands from the exact projection (issue #13).

The AL stops when every constraint is within ``strain.tol`` (1e-4 strain). That bounds the
violation, not the distance to the metric-nearest feasible point, which is what the projection
is meant to return. This benchmark runs ``hanging`` for some frames, keeps the state (positions,
velocities, multipliers), and from that same state projects once with each solver setting, then
once more with an "exact" setting (tol 1e-8, tight inner solves) as the reference.

    python -m benchmarks.projection_error [--resolution 9] [--frames 10] [--methods svd mapping]

Prints a Markdown table: per method and setting, the largest vertex distance to the exact
projection (m), the violation, AL rounds, Newton steps and the one projection's time (rough: a
single call on a shared machine; a setting's first call may include a compile, so each
setting is timed on its second call from the same state).
"""
import argparse

import numpy as np

from benchmarks.harness import commit, configure, machine
from cloth.strain.families import METHODS

# The reference: the active-set Newton model (the merit's Hessian, exact solves) stopped on a
# tight tolerance of both violation and stationarity. (The margin model's tight solves do not
# converge: two of them, tol 1e-8 and 1e-9, differed by 1.2 mm; docs/speed/motion.md.)
EXACT = dict(newton_model="active-set", linear_solver="cholesky", stop="kkt", tol=1e-8,
             kkt_velocity=1e-6, max_newton=30, curvature="exact", inner_rtol=0.0)
# The active-set model as a user would switch it on (strain.newton_model, strain.stop; mapping
# converges with its exact curvature).
ACTIVE_SET = dict(newton_model="active-set", stop="kkt", curvature="exact")
SETTINGS = {
    "default": {},
    "active-set, kkt stop, exact curvature": ACTIVE_SET,
    "active-set, kkt 1 mm/s": dict(ACTIVE_SET, kkt_velocity=1e-3),
    "active-set, tol 1e-5": dict(ACTIVE_SET, tol=1e-5),
    "exact steps (cholesky)": dict(linear_solver="cholesky"),
    "inner_rtol 0 (every round runs max_newton steps)": dict(inner_rtol=0.0),
    "cg_rtol 0.01": dict(cg_rtol=0.01),
    "max_newton 10": dict(max_newton=10),
    "max_newton 10, inner_rtol 0": dict(max_newton=10, inner_rtol=0.0),
    "tight inner (max_newton 30, cg_rtol 1e-6, inner_rtol 0)": dict(max_newton=30, cg_rtol=1e-6,
                                                                   max_cg=400, inner_rtol=0.0),
}
KEYS = ("max_newton", "cg_rtol", "max_cg", "tol", "inner_rtol", "linear_solver", "stop",
        "kkt_velocity", "curvature", "newton_model")


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

    def substep():
        """From the saved state (positions, velocities, multipliers): the unconstrained
        step, then the projection."""
        sim.model.set_positions(x)
        sim.model.set_velocities(v)
        lim.set_face_state(faces)           # the multipliers (same faces: scale 1)
        sim._update_pins(sim.time + sim.h)
        sim.dynamics.step(sim.h)
        sim.dynamics.system_matrix(sim.h, lim.system_metric())
        lim.project(sim.h)

    for name, over in [("exact", EXACT)] + list(SETTINGS.items()):
        for k, val in {**base, **over}.items():
            if k == "newton_model":
                lim.set_newton_model(val)   # the penalty follows the model
            else:
                setattr(lim, k, val)
        lim._upload_params()                # inner_rtol, margin, curvature: the kernels' params
        substep()
        if name != "exact":
            substep()                       # timed without the first call's compile
        elif not lim.last_converged or lim.last_fallback:
            raise SystemExit(f"{method}: the reference did not converge ({lim.last_iterations} "
                             f"rounds, fallback {lim.last_fallback}): no distance to measure")
        results[name] = (sim.model.positions(), lim.last_violation_max, lim.last_iterations,
                         lim.last_newton, lim.last_ms)
    exact = results.pop("exact")[0]
    edge = sim.model.typical_edge()
    return [(name, float(np.abs(xs - exact).max()), edge, viol, rounds, newton, ms)
            for name, (xs, viol, rounds, newton, ms) in results.items()]


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
          "Newton steps | ms (one solve) |")
    print("|---|---|---|---|---|---|---|---|")
    for method in args.methods:
        for name, dist, edge, viol, rounds, newton, ms in measure(method, args.resolution,
                                                                  args.frames):
            print(f"| {method} | {name} | {1e3 * dist:.3f} | {100 * dist / edge:.2f} % | "
                  f"{viol:.1e} | {rounds} | {newton} | {ms:.0f} |", flush=True)


if __name__ == "__main__":
    main()
