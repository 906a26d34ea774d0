"""How many loop iterations each serial kernel phase runs, against lavapipe's cap.

Mesa's llvmpipe (Debian's software Vulkan, lavapipe) runs at most 65535 loop iterations in one
shader invocation, all its loops together, then ends every loop without an error
(cloth/strain/direct.py, ``LOOP_CAP``). Loom's serial kernels are one invocation each, so a
phase that needs more silently leaves work undone. This runs the hanging scene on ``--arch``
with the Cholesky strain path (the one Vulkan runs) up to its first strain Newton step (after
its first dynamics step: the host-loop dynamics kernels, which only Vulkan and Metal run, are
probed there), runs each phase once more in a probe kernel followed by a counting loop of 2^20
iterations, and prints what the phase used: 65535 minus what the counter reached ("no cap"
where the counter got past 65535, e.g. on the CPU). The probes overwrite the solver's work
arrays, so the script stops after printing.

    python -m benchmarks.loop_cap --arch vulkan --resolution 25

Measured on lavapipe (Mesa 22.3.6, hanging, mapping, 2026-12-05), iterations at resolutions
20 / 22 / 25 (400 / 484 / 625 vertices): the one-launch Newton system (``newton_system``)
40790 / 50598 / capped; at 25 its residual part 25710 and its matrix part 40323; the merit
14715, a constraint assembly 1153, the multiplier update 2406; the dynamics' linearise 31115
and a CG iteration 16594.
"""
import argparse
import sys

BIG = 1 << 20
CAP = 65535


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--arch", default="vulkan")
    p.add_argument("--resolution", type=int, default=25)
    args = p.parse_args(argv)

    import os
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    sys.path.insert(0, root)
    import main as loom_main
    from cloth import backend

    init = backend.init

    def init_and_hook(*a, **k):
        init(*a, **k)
        _hook()

    backend.init = init_and_hook
    try:
        loom_main.main(["hanging", "--headless", "--arch", args.arch, "--resolution",
                        str(args.resolution), "--frames", "1", "--no-images", "--quiet",
                        "--set", 'strain.linear_solver="cholesky"',
                        "--out", os.path.join("/tmp", "loom_loop_cap")])
    except _Done:
        pass
    return 0


class _Done(Exception):
    pass


def _report(name, out):
    remaining = int(out.to_numpy()[0])
    used = "no cap" if remaining > CAP else str(CAP - remaining) + \
        ("  (capped: the phase needs more)" if remaining <= 0 else "")
    print(f"  {name:<34} {used}")


