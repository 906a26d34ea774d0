"""The implicit step's linear solve: matrix-free PCG (dynamics.py) against an assembled Taichi
sparse matrix solved by Eigen's sparse Cholesky (LLT / LDLT) or Taichi's sparse CG
(dynamics_sparse.py), on the hanging scene.

    python -m benchmarks.linear_solver --set material.preset=cotton --resolutions 23 45 90

For each resolution the scene runs ``--warm`` frames (so the sheet is falling and stretching),
then on ``--steps`` consecutive states every solver takes the same step from the same state
(x, v and the matrix-free warm start restored in between). Reported: median ms per step split
into prepare (forces, rhs) / assembly / factorisation / solve, the CG iterations, and the
largest velocity and position difference from a tightly converged matrix-free CG
(cg_tol 1e-10). The sheet then advances with the default matrix-free step. The symbolic analysis
(AMD ordering, once per mesh) is reported separately. Timings on a shared machine are noisy:
medians over the steps.
"""
import argparse
import sys
import time


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolutions", type=int, nargs="+", default=[23, 45, 90])
    ap.add_argument("--warm", type=int, default=8, help="frames before measuring")
    ap.add_argument("--steps", type=int, default=5, help="measured steps")
    ap.add_argument("--solvers", nargs="+", default=["llt", "ldlt", "sparse-cg"])
    ap.add_argument("--ref-tol", type=float, default=1e-10)
    ap.add_argument("--set", action="append", default=[])
    args = ap.parse_args()
    from cloth import backend
    backend.init("cpu", "f64")
    import numpy as np
    import taichi as ti
    import scenes
    from cloth.config import parse_assignment
    from cloth.dynamics import DynamicsSettings, ImplicitEuler
    from cloth.dynamics_sparse import SparseImplicitEuler
    from cloth.simulator import Simulator
    from scenes.common import resolve

    module = scenes.get("hanging")
    rows = []
    for res in args.resolutions:
        # The free sheet (hanging limits strain by default); --set strain.method=... changes it.
        cfg = resolve(module.DEFAULTS, [{"strain": {"method": "none"}}] +
                      [parse_assignment(s) for s in args.set] + [{"cloth": {"resolution": res}}])
        sim = Simulator(module.build(cfg), cfg)
        m, h, mf = sim.model, sim.h, sim.dynamics
        base = mf.settings
        ref = ImplicitEuler(m, DynamicsSettings(gravity=base.gravity, cg_tol=args.ref_tol,
                                                cg_max_iters=100000,
                                                stitch_stiffness=base.stitch_stiffness))
        sparse = {name: SparseImplicitEuler(m, DynamicsSettings(
            gravity=base.gravity, cg_tol=base.cg_tol, cg_max_iters=100000,
            stitch_stiffness=base.stitch_stiffness), linear_solver=name) for name in args.solvers}
        for _ in range(args.warm):
            sim.step_frame()
        rec = {k: [] for k in ["mf", "ref"] + list(args.solvers)}
        analyze = {}

        def timed(dyn, x0, v0, dv0):
            m.set_positions(x0)
            m.set_velocities(v0)
            if dv0 is not None:
                dyn.dv.from_numpy(dv0)
            ti.sync()
            t = time.perf_counter()
            it = dyn.step(h)
            ti.sync()
            return 1e3 * (time.perf_counter() - t), it, m.positions(), m.velocities()

        for k in range(args.steps + 1):          # step 0: compile + symbolic analysis, dropped
            x0, v0, dv0 = m.positions(), m.velocities(), mf.dv.to_numpy()
            ms, it, xr, vr = timed(ref, x0, v0, dv0)
            if k:
                rec["ref"].append(dict(ms=ms, it=it))
            for name, dyn in sparse.items():
                ms, it, xs, vs = timed(dyn, x0, v0, dv0)
                if k == 0:
                    analyze[name] = dyn.last_timings.get("analyze", 0.0)
                else:
                    rec[name].append(dict(ms=ms, it=it, dv=np.abs(vs - vr).max(),
                                          dx=np.abs(xs - xr).max(), **dyn.last_timings))
            ms, it, xs, vs = timed(mf, x0, v0, dv0)  # the sheet advances with this step
            if k:
                rec["mf"].append(dict(ms=ms, it=it, dv=np.abs(vs - vr).max(),
                                      dx=np.abs(xs - xr).max(),
                                      dvmax=np.abs(vr - v0).max()))
        med = lambda name, key: float(np.median([r[key] for r in rec[name]]))  # noqa: E731
        mx = lambda name, key: float(np.max([r[key] for r in rec[name]]))      # noqa: E731
        preset = cfg["material"]["preset"]
        nf = m.n_faces
        rows.append(f"| {preset} | {nf} | matrix-free PCG tol {args.ref_tol:g} | "
                    f"{med('ref', 'ms'):.1f} | - | - | - | - | {med('ref', 'it'):.0f} | 0 (reference) | 0 |")
        rows.append(f"| {preset} | {nf} | matrix-free PCG tol {base.cg_tol:g} | {med('mf', 'ms'):.1f} | - | - "
                    f"| - | - | {med('mf', 'it'):.0f} | {mx('mf', 'dv'):.2e} | {mx('mf', 'dx'):.2e} |")
        for name in args.solvers:
            label = {"llt": "Eigen LLT", "ldlt": "Eigen LDLT",
                     "sparse-cg": f"Taichi SparseCG (Jacobi-scaled) tol {base.cg_tol:g}"}[name]
            rows.append(f"| {preset} | {nf} | {label} (analyze {analyze[name]:.0f} ms once) | "
                        f"{med(name, 'ms'):.1f} | {med(name, 'prepare'):.1f} | "
                        f"{med(name, 'assembly'):.1f} | {med(name, 'factorize'):.1f} | "
                        f"{med(name, 'solve'):.1f} | - | {mx(name, 'dv'):.2e} | {mx(name, 'dx'):.2e} |")
        print(f"# {preset} {nf} faces: |dv| of the step up to {mx('mf', 'dvmax'):.3g} m/s",
              file=sys.stderr, flush=True)
        for r in rows[-2 - len(args.solvers):]:
            print(r, file=sys.stderr, flush=True)
    print("| preset | triangles | solver | ms/step (median) | prepare | assembly | factorize | "
          "solve | CG iters | max abs dv diff (m/s) | max abs x diff (m) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(r)


if __name__ == "__main__":
    main()
