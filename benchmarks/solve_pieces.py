"""Where a Newton step of the one-kernel strain solve spends its time, piece by piece, per mesh
size (issue #13: what keeps the cost above N^1).

    python -m benchmarks.solve_pieces --resolutions 33 181 [--method mapping] [--frames 6]

Runs ``hanging`` for F frames, captures the arguments of the last ``al.solve_al`` launch, and
times each piece of the solve on that state in a kernel of its own, serially like the solve
(``reps`` repetitions in one launch, minus an empty launch). The pieces, and how often a
Newton step runs each (solve_al):
  assemble values   the constraint values at a line-search trial (``assemble_values``; once
                    per trial);
  assemble all      values, gradients and curvature data at the point reached (once);
  merit terms       the merit's constraint terms (``merit_constraints``; once per trial);
  W product         a product with the metric W (``metric_along``'s W d; once);
  residual          -grad L_A from W (x - x_hat) (once);
  Newton matrix     H written out in W's block pattern (once);
  H product         one PCG iteration's product with H (max_cg times);
  precondition      one application of the preconditioner the solve used (max_cg + 1 times).
Prints a Markdown table: ms per piece and ns per face. Timings on a shared 2-core machine
carry tens of percent of noise; compare sizes within one run.
"""
import argparse
import functools
import inspect
import time

PIECES = ("assemble values", "assemble all", "merit terms", "W product", "residual",
          "Newton matrix", "H product", "precondition")


def capture(resolution, method, frames):
    """(simulator, {argument name: value}) of the last solve_al launch after ``frames``
    frames of hanging."""
    import scenes
    from cloth.simulator import Simulator
    from cloth.strain import al
    from scenes.common import resolve
    module = scenes.get("hanging")
    cfg = resolve(module.DEFAULTS, [{"cloth": {"resolution": resolution},
                                     "strain": {"method": method}}])
    sim = Simulator(module.build(cfg), cfg)
    names = list(inspect.signature(al.solve_al).parameters)
    last = {}
    original = al.solve_al

    def recording(*args):
        last["args"] = dict(zip(names, args))
        original(*args)
    al.solve_al = recording
    try:
        for _ in range(frames):
            sim.step_frame()
    finally:
        al.solve_al = original
    return sim, last["args"]


def time_pieces(a):
    """ms per piece (PIECES order) on the captured arguments ``a``."""
    import taichi as ti
    from cloth.strain.buffers import B_MU0, B_PC_MODE
    piece = piece_kernel()
    budget = a["budget"]
    order = ("mesh", "metric", "cons", "contacts", "vec", "pc")
    args = [a["method"], float(budget[B_MU0]), int(budget[B_PC_MODE])] + [a[k] for k in order]
    out = []
    reps = max(3, int(50 * 2000 / a["mesh"].n_faces))
    for which in range(len(PIECES)):
        piece(which, 1, *args)          # compile, warm the caches
        ti.sync()
        t = time.perf_counter()
        piece(which, reps, *args)
        ti.sync()
        full = time.perf_counter() - t
        t = time.perf_counter()
        piece(which, 0, *args)
        ti.sync()
        empty = time.perf_counter() - t
        out.append(1e3 * max(full - empty, 0.0) / reps)
    return out


@functools.lru_cache(maxsize=None)
def piece_kernel():
    """The timing kernel: one piece of ``al.solve_al``, ``reps`` times, on the solve's own
    arrays. Made on first call (after ``backend.init``: the strain modules create Taichi
    types at import, and the benchmarks must import none), then reused, so each size does not
    compile it again."""
    import taichi as ti

    from cloth.strain import al
    from cloth.strain.buffers import (P_CONTACT_SCALE, P_CURVATURE, P_MARGIN, P_SVD_DELTA,
                                      ConstraintPack, ContactPack, MeshPack, MetricPack,
                                      PrecondPack, VectorPack)

    @ti.kernel
    def piece(which: int, reps: int, method: ti.template(), mu: float, pc_mode: int,
              mesh: MeshPack, metric: MetricPack, cons: ConstraintPack, contacts: ContactPack,
              vec: VectorPack, pc: PrecondPack) -> float:
        ti.loop_config(serialize=True)
        acc = 0.0
        for _ in range(1):
            K, nv, nf, ns = cons.n_per_face, mesh.n_verts, mesh.n_faces, contacts.n_stitches
            use_twist = mesh.params[P_SVD_DELTA] > 0.0 and ti.static(method == al.SVD) and \
                mesh.params[P_CURVATURE] == 0.0
            margin, c_scale = mesh.params[P_MARGIN], mesh.params[P_CONTACT_SCALE]
            for n in range(nv):
                vec.d[n] = vec.p[n]                          # a direction to multiply with
            for _rep in range(reps):
                if which == 0:
                    al.assemble_values(method, nf, vec.x, mesh, cons)
                elif which == 1:
                    al.assemble_all(method, nf, vec.x, mesh, cons)
                elif which == 2:
                    acc += al.merit_constraints(K, nv, nf, ns, mu, vec.x, cons, contacts)
                elif which == 3:
                    acc += al.metric_along(nv, vec.x, metric, vec)[2]
                elif which == 4:
                    al.residual(K, nv, nf, ns, mu, vec.x, mesh, cons, contacts, vec)
                elif which == 5:
                    al.newton_matrix(K, nv, nf, ns, mu, margin, c_scale, use_twist, False,
                                     vec.x, mesh, metric, cons, contacts)
                elif which == 6:
                    for n in range(nv):
                        vec.Ap[n] = al.metric_times(n, metric.w_ptr, metric.w_col, metric.H,
                                                    vec.p)
                else:
                    acc += al.precondition(pc_mode, nv, pc, vec.r, vec.z)
        return acc

    return piece


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolutions", type=int, nargs="+", default=[33, 91, 181])
    ap.add_argument("--method", default="mapping")
    ap.add_argument("--frames", type=int, default=6)
    args = ap.parse_args()
    from cloth import backend
    backend.init("cpu", "f64")
    rows = []
    for res in args.resolutions:
        sim, captured = capture(res, args.method, args.frames)
        ms = time_pieces(captured)
        rows.append((sim.model.n_faces, ms))
        print(f"resolution {res}: {sim.model.n_faces} faces, "
              + ", ".join(f"{p} {t:.3f} ms" for p, t in zip(PIECES, ms)), flush=True)
    print()
    print("| faces | " + " | ".join(PIECES) + " |")
    print("|---" * (len(PIECES) + 1) + "|")
    for faces, ms in rows:
        cells = [f"{t:.3g} ms ({1e6 * t / faces:.0f} ns/face)" for t in ms]
        print(f"| {faces} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
