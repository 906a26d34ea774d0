"""How good is the AL's Newton matrix, and what would the exact one buy? (issue #13)

    python -m benchmarks.curvature [--resolution 25] [--settle 60] [--frames 30] [--out docs/speed]

For each method: ``hanging`` (implicit coupling, Cholesky path) runs ``--settle`` frames, then
1. **the model against the truth**: at that state (margin 0, so that the matrix is the
   generalised Hessian of L_A), the finite difference of the residual along a direction d,
   -(r(x + e d) - r(x - e d)) / 2e, against H d, for the Newton direction and a random one,
   with the curvature model (``constraints.py``) and with the exact PSD curvature
   (``cloth/strain/exact_curvature.py``, "full" and "split");
2. **what it buys**: ``--frames`` more frames with each matrix, and with the split computed in
   the kernels ("kernel", ``strain.curvature = "exact"``), default settings otherwise:
   AL rounds and Newton steps per substep (median) and the mean kinetic energy.
Each (method, matrix) runs in its own child process from the same deterministic start.

This replaces ``benchmarks/newton_model.py``, which made check 1 with the solver's own margin
(2026-12-02): with ``active_margin`` 1e-2 the svd model was ~90x stiffer than L_A along the
Newton step (the near-active constraints' Gauss-Newton terms, which L_A does not have), so
exact Newton steps were too short and the inner loop stagnated; the margin is kept because
without it the steps run into constraints that switch on (measured again with the exact
curvature, hanging res 25 mapping, frames 61-100: margin 0 ran into the 100-round cap every
substep; 1e-3 converged but its cloth moved more, mean KE 2.6e-5 J against 8.5e-6 J at 1e-2).
Writes ``curvature.md`` (and .json) to ``--out``.
"""
import argparse
import json
import os
import subprocess
import sys

import numpy as np

from benchmarks.harness import commit, configure, machine
from cloth.strain.families import METHODS

# The Newton matrix's constraint curvature: the model of constraints.py, or the exact one made
# positive semi-definite as a 9x9 per face ("full") or in its two parts through C ("split"),
# see cloth/strain/exact_curvature.py.
MATRICES = ("model", "full", "split")
# Frames only (no check): the exact curvature in the kernels (strain.curvature = "exact",
# c_curvature.py), the default since this benchmark.
RUNS = MATRICES + ("kernel",)


def _residual_and_matrix(lim, x, mid, K, mu, metric, chol, mode):
    from cloth import ndarrays
    from cloth.strain import direct, exact_curvature
    ws, m = lim._ws, lim.model
    nv = m.n_verts
    full = ws.x.to_numpy()
    full[:nv] = x
    ws.x.from_numpy(full)
    lim._assemble(mid, ws.x)
    if mode != "model":
        ndarrays.zero(ws.kappa)
        ndarrays.zero(ws.twist)
    direct.fill_newton_system(lim, mid, K, mu, metric)
    if mode != "model":
        exact_curvature.add_to_newton_matrix(lim, lim.method, K, mu, metric, mode)
    return ws.r.to_numpy()[:nv].reshape(-1).copy(), chol.matrix(ws.H.to_numpy()[:metric.nnz])


def hessian_check(sim, eps=1e-7):
    """Relative error |FD - H d| / |FD| and the curvatures d.FD, d.H d along the Newton
    direction and a random one, for the model and the exact matrix."""
    from scipy.sparse.linalg import spsolve
    from cloth.strain.solver import METHOD_IDS, N_CONSTRAINTS
    lim = sim.strain
    saved_margin = lim.active_margin
    lim.active_margin = 0.0
    lim._upload_params()
    ws, m = lim._ws, lim.model
    mid, K = METHOD_IDS[lim.method], N_CONSTRAINTS[lim.method]
    metric, chol = lim._direct_metric(True)
    mu = lim.mu_scale * lim._mean_mass(metric)
    x0 = ws.x.to_numpy()[:m.n_verts].copy()
    free = np.repeat(ws.pinned.to_numpy()[:m.n_verts] == 0, 3)
    out = {}
    for mode in MATRICES:
        r0, H0 = _residual_and_matrix(lim, x0, mid, K, mu, metric, chol, mode)
        directions = {"newton": spsolve(H0.tocsc(), r0),
                      "random": np.random.default_rng(0).standard_normal(3 * m.n_verts)}
        for name, d in directions.items():
            d = d * free
            d /= np.abs(d).max()
            Hd = H0 @ d
            r_plus, _ = _residual_and_matrix(lim, x0 + eps * d.reshape(-1, 3), mid, K, mu,
                                             metric, chol, mode)
            r_minus, _ = _residual_and_matrix(lim, x0 - eps * d.reshape(-1, 3), mid, K, mu,
                                              metric, chol, mode)
            fd = -(r_plus - r_minus) / (2.0 * eps)
            key = f"{mode} {name}"
            out[key] = dict(rel_err=float(np.linalg.norm((fd - Hd)[free]) /
                                          np.linalg.norm(fd[free])),
                            dFD=float(d @ fd), dHd=float(d @ Hd))
    _residual_and_matrix(lim, x0, mid, K, mu, metric, chol, "model")
    lim.active_margin = saved_margin
    lim._upload_params()
    return out


