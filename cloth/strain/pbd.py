"""The per-triangle projection baselines (PBD style, ``strain.solver`` = jacobi or
gauss-seidel): each triangle projected onto its own limits in turn, for comparison with the
augmented Lagrangian (``al.py``).
"""
import taichi as ti

from .al import contact_g, contact_normal, eval_face, stitch_g
from .buffers import CONTACT_SLOTS, P_CONTACT_SCALE, ST_ITERS, A, ContactPack, MeshPack, T


# ---- the per-triangle projection baseline (PBD style) ------------------------------------
@ti.func
def project_face(method: ti.template(), f, jacobi, x: T, mesh: T, acc: T, cnt: T):
    """Move the face's vertices along the gradient of its most violated constraint so that
    its linearisation is satisfied, weighted by inverse mass (pins have none); Jacobi
    accumulates the moves, Gauss-Seidel applies them at once. Returns the violation found
    (strain units)."""
    out = eval_face(method, f, x, mesh)
    worst = 0.0
    gr = ti.Vector([0.0] * 9)
    for c in ti.static(range(out.g.n)):
        if out.g[c] > worst:
            worst = out.g[c]
            for m in ti.static(range(9)):
                gr[m] = out.grad[c, m]
    if worst > 0.0:
        ids = mesh.face_verts[f]
        wn = ti.Vector([0.0, 0.0, 0.0])
        denom = 0.0
        for n in ti.static(range(3)):
            if mesh.pinned[ids[n]] == 0:
                wn[n] = 1.0 / mesh.mass[ids[n]]
            denom += wn[n] * (gr[3 * n] ** 2 + gr[3 * n + 1] ** 2 + gr[3 * n + 2] ** 2)
        if denom > 0.0:
            for n in ti.static(range(3)):
                dx = -worst * wn[n] / denom * ti.Vector([gr[3 * n], gr[3 * n + 1],
                                                         gr[3 * n + 2]])
                if jacobi:
                    acc[ids[n]] += dx
                    cnt[ids[n]] += 1.0
                else:
                    x[ids[n]] += dx
    return worst / ti.sqrt(mesh.rest_area[f])


@ti.kernel
def pbd_solve(method: ti.template(), jacobi: int, tol: float, max_iters: int, omega: float,
              x: A, mesh: MeshPack, contacts: ContactPack, acc: A, cnt: A, stats: A):
    """Jacobi (averaged, relaxed by omega) or Gauss-Seidel (in place, serial order) sweeps of
    per-triangle projections, each followed by projecting every vertex onto its contact
    half-space, until the worst violation seen in a sweep is below tol."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        nv, nf, ns = mesh.n_verts, mesh.n_faces, contacts.n_stitches
        it = 0
        while it < max_iters:
            if jacobi:
                for n in range(nv):
                    acc[n] = ti.Vector([0.0, 0.0, 0.0])
                    cnt[n] = 0.0
            viol = 0.0
            for f in range(nf):
                viol = ti.max(viol, project_face(method, f, jacobi, x, mesh, acc, cnt))
            if jacobi:
                for n in range(nv):
                    if cnt[n] > 0.0:
                        x[n] += omega * acc[n] / cnt[n]
            for k in range(ns):
                cs = stitch_g(contacts.stitch, x, k)
                a, b = contacts.stitch[k][0], contacts.stitch[k][1]
                wa = 0.0 if mesh.pinned[a] == 1 else 1.0 / mesh.mass[a]
                wb = 0.0 if mesh.pinned[b] == 1 else 1.0 / mesh.mass[b]
                if wa + wb > 0.0:
                    x[a] -= wa / (wa + wb) * cs
                    x[b] += wb / (wa + wb) * cs
                    viol = ti.max(viol, cs.norm() / mesh.params[P_CONTACT_SCALE])
            for n in range(nv):
                for j in ti.static(range(CONTACT_SLOTS)):
                    gc = contact_g(contacts.contact, x, n, j)
                    if gc > 0.0 and mesh.pinned[n] == 0:
                        x[n] += gc * contact_normal(contacts.contact, n, j)
                        viol = ti.max(viol, gc / mesh.params[P_CONTACT_SCALE])
            if viol < tol:
                break
            it += 1
        stats[ST_ITERS] = it
