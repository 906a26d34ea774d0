"""How far the AL's Newton matrix (the model the PCG and Cholesky paths solve with) is from the
true Hessian of the merit it minimises, per ``strain.active_margin`` (issue #13).

    python -m benchmarks.newton_model [--methods mapping svd] [--resolution 9] [--frames 20]

At a real substep of ``hanging`` (coupling implicit, after F frames, penalty 4x the first
round's), along random directions d (pinned vertices fixed): the true Hessian times d is the
central difference of the residual r = -grad L_A (r is checked against the merit in
tests/test_al_merit.py), the model's is H d with H as ``direct.newton_system`` (``al.newton_matrix``) assembles it.
Prints |H d - H_true d| / |H_true d| and the Rayleigh ratio d.H.d / d.H_true.d: a ratio of q
means the model is q times too stiff along d, and a full Newton step then covers about 1/q of
the way (linear convergence, rate ~ 1 - 1/q).
"""
import argparse

import numpy as np


def newton_system_at(lim, mid, K, mu, metric):
    """A function x -> (r, H) at positions x (numpy, the work array's shape): the residual
    -grad L_A (flattened) and the Newton matrix (scipy CSR) as ``direct.newton_system``
    assembles them for the limiter ``lim`` with penalty ``mu``."""
    from cloth.strain import direct
    ws, nv = lim._ws, lim.model.n_verts

    def residual_and_matrix(xs):
        ws.x.from_numpy(xs)
        lim._assemble(mid, ws.x)
        direct.fill_newton_system(lim, mid, K, mu, metric)
        return ws.r.to_numpy()[:nv].ravel().copy(), metric.to_scipy(ws.H)
    return residual_and_matrix


def directional_errors(residual_and_matrix, x0, nv, free, rng, directions, eps=1e-7, H=None):
    """Along random directions d (zero where ``free`` is False): the relative error
    |H d - H_true d| / |H_true d| and the Rayleigh ratio d.H.d / d.H_true.d, with H_true d
    the central difference of the residual (H: the matrix at x0, if the caller has it).
    Returns (errors, ratios) per direction."""
    if H is None:
        _, H = residual_and_matrix(x0)
    rel, ratio = [], []
    for _ in range(directions):
        d = np.zeros_like(x0)
        d[:nv] = rng.standard_normal((nv, 3)) * free
        rp, _ = residual_and_matrix(x0 + eps * d)
        rm, _ = residual_and_matrix(x0 - eps * d)
        true_d = -(rp - rm) / (2 * eps)
        model_d = H @ d[:nv].ravel()
        rel.append(np.linalg.norm(model_d - true_d) / np.linalg.norm(true_d))
        ratio.append(d[:nv].ravel() @ model_d / (d[:nv].ravel() @ true_d))
    return rel, ratio


def measure(method, resolution, frames, margins, directions=4, seed=0):
    from benchmarks.harness import configure
    from cloth.simulator import Simulator
    from cloth.strain.constraints import METHOD_IDS, N_CONSTRAINTS
    _, cfg, setup = configure("hanging", {"cloth": {"resolution": resolution},
                                          "strain": {"method": method, "coupling": "implicit"}})
    sim = Simulator(setup, cfg)
    for _ in range(frames):
        sim.step_frame()
    lim, m = sim.strain, sim.model
    ws = lim._ws
    nv, mid, K = m.n_verts, METHOD_IDS[method], N_CONSTRAINTS[method]
    metric = lim._newton_metric(True)
    mu = 4.0 * lim.mu_scale * lim._mean_mass(metric)
    x0 = ws.x.to_numpy()
    free = (m.pinned == 0)[:, None]
    rng = np.random.default_rng(seed)
    residual_and_matrix = newton_system_at(lim, mid, K, mu, metric)
    rows = []
    for margin in margins:
        lim.active_margin = margin
        lim._upload_params()
        rel, ratio = directional_errors(residual_and_matrix, x0, nv, free, rng, directions)
        ws.x.from_numpy(x0)
        rows.append((method, resolution, margin, rel, ratio))
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--methods", nargs="+", default=["mapping", "svd", "warp-weft"])
    ap.add_argument("--resolution", type=int, default=9)
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--margins", nargs="+", type=float, default=[1e-2, 3e-3, 1e-3, 0.0])
    args = ap.parse_args()
    from cloth import backend
    backend.init("cpu", "f64")
    print("| method | faces res | active_margin | rel. error of H d | d.H.d / d.H_true.d |")
    print("|---|---|---|---|---|")
    for method in args.methods:
        for method_, res, margin, rel, ratio in measure(method, args.resolution, args.frames,
                                                        args.margins):
            print(f"| {method_} | {res} | {margin:g} | "
                  f"{min(rel):.3f} ... {max(rel):.3f} | {min(ratio):.2f} ... {max(ratio):.2f} |",
                  flush=True)


if __name__ == "__main__":
    main()