def _hook():
    """Define the probe kernels (after backend.init: the strain modules create their Taichi
    types at import) and wrap the solvers' entry points."""
    import taichi as ti

    from cloth import dynamics as D
    from cloth.strain import direct
    from cloth.strain.al import (SVD, assemble_all, fill_c_curvature, merit, metric_gradient,
                                 newton_matrix, residual, update_multipliers)
    from cloth.strain.buffers import (P_CONTACT_SCALE, P_CURVATURE, P_MARGIN, P_SVD_DELTA, A,
                                      ConstraintPack, ContactPack, MeshPack, MetricPack,
                                      VectorPack)

    @ti.func
    def count():
        n = 0
        for _ in range(BIG):
            n += 1
        return n

    @ti.kernel
    def p_rhs(mu: float, mesh: MeshPack, metric: MetricPack, cons: ConstraintPack,
              contacts: ContactPack, vec: VectorPack, out: A):
        ti.loop_config(serialize=True)
        for _ in range(1):
            K, nv, nf, ns = cons.n_per_face, mesh.n_verts, mesh.n_faces, contacts.n_stitches
            metric_gradient(nv, vec.x, metric, vec)
            residual(K, nv, nf, ns, mu, vec.x, mesh, cons, contacts, vec)
            out[0] = count()

    @ti.kernel
    def p_lhs(method: ti.template(), mu: float, mesh: MeshPack, metric: MetricPack,
              cons: ConstraintPack, contacts: ContactPack, vec: VectorPack, out: A):
        ti.loop_config(serialize=True)
        for _ in range(1):
            K, nv, nf, ns = cons.n_per_face, mesh.n_verts, mesh.n_faces, contacts.n_stitches
            exact = mesh.params[P_CURVATURE] > 0.0
            if exact:
                fill_c_curvature(method, K, nf, mu, vec.x, mesh, cons)
            use_twist = mesh.params[P_SVD_DELTA] > 0.0 and ti.static(method == SVD) and \
                not exact
            newton_matrix(K, nv, nf, ns, mu, mesh.params[P_MARGIN],
                          mesh.params[P_CONTACT_SCALE], use_twist, exact, vec.x, mesh, metric,
                          cons, contacts)
            out[0] = count()

    @ti.kernel
    def p_assemble(method: ti.template(), mesh: MeshPack, cons: ConstraintPack,
                   vec: VectorPack, out: A):
        ti.loop_config(serialize=True)
        for _ in range(1):
            assemble_all(method, mesh.n_faces, vec.x, mesh, cons)
            out[0] = count()

    @ti.kernel
    def p_merit(mu: float, mesh: MeshPack, metric: MetricPack, cons: ConstraintPack,
                contacts: ContactPack, vec: VectorPack, out: A):
        ti.loop_config(serialize=True)
        for _ in range(1):
            K, nv, nf, ns = cons.n_per_face, mesh.n_verts, mesh.n_faces, contacts.n_stitches
            out[1] = merit(K, nv, nf, ns, mu, vec.x, vec.x_hat, metric, cons, contacts)
            out[0] = count()

    @ti.kernel
    def p_multipliers(mu: float, mesh: MeshPack, cons: ConstraintPack, contacts: ContactPack,
                      vec: VectorPack, out: A):
        ti.loop_config(serialize=True)
        for _ in range(1):
            K, nv, nf, ns = cons.n_per_face, mesh.n_verts, mesh.n_faces, contacts.n_stitches
            viol, _comp = update_multipliers(K, nv, nf, ns, mu, 1e30,
                                             mesh.params[P_CONTACT_SCALE], vec.x, mesh, cons,
                                             contacts)
            out[1] = viol
            out[0] = count()

    @ti.kernel
    def p_linearise(coef: A, mesh: D.MeshPack, state: D.StatePack, elems: D.ElementPack,
                    cg: D.SolvePack, out: A):
        ti.loop_config(serialize=True)
        for _ in range(1):
            D.linearise(D.constants(coef), mesh, state, elems, cg)
            out[0] = count()

    @ti.kernel
    def p_iteration(rz: float, coef: A, mesh: D.MeshPack, elems: D.ElementPack,
                    cg: D.SolvePack, out: A):
        ti.loop_config(serialize=True)
        for _ in range(1):
            o = D.cg_iteration(rz, D.constants(coef), mesh, elems, cg)
            out[1] = o[0]
            out[0] = count()

    out = ti.ndarray(float, 4)
    dyn = {}

    linearise, iteration = D._linearise, D._iteration

    # (The host-loop launches take the probe count ``two`` first: ImplicitEuler._check_loops.)
    def linearise_probe(two, *a):
        p_linearise(*a, out)
        dyn["linearise"] = int(out.to_numpy()[0])
        return linearise(two, *a)

    def iteration_probe(two, *a):
        if "cg_iteration" not in dyn:
            cg = a[-1]            # the probe's iteration changes the CG's vectors: put back
            vectors = [cg.dv, cg.res, cg.z, cg.p, cg.Ap, cg.precond]
            saved = [arr.to_numpy() for arr in vectors]
            p_iteration(*a, out)
            dyn["cg_iteration"] = int(out.to_numpy()[0])
            for arr, val in zip(vectors, saved):
                arr.from_numpy(val)
        return iteration(two, *a)

    D._linearise, D._iteration = linearise_probe, iteration_probe

    def fill_probe(lim, mid, K, mu, metric):
        m = lim.model
        nv, nf = m.n_verts, m.n_faces
        mesh, met, cons, contacts, vec = direct.packs(lim, metric, K)
        print(f"hanging, resolution {int(round(nv ** 0.5))}: {nv} vertices, {nf} faces, "
              f"{K} constraints a face; loop iterations a launch (cap {CAP}):")
        for name, value in dyn.items():
            print(f"  {'dynamics ' + name:<34} "
                  f"{'no cap' if value > CAP else CAP - value}")
        p_rhs(mu, mesh, met, cons, contacts, vec, out)
        _report("newton_rhs (residual)", out)
        p_lhs(mid, mu, mesh, met, cons, contacts, vec, out)
        _report("newton_lhs (Newton matrix)", out)
        p_merit(mu, mesh, met, cons, contacts, vec, out)
        _report("merit", out)
        p_assemble(mid, mesh, cons, vec, out)
        _report("assemble_all", out)
        p_multipliers(mu, mesh, cons, contacts, vec, out)
        _report("update_multipliers", out)
        raise _Done()

    direct.fill_newton_system = fill_probe


if __name__ == "__main__":
    sys.exit(main())
