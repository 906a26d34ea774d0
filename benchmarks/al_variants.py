"""Variants of the strain projection's AL, run on the host from a saved substep, to study which
Newton model and globalisation converge to the minimiser (issue #32, docs/speed/motion.md).

    python -m benchmarks.al_variants hanging 10 --resolution 25 --method warp-weft
    python -m benchmarks.al_variants drape 7 --method mapping --variants pdas,mu=0.1 host-exact,mu=0.1

The scene runs ``frames`` frames with exact steps; the next substep's projection is then
solved from the same state by each variant, and each answer's distance to the first variant's
(the reference, solved tightly) is printed with its rounds, Newton steps and step lengths.

Each variant is the AL of ``cloth/strain/direct.py`` (the library's kernels assemble the
constraints, the residual, the Newton matrix and run the Armijo line search) with the Newton
step solved exactly (CHOLMOD), and these changes, as comma-separated words:
  margin=M       the active margin of the Newton matrix (the library's: 1e-2)
  mu=S           the initial penalty times the library's
  kkt=V          stop only when feasible and the round's first Newton step moves no vertex by
                 more than V metres (else: the library's violation stop)
  pdas           the Newton step's active set predicted primal-dual style: the step is solved
                 again with every constraint its linearisation activates (t + J d > 0) until
                 the set stops changing (needs margin 0)
  host-exact     the constraints' exact curvature through C = F^T F, from the kernels'
                 c_curvature data but made positive semi-definite on the host (the kernels'
                 own assembly of it is indefinite: docs/speed/motion.md)
  newton=N       Newton steps per round; rounds=N  AL rounds at most
  inner=N        at most N PDAS solves per Newton step (default 10)
  pcg=N          solve each Newton system by N PCG iterations preconditioned by W's exact
                 factor (warm-started across the PDAS re-solves) instead of exactly
Slow (numpy, a factorisation per step): a research tool, not a solver.
"""
import argparse

import numpy as np
import scipy.sparse as sp


def _solve(A, b, pcg=None, x0=None):
    """A^-1 b exactly (CHOLMOD), or by ``pcg`` = (iterations, preconditioner) from x0."""
    if pcg is None:
        from sksparse.cholmod import cholesky
        return cholesky(A.tocsc())(b)
    iters, precondition = pcg
    x = np.zeros_like(b) if x0 is None else x0.copy()
    r = b - A @ x
    z = precondition(r)
    p = z.copy()
    rz = r @ z
    for _ in range(iters):
        Ap = A @ p
        pAp = p @ Ap
        if not pAp > 0:
            break
        a = rz / pAp
        x += a * p
        r -= a * Ap
        z = precondition(r)
        rz, rz_old = r @ z, rz
        p = z + (rz / rz_old) * p
    return x


def _set_param(lim, index, value):
    p = lim._ws.params.to_numpy()
    p[index] = value
    lim._ws.params.from_numpy(p)


