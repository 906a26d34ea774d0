"""Cloth self-collision by repulsion impulses (Bridson, Fedkiw, Anderson 2002, section 7.2).

Per substep [t, t + h], with ``x_start = x - h v`` (see collider.py):
1. broad phase: a spatial hash (cell size ~ the mean edge length; built in Taichi every substep:
   count, prefix sum, fill) holds every triangle and every edge under its bounding box *swept*
   over the substep (start to predicted end) and grown by 1.5 x thickness; a vertex (or edge)
   queries the cells of its own swept box; each candidate is taken once, in the cell holding
   the low corner of the two boxes' overlap. Pairs that share a vertex are skipped;
2. proximity at the start positions: vertex-triangle and edge-edge closest points. A pair is
   kept when it is within 1.5 x thickness or closing fast enough to get there within two
   substeps at its present normal velocity. Each pair is stored as four vertices with weights
   ``w`` (relative velocity ``sum w_k v_k``; vertex-face: (1, -b0, -b1, -b2), edge-edge:
   (1-a, a, -(1-b), -b)) and the unit normal ``n`` from the second primitive to the first;
3. impulses, Gauss-Seidel over the pairs for a few sweeps: the normal relative velocity is
   raised to what keeps the gap at the end of the substep at the thickness,
   ``v_n >= (thickness - d0) / h`` (an approaching pair may close at most down to the thickness,
   an overlapping one is pushed apart, by ``restore`` of the overlap per substep); the impulse
   is split by weights and inverse masses as in Bridson's ``I~ = 2I / (1 + sum w^2)``,
   generalised to unequal masses: ``dv_k = w_k / m_k * I n``, ``I = dv_n / sum(w_k^2 / m_k)``.
   Pinned vertices have infinite mass; vertices the collider flagged as resting on an obstacle
   count ``1 / contact_mass_ratio`` times heavier (so the upper layer yields, not the ground);
4. positions of touched vertices are re-integrated, ``x = x_start + h v``.
This is proximity-based (no exact continuous test between the cloth and itself, no untangling):
pairs that already crossed are pushed further apart on the wrong side, and a pair closing by
more than its gap plus 1.5 thickness in one substep with a sideways motion may be missed; keep
the substep small enough that the thickness is not skipped at the speeds of the scene.
No friction between layers.
"""
import time

import taichi as ti

from .geom import closest_on_triangle, closest_segments, safe_normalize


def _pow2(n):
    p = 1
    while p < n:
        p *= 2
    return p


