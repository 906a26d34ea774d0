"""The constrained step, old and new side by side (issue #13): strain-limiting ms per frame, AL
rounds, Newton steps, converged fraction, and the kinetic energy of a cloth that should hang
still.

    python -m benchmarks.solver --out docs/speed                  # rest + speed, ~25 min
    python -m benchmarks.solver --quick --out /tmp/solver         # a few minutes

Variants (``strain.coupling`` / ``strain.linear_solver``):
  projection/pcg     the paper's split step (eq. 6: project x_hat in the mass metric) with the
                     one-kernel block-Jacobi PCG Newton solver: the solver before #13;
  implicit/pcg       the projection in the implicit step's metric A = (1 + h a) M + h (b + h) K
                     (one linearised backward-Euler step with the limits as constraints);
  implicit/cholesky  the same with exact Newton steps (CHOLMOD, analysis reused per mesh).

Rest: hanging, soft cloth, mapping / svd / warp-weft at +-1 % / +-5 %, one substep per frame,
mean kinetic energy over frames 120-150 (the issue's measure). Speed: hanging at the given
resolutions, frames 2..F (frame 1 compiles), median ms of the strain_limit stage.
Each configuration runs in its own child process (clean kernel caches and timings).
"""
import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

VARIANTS = (("projection", "pcg"), ("implicit", "pcg"), ("implicit", "cholesky"))


def child(res, method, coupling, linear_solver, frames, ke_from):
    from cloth import backend
    backend.init("cpu", "f64")
    import scenes
    from scenes.common import resolve
    from cloth.simulator import Simulator
    from cloth import metrics
    mod = scenes.get("hanging")
    cfg = resolve(mod.DEFAULTS, [{"cloth": {"resolution": res},
                                  "strain": {"method": method, "coupling": coupling,
                                             "linear_solver": linear_solver}}])
    sim = Simulator(mod.build(cfg), cfg)
    ke, ms, rounds, newton, conv, viol = [], [], [], [], [], []
    for _ in range(frames):
        sim.step_frame()
        m = sim.model
        ke.append(metrics.kinetic_energy(m.velocities(), m.mass))
        ms.append(sim.stage("strain_limit").ms)
        rounds.append(sim.strain.last_iterations)
        newton.append(sim.strain.last_newton)
        conv.append(bool(sim.strain.last_converged))
        viol.append(sim.strain.last_violation_max)
    ms, rounds = np.array(ms[1:]), np.array(rounds[1:])
    return dict(res=res, faces=sim.model.n_faces, method=method, coupling=coupling,
                linear_solver=linear_solver, frames=frames,
                ke_mean=float(np.mean(ke[ke_from:])) if ke_from < frames else None,
                ms_median=float(np.median(ms)), ms_p90=float(np.percentile(ms, 90)),
                rounds_median=float(np.median(rounds)), rounds_max=int(rounds.max()),
                newton_median=float(np.median(newton[1:])),
                converged=float(np.mean(conv[1:])), viol_max=float(max(viol[1:])))


def run_child(*args):
    cmd = [sys.executable, "-m", "benchmarks.solver", "--child", json.dumps(args)]
    out = subprocess.run(cmd, capture_output=True, text=True,
                         cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    if out.returncode != 0:
        return {"error": out.stderr.strip().splitlines()[-1] if out.stderr.strip() else "?",
                "args": args}
    return json.loads(out.stdout.strip().splitlines()[-1])


def table(rows, keys, heads):
    lines = ["| " + " | ".join(heads) + " |", "|" + "---|" * len(heads)]
    for r in rows:
        cells = []
        for k in keys:
            v = r.get(k)
            cells.append(f"{v:.3g}" if isinstance(v, float) else str(v))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--child")
    ap.add_argument("--out", default="docs/speed")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--resolutions", type=int, nargs="+", default=[25, 46])
    ap.add_argument("--speed-frames", type=int, default=20)
    args = ap.parse_args()
    if args.child:
        print(json.dumps(child(*json.loads(args.child))))
        return
    os.makedirs(args.out, exist_ok=True)
    t0 = time.time()
    rest_frames = 40 if args.quick else 150
    rest_from = 30 if args.quick else 120
    rest, speed = [], []
    methods = ("mapping",) if args.quick else ("mapping", "svd", "warp-weft")
    jobs = [("rest", (9, m, c, s, rest_frames, rest_from)) for m in methods
            for c, s in VARIANTS[:2]]
    res_list = args.resolutions[:1] if args.quick else args.resolutions
    jobs += [("speed", (r, "mapping", c, s, args.speed_frames, args.speed_frames))
             for r in res_list for c, s in VARIANTS]
    for i, (kind, a) in enumerate(jobs):
        print(f"[{i + 1}/{len(jobs)}] {kind} {a} ({time.time() - t0:.0f} s)", file=sys.stderr,
              flush=True)
        (rest if kind == "rest" else speed).append(run_child(*a))
    with open(os.path.join(args.out, "solver.json"), "w") as fh:
        json.dump({"rest": rest, "speed": speed}, fh, indent=1)
    md = ["# The constrained step: split projection vs implicit coupling (issue #13)", "",
          f"`python -m benchmarks.solver{' --quick' if args.quick else ''}`, "
          f"{time.strftime('%Y-%m-%d')}, 2-core CPU, f64, machine shared with other jobs "
          "(timings are indicative; compare within a table).", "",
          f"## Rest: hanging resolution 9, mean kinetic energy over frames {rest_from}-"
          f"{rest_frames} (J)", "",
          table(rest, ["method", "coupling", "linear_solver", "ke_mean", "ms_median",
                       "rounds_median", "newton_median", "converged"],
                ["method", "coupling", "Newton solve", "KE (J)", "SL ms/frame",
                 "AL rounds", "Newton steps", "converged"]), "",
          f"## Speed: hanging, mapping, frames 2-{args.speed_frames}", "",
          table(speed, ["faces", "coupling", "linear_solver", "ms_median", "ms_p90",
                        "rounds_median", "rounds_max", "newton_median", "converged",
                        "viol_max"],
                ["faces", "coupling", "Newton solve", "SL ms median", "p90", "rounds",
                 "max", "Newton", "converged", "max viol"]), ""]
    with open(os.path.join(args.out, "solver.md"), "w") as fh:
        fh.write("\n".join(md))
    print("\n".join(md))


if __name__ == "__main__":
    main()
