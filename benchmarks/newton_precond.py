"""How much of a resting substep's Newton step does PCG find, per preconditioner (issue #13)?

    python -m benchmarks.newton_precond --out docs/speed     # ~1 min
    python -m benchmarks.newton_precond --settle 2 --substeps 2 --resolution 46 91 129 \
        --no-factor --out docs/speed/multigrid                # falling, up to 32k faces

Captures the strain solve's Newton system H d = -grad L_A of consecutive substeps of the hanging
cloth near rest (mapping, coupling implicit), at the start of each solve (round 0: the warm
multipliers, the penalty mu and, for comparison, 4 mu), and runs conjugate gradients on it
with:
  jacobi       H's 3x3 diagonal blocks, the preconditioner of the kernel path (al.py);
  two-level    block Jacobi plus a coarse correction on K x K aggregates of vertices, each
               with its rigid motions (3 translations, 3 rotations), applied as
               coarse - smooth - coarse;
  stale factor the exact factorisation of the *previous* substep's matrix (the same penalty,
               or the other one): what reusing a factorisation across substeps gives;
  multigrid    the aggregation multigrid of the implicit step's matrix A that the kernel
               uses above 2000 faces (cloth/strain/multigrid.py; ``apply_reference``, the
               kernel's cycle in numpy), built at this substep.
The measure is the error of the iterate in the H-norm, |d_k - d*|_H / |d*|_H, after k
iterations (d* the exact step). Why the H-norm and not the residual: at rest most of the
exact step's energy lies in the cloth's soft global modes (swinging, bending), whose residual
is small, so a preconditioner can bring the residual down by 10 and still leave the step's
motion unresolved; that motion is what the resting cloth's velocity is made of.
"""
import argparse
import os
import sys
import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spl

ITERATIONS = (2, 4, 8, 16, 32)
RESIDUAL_AT = 16          # the kernel path's PCG budget at this size (mapping, ~1.2k faces)


def capture(resolution, settle_frames, substeps, at="prev"):
    """[(x_prev, free, {"mu": (H, r), "4mu": (H, r)}, A)] for ``substeps`` consecutive
    solves after ``settle_frames`` frames: the Newton system at the solve's start (the
    previous positions, as the implicit coupling starts there at rest), and the implicit
    step's matrix with pinned rows and columns made the identity (BSR)."""
    from benchmarks.harness import configure
    from benchmarks.newton_model import newton_system_at
    from cloth.simulator import Simulator
    from cloth.strain.constraints import METHOD_IDS, N_CONSTRAINTS
    from cloth.strain.factor_precond import pinned_values
    _, cfg, setup = configure("hanging", {"cloth": {"resolution": resolution},
                                          "strain": {"method": "mapping",
                                                     "coupling": "implicit"}})
    sim = Simulator(setup, cfg)
    for _ in range(settle_frames):
        sim.step_frame()
    lim = sim.strain
    solve = lim._solve_al
    systems = []

    def capturing(mid, K, metric, *rest):
        ws, nv = lim._ws, lim.model.n_verts
        x_hat, lam = ws.x.to_numpy(), ws.lam.to_numpy()
        free = ws.pinned.to_numpy()[:nv] == 0
        x0 = x_hat.copy()
        if at == "prev":
            x0[:nv][free] = ws.fric.to_numpy()[:nv, :3][free]    # x_prev
        mu = lim.mu_scale * lim._mean_mass(metric)
        out = {}
        for tag, scale in (("mu", 1.0), ("4mu", 4.0)):
            r, H = newton_system_at(lim, METHOD_IDS[lim.method], N_CONSTRAINTS[lim.method],
                                    scale * mu, metric)(x0)
            out[tag] = ((0.5 * (H + H.T)).tocsc(), r)
        ws.x.from_numpy(x_hat)          # as the solve expects them
        ws.lam.from_numpy(lam)
        values = pinned_values(metric, ~free)
        A = sp.bsr_matrix((values, metric.col_np, metric.ptr_np), shape=(3 * nv, 3 * nv))
        systems.append((x0[:nv], free, out, A))
        return solve(mid, K, metric, *rest)
    lim._solve_al = capturing
    for _ in range(substeps):
        sim.step_frame()
    return systems


