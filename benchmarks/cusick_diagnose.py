"""What decides a Cusick drape (docs/fabrics.md): one run of benchmarks/cusick.py's drape
(start 0, the graded mesh), taken apart.

    python -m benchmarks.cusick_diagnose energy denim --method none --shear-scale 1 4 0.1
    python -m benchmarks.cusick_diagnose frames denim --method warp-weft --seconds 1
    python -m benchmarks.cusick_diagnose energy denim --method warp-weft --settle-speed 0
    python -m benchmarks.cusick_diagnose substep wool-suiting --method warp-weft --h 0.005 \
        --edge-h 0.005 --frame 20

``energy``: per factor on the shear stiffness, the drape's DC and folds and, at its end, the
potential energy gravity lost, the bending energy ((B/2) sum x^T Q x, cloth/bending.py), the
membrane energy along warp, weft and in shear (the St. Venant-Kirchhoff terms of
cloth/dynamics.py), the skirt's shear angle (p95, max) and thread strain (p95 of |E11|,
|E22|), and under a strain-limiting method how many skirt faces have each constraint within
1e-4 of its bound. ``frames``: per frame (the first 12, then every 10th) the projection's
rounds, the largest violation where the dynamics put the cloth (x_hat) and after the
projection, and the RMS speed. ``--settle-speed``: cloth.strain.solver.SETTLE_SPEED for the
run (the speed below which a vertex's projection starts where the substep began; 0: every
vertex starts at x_hat); ``--solve exact``: strain.solve for the run. ``substep``: the drape
run to ``--frame`` (fast solve), then that frame's next substep projected from the same state
(``Simulator.substep_state``) by the fast and by the exact solve, each in the kernels (PCG
Newton steps, the default on a CPU) and in the host loop (Newton steps solved exactly by
sparse Cholesky, ``cloth/strain/direct.py``; the reference): how far the dynamics moved the
free skirt down (x_hat) and how much of that each projection kept, with its rounds and time
(a solve's first projection includes its compile; each is run twice and the second timed).
"""
import argparse
import json

import numpy as np


def energies(x, fabric, h, edge_h, scale):
    """The energy split of a drape's final positions ``x`` (see the module docstring)."""
    from benchmarks import cusick
    from cloth import bending, fabrics, metrics
    from cloth.model import build_edges
    uv, faces = cusick.disk_mesh(h, edge_h=edge_h)
    m = dict(fabrics.derive(fabric)["material"])
    for k in ("k_warp", "k_weft"):
        m[k] *= scale.get("membrane", 1.0)
    m["k_shear"] *= scale.get("shear", 1.0)
    m["k_bend"] *= scale.get("bend", 1.0)
    F = metrics.deformation_gradients(x, faces, metrics.material_Dm_inv(uv, faces))
    fu, fv = F[:, :, 0], F[:, :, 1]                # the grain is the material axes here
    E11 = 0.5 * (np.sum(fu * fu, 1) - 1.0)
    E22 = 0.5 * (np.sum(fv * fv, 1) - 1.0)
    E12 = 0.5 * np.sum(fu * fv, 1)
    A = metrics.material_areas(uv, faces)
    pinned = np.linalg.norm(uv, axis=1) <= cusick.R_SUPPORT + 1e-9
    ev, ef, eo = build_edges(faces)
    Q = bending.isotropic_matrix(uv, faces, ev, ef, eo, A, pinned)
    mass = np.zeros(len(uv))
    np.add.at(mass, faces.ravel(), np.repeat(A / 3.0, 3))
    skirt = np.linalg.norm(uv[faces].mean(axis=1), axis=1) > cusick.R_SUPPORT
    gamma = np.degrees(np.abs(np.arcsin(np.clip(2 * E12[skirt], -1, 1))))
    return dict(gravity=float(m["density"] * 9.81 * np.sum(mass * (cusick.HEIGHT - x[:, 1]))),
                bend=0.5 * m["k_bend"] * sum(float(x[:, c] @ (Q @ x[:, c])) for c in range(3)),
                warp=float(np.sum(A * m["k_warp"] * E11 ** 2 / 2)),
                weft=float(np.sum(A * m["k_weft"] * E22 ** 2 / 2)),
                shear=float(np.sum(A * 2 * m["k_shear"] * E12 ** 2)),
                gamma_p95_deg=float(np.percentile(gamma, 95)), gamma_max_deg=float(gamma.max()),
                thread_p95=float(np.percentile(np.abs(np.r_[E11[skirt], E22[skirt]]), 95)))


def at_bound(x, fabric, h, edge_h, method):
    """Per constraint of ``method``, how many skirt faces are within 1e-4 of its bound."""
    from benchmarks import cusick
    from cloth import fabrics, metrics
    uv, faces = cusick.disk_mesh(h, edge_h=edge_h)
    g = metrics.own_constraint_values(method, x, faces, metrics.material_Dm_inv(uv, faces),
                                      np.tile(np.eye(2), (len(faces), 1, 1)),
                                      fabrics.derive(fabric)["strain"])
    skirt = np.linalg.norm(uv[faces].mean(axis=1), axis=1) > cusick.R_SUPPORT
    return [int(n) for n in (g[skirt] > -1e-4).sum(axis=0)]


