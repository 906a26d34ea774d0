"""Is the AL solver's Newton model the Hessian of L_A? (issue #13's diagnosis)

    python -m benchmarks.newton_model                      # hanging res 9, svd, frame 128
    python -m benchmarks.newton_model --margin 1e-9        # the same without the near margin

Runs the hanging cloth to rest with the Cholesky path, then compares the assembled Newton matrix
H (``strain/direct.py newton_system``) with forward finite differences of the residual
r = -grad L_A along a random direction and along the Newton step H^-1 r. Measured (2026-12-02):
with the default ``active_margin`` 1e-2 the model is 2x too stiff along a random direction and
~90x too stiff along the Newton step (d.Hd 20.6 vs 0.23), so exact Newton steps are ~90x too
short and the inner loop stagnates (|r| 9.3e-6 over five steps); with the margin off, H matches
the finite differences to 0.2 %. warp-weft without the margin: exact too (0.4 %). mapping is
different: without the margin its model is ~16x too soft along the Newton step (d.Hd 0.083 vs
1.33; the inverse-mapping constraints' curvature is only partly modelled), with it ~1.7x too
soft along the step and 2.5x too stiff along a random direction.
"""
import argparse

import numpy as np


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=9)
    ap.add_argument("--method", default="svd")
    ap.add_argument("--frames", type=int, default=128)
    ap.add_argument("--margin", type=float, default=None,
                    help="active_margin to check the model with (default: the solver's)")
    a = ap.parse_args()
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla
    from cloth import backend
    backend.init("cpu", "f64")
    import scenes
    from scenes.common import resolve
    from cloth.simulator import Simulator
    from cloth.strain import direct
    from cloth.strain.solver import METHOD_IDS, N_CONSTRAINTS

    mod = scenes.get("hanging")
    cfg = resolve(mod.DEFAULTS, [{"cloth": {"resolution": a.resolution},
                                  "strain": {"method": a.method, "linear_solver": "cholesky"}}])
    sim = Simulator(mod.build(cfg), cfg)
    for _ in range(a.frames):
        sim.step_frame()
    lim, m = sim.strain, sim.model
    ws = lim._ws
    if a.margin is not None:
        lim.active_margin = a.margin
        lim._upload_params()
    metric, _chol = lim._direct_metric(True)
    mid, K = METHOD_IDS[a.method], N_CONSTRAINTS[a.method]
    nv, nf, ns = m.n_verts, m.n_faces, len(lim._stitches)
    mu = lim.mu_scale * lim._mean_mass(metric)

    def residual_and_model(x):
        full = ws.x.to_numpy()
        full[:nv] = x
        ws.x.from_numpy(full)
        lim._assemble(mid, ws.x)
        direct.fill_newton_system(lim, mid, K, mu, metric)
        v = ws.H.to_numpy()[:metric.nnz]
        H = sp.bsr_matrix((v, metric.col_np, metric.ptr_np), shape=(3 * nv, 3 * nv)).tocsr()
        return ws.r.to_numpy()[:nv].reshape(-1), H

    x0 = ws.x.to_numpy()[:nv].copy()
    r0, H0 = residual_and_model(x0)
    pinned = ws.pinned.to_numpy()[:nv] == 1
    print(f"hanging res {a.resolution} {a.method} frame {a.frames}, margin "
          f"{lim.active_margin:g}, mu {mu:.3g}: |r| {np.linalg.norm(r0):.3e}")
    rng = np.random.default_rng(0)
    for name, d in (("random", rng.standard_normal(3 * nv)),
                    ("Newton step", spla.spsolve(H0.tocsc(), r0))):
        d = d.reshape(nv, 3)
        d[pinned] = 0.0
        d = d.reshape(-1) / np.abs(d).max()
        Hd = H0 @ d
        for eps in (1e-6, 1e-7):
            r1, _ = residual_and_model(x0 + eps * d.reshape(nv, 3))
            fd = -(r1 - r0) / eps                  # r = -grad L_A
            print(f"  {name:11s} eps {eps:g}: d.Hd {d @ Hd:.4e}  d.(FD) {d @ fd:.4e}  "
                  f"|Hd - FD| / |FD| {np.linalg.norm(Hd - fd) / np.linalg.norm(fd):.3f}")
    residual_and_model(x0)


if __name__ == "__main__":
    main()
