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

The search for pairs runs in parallel, and the pair list is the same in every run on any
number of threads: the impulses are applied in its order (Gauss-Seidel), so an order that
followed thread scheduling made two runs of the tshirt scene end 8 mm apart after 10 frames.
Each primitive that looks for pairs (a vertex, an edge) writes the pairs it keeps into its
own block of ``_Slots``, in the order it meets them (the hash's, filled serially); the blocks
are then packed in the primitives' order: vertex-triangle pairs by vertex, then edge-edge
pairs by edge.

Every buffer is an ndarray and every kernel a module-level function of ndarray arguments (the
model's arrays and the buffers below), so the kernels compile once per process however many
models and colliders it builds, and a buffer reallocated for a larger mesh needs no recompile.
The kernels with the most arrays take them in named argpacks (``GeoPack``, ``HashPack``,
``SlotPack``, ``PairPack``), as cloth/dynamics.py and cloth/strain/buffers.py do.
"""
import time

import taichi as ti

from .. import ndarrays
from ..ndarrays import A, T
from .geom import closest_on_triangle, closest_segments, safe_normalize
from .obstacles import THICKNESS


# Indices into SelfCollision._sums (written by _prepare) and _cnt (entry and pair counts, and
# the most pairs one primitive kept).
S_MAX_SPEED, S_EDGE_SUM = 0, 1
C_TRI, C_EDGE, C_PAIRS, C_MOST = 0, 1, 2, 3
# Pair slots per primitive at first (more when one keeps more: the search runs again).
FIRST_SLOTS = 8

# Named argument groups: the broad and narrow phase took up to 24 positional arguments. Made
# once per set of arrays (``SelfCollision._packs``, ndarrays.PackCache) and again when one was
# replaced (larger entry or pair arrays, a model with larger capacities).
#   geo    the substep's start and predicted end positions, velocities, face and edge vertices;
#   table  the spatial hash: bucket counts and starts, and the entries (id, cell) of the
#          triangles and of the edges;
#   slots  each primitive's block of kept pairs, their count and the block's place in the list
#          (``_Slots``);
#   pairs  the proximity pairs (``_Pairs``).
GeoPack = ti.types.argpack(x0=A, x=A, v=A, fv=A, ev=A)
HashPack = ti.types.argpack(tri_count=A, tri_start=A, edge_count=A, edge_start=A, te_id=A,
                            te_cell=A, ee_id=A, ee_cell=A)
SlotPack = ti.types.argpack(s_idx=A, s_w=A, s_n=A, s_d=A, s_count=A, s_offset=A)
PairPack = ti.types.argpack(p_idx=A, p_w=A, p_n=A, p_d=A)


def _pow2(n):
    p = 1
    while p < n:
        p *= 2
    return p


class SelfCollision:
    def __init__(self, model, thickness=THICKNESS, iterations=6, restore=0.5,
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
        self._sums = ti.ndarray(float, 2)      # S_MAX_SPEED, S_EDGE_SUM
        self._cnt = ti.ndarray(ti.i32, 4)      # C_TRI, C_EDGE, C_PAIRS: entries and pairs
        self._packs = ndarrays.PackCache()
        self._ensure_model_capacity()

    # -- allocation ----------------------------------------------------------------------------
    # Buffers are sized from the model's capacities and replaced by larger ones when a model
    # with larger capacities comes (the kernels take them as arguments, so nothing recompiles).
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
        self.slots = _Slots(V + E, FIRST_SLOTS)
        self.pairs = _Pairs(4 * V)

    # -- one substep ---------------------------------------------------------------------------
    def on_mesh_changed(self):
        self._ensure_model_capacity()

    def prepare_contacts(self):
        """Clear and return the per-vertex obstacle-contact flags (the collider sets them
        before ``resolve``); flagged vertices count ``1 / contact_mass_ratio`` times heavier."""
        self._ensure_model_capacity()
        ndarrays.zero(self.geo.contact)
        return self.geo.contact

    def resolve(self, h):
        t0 = time.perf_counter()
        self._ensure_model_capacity()
        m = self.model
        nv, nf, ne = m.n_verts, m.n_faces, m.n_edges
        st = m.state
        g = self.geo
        _prepare(g.x0, g.touched, st.x, st.v, m.edge_verts, nv, ne, h, self._sums)
        geo = self._packs.get("geo", GeoPack, x0=g.x0, x=st.x, v=st.v, fv=m.face_verts,
                              ev=m.edge_verts)
        mean_edge = float(self._sums[S_EDGE_SUM]) / max(ne, 1)
        r = 1.5 * self.thickness                  # detection radius
        cs = max(mean_edge, 2.0 * r)              # cell size
        ahead = 2.0 * h                           # look-ahead time for keeping a pair
        # Hash: count, prefix sum, fill (re-run once if an entry array was too small).
        for _ in range(2):
            _count_entries(geo, g.tri_count, g.edge_count, nf, ne, cs, r, self._cnt)
            nt, nee = int(self._cnt[C_TRI]), int(self._cnt[C_EDGE])
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
        te, ee = self.tri_entries, self.edge_entries
        table = self._packs.get("table", HashPack, tri_count=g.tri_count,
                                tri_start=g.tri_start, edge_count=g.edge_count,
                                edge_start=g.edge_start, te_id=te.id, te_cell=te.cell,
                                ee_id=ee.id, ee_cell=ee.cell)
        _fill_entries(geo, table, nf, ne, cs, r)
        # Proximity pairs: each primitive's into its slots (again with more slots when one
        # kept more than its block holds), then packed in order into the pair list.
        while True:
            _find_pairs(geo, table, self._slot_pack(), nv, ne, cs, r, ahead, self.thickness,
                        self.slots.k, self._cnt)
            most = int(self._cnt[C_MOST])
            if most <= self.slots.k:
                break
            self.slots = _Slots(self.slots.primitives, _pow2(most))
            self.realloc_count += 1
        _pair_offsets(self._slot_pack(), nv + ne, self._cnt)
        npairs = int(self._cnt[C_PAIRS])
        if npairs > self.pairs.cap:
            self.pairs = _Pairs(int(npairs * 1.5))
            self.realloc_count += 1
        if npairs > 0:
            _pack_pairs(self._slot_pack(), self._pair_pack(), nv + ne, self.slots.k)
        self.last_pairs = npairs
        if npairs > 0:
            _impulses(g.contact, g.touched, self._pair_pack(), st.v, m.vert_mass,
                      m.vert_pinned, npairs, h, self.thickness, self.restore, self.iterations,
                      self.contact_mass_ratio)
            _reintegrate(g.x0, g.touched, st.x, st.v, m.vert_pinned, nv, h)
        ti.sync()
        self.last_ms = 1e3 * (time.perf_counter() - t0)

    def _pair_pack(self):
        pr = self.pairs
        return self._packs.get("pairs", PairPack, p_idx=pr.idx, p_w=pr.w, p_n=pr.n, p_d=pr.d)

    def _slot_pack(self):
        sl = self.slots
        return self._packs.get("slots", SlotPack, s_idx=sl.idx, s_w=sl.w, s_n=sl.n, s_d=sl.d,
                               s_count=sl.count, s_offset=sl.offset)


class _Geo:
    """Per-vertex start positions and flags, and the hash buckets, sized from the model's
    capacities (``n_buckets`` a power of two)."""

    def __init__(self, v_cap, n_buckets):
        self.n_buckets = n_buckets
        self.x0 = ti.ndarray(ti.types.vector(3, float), v_cap)
        self.touched = ti.ndarray(ti.i32, v_cap)
        self.contact = ti.ndarray(ti.i32, v_cap)
        self.tri_count = ti.ndarray(ti.i32, n_buckets)
        self.tri_start = ti.ndarray(ti.i32, n_buckets)
        self.edge_count = ti.ndarray(ti.i32, n_buckets)
        self.edge_start = ti.ndarray(ti.i32, n_buckets)


class _Entries:
    """Hash entries: primitive id and the cell it was inserted under (to reject collisions)."""

    def __init__(self, cap):
        self.cap = max(int(cap), 64)
        self.id = ti.ndarray(ti.i32, self.cap)
        self.cell = ti.ndarray(ti.types.vector(3, ti.i32), self.cap)


class _Slots:
    """Each primitive's block of ``k`` pair slots (vertices 0..nv-1, then edges nv + e): the
    pairs it kept (as ``_Pairs``), how many, and where its block starts in the pair list."""

    def __init__(self, primitives, k):
        self.primitives, self.k = int(primitives), int(k)
        n = self.primitives * self.k
        self.idx = ti.ndarray(ti.types.vector(4, ti.i32), n)
        self.w = ti.ndarray(ti.types.vector(4, float), n)
        self.n = ti.ndarray(ti.types.vector(3, float), n)
        self.d = ti.ndarray(float, n)
        self.count = ti.ndarray(ti.i32, self.primitives)
        self.offset = ti.ndarray(ti.i32, self.primitives)


class _Pairs:
    """Proximity pairs: 4 vertices, weights, unit normal, start distance."""

    def __init__(self, cap):
        self.cap = max(int(cap), 64)
        self.idx = ti.ndarray(ti.types.vector(4, ti.i32), self.cap)
        self.w = ti.ndarray(ti.types.vector(4, float), self.cap)
        self.n = ti.ndarray(ti.types.vector(3, float), self.cap)
        self.d = ti.ndarray(float, self.cap)


# -- kernels and their helpers -------------------------------------------------------------------
# Names: x0 start positions, x predicted end positions, v velocities, fv / ev face and edge
# vertices (loose, or members of ``geo``); cs the hash cell size, r the detection radius
# (1.5 x thickness).

@ti.kernel
def _prepare(x0: A, touched: A, x: A, v: A, ev: A, nv: ti.i32, ne: ti.i32, h: float, sums: A):
    sums[S_MAX_SPEED] = 0.0
    sums[S_EDGE_SUM] = 0.0
    for i in range(nv):
        x0[i] = x[i] - h * v[i]
        touched[i] = 0
        ti.atomic_max(sums[S_MAX_SPEED], v[i].norm())
    for e in range(ne):
        a, b = ev[e][0], ev[e][1]
        ti.atomic_add(sums[S_EDGE_SUM], (x0[a] - x0[b]).norm())


@ti.func
def _cell(p, cs):
    return ti.cast(ti.floor(p / cs), ti.i32)


@ti.func
def _hash(c, n_buckets):
    hv = (c[0] * 73856093) ^ (c[1] * 19349663) ^ (c[2] * 83492791)
    return hv & (n_buckets - 1)


# Boxes are swept over the substep (start x0 to predicted end x = x0 + h v), so the
# broad phase needs no global speed bound: a slow region stays cheap when one corner flaps.
@ti.func
def _tri_box(x0: T, x: T, fv: T, t, r):
    f = fv[t]
    lo = ti.min(x0[f[0]], x[f[0]])
    hi = ti.max(x0[f[0]], x[f[0]])
    for j in ti.static(range(1, 3)):
        lo = ti.min(lo, ti.min(x0[f[j]], x[f[j]]))
        hi = ti.max(hi, ti.max(x0[f[j]], x[f[j]]))
    return lo - r, hi + r


@ti.func
def _edge_box(x0: T, x: T, ev: T, e, r):
    a, b = ev[e][0], ev[e][1]
    lo = ti.min(ti.min(x0[a], x[a]), ti.min(x0[b], x[b]))
    hi = ti.max(ti.max(x0[a], x[a]), ti.max(x0[b], x[b]))
    return lo - r, hi + r


@ti.kernel
def _count_entries(geo: GeoPack, tri_count: A, edge_count: A, nf: ti.i32, ne: ti.i32,
                   cs: float, r: float, cnt: A):
    nb = tri_count.shape[0]
    cnt[C_TRI] = 0
    cnt[C_EDGE] = 0
    for b in range(nb):
        tri_count[b] = 0
        edge_count[b] = 0
    for t in range(nf):
        lo, hi = _tri_box(geo.x0, geo.x, geo.fv, t, r)
        c0, c1 = _cell(lo, cs), _cell(hi, cs)
        for i, j, k in ti.ndrange((c0[0], c1[0] + 1), (c0[1], c1[1] + 1), (c0[2], c1[2] + 1)):
            ti.atomic_add(tri_count[_hash(ti.Vector([i, j, k]), nb)], 1)
        span = c1 - c0 + 1
        ti.atomic_add(cnt[C_TRI], span[0] * span[1] * span[2])
    for e in range(ne):
        lo, hi = _edge_box(geo.x0, geo.x, geo.ev, e, r)
        c0, c1 = _cell(lo, cs), _cell(hi, cs)
        for i, j, k in ti.ndrange((c0[0], c1[0] + 1), (c0[1], c1[1] + 1), (c0[2], c1[2] + 1)):
            ti.atomic_add(edge_count[_hash(ti.Vector([i, j, k]), nb)], 1)
        span = c1 - c0 + 1
        ti.atomic_add(cnt[C_EDGE], span[0] * span[1] * span[2])


@ti.kernel
def _fill_entries(geo: GeoPack, table: HashPack, nf: ti.i32, ne: ti.i32, cs: float, r: float):
    nb = table.tri_count.shape[0]
    # Exclusive prefix sums (serial: one pass over the buckets), counts reused as cursors.
    ti.loop_config(serialize=True)
    for _ in range(1):
        st = 0
        se = 0
        for b in range(nb):
            table.tri_start[b] = st
            st += table.tri_count[b]
            table.tri_count[b] = 0
            table.edge_start[b] = se
            se += table.edge_count[b]
            table.edge_count[b] = 0
    # Serial fills, so that a bucket's entries come in the elements' order, and with them each
    # primitive's pairs (_find_pairs). Parallel fills with atomic cursors were slower on two
    # cores (tshirt, 2,385 faces: 1.9-2.0 ms a fill against 1.3 serial).
    ti.loop_config(serialize=True)
    for t in range(nf):
        lo, hi = _tri_box(geo.x0, geo.x, geo.fv, t, r)
        _insert(t, lo, hi, cs, nb, table.tri_start, table.tri_count, table.te_id,
                table.te_cell)
    ti.loop_config(serialize=True)
    for e in range(ne):
        lo, hi = _edge_box(geo.x0, geo.x, geo.ev, e, r)
        _insert(e, lo, hi, cs, nb, table.edge_start, table.edge_count, table.ee_id,
                table.ee_cell)


@ti.func
def _insert(elem, lo, hi, cs, nb, start: T, count: T, ids: T, cells: T):
    """Element ``elem`` into every hash bucket its box [lo, hi] overlaps (the bucket's next
    free slot of the counting sort)."""
    c0, c1 = _cell(lo, cs), _cell(hi, cs)
    for i, j, k in ti.ndrange((c0[0], c1[0] + 1), (c0[1], c1[1] + 1), (c0[2], c1[2] + 1)):
        c = ti.Vector([i, j, k])
        hb = _hash(c, nb)
        slot = start[hb] + ti.atomic_add(count[hb], 1)
        ids[slot] = elem
        cells[slot] = c


@ti.func
def _keep(v: T, idx, w, n, d, ahead, th):
    """Whether a candidate is kept: (nearly) in contact, or closing fast enough to get there
    within about two substeps at its present relative normal velocity. With a detection
    radius of the order of an edge, most candidates are neighbours in the same layer that are
    not approaching, and the serial impulse loop is the cost centre."""
    vn = 0.0
    for j in ti.static(range(4)):
        vn += w[j] * v[idx[j]].dot(n)
    return d - ahead * ti.max(-vn, 0.0) < 1.5 * th


@ti.func
def _put(slots: T, p, c, k_slots, idx, w, n, d):
    """The c-th pair kept by primitive ``p`` into its block (dropped past the block's end:
    the search then runs again with larger blocks)."""
    if c < k_slots:
        s = p * k_slots + c
        slots.s_idx[s] = idx
        slots.s_w[s] = w
        slots.s_n[s] = n
        slots.s_d[s] = d


@ti.kernel
def _find_pairs(geo: GeoPack, table: HashPack, slots: SlotPack, nv: ti.i32, ne: ti.i32,
                cs: float, r: float, ahead: float, th: float, k_slots: ti.i32, cnt: A):
    # Candidates: swept boxes overlap (the inserted primitive's grown by 1.5 thickness).
    # Each candidate is met in every cell both boxes cover; it is taken only in the cell
    # holding the low corner of the overlap, so once. Proximity is measured at the start.
    # Parallel: each vertex and edge keeps its pairs in its own slots, in the order it
    # meets them, so the list _pack_pairs makes does not depend on the threads.
    nb = table.tri_count.shape[0]
    cnt[C_MOST] = 0
    # vertex - triangle
    for i in range(nv):
        kept = 0
        p = geo.x0[i]
        lo1 = ti.min(p, geo.x[i])
        hi1 = ti.max(p, geo.x[i])
        c0, c1 = _cell(lo1, cs), _cell(hi1, cs)
        for ci, cj, ck in ti.ndrange((c0[0], c1[0] + 1), (c0[1], c1[1] + 1),
                                     (c0[2], c1[2] + 1)):
            c = ti.Vector([ci, cj, ck])
            hb = _hash(c, nb)
            for s in range(table.tri_start[hb], table.tri_start[hb] + table.tri_count[hb]):
                if all(table.te_cell[s] == c):
                    t = table.te_id[s]
                    f = geo.fv[t]
                    if f[0] != i and f[1] != i and f[2] != i:
                        lo2, hi2 = _tri_box(geo.x0, geo.x, geo.fv, t, r)
                        if all(_cell(ti.max(lo1, lo2), cs) == c) and all(lo1 <= hi2) \
                                and all(lo2 <= hi1):
                            a, b, cc = geo.x0[f[0]], geo.x0[f[1]], geo.x0[f[2]]
                            q, w = closest_on_triangle(p, a, b, cc)
                            dvec = p - q
                            d = dvec.norm()
                            fn = safe_normalize((b - a).cross(cc - a),
                                                ti.Vector([0.0, 0.0, 1.0]))
                            if fn.dot(dvec) < 0.0:
                                fn = -fn
                            n = fn
                            if d > 1e-9 * cs:
                                n = dvec / d
                            idx = ti.Vector([i, f[0], f[1], f[2]])
                            wts = ti.Vector([1.0, -w[0], -w[1], -w[2]])
                            if _keep(geo.v, idx, wts, n, d, ahead, th):
                                _put(slots, i, kept, k_slots, idx, wts, n, d)
                                kept += 1
        slots.s_count[i] = kept
        ti.atomic_max(cnt[C_MOST], kept)
    # edge - edge (each unordered pair once: e2 > e)
    for e in range(ne):
        kept = 0
        lo1, hi1 = _edge_box(geo.x0, geo.x, geo.ev, e, 0.0)
        c0, c1 = _cell(lo1, cs), _cell(hi1, cs)
        a1, b1 = geo.ev[e][0], geo.ev[e][1]
        for ci, cj, ck in ti.ndrange((c0[0], c1[0] + 1), (c0[1], c1[1] + 1),
                                     (c0[2], c1[2] + 1)):
            c = ti.Vector([ci, cj, ck])
            hb = _hash(c, nb)
            for s in range(table.edge_start[hb], table.edge_start[hb] + table.edge_count[hb]):
                e2 = table.ee_id[s]
                if e2 > e and all(table.ee_cell[s] == c):
                    a2, b2 = geo.ev[e2][0], geo.ev[e2][1]
                    if a1 != a2 and a1 != b2 and b1 != a2 and b1 != b2:
                        lo2, hi2 = _edge_box(geo.x0, geo.x, geo.ev, e2, r)
                        if all(_cell(ti.max(lo1, lo2), cs) == c) and all(lo1 <= hi2) \
                                and all(lo2 <= hi1):
                            p1, q1 = geo.x0[a1], geo.x0[b1]
                            p2, q2 = geo.x0[a2], geo.x0[b2]
                            sa, tb = closest_segments(p1, q1, p2, q2)
                            dvec = (p1 + sa * (q1 - p1)) - (p2 + tb * (q2 - p2))
                            d = dvec.norm()
                            n = safe_normalize((q1 - p1).cross(q2 - p2),
                                               ti.Vector([0.0, 0.0, 1.0]))
                            if d > 1e-9 * cs:
                                n = dvec / d
                            idx = ti.Vector([a1, b1, a2, b2])
                            wts = ti.Vector([1.0 - sa, sa, tb - 1.0, -tb])
                            if _keep(geo.v, idx, wts, n, d, ahead, th):
                                _put(slots, nv + e, kept, k_slots, idx, wts, n, d)
                                kept += 1
        slots.s_count[nv + e] = kept
        ti.atomic_max(cnt[C_MOST], kept)


@ti.kernel
def _pair_offsets(slots: SlotPack, n_prim: ti.i32, cnt: A):
    """Where each primitive's pairs start in the list (an exclusive prefix sum of the
    counts, serial: one pass over the primitives); the total into cnt[C_PAIRS]."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        total = 0
        for p in range(n_prim):
            slots.s_offset[p] = total
            total += slots.s_count[p]
        cnt[C_PAIRS] = total


@ti.kernel
def _pack_pairs(slots: SlotPack, pairs: PairPack, n_prim: ti.i32, k_slots: ti.i32):
    """Each primitive's block copied to its place in the list."""
    for p in range(n_prim):
        base = p * k_slots
        c = slots.s_count[p]
        o = slots.s_offset[p]
        for j in range(c):
            pairs.p_idx[o + j] = slots.s_idx[base + j]
            pairs.p_w[o + j] = slots.s_w[base + j]
            pairs.p_n[o + j] = slots.s_n[base + j]
            pairs.p_d[o + j] = slots.s_d[base + j]


@ti.kernel
def _impulses(contact: A, touched: A, pairs: PairPack, v: A, mass: A, pinned: A,
              npairs: ti.i32, h: float, th: float, restore: float, iters: ti.i32, ratio: float):
    # Gauss-Seidel: pairs share vertices, so sequential updates converge where Jacobi
    # averaging would need many more sweeps.
    ti.loop_config(serialize=True)
    for _ in range(iters):
        for k in range(npairs):
            idx = pairs.p_idx[k]
            w = pairs.p_w[k]
            n = pairs.p_n[k]
            gap = th - pairs.p_d[k]
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
                    if contact[idx[j]] != 0:
                        im[j] *= ratio
                denom += w[j] * w[j] * im[j]
            if vn < target and denom > 0.0:
                imp = (target - vn) / denom
                for j in ti.static(range(4)):
                    if im[j] > 0.0:
                        v[idx[j]] += (w[j] * imp * im[j]) * n
                        touched[idx[j]] = 1


@ti.kernel
def _reintegrate(x0: A, touched: A, x: A, v: A, pinned: A, nv: ti.i32, h: float):
    for i in range(nv):
        if touched[i] == 1 and pinned[i] == 0:
            x[i] = x0[i] + h * v[i]