class Substep:
    """The arrays of one projection (what ``StrainLimiter.project`` sets up before solving)."""

    def __init__(self, sim, contacts):
        from cloth.strain import al
        from cloth.strain.constraints import METHOD_IDS, N_CONSTRAINTS
        lim = self.lim = sim.strain
        lim._sync_mesh()
        ws, m = lim._ws, lim.model
        self.nv, self.nf, self.h, self.contacts = m.n_verts, m.n_faces, sim.h, contacts
        al.begin_solve(self.nv, float(sim.h), int(contacts and lim.friction),
                       int(not contacts), 0, 0.0, 0, ws.step_pack(m.state), ws.vector_pack(),
                       ws.contact_pack(), ws.stats)
        self.metric = lim._newton_metric(lim.coupling == "implicit" and lim._system_ready)
        mean = lim._mean_mass(self.metric)
        self.mu0, self.mu_max = lim.mu_scale * mean, lim.mu_max_scale * mean
        self.mid, self.K = METHOD_IDS[lim.method], N_CONSTRAINTS[lim.method]
        self.faces = m.faces[: self.nf]
        self.pinned = m.pinned[: self.nv]

    def positions(self):
        return self.lim._ws.x.to_numpy()[: self.nv].astype(np.float64)

    def jacobian(self, mu):
        """(J, t): each constraint's gradient as a sparse row (pinned columns zero) and
        t = g + lam / mu; the strain constraints, then the contact slots."""
        ws, nv, nf, K = self.lim._ws, self.nv, self.nf, self.K
        g, lam = ws.g.to_numpy()[:nf, :K], ws.lam.to_numpy()[:nf, :K]
        grad = ws.grad.to_numpy()[:nf, :K]
        G = np.empty((nf, K, 9))
        G[:, 0::2], G[:, 1::2] = grad[:, 0::2], -grad[:, 0::2]      # bound pairs (al.py)
        cols = (3 * self.faces[:, None, :, None] + np.arange(3)).reshape(nf, 1, 9)
        rows = np.arange(nf * K).reshape(nf, K, 1)
        R = [np.broadcast_to(rows, (nf, K, 9)).ravel()]
        C = [np.broadcast_to(cols, (nf, K, 9)).ravel()]
        V, t, n_rows = [G.ravel()], [(g + lam / mu).ravel()], nf * K
        if self.contacts:
            c, lc = ws.contact.to_numpy()[:nv], ws.lam_c.to_numpy()[:nv]
            gc = c[..., 3] - np.einsum("vjk,vk->vj", c[..., :3], self.positions())
            R.append(np.repeat(n_rows + np.arange(2 * nv), 3))
            C.append((3 * np.repeat(np.arange(nv), 2)[:, None] + np.arange(3)).ravel())
            V.append(-c[..., :3].reshape(-1))
            t.append((gc + lc / mu).ravel())
            n_rows += 2 * nv
        J = sp.csr_matrix((np.concatenate(V), (np.concatenate(R), np.concatenate(C))),
                          shape=(n_rows, 3 * nv))
        return (J @ sp.diags(np.repeat(~self.pinned, 3).astype(float))).tocsr(), \
            np.concatenate(t)

    def exact_curvature(self):
        """The faces' exact constraint curvature S (x) I3 + J^T Hc J from the kernels' curv
        arrays (c_curvature.py), with T and Hc clamped positive semi-definite here."""
        ws, act = self.lim._ws, None
        curv = ws.curv.to_numpy()[: self.nf]
        act = curv[:, 1, 6] > 0
        c0, c1, c2 = curv[act, 0], curv[act, 1], curv[act, 2]
        Mr = c0[:, :6].reshape(-1, 3, 2)
        T = _psd(c0[:, [6, 7, 7, 8]].reshape(-1, 2, 2))
        Hc = _psd(c1[:, [0, 1, 2, 1, 3, 4, 2, 4, 5]].reshape(-1, 3, 3))
        w0, w1 = c2[:, 0:3], c2[:, 3:6]
        n = len(Mr)
        J = np.zeros((n, 3, 9))
        for v in range(3):
            a, b = Mr[:, v, 0:1], Mr[:, v, 1:2]
            J[:, 0, 3 * v:3 * v + 3] = 2 * a * w0
            J[:, 1, 3 * v:3 * v + 3] = a * w1 + b * w0
            J[:, 2, 3 * v:3 * v + 3] = 2 * b * w1
        S = np.einsum("fai,fij,fbj->fab", Mr, T, Mr)
        B = np.einsum("fab,ij->faibj", S, np.eye(3)).reshape(n, 9, 9) + \
            np.einsum("fki,fkl,flj->fij", J, Hc, J)
        idx = (3 * self.faces[act][:, :, None] + np.arange(3)).reshape(n, 9)
        rows = np.broadcast_to(idx[:, :, None], (n, 9, 9)).ravel()
        cols = np.broadcast_to(idx[:, None, :], (n, 9, 9)).ravel()
        free = np.repeat(~self.pinned, 3)
        keep = free[rows] & free[cols]
        return sp.csr_matrix((B.ravel()[keep], (rows[keep], cols[keep])),
                             shape=(3 * self.nv,) * 2)