def block_jacobi(H):
    nb = H.shape[0] // 3
    inv = np.array([np.linalg.inv(H[3 * i:3 * i + 3, 3 * i:3 * i + 3].toarray())
                    for i in range(nb)])
    return lambda v: np.einsum("nij,nj->ni", inv, v.reshape(nb, 3)).ravel()


def rigid_aggregates(x, free, k):
    """The coarse space: vertices binned into k x k cells across the cloth's two longest
    extents, each cell with its rigid motions (translations, rotations about its centroid);
    pinned vertices do not move. A (3 nv, <= 6 k^2) sparse matrix."""
    axes = np.argsort(np.ptp(x, axis=0))[-2:]
    lo, span = x[:, axes].min(0), np.ptp(x[:, axes], axis=0) + 1e-12
    cell = np.minimum(((x[:, axes] - lo) / span * k).astype(int), k - 1)
    agg = cell[:, 0] * k + cell[:, 1]
    count = np.bincount(agg, minlength=k * k)
    centroid = np.stack([np.bincount(agg, weights=x[:, c], minlength=k * k)
                         for c in range(3)], axis=1) / np.maximum(count, 1)[:, None]
    rows, cols, vals = [], [], []
    for v in np.flatnonzero(free):
        arm = x[v] - centroid[agg[v]]
        for a in range(3):
            e = np.eye(3)[a]
            rows.append(3 * v + a), cols.append(6 * agg[v] + a), vals.append(1.0)
            rot = np.cross(e, arm)
            for c in range(3):
                rows.append(3 * v + c), cols.append(6 * agg[v] + 3 + a), vals.append(rot[c])
    Z = sp.csr_matrix((vals, (rows, cols)), shape=(3 * len(x), 6 * k * k))
    return Z[:, np.flatnonzero(np.abs(Z).sum(axis=0).A1 > 0)]


def two_level(H, Z):
    smooth = block_jacobi(H)
    coarse = np.linalg.inv((Z.T @ H @ Z).toarray())

    def apply(v):
        y = Z @ (coarse @ (Z.T @ v))
        y = y + smooth(v - H @ y)
        return y + Z @ (coarse @ (Z.T @ (v - H @ y)))
    return apply


def h_norm_errors(H, r, precondition, iterations=ITERATIONS):
    """|d_k - d*|_H / |d*|_H after each of ``iterations`` PCG iterations from d = 0, and the
    relative residual |r_k| / |r| after RESIDUAL_AT iterations."""
    exact = spl.splu(H).solve(r)
    norm = np.sqrt(exact @ (H @ exact))
    d, res = np.zeros_like(r), r.copy()
    z = precondition(res)
    p, rz = z.copy(), res @ z
    out = []
    for k in range(1, max(iterations) + 1):
        Ap = H @ p
        alpha = rz / (p @ Ap)
        d += alpha * p
        res -= alpha * Ap
        z = precondition(res)
        rz, rz_old = res @ z, rz
        p = z + (rz / rz_old) * p
        if k in iterations:
            e = d - exact
            out.append(float(np.sqrt(e @ (H @ e)) / norm))
        if k == RESIDUAL_AT:
            residual = float(np.linalg.norm(res) / np.linalg.norm(r))
    return out, residual


