"""ms per CG iteration of ``ImplicitEuler.step`` on one sheet against the parallel CG
experiment (benchmarks/dynamics_parallel.py, docs/speed/parallel.md), at this process's
thread count (TI_CPU_MAX_NUM_THREADS). As parallel.md measured the first attempt: an n x n
sheet (as tests/helpers.sheet_model makes it; k_warp 200, k_weft 150, k_shear 5, k_bend 1e-5,
pinned at two corners), 3 steps, then the best of ``--repeats`` steps, each from the same
positions, velocities and warm start; optimised kernels unless LOOM_FAST_COMPILE says.

    TI_CPU_MAX_NUM_THREADS=2 python benchmarks/parallel_cg_step.py --n 91
"""
import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, nargs="+", default=[23, 46, 91])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--bending", default="isotropic")
    args = ap.parse_args()
    os.environ.setdefault("LOOM_FAST_COMPILE", "0")
    from cloth import backend
    backend.init("cpu", "f64")
    import taichi as ti
    from benchmarks.dynamics_parallel import ParallelCG
    from cloth.dynamics import ImplicitEuler
    from cloth.model import ClothModel, Material, MeshArrays
    from cloth.sheet import make_sheet
    threads = ti.lang.impl.current_cfg().cpu_max_num_threads
    for n in args.n:
        for parallel in (False, True):
            uv, faces = make_sheet(1.0, 1.0, n, n, "alternating")
            pinned = np.zeros(len(uv), bool)
            pinned[[0, n - 1]] = True
            m = ClothModel(MeshArrays(uv=uv, x=np.c_[uv, np.zeros(len(uv))], faces=faces,
                                      pinned=pinned),
                           Material(k_warp=200, k_weft=150, k_shear=5, k_bend=1e-5),
                           bending=args.bending)
            dyn = ImplicitEuler(m)
            step = dyn.step
            if parallel:
                cg = ParallelCG(dyn)
                step = lambda h: cg.step(dyn, h)[1]   # noqa: E731
            for _ in range(3):
                step(1 / 30)
            x0, v0, dv0 = m.positions(), m.velocities(), dyn.warm_start()
            best, cpu, its = 1e9, 1e9, 0
            for _ in range(args.repeats):
                m.set_positions(x0)
                m.set_velocities(v0)
                dyn.set_warm_start(dv0)
                t, c = time.perf_counter(), time.process_time()
                its = step(1 / 30)
                best = min(best, time.perf_counter() - t)
                cpu = min(cpu, time.process_time() - c)
            print(f"n {n} ({2 * (n - 1) ** 2} triangles) threads {threads} "
                  f"{'parallel' if parallel else 'serial  '}: {1e3 * best:.2f} ms a step, "
                  f"{its} CG iterations, {1e3 * best / max(its, 1):.3f} ms / iteration "
                  f"(CPU time {1e3 * cpu / max(its, 1):.3f})",
                  flush=True)


if __name__ == "__main__":
    main()