def _psd(M):
    w, V = np.linalg.eigh(M)
    return np.einsum("fij,fj,fkj->fik", V, np.maximum(w, 0.0), V)


def solve(step, margin=1e-2, mu=1.0, kkt=None, pdas=False, host_exact=False, newton=5,
          rounds=100, tol=1e-4, pcg=None, resolves=10):
    """One projection by the variant; returns (x, log)."""
    from cloth import ndarrays
    from cloth.strain import direct
    from cloth.strain.buffers import P_CURVATURE, P_MARGIN, ST_START_VIOL
    lim, ws, metric = step.lim, step.lim._ws, step.metric
    nv, K, mid = step.nv, step.K, step.mid
    m, m_max = step.mu0 * mu, step.mu_max
    _set_param(lim, P_MARGIN, margin)
    packs = direct.packs(lim, metric, K)  # (mesh, metric, constraints, contacts, vectors)
    direct.start(mid, m, int(lim.coupling == "implicit"), tol, *packs, ws.stats)
    log = dict(rounds=0, newton=0, solves=0, alpha=[], first_step=[], converged=False)
    if ws.stats.to_numpy()[ST_START_VIOL] < tol:
        log["converged"] = True
        return step.positions(), log
    solver = None
    if pcg:
        from sksparse.cholmod import cholesky
        W = metric.to_scipy().tocsr()
        free = np.repeat(~step.pinned, 3).astype(float)
        Wp = (sp.diags(free) @ W @ sp.diags(free) + sp.diags(1.0 - free)).tocsc()
        solver = (int(pcg), cholesky(Wp))
    viol = comp = np.inf
    while log["rounds"] < rounds and not log["converged"]:
        for inner in range(newton):
            if host_exact:
                _set_param(lim, P_CURVATURE, 1.0)
                direct.fill_newton_system(lim, mid, K, m, metric)       # fills curv
                C = step.exact_curvature()
                _set_param(lim, P_CURVATURE, 0.0)
                kappa, twist = ws.kappa.to_numpy(), ws.twist.to_numpy()
                ndarrays.zero(ws.kappa)
                ndarrays.zero(ws.twist)
                direct.fill_newton_system(lim, mid, K, m, metric)
                ws.kappa.from_numpy(kappa)
                ws.twist.from_numpy(twist)
                H = metric.to_scipy(ws.H) + C
            else:
                direct.fill_newton_system(lim, mid, K, m, metric)
                H = metric.to_scipy(ws.H)
            r = ws.r.to_numpy()[:nv].reshape(-1).astype(np.float64)
            if pdas:
                d = _pdas_step(step, m, r, H, log, max_inner=resolves, pcg=solver)
            else:
                d = _solve(H, r, solver)
                log["solves"] += 1
            log["newton"] += 1
            d_max = float(np.linalg.norm(d.reshape(-1, 3), axis=1).max())
            if inner == 0:
                log["first_step"].append(d_max)
                if kkt is not None and viol < tol and comp < tol and d_max <= kkt:
                    log["converged"] = True
                    break
            full = np.zeros((ws.d.shape[0], 3))
            full[:nv] = d.reshape(nv, 3)
            ws.d.from_numpy(full)
            direct.line_search(mid, m, *packs, ws.info)
            out = ws.info.to_numpy()
            log["alpha"].append(float(out[direct.I_ALPHA]))
            if out[direct.I_ALPHA] == 0.0 or (kkt is not None and d_max < 0.1 * kkt) or \
                    (kkt is None and out[direct.I_STEP] < 1e-8):
                break
        if log["converged"]:
            break
        direct.multipliers(m, m_max, ws.x, ws.mesh_pack(), ws.constraint_pack(K),
                           ws.contact_pack(), ws.info)
        out = ws.info.to_numpy()
        viol, comp = float(out[direct.I_VIOL]), float(out[direct.I_COMP])
        log["rounds"] += 1
        if kkt is None:
            log["converged"] = viol < tol and comp < tol
        if not (kkt is not None and viol < tol):
            m = min(m * lim.mu_grow, m_max)
    log["viol"] = viol
    return step.positions(), log