@ti.data_oriented
class SelfCollision:
    def __init__(self, model, thickness=0.004, iterations=6, restore=0.5,
                 contact_mass_ratio=0.01):
        if not thickness > 0:
            raise ValueError(f"self-collision thickness must be > 0 m (got {thickness})")
        self.model = model
        self.thickness = float(thickness)
        self.iterations = int(iterations)
        self.restore = float(restore)
        self.contact_mass_ratio = float(contact_mass_ratio)
        self.last_pairs = 0
        self.last_ms = 0.0
        self.realloc_count = 0
        self._caps = None
        # 0: max speed, 1: edge length sum, 2: cell size, 3: detection radius,
        # 4: look-ahead time for keeping a pair, 5: thickness
        self._scal = ti.field(float, 6)
        self._cnt = ti.field(ti.i32, 4)        # 0: tri entries, 1: edge entries, 2: pairs
        self._ensure_model_capacity()

    # -- allocation ----------------------------------------------------------------------------
    # Kernels take the buffers as template arguments: a data-oriented kernel compiled once
    # would keep pointing at the old fields if an attribute were simply re-assigned.
    def _ensure_model_capacity(self):
        m = self.model
        caps = (m.v_cap, m.f_cap, m.e_cap)
        if self._caps is not None and all(c <= o for c, o in zip(caps, self._caps)):
            return
        self._caps = caps
        V, F, E = caps
        self.geo = _Geo(V, _pow2(2 * (F + E)))
        self.tri_entries = _Entries(12 * F)
        self.edge_entries = _Entries(12 * E)
        self.pairs = _Pairs(4 * V)

    # -- one substep ---------------------------------------------------------------------------
    def on_mesh_changed(self):
        self._ensure_model_capacity()

    def prepare_contacts(self):
        """Clear and return the per-vertex obstacle-contact flags (the collider sets them
        before ``resolve``); flagged vertices count ``1 / contact_mass_ratio`` times heavier."""
        self._ensure_model_capacity()
        self.geo.contact.fill(0)
        return self.geo.contact

    def resolve(self, h):
        t0 = time.perf_counter()
        self._ensure_model_capacity()
        m = self.model
        nv, nf, ne = m.n_verts, m.n_faces, m.n_edges
        st = m.state
        self._prepare(self.geo, st.x, st.v, m.edge_verts, nv, ne, h)
        mean_edge = float(self._scal[1]) / max(ne, 1)
        r = 1.5 * self.thickness
        cs = max(mean_edge, 2.0 * r)
        self._scal[2] = cs
        self._scal[3] = r
        self._scal[4] = 2.0 * h
        self._scal[5] = self.thickness
        # Hash: count, prefix sum, fill (re-run once if an entry array was too small).
        for _ in range(2):
            self._count_entries(self.geo, st.x, m.face_verts, m.edge_verts, nf, ne)
            nt, nee = int(self._cnt[0]), int(self._cnt[1])
            grown = False
            if nt > self.tri_entries.cap:
                self.tri_entries = _Entries(int(nt * 1.5))
                grown = True
            if nee > self.edge_entries.cap:
                self.edge_entries = _Entries(int(nee * 1.5))
                grown = True
            if not grown:
                break
            self.realloc_count += 1
        self._fill_entries(self.geo, self.tri_entries, self.edge_entries, st.x, m.face_verts,
                           m.edge_verts, nf, ne)
        # Proximity pairs (re-run once with a larger array on overflow).
        for _ in range(2):
            self._cnt[2] = 0
            self._find_pairs(self.geo, self.tri_entries, self.edge_entries, self.pairs,
                             st.x, m.face_verts, m.edge_verts, st.v, nv, ne)
            npairs = int(self._cnt[2])
            if npairs <= self.pairs.cap:
                break
            self.pairs = _Pairs(int(npairs * 1.5))
            self.realloc_count += 1
        npairs = min(npairs, self.pairs.cap)
        self.last_pairs = npairs
        if npairs > 0:
            self._impulses(self.geo, self.pairs, st.v, m.vert_mass, m.vert_pinned, npairs, h,
                           self.thickness, self.restore, self.iterations,
                           self.contact_mass_ratio)
            self._reintegrate(self.geo, st.x, st.v, m.vert_pinned, nv, h)
        ti.sync()
        self.last_ms = 1e3 * (time.perf_counter() - t0)

    @ti.kernel
    def _prepare(self, g: ti.template(), x: ti.template(), v: ti.template(), ev: ti.template(),
                 nv: ti.i32, ne: ti.i32, h: float):
        self._scal[0] = 0.0
        self._scal[1] = 0.0
        for i in range(nv):
            g.x0[i] = x[i] - h * v[i]
            g.touched[i] = 0
            ti.atomic_max(self._scal[0], v[i].norm())
        for e in range(ne):
            a, b = ev[e][0], ev[e][1]
            ti.atomic_add(self._scal[1], (g.x0[a] - g.x0[b]).norm())

    @ti.func
    def _cell(self, p):
        return ti.cast(ti.floor(p / self._scal[2]), ti.i32)

    @ti.func
    def _hash(self, g: ti.template(), c):
        hv = (c[0] * 73856093) ^ (c[1] * 19349663) ^ (c[2] * 83492791)
        return hv & (g.n_buckets - 1)

    # Boxes are swept over the substep (start x0 to predicted end x = x0 + h v), so the
    # broad phase needs no global speed bound: a slow region stays cheap when one corner flaps.
    @ti.func
    def _tri_box(self, g: ti.template(), x: ti.template(), fv: ti.template(), t, grow):
        f = fv[t]
        lo = ti.min(g.x0[f[0]], x[f[0]])
        hi = ti.max(g.x0[f[0]], x[f[0]])
        for j in ti.static(range(1, 3)):
            lo = ti.min(lo, ti.min(g.x0[f[j]], x[f[j]]))
            hi = ti.max(hi, ti.max(g.x0[f[j]], x[f[j]]))
        r = self._scal[3] * grow
        return lo - r, hi + r

    @ti.func
    def _edge_box(self, g: ti.template(), x: ti.template(), ev: ti.template(), e, grow):
        a, b = ev[e][0], ev[e][1]
        lo = ti.min(ti.min(g.x0[a], x[a]), ti.min(g.x0[b], x[b]))
        hi = ti.max(ti.max(g.x0[a], x[a]), ti.max(g.x0[b], x[b]))
        r = self._scal[3] * grow
        return lo - r, hi + r

    @ti.kernel
    def _count_entries(self, g: ti.template(), x: ti.template(), fv: ti.template(),
                       ev: ti.template(), nf: ti.i32, ne: ti.i32):
        self._cnt[0] = 0
        self._cnt[1] = 0
        for b in range(g.n_buckets):
            g.tri_count[b] = 0
            g.edge_count[b] = 0
        for t in range(nf):
            lo, hi = self._tri_box(g, x, fv, t, 1.0)
            c0, c1 = self._cell(lo), self._cell(hi)
            for i, j, k in ti.ndrange((c0[0], c1[0] + 1), (c0[1], c1[1] + 1), (c0[2], c1[2] + 1)):
                ti.atomic_add(g.tri_count[self._hash(g, ti.Vector([i, j, k]))], 1)
                ti.atomic_add(self._cnt[0], 1)
        for e in range(ne):
            lo, hi = self._edge_box(g, x, ev, e, 1.0)
            c0, c1 = self._cell(lo), self._cell(hi)
            for i, j, k in ti.ndrange((c0[0], c1[0] + 1), (c0[1], c1[1] + 1), (c0[2], c1[2] + 1)):
                ti.atomic_add(g.edge_count[self._hash(g, ti.Vector([i, j, k]))], 1)
                ti.atomic_add(self._cnt[1], 1)

    @ti.kernel
    def _fill_entries(self, g: ti.template(), te: ti.template(), ee: ti.template(),
                      x: ti.template(), fv: ti.template(), ev: ti.template(), nf: ti.i32,
                      ne: ti.i32):
        # Exclusive prefix sums (serial: one pass over the buckets), counts reused as cursors.
        ti.loop_config(serialize=True)
        for _ in range(1):
            st = 0
            se = 0
            for b in range(g.n_buckets):
                g.tri_start[b] = st
                st += g.tri_count[b]
                g.tri_count[b] = 0
                g.edge_start[b] = se
                se += g.edge_count[b]
                g.edge_count[b] = 0
        # Serial fills: the order of entries within a bucket decides the order of the pair
        # list, and the impulses are applied in that order (Gauss-Seidel), so a parallel fill
        # made runs differ from run to run (measured: 8 mm after 10 tshirt frames; the chest
        # wrinkle measure of Table 2 moved by 15 % between two identical runs).
        ti.loop_config(serialize=True)
        for t in range(nf):
            lo, hi = self._tri_box(g, x, fv, t, 1.0)
            c0, c1 = self._cell(lo), self._cell(hi)
            for i, j, k in ti.ndrange((c0[0], c1[0] + 1), (c0[1], c1[1] + 1), (c0[2], c1[2] + 1)):
                c = ti.Vector([i, j, k])
                hb = self._hash(g, c)
                slot = g.tri_start[hb] + ti.atomic_add(g.tri_count[hb], 1)
                te.id[slot] = t
                te.cell[slot] = c
        ti.loop_config(serialize=True)
        for e in range(ne):
            lo, hi = self._edge_box(g, x, ev, e, 1.0)
            c0, c1 = self._cell(lo), self._cell(hi)
            for i, j, k in ti.ndrange((c0[0], c1[0] + 1), (c0[1], c1[1] + 1), (c0[2], c1[2] + 1)):
                c = ti.Vector([i, j, k])
                hb = self._hash(g, c)
                slot = g.edge_start[hb] + ti.atomic_add(g.edge_count[hb], 1)
                ee.id[slot] = e
                ee.cell[slot] = c

    @ti.func
    def _add_pair(self, pr: ti.template(), v: ti.template(), idx, w, n, d):
        # Keep a pair only if it is (nearly) in contact or closing fast enough to get there
        # within about two substeps at its present relative normal velocity: with a detection
        # radius of the order of an edge, most candidates are neighbours in the same layer
        # that are not approaching, and the serial impulse loop is the cost centre.
        vn = 0.0
        for j in ti.static(range(4)):
            vn += w[j] * v[idx[j]].dot(n)
        if d - self._scal[4] * ti.max(-vn, 0.0) < 1.5 * self._scal[5]:
            k = ti.atomic_add(self._cnt[2], 1)
            if k < pr.cap:
                pr.idx[k] = idx
                pr.w[k] = w
                pr.n[k] = n
                pr.d[k] = d

    @ti.kernel
    def _find_pairs(self, g: ti.template(), te: ti.template(), ee: ti.template(),
                    pr: ti.template(), x: ti.template(), fv: ti.template(), ev: ti.template(),
                    v: ti.template(), nv: ti.i32, ne: ti.i32):
        # Candidates: swept boxes overlap (the inserted primitive's grown by 1.5 thickness).
        # Each candidate is met in every cell both boxes cover; it is taken only in the cell
        # holding the low corner of the overlap, so once. Proximity is measured at the start.
        # Serial, so that the pair list has the same order in every run (see _fill_entries).
        # vertex - triangle
        ti.loop_config(serialize=True)
        for i in range(nv):
            p = g.x0[i]
            lo1 = ti.min(p, x[i])
            hi1 = ti.max(p, x[i])
            c0, c1 = self._cell(lo1), self._cell(hi1)
            for ci, cj, ck in ti.ndrange((c0[0], c1[0] + 1), (c0[1], c1[1] + 1),
                                         (c0[2], c1[2] + 1)):
                c = ti.Vector([ci, cj, ck])
                hb = self._hash(g, c)
                for s in range(g.tri_start[hb], g.tri_start[hb] + g.tri_count[hb]):
                    if all(te.cell[s] == c):
                        t = te.id[s]
                        f = fv[t]
                        if f[0] != i and f[1] != i and f[2] != i:
                            lo2, hi2 = self._tri_box(g, x, fv, t, 1.0)
                            if all(self._cell(ti.max(lo1, lo2)) == c) and all(lo1 <= hi2) \
                                    and all(lo2 <= hi1):
                                a, b, cc = g.x0[f[0]], g.x0[f[1]], g.x0[f[2]]
                                q, w = closest_on_triangle(p, a, b, cc)
                                dvec = p - q
                                d = dvec.norm()
                                fn = safe_normalize((b - a).cross(cc - a),
                                                    ti.Vector([0.0, 0.0, 1.0]))
                                if fn.dot(dvec) < 0.0:
                                    fn = -fn
                                n = fn
                                if d > 1e-9 * self._scal[2]:
                                    n = dvec / d
                                self._add_pair(pr, v, ti.Vector([i, f[0], f[1], f[2]]),
                                               ti.Vector([1.0, -w[0], -w[1], -w[2]]), n, d)
        # edge - edge (each unordered pair once: e2 > e)
        ti.loop_config(serialize=True)
        for e in range(ne):
            lo1, hi1 = self._edge_box(g, x, ev, e, 0.0)
            c0, c1 = self._cell(lo1), self._cell(hi1)
            a1, b1 = ev[e][0], ev[e][1]
            for ci, cj, ck in ti.ndrange((c0[0], c1[0] + 1), (c0[1], c1[1] + 1),
                                         (c0[2], c1[2] + 1)):
                c = ti.Vector([ci, cj, ck])
                hb = self._hash(g, c)
                for s in range(g.edge_start[hb], g.edge_start[hb] + g.edge_count[hb]):
                    e2 = ee.id[s]
                    if e2 > e and all(ee.cell[s] == c):
                        a2, b2 = ev[e2][0], ev[e2][1]
                        if a1 != a2 and a1 != b2 and b1 != a2 and b1 != b2:
                            lo2, hi2 = self._edge_box(g, x, ev, e2, 1.0)
                            if all(self._cell(ti.max(lo1, lo2)) == c) and all(lo1 <= hi2) \
                                    and all(lo2 <= hi1):
                                p1, q1 = g.x0[a1], g.x0[b1]
                                p2, q2 = g.x0[a2], g.x0[b2]
                                sa, tb = closest_segments(p1, q1, p2, q2)
                                dvec = (p1 + sa * (q1 - p1)) - (p2 + tb * (q2 - p2))
                                d = dvec.norm()
                                n = safe_normalize((q1 - p1).cross(q2 - p2),
                                                   ti.Vector([0.0, 0.0, 1.0]))
                                if d > 1e-9 * self._scal[2]:
                                    n = dvec / d
                                self._add_pair(pr, v, ti.Vector([a1, b1, a2, b2]),
                                               ti.Vector([1.0 - sa, sa, tb - 1.0, -tb]), n, d)

    @ti.kernel
    def _impulses(self, g: ti.template(), pr: ti.template(), v: ti.template(),
                  mass: ti.template(), pinned: ti.template(), npairs: ti.i32, h: float,
                  th: float, restore: float, iters: ti.i32, ratio: float):
        # Gauss-Seidel: pairs share vertices, so sequential updates converge where Jacobi
        # averaging would need many more sweeps.
        ti.loop_config(serialize=True)
        for _ in range(iters):
            for k in range(npairs):
                idx = pr.idx[k]
                w = pr.w[k]
                n = pr.n[k]
                gap = th - pr.d[k]
                target = gap / h
                if gap > 0.0:
                    target *= restore
                vn = 0.0
                denom = 0.0
                im = ti.Vector([0.0, 0.0, 0.0, 0.0])
                for j in ti.static(range(4)):
                    vn += w[j] * v[idx[j]].dot(n)
                    if pinned[idx[j]] == 0 and mass[idx[j]] > 0.0:
                        im[j] = 1.0 / mass[idx[j]]
                        if g.contact[idx[j]] != 0:
                            im[j] *= ratio
                    denom += w[j] * w[j] * im[j]
                if vn < target and denom > 0.0:
                    imp = (target - vn) / denom
                    for j in ti.static(range(4)):
                        if im[j] > 0.0:
                            v[idx[j]] += (w[j] * imp * im[j]) * n
                            g.touched[idx[j]] = 1

    @ti.kernel
    def _reintegrate(self, g: ti.template(), x: ti.template(), v: ti.template(),
                     pinned: ti.template(), nv: ti.i32, h: float):
        for i in range(nv):
            if g.touched[i] == 1 and pinned[i] == 0:
                x[i] = g.x0[i] + h * v[i]