def measure(resolution=25, settle_frames=130, substeps=4, aggregates=(4, 8), factor=True,
            at="prev"):
    from cloth.strain import multigrid
    systems = capture(resolution, settle_frames, substeps, at)
    rows = []
    for i in range(1, len(systems)):
        x, free, now, A = systems[i]
        before = systems[i - 1][2]
        hierarchy = multigrid.build(A, ~free)
        for tag, (H, r) in now.items():
            cases = [("jacobi", block_jacobi(H))]
            cases += [(f"two-level, {k}x{k} aggregates", two_level(H, rigid_aggregates(x, free,
                                                                                    k)))
                      for k in aggregates]
            if factor:
                cases += [(f"stale factor ({old} of the substep before)",
                           spl.splu(before[old][0]).solve) for old in ("mu", "4mu")]
            cases += [("multigrid of A (multigrid.py)",
                       lambda v, h=hierarchy: multigrid.apply_reference(h, v))]
            for name, prec in cases:
                errors, residual = h_norm_errors(H, r, prec)
                rows.append(dict(substep=i, penalty=tag, preconditioner=name, errors=errors,
                                 residual=residual))
    return rows


def write(rows, out, how, settle, at="prev"):
    names = list(dict.fromkeys(r["preconditioner"] for r in rows))
    heads = ["faces", "penalty", "preconditioner"] + [f"after {k}" for k in ITERATIONS] + \
        [f"|r_k| / |r| after {RESIDUAL_AT}"]
    where = ("near rest" if settle >= 100 else
             f"falling (captured after {settle} frames from the start)")
    where += (", linearised at the previous positions" if at == "prev" else
              ", linearised at x_hat (the unconstrained step's end)")
    md = ["# PCG on a substep's Newton system: the H-norm error per preconditioner",
          "", f"{how}, {time.strftime('%Y-%m-%d')}. hanging, mapping, coupling implicit, "
          f"{where}; see the module docstring. Each cell: the median over "
          "the captured substeps of |d_k - d*|_H / |d*|_H after k iterations (1 = nothing "
          "of the exact step found), and of the relative residual (the kernel path stops at "
          "0.1).", "",
          "| " + " | ".join(heads) + " |", "|" + "---|" * len(heads)]
    for faces in dict.fromkeys(r["faces"] for r in rows):
        for tag in ("mu", "4mu"):
            for name in names:
                mine = [r for r in rows if r["penalty"] == tag and r["preconditioner"] == name
                        and r["faces"] == faces]
                if not mine:
                    continue
                errs = np.median([r["errors"] for r in mine], axis=0)
                res = np.median([r["residual"] for r in mine])
                md.append(f"| {faces} | {tag} | {name} | " +
                          " | ".join(f"{e:.3f}" for e in errs) + f" | {res:.2g} |")
    name = "newton_precond.md" if at == "prev" else "newton_precond_at_hat.md"
    with open(os.path.join(out, name), "w") as fh:
        fh.write("\n".join(md) + "\n")
    print("\n".join(md))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/speed")
    ap.add_argument("--resolution", type=int, nargs="+", default=[25])
    ap.add_argument("--settle", type=int, default=130, help="frames before the capture")
    ap.add_argument("--substeps", type=int, default=4)
    ap.add_argument("--no-factor", action="store_true",
                    help="skip the stale factors (a sparse LU of H: slow from ~16k faces)")
    ap.add_argument("--at", choices=("prev", "hat"), default="prev",
                    help="linearise at the previous positions (where the solve starts at "
                    "rest) or at x_hat (the unconstrained step's end; the solve starts at "
                    "the one of the two with the lower merit)")
    args = ap.parse_args()
    from cloth import backend
    backend.init("cpu", "f64")
    t0 = time.time()
    rows = []
    for res in args.resolution:
        faces = 2 * (res - 1) ** 2
        rows += [dict(r, faces=faces) for r in measure(res, args.settle, args.substeps,
                                                       factor=not args.no_factor,
                                                       at=args.at)]
    os.makedirs(args.out, exist_ok=True)
    cmd = " ".join(["python -m benchmarks.newton_precond"] + sys.argv[1:])
    write(rows, args.out, f"`{cmd}` ({time.time() - t0:.0f} s)", args.settle, args.at)


if __name__ == "__main__":
    main()