def child(method, resolution, settle, frames, mode, check):
    from cloth import metrics
    from cloth.simulator import Simulator
    _, cfg, setup = configure("hanging", {"cloth": {"resolution": resolution},
                                          "strain": {"method": method, "coupling": "implicit",
                                                     "linear_solver": "cholesky",
                                                     "curvature": "exact" if mode == "kernel"
                                                     else "model"}})
    sim = Simulator(setup, cfg)
    for _ in range(settle):
        sim.step_frame()
    row = dict(method=method, matrix=mode, faces=sim.model.n_faces)
    if check:
        row["check"] = hessian_check(sim)
    sim.strain.exact_curvature = False if mode in ("model", "kernel") else mode
    sim.strain._upload_params()
    rounds, newton, ke, ms = [], [], [], []
    for _ in range(frames):
        sim.step_frame()
        s = sim.strain
        rounds.append(s.last_iterations)
        newton.append(s.last_newton)
        ms.append(s.last_ms)
        ke.append(metrics.kinetic_energy(sim.model.velocities(), sim.model.mass))
    row.update(rounds=float(np.median(rounds)), rounds_max=int(max(rounds)),
               newton=float(np.median(newton)), ke_mean=float(np.mean(ke)),
               ke_last10=float(np.mean(ke[-10:])), ms=float(np.median(ms)))
    return row


def markdown(rows, args):
    lines = ["# The Newton matrix's curvature: model against exact (issue #13)", "",
             f"`python -m benchmarks.curvature --resolution {args.resolution} --settle "
             f"{args.settle} --frames {args.frames}`. {machine()}; commit {commit()}.", "",
             f"`hanging` res {args.resolution}, implicit coupling, Cholesky path, after "
             f"{args.settle} frames." + (" Kernels compiled with LOOM_FAST_COMPILE=1."
                                         if os.environ.get("LOOM_FAST_COMPILE") else ""), "",
             "## 1. Finite difference of the residual against H d (margin 0, step 1e-7 m)", "",
             "| method | matrix | direction | rel. error | d.FD | d.H d |", "|---|---|---|---|---|---|"]
    for row in rows:
        for key, c in row.get("check", {}).items():
            matrix, direction = key.split()
            lines.append(f"| {row['method']} | {matrix} | {direction} | {c['rel_err']:.3g} | "
                         f"{c['dFD']:.3g} | {c['dHd']:.3g} |")
    lines += ["", f"## 2. The next {args.frames} frames with each matrix (default margin)", "",
              "| method | matrix | AL rounds (median / max) | Newton steps (median) | "
              "mean KE (J) | KE, last 10 frames (J) | SL ms (median) |",
              "|---|---|---|---|---|---|---|"]
    for row in rows:
        lines.append(f"| {row['method']} | {row['matrix']} | "
                     f"{row['rounds']:.0f} / {row['rounds_max']} | {row['newton']:.0f} | "
                     f"{row['ke_mean']:.3g} | {row['ke_last10']:.3g} | {row['ms']:.0f} |")
    lines += ["", "\"full\" and \"split\" are computed on the host (numpy, finite "
              "differences), so their times say nothing about the cost in the kernels; "
              "\"kernel\" is the split computed in the Newton kernels (c_curvature.py), the "
              "default `strain.curvature = \"exact\"`."]
    return "\n".join(lines) + "\n"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=25)
    ap.add_argument("--settle", type=int, default=60)
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    ap.add_argument("--out", default="docs/speed")
    ap.add_argument("--child", nargs=2, metavar=("METHOD", "MATRIX"))
    args = ap.parse_args()
    if args.child:
        from cloth import backend
        backend.init("cpu", "f64")
        mode = args.child[1]
        row = child(args.child[0], args.resolution, args.settle, args.frames, mode,
                    check=mode == "model")
        print("ROW " + json.dumps(row))
        return
    rows = []
    for method in args.methods:
        for mode in RUNS:
            print(f"{method}, {mode} matrix ...", flush=True)
            cmd = [sys.executable, "-m", "benchmarks.curvature", "--child", method, mode,
                   "--resolution", str(args.resolution), "--settle", str(args.settle),
                   "--frames", str(args.frames)]
            out = subprocess.run(cmd, capture_output=True, text=True, check=True).stdout
            rows.append(json.loads(out.split("ROW ", 1)[1]))
    os.makedirs(args.out, exist_ok=True)
    text = markdown(rows, args)
    with open(os.path.join(args.out, "curvature.md"), "w") as fh:
        fh.write(text)
    with open(os.path.join(args.out, "curvature.json"), "w") as fh:
        json.dump(rows, fh, indent=1)
    print(text)


if __name__ == "__main__":
    main()