def _pdas_step(step, mu, r0, H0, log, max_inner=10, pcg=None):
    """The Newton step of the linearised constraints' piecewise-quadratic model, its active
    set predicted from t + J d > 0 and re-solved until it stops changing. H0 and r0 hold the
    constraints active at x (t > 0): they are taken out and the predicted set put in."""
    J, t = step.jacobian(mu)
    active = t > 0
    JA = J[active]
    base = H0 - mu * (JA.T @ JA)
    r_base = r0 + mu * (JA.T @ t[active])
    d = None
    for _ in range(max_inner):
        JA = J[active]
        d = _solve((base + mu * (JA.T @ JA)).tocsr(), r_base - mu * (JA.T @ t[active]), pcg, d)
        log["solves"] += 1
        predicted = t + J @ d > 0
        if np.array_equal(predicted, active):
            break
        active = predicted
    return d


def parse(spec):
    kw = {}
    for word in spec.split(","):
        key, _, value = word.partition("=")
        if key in ("pdas", "host-exact"):
            kw[key.replace("-", "_")] = True
        elif key in ("newton", "rounds", "pcg"):
            kw[key] = int(value)
        elif key == "inner":
            kw["resolves"] = int(value)
        elif key in ("margin", "mu", "kkt", "tol"):
            kw[key] = float(value)
        else:
            raise SystemExit(f"unknown variant word '{key}' (see the module's docstring)")
    return kw


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    ap.add_argument("frames", type=int)
    ap.add_argument("--resolution", type=int, default=25)
    ap.add_argument("--method", default="mapping")
    ap.add_argument("--variants", nargs="+", default=[
        "margin=0,pdas,mu=0.1,kkt=1e-9,tol=1e-9,newton=30,rounds=60",     # the reference
        "margin=0.01", "margin=0.01,kkt=1e-5,newton=10",
        "margin=0,pdas,mu=0.1,kkt=1e-5,newton=10", "margin=0,pdas,mu=0.01,kkt=1e-5,newton=2"])
    a = ap.parse_args()
    from cloth import backend
    backend.init("cpu", "f64")
    from benchmarks.harness import configure
    from cloth.simulator import Simulator
    _, cfg, setup = configure(a.scene, {"cloth": {"resolution": a.resolution},
                                        "strain": {"method": a.method,
                                                   "linear_solver": "cholesky"}})
    sim = Simulator(setup, cfg)
    for _ in range(a.frames):
        sim.step_frame()
    ws = sim.strain._ws
    x0, v0 = sim.model.positions(), sim.model.velocities()
    mult = [arr.to_numpy() for arr in (ws.lam, ws.lam_c, ws.lam_t, ws.lam_s)]
    contacts = sim.collider is not None and bool(sim.collider.obstacles)
    ref = None
    for spec in a.variants:
        sim.model.set_positions(x0)
        sim.model.set_velocities(v0)
        for arr, val in zip((ws.lam, ws.lam_c, ws.lam_t, ws.lam_s), mult):
            arr.from_numpy(val)
        sim._update_pins(sim.time + sim.h)
        sim.dynamics.step(sim.h)
        sim.dynamics.system_matrix(sim.h, sim.strain.system_metric())
        for name in ("self_collision", "collision"):
            if sim.stage(name).enabled:
                sim.stage(name).run()
        if contacts:
            sim.collider.contact_planes(sim.time + sim.h, sim.strain.contact_planes,
                                        reach=0.5 * sim.model.typical_edge(),
                                        mu_out=sim.strain.contact_friction)
        x, log = solve(Substep(sim, contacts), **parse(spec))
        ref = x if ref is None else ref
        alpha = np.array(log["alpha"] or [1.0])
        print(f"{spec:55s} {1e3 * np.abs(x - ref).max():8.3f} mm  rounds {log['rounds']:3d} "
              f"newton {log['newton']:4d} solves {log['solves']:4d} converged "
              f"{log['converged']!s:5s} alpha median {np.median(alpha):.2g} min "
              f"{alpha.min():.2g}", flush=True)


if __name__ == "__main__":
    main()