@ti.data_oriented
class _Geo:
    """Per-vertex start positions and the hash buckets, sized from the model's capacities."""

    def __init__(self, v_cap, n_buckets):
        self.n_buckets = n_buckets
        self.x0 = ti.Vector.field(3, float, v_cap)
        self.touched = ti.field(ti.i32, v_cap)
        self.contact = ti.field(ti.i32, v_cap)
        self.tri_count = ti.field(ti.i32, n_buckets)
        self.tri_start = ti.field(ti.i32, n_buckets)
        self.edge_count = ti.field(ti.i32, n_buckets)
        self.edge_start = ti.field(ti.i32, n_buckets)


@ti.data_oriented
class _Entries:
    """Hash entries: primitive id and the cell it was inserted under (to reject collisions)."""

    def __init__(self, cap):
        self.cap = max(int(cap), 64)
        self.id = ti.field(ti.i32, self.cap)
        self.cell = ti.Vector.field(3, ti.i32, self.cap)


@ti.data_oriented
class _Pairs:
    """Proximity pairs: 4 vertices, weights, unit normal, start distance."""

    def __init__(self, cap):
        self.cap = max(int(cap), 64)
        self.idx = ti.Vector.field(4, ti.i32, self.cap)
        self.w = ti.Vector.field(4, float, self.cap)
        self.n = ti.Vector.field(3, float, self.cap)
        self.d = ti.field(float, self.cap)