def frame_logger(log):
    """A Simulator subclass that logs the projection of each frame (``frames``)."""
    from cloth.simulator import Simulator
    from cloth.strain.buffers import ST_START_VIOL

    class Logged(Simulator):
        def step_frame(self):
            out = super().step_frame()
            if self.frame <= 12 or self.frame % 10 == 0:
                v = self.model.velocities()
                st = self.strain._ws.stats.to_numpy()
                log(f"frame {self.frame}: rounds {self.strain.last_iterations}, violation at "
                    f"x_hat {st[ST_START_VIOL]:.2e}, after {self.strain.last_violation_max:.2e}, "
                    f"RMS speed {1000 * np.sqrt(np.mean(np.sum(v ** 2, 1))):.2f} mm/s")
            return out
    return Logged


class _Reached(Exception):
    """Raised by ``stopping_at``'s simulator at the frame asked for, carrying it."""


def stopping_at(frame):
    """A Simulator subclass that stops the run (``_Reached``, holding the simulator) once
    ``frame`` frames are done (``substep``)."""
    from cloth.simulator import Simulator

    class Stopping(Simulator):
        def step_frame(self):
            out = super().step_frame()
            if self.frame >= frame:
                raise _Reached(self)
            return out
    return Stopping


def substep_report(sim, log):
    """The next substep of ``sim`` projected by the fast and by the exact solve from the same
    state (see the module docstring)."""
    from cloth import metrics
    m, lim = sim.model, sim.strain
    state = sim.substep_state()
    x0 = m.positions()
    free = ~m.pinned
    Dm_inv = metrics.material_Dm_inv(m.uv, m.faces)
    for solve, path in (("fast", "kernels"), ("exact", "kernels"), ("fast", "host loop"),
                        ("exact", "host loop")):
        sim._change("strain", solve=solve)
        lim.set_host_loop(path == "host loop")  # the path Vulkan takes, here on the CPU
        for _ in range(2):                      # the second one timed (compile, factor)
            sim.set_substep_state(state)
            x_hat = sim.run_substep_through("strain_limit")
        x = m.positions()
        g = metrics.own_constraint_values(sim.method, x_hat, m.faces, Dm_inv, m.grain,
                                          sim.bands(), lim.isotropy)
        drop_hat = float(np.mean(x0[free, 1] - x_hat[free, 1]))
        drop = float(np.mean(x0[free, 1] - x[free, 1]))
        log(json.dumps(dict(
            solve=solve, path=path, frame=sim.frame, faces=int(m.n_faces),
            faces_past_bands_at_x_hat=int((g > 0).any(axis=1).sum()),
            largest_violation_at_x_hat=round(float(g.max()), 4),
            mean_drop_x_hat_mm=round(1e3 * drop_hat, 4), mean_drop_kept_mm=round(1e3 * drop, 4),
            share_kept=round(drop / drop_hat, 4), rounds=lim.last_iterations,
            newton=lim.last_newton, cg=lim.last_cg, ms=round(lim.last_ms, 1),
            violation_after=float(f"{lim.last_violation_max:.2e}"))), flush=True)
    lim.set_host_loop(False)
    sim._change("strain", solve="fast")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("what", choices=("energy", "frames", "substep"))
    ap.add_argument("fabric")
    ap.add_argument("--method", default="none")
    ap.add_argument("--h", type=float, default=0.01)
    ap.add_argument("--edge-h", type=float, default=None,
                    help="triangle size at the support's edge (default: half --h, the graded "
                         "mesh; give --h for a uniform one)")
    ap.add_argument("--frame", type=int, default=20, help="substep: the frame to stop at")
    ap.add_argument("--shear-scale", type=float, nargs="*", default=[1.0])
    ap.add_argument("--membrane-scale", type=float, default=1.0)
    ap.add_argument("--seconds", type=float, default=4.0)
    ap.add_argument("--settle-speed", type=float, default=None)
    ap.add_argument("--solve", choices=("fast", "exact"), default=None,
                    help="strain.solve for the run (default: the configuration's, fast)")
    a = ap.parse_args()
    from cloth import backend
    backend.init("cpu", "f64")
    from benchmarks import cusick
    from cloth import simulator
    import cloth.strain.solver as solver
    if a.settle_speed is not None:
        solver.SETTLE_SPEED = a.settle_speed
    if a.solve:
        from cloth import fabrics
        apply = fabrics.apply_fabric

        def with_solve(cfg, name):
            out = apply(cfg, name)
            out["strain"]["solve"] = a.solve
            return out
        fabrics.apply_fabric = with_solve        # cusick.run looks it up at each call
    edge_h = a.h / 2 if a.edge_h is None else a.edge_h
    if a.what == "substep":
        simulator.Simulator = stopping_at(a.frame)
        try:
            cusick.run(a.fabric, a.h, 0, a.method, seconds=a.seconds, edge_h=edge_h,
                       log=lambda m: None)
        except _Reached as reached:
            substep_report(reached.args[0], print)
            return
        raise SystemExit(f"the drape settled before frame {a.frame}")
    if a.what == "frames":
        simulator.Simulator = frame_logger(print)
        cusick.MIN_SECONDS = a.seconds          # log the whole time asked for
    for s in a.shear_scale:
        scale = dict(shear=s, membrane=a.membrane_scale)
        r = cusick.run(a.fabric, a.h, 0, a.method, seconds=a.seconds, scale=scale,
                       edge_h=edge_h, log=lambda m: None)
        out = dict(shear_scale=s, membrane_scale=a.membrane_scale, DC=round(r["DC"], 4),
                   folds=r["folds"], frames=r["frames"])
        if a.what == "energy":
            out.update(energies(r["x"], a.fabric, a.h, edge_h, scale))
            if a.method != "none":
                out["at_bound"] = at_bound(r["x"], a.fabric, a.h, edge_h, a.method)
        print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
