"""How far one substep's strain projection lands from the exact projection (issue #13).

The AL stops when every constraint is within ``strain.tol`` (1e-4 strain). That bounds the
violation, not the distance to the metric-nearest feasible point, which is what the projection
is meant to return. This benchmark runs a scene (``hanging`` unless told) for some frames,
keeps its state (positions, velocities, multipliers, the last projection's velocities), and
from that same state runs the next substep through its projection once with each solver
setting, and once with an "exact" setting (tol 1e-8, tight inner solves) as the reference.

    python -m benchmarks.projection_error [--scene hanging] [--resolution 9] [--frames 10]
                                          [--methods svd mapping]

Any scene: drape's contacts and tshirt's seams are constraints of the same projection. Prints
a Markdown table: per method and setting, the largest and the RMS vertex distance to the
exact projection, how far its objective (x - x_hat)^T W (x - x_hat) / 2 lies above the exact
one's, the violation, AL rounds, Newton steps and the one projection's time (rough: a
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
    # The default's own stop on stationarity (the Newton step at the answer), old rule beside new.
    "kkt stop": dict(stop="kkt"),
    "active-set, kkt stop, exact curvature": ACTIVE_SET,
    "active-set, kkt 1 mm/s": dict(ACTIVE_SET, kkt_velocity=1e-3),
    "active-set, tol 1e-5": dict(ACTIVE_SET, tol=1e-5),
    # The host loop's active-set step (sparse Cholesky): where the kernels' PCG step falls back
    # (tshirt's seams: block Jacobi does not see the stitch couplings).
    "active-set, exact steps": dict(ACTIVE_SET, linear_solver="cholesky"),
    "exact steps (cholesky)": dict(linear_solver="cholesky"),
    "exact steps, kkt stop": dict(linear_solver="cholesky", stop="kkt"),
    "inner_rtol 0 (every round runs max_newton steps)": dict(inner_rtol=0.0),
    "cg_rtol 0.01": dict(cg_rtol=0.01),
    "max_newton 10": dict(max_newton=10),
    "max_newton 10, inner_rtol 0": dict(max_newton=10, inner_rtol=0.0),
    "tight inner (max_newton 30, cg_rtol 1e-6, inner_rtol 0)": dict(max_newton=30, cg_rtol=1e-6,
                                                                   max_cg=400, inner_rtol=0.0),
}
KEYS = ("max_newton", "cg_rtol", "max_cg", "tol", "inner_rtol", "linear_solver", "stop",
        "kkt_velocity", "curvature", "newton_model")


def objective(x, x_hat, W):
    """The projection's objective (x - x_hat)^T W (x - x_hat) / 2: the exact projection is the
    feasible point where it is least, so its excess is motion a solve takes out needlessly."""
    e = (np.asarray(x) - np.asarray(x_hat)).ravel()
    return 0.5 * e @ (W @ e)


def measure(scene, method, resolution, frames):
    from cloth.simulator import Simulator
    over = {"strain": {"method": method}}
    if resolution:
        over["cloth"] = {"resolution": resolution}
    _, cfg, setup = configure(scene, over)
    sim = Simulator(setup, cfg)
    for _ in range(frames):
        sim.step_frame()
    lim = sim.strain
    state = sim.substep_state()     # positions, velocities, multipliers, last velocities
    base = {k: getattr(lim, k) for k in KEYS}
    results = {}

    def substep():
        """From the saved state: the substep's stages through the projection (pins, the
        implicit step, the obstacle passes, the projection with the contacts and seams)."""
        sim.set_substep_state(state)
        x_hat = sim.run_substep_through("strain_limit")
        return x_hat, sim.strain.system_metric().to_scipy()

    for name, over in [("exact", EXACT)] + list(SETTINGS.items()):
        for k, val in {**base, **over}.items():
            if k == "newton_model":
                lim.set_newton_model(val)   # the penalty follows the model
            else:
                setattr(lim, k, val)
        lim._upload_params()                # inner_rtol, margin, curvature: the kernels' params
        x_hat, W = substep()
        if name != "exact":
            x_hat, W = substep()            # timed without the first call's compile
        elif not lim.last_converged or lim.last_fallback:
            raise SystemExit(f"{method}: the reference did not converge ({lim.last_iterations} "
                             f"rounds, fallback {lim.last_fallback}): no distance to measure")
        x = sim.model.positions()
        results[name] = (x, objective(x, x_hat, W), lim.last_violation_max, lim.last_iterations,
                         lim.last_newton, lim.last_ms)
    exact, f_exact = results.pop("exact")[:2]
    edge = sim.model.typical_edge()
    return [(name, float(np.abs(xs - exact).max()),
             float(np.sqrt(np.mean(np.sum((xs - exact) ** 2, axis=1)))), f / f_exact - 1.0,
             edge, viol, rounds, newton, ms)
            for name, (xs, f, viol, rounds, newton, ms) in results.items()]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default="hanging", choices=("hanging", "drape", "pull", "tshirt"))
    ap.add_argument("--resolution", type=int, default=None,
                    help="the sheet's resolution (default 9; tshirt has its own mesh)")
    ap.add_argument("--frames", type=int, default=10, help="frames before the measured substep")
    ap.add_argument("--methods", nargs="+", default=None, choices=METHODS,
                    help="default: all three (tshirt: its own, mapping)")
    args = ap.parse_args(argv)
    resolution = None if args.scene == "tshirt" else (args.resolution or 9)
    methods = args.methods or (["mapping"] if args.scene == "tshirt" else list(METHODS))
    from cloth import backend
    backend.init("cpu", "f64")
    size = f"resolution {resolution}" if resolution else "its own mesh"
    print(f"{args.scene}, {size}, the projection of the first substep after frame "
          f"{args.frames}; commit {commit()}; {machine()}\n")
    print("| method | setting | distance to exact (mm) | of an edge | RMS (mm) | objective "
          "above exact | violation | rounds | Newton steps | ms (one solve) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for method in methods:
        for name, dist, rms, gap, edge, viol, rounds, newton, ms in measure(
                args.scene, method, resolution, args.frames):
            print(f"| {method} | {name} | {1e3 * dist:.3f} | {100 * dist / edge:.2f} % | "
                  f"{1e3 * rms:.3f} | {100 * gap:.2g} % | {viol:.1e} | {rounds} | {newton} | "
                  f"{ms:.0f} |", flush=True)


if __name__ == "__main__":
    main()
