"""How far the default constrained step's trajectory lands from a tightly solved one (issue
#13), before the hanging sheet buckles (frame 3, see benchmarks/speed_vs_error.py).

    python -m benchmarks.trajectory_error [--resolution 25] [--method mapping] [--max-cg 15 50]

Runs ``hanging`` (coupling implicit, one substep per frame) for 3 frames with two tight
references (A: max_cg 1000, cg_rtol 1e-4, max_newton 20, tol 1e-6; B: 2000, 1e-5, 40, 1e-7)
and with each PCG budget. Prints the RMS vertex distance at frame 3 over the cloth's diagonal:
B against A (how settled the reference is) and each run against B, with its strain-limiting ms.
"""
import argparse

import numpy as np

REFERENCES = (dict(max_cg=1000, cg_rtol=1e-4, max_newton=20, tol=1e-6),
              dict(max_cg=2000, cg_rtol=1e-5, max_newton=40, tol=1e-7))


def run(resolution, method, settings, frames=3):
    from benchmarks.harness import configure
    from cloth.simulator import Simulator
    _, cfg, setup = configure("hanging", {"cloth": {"resolution": resolution},
                                          "strain": {"method": method}})
    sim = Simulator(setup, cfg)
    for key, value in settings.items():
        setattr(sim.strain, key, value)
    sim.strain._upload_params()
    ms = []
    for _ in range(frames):
        sim.step_frame()
        ms.append(sim.stage("strain_limit").ms)
    diagonal = float(np.linalg.norm(np.ptp(sim.model.uv, axis=0)))
    return sim.model.positions(), float(np.median(ms[1:])), diagonal


def rms(a, b, diagonal):
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))) / diagonal)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=25)
    ap.add_argument("--method", default="mapping")
    ap.add_argument("--max-cg", type=int, nargs="+", default=[15, 50])
    args = ap.parse_args()
    from cloth import backend
    backend.init("cpu", "f64")
    ref_a, _, diagonal = run(args.resolution, args.method, REFERENCES[0])
    ref_b, _, _ = run(args.resolution, args.method, REFERENCES[1])
    print(f"hanging res {args.resolution}, {args.method}, frame 3, RMS distance / diagonal")
    print(f"reference B against A: {rms(ref_b, ref_a, diagonal):.2e}")
    for budget in args.max_cg:
        x, ms, _ = run(args.resolution, args.method, {"max_cg": budget})
        print(f"max_cg {budget}: {rms(x, ref_b, diagonal):.2e} against B "
              f"(strain limiting {ms:.1f} ms, median of frames 2-3)", flush=True)


if __name__ == "__main__":
    main()
