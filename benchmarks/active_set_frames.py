"""Frame by frame, how the strain projection converges on a scene from its start: rounds,
Newton steps, linear solves, factorisations, fallbacks and the final violation and stationarity
of the last substep's projection, with the frame's time (docs/speed/motion.md).

    python -m benchmarks.active_set_frames [--scene hanging] [--resolution 25] [--method mapping]
        [--frames 8] [--set KEY=VALUE ...]

Default settings: the active-set Newton model, the kkt stop, exact curvature and Cholesky
solves (``strain.newton_model = "active-set"``); ``--set`` overrides (TOML values, as
``main.py --set``). A fallback (``fb 1``) is a projection that did not converge in its rounds
and was solved again with the margin model.
"""
import argparse
import time

ACTIVE_SET = {"newton_model": "active-set", "stop": "kkt", "linear_solver": "cholesky",
              "curvature": "exact"}


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m benchmarks.active_set_frames",
                                description=__doc__.split("\n")[0])
    p.add_argument("--scene", default="hanging")
    p.add_argument("--resolution", type=int, default=25)
    p.add_argument("--method", default="mapping")
    p.add_argument("--frames", type=int, default=8)
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    a = p.parse_args(argv)
    from cloth import backend
    backend.init("cpu", "f64")
    from benchmarks.harness import configure
    from cloth.config import parse_assignment
    from cloth.simulator import Simulator
    over = {"strain": {"method": a.method, **ACTIVE_SET}}
    if a.resolution:
        over["cloth"] = {"resolution": a.resolution}
    _, cfg, setup = configure(a.scene, [over] + [parse_assignment(s) for s in a.set])
    sim = Simulator(setup, cfg)
    lim = sim.strain
    print(f"{a.scene}, resolution {a.resolution}, {a.method}, {sim.model.n_faces} faces; "
          f"strain {dict(sim.settings.to_dict()['strain'])}")
    fallbacks = 0
    for f in range(a.frames):
        t0 = time.perf_counter()
        sim.step_frame()
        ms = 1e3 * (time.perf_counter() - t0)
        fallbacks += int(bool(getattr(lim, "last_fallback", False)))
        print(f"frame {f + 1:3d} {ms:8.1f} ms  fallback {int(bool(lim.last_fallback))}  "
              f"rounds {lim.last_iterations:3d}  newton {lim.last_newton:4d}  "
              f"solves {lim.last_solves:4d}  factorisations {lim.last_factorizations:4d}  "
              f"violation {lim.last_violation_max:.1e}  stationarity "
              f"{lim.last_stationarity:.1e} m/s", flush=True)
    print(f"fallbacks: {fallbacks} of {a.frames} frames (last substep of each)")


if __name__ == "__main__":
    main()
