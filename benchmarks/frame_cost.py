"""ms per frame of a scene at several resolutions, split by stage, and the start-up time.

    python -m benchmarks.frame_cost --scene hanging --resolutions 23 45 90 --frames 30
"""
import argparse
import time


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="hanging")
    ap.add_argument("--resolutions", type=int, nargs="+", default=[23, 45, 90])
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--set", action="append", default=[])
    ap.add_argument("--precision", default="f64")
    args = ap.parse_args()
    t0 = time.perf_counter()
    from cloth import backend
    backend.init("cpu", args.precision)
    import numpy as np
    import scenes
    from cloth.config import parse_assignment
    from cloth.simulator import Simulator
    from scenes.common import resolve
    module = scenes.get(args.scene)
    print(f"| triangles | first frame (s) | ms/frame median | " +
          " | ".join(["stage ms (median)"]) + " |")
    print("|---|---|---|---|")
    for res in args.resolutions:
        cfg = resolve(module.DEFAULTS, [parse_assignment(s) for s in args.set] +
                      [{"cloth": {"resolution": res}}])
        sim = Simulator(module.build(cfg), cfg)
        t1 = time.perf_counter()
        sim.step_frame()
        first = time.perf_counter() - t1
        per_stage = {s.name: [] for s in sim.stages}
        totals = []
        for _ in range(args.frames):
            t1 = time.perf_counter()
            sim.step_frame()
            totals.append(1000 * (time.perf_counter() - t1))
            for s in sim.stages:
                per_stage[s.name].append(s.ms)
        stages = ", ".join(f"{k} {np.median(v):.1f}" for k, v in per_stage.items() if np.max(v) > 0)
        print(f"| {sim.model.n_faces} | {first:.2f} | {np.median(totals):.1f} | {stages} |")
    print(f"\nprocess start to end: {time.perf_counter() - t0:.1f} s ({args.precision}, cpu)")


if __name__ == "__main__":
    main()
