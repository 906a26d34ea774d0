"""An experiment, not the simulator's path: the implicit step's CG with its loops over the
faces and vertices on every CPU thread (the second parallel design tried, docs/speed/
parallel.md, which has its timings and why it is not used). ``ParallelCG(dyn).step(dyn, h)``
does what ``ImplicitEuler.step(h)`` does; benchmarks/parallel_cg_step.py times the two and
tests/test_dynamics_parallel.py checks that they agree. To use it in the simulator,
``ImplicitEuler.step`` would call it for meshes above a size (on a CPU with more than one
Taichi thread) once it wins there.

The step is three kinds of launch with the CG loop's control on the host:

- ``begin`` (serial, as the serial step): linearise, prescribe the pinned dv, start PCG; it leaves
  r.z, b.P b and whether CG is to run in ``scal``.
- ``iterations``: ``BLOCK`` CG iterations a launch, unrolled; each iteration is four
  parallel loops and two serial sums:
    1. a loop over the faces: each face's membrane K p (``dynamics.face_UW``, the serial
       loop's own func) split into its three corner terms, each written to its own slot of
       ``corner`` (no two faces write one slot: no atomics);
    2. a loop over the vertices: each free vertex gathers its own row of A p: the mass, its
       face corners (the slots of vertex i are face_ptr[i] .. face_ptr[i+1], a CSR list built
       on the host once per mesh, ``Incidence``), its hinges' terms (the hinge energy,
       computed in place from its vertex -> hinge list), its row of the bending matrix Q
       (``dynamics.bend_row``), its stitches, and the pin filter; it writes A p and its term
       of p.A p into ``part``;
    3. (serial) p.A p = the sum of ``part`` in vertex order; the step length;
    4. dv, r and z = P r per vertex, and each vertex's term of r.z;
    5. (serial) r.z in vertex order, CG's beta, the relative residual, whether to go on;
    6. p = z + beta p (pinned rows filtered).
  An iteration after CG stopped runs its loops over zero elements.
- ``finish`` (serial): v += dv, x += h v, pins on target; returns (relative residual,
  iterations) as ``_step`` does.

Answers: every vertex adds its terms in the order the serial ``apply_A`` does (mass, faces in
face order, hinges in edge order, its bending row, stitches in stitch order, then the pin
filter), each term by the same expression, and the two dot products are summed by one thread
in vertex order, as the serial loop sums them; so the result does not depend on the thread
count. It is not bit for bit the serial kernel's (Taichi compiles with fast math, and LLVM
may reorder the serial kernel's sums): tests/test_dynamics_parallel.py measured the same CG
iterations and positions within 2e-16 m, velocities 7e-15 m/s, after four steps.

Why this shape (Taichi 1.7.4 on the CPU, docs/speed/parallel.md): a parallel range-for is
split into tasks of at least 512 iterations (so the loops run over faces and vertices, and
meshes under ~1,000 vertices stay on one core), each parallel loop costs 6-16 us to start
(so one face loop and one gather loop per A p, not a loop per element kind, and the hinges'
and stitches' terms computed by the vertices that receive them), and a kernel's top-level
locals are slow inside parallel bodies (so the step's constants are the kernel's own scalar
arguments, and the CG scalars and counts are read from ``scal``). The kernels are made at
first use (``kernels``): a benchmark module makes no Taichi type on import.
"""
import numpy as np
import taichi as ti

from cloth.ndarrays import A, T

# CG iterations an ``iterations`` launch (unrolled): a launch with its ~35 arrays costs
# ~0.2 ms on the host, an iteration after CG stopped ~40 us of empty loops.
BLOCK = 16

# ``scal``: the CG's scalars between the phases (a float ndarray, written by the serial tasks).
# The counts and CG's stopping rule too (``_begin`` copies them from ``coef``).
S_RZ, S_BNORM, S_REL, S_ITERS, S_ACTIVE, S_STEP, S_BETA, S_P, S_NV, S_NF, S_TOL, S_MAX_ITERS = \
    range(12)
N_SCAL = 12


class Incidence:
    """Vertex -> element lists (CSR, built on the host from the mesh's numpy arrays and
    uploaded as ndarrays), each vertex's list in element order (a stable sort), the order the
    serial loops add the elements' terms in:
    - faces: vertex i's face corners are the slots face_ptr[i] .. face_ptr[i+1] of the
      corner array the face pass writes; ``face_slot[f, n]`` is the slot of corner n of f;
    - hinges (interior edges, the hinge energy only): entries 4 e + n, n the stencil vertex;
    - stitches: entries 2 s + end."""

    def __init__(self, nv, faces, stencils, stitches):
        self.key = None
        ptr, order = self._csr(nv, faces)
        slot = np.empty(len(order), np.int32)
        slot[order] = np.arange(len(order), dtype=np.int32)
        self.face_ptr = self._upload(ptr)
        self.face_slot = ti.ndarray(ti.types.vector(3, ti.i32), max(len(faces), 1))
        self.face_slot.from_numpy(slot.reshape(-1, 3) if len(faces) else
                                  np.zeros((1, 3), np.int32))
        ids = stencils[:, 4] if len(stencils) else np.zeros(0, np.int64)
        ptr, order = self._csr(nv, stencils[:, :4])
        entry = (4 * ids[:, None] + np.arange(4)[None, :]).reshape(-1)
        self.hinge_ptr, self.hinge_idx = self._upload(ptr), self._upload(entry[order])
        ptr, order = self._csr(nv, stitches)
        self.stitch_ptr, self.stitch_idx = self._upload(ptr), self._upload(order)

    @staticmethod
    def _csr(nv, elems):
        """(ptr, order): vertex i's entries are order[ptr[i]:ptr[i+1]], each the position
        k e + n of a vertex in the flattened (n_elems, k) array ``elems``, increasing."""
        verts = np.asarray(elems, np.int64).reshape(-1)
        order = np.argsort(verts, kind="stable").astype(np.int32)
        ptr = np.zeros(nv + 1, np.int32)
        np.cumsum(np.bincount(verts, minlength=nv), out=ptr[1:])
        return ptr, order

    @staticmethod
    def _upload(a):
        a = np.asarray(a, np.int32)
        nd = ti.ndarray(ti.i32, max(len(a), 1))
        nd.from_numpy(a if len(a) else np.zeros(1, np.int32))
        return nd


def incidence(dyn):
    """The ``Incidence`` of ``dyn``'s mesh, its bending energy and its stitches, built again
    only when one of them changed (a remesh, new stitches)."""
    m = dyn.model
    faces = m.faces
    key = (faces, m.bending, m.n_verts, dyn.n_hinges, dyn.stitches_np.tobytes())
    inc = getattr(dyn, "_incidence", None)
    if inc is not None and inc.key[0] is faces and inc.key[1:] == key[1:]:
        return inc
    if dyn.n_hinges:
        ev, ef, eo = m.edge_topology()
        inner = np.flatnonzero(np.asarray(ef)[:, 1] >= 0)
        stencils = np.c_[np.asarray(ev)[inner], np.asarray(eo)[inner], inner]
    else:
        stencils = np.zeros((0, 5), np.int64)
    st = dyn.stitches_np if dyn.n_stitches else np.zeros((0, 2), np.int64)
    inc = Incidence(m.n_verts, np.asarray(faces), stencils, st)
    inc.key = key          # holds ``faces``: its id cannot be reused while this is kept
    dyn._incidence = inc
    return inc


# The arrays ``_iterations`` reads, in one argpack of its own (cloth's kernels take at most 12
# parameters, tests/test_kernel_signatures.py); made once per set of arrays (``PackCache``).
ITER_MEMBERS = {
    "mesh": ("vert_mass", "vert_pinned", "face_verts", "face_rest_area", "edge_verts",
             "edge_opp", "edge_bend_weight", "bend_ptr", "bend_col", "bend_val"),
    "dyn": ("stitch", "face_fu", "face_fv", "face_E", "face_wa", "face_wb", "edge_grad", "dv",
            "res", "z", "p", "Ap", "precond"),
    "inc": ("face_ptr", "face_slot", "hinge_ptr", "hinge_idx", "stitch_ptr", "stitch_idx"),
    "own": ("part", "scal", "corner"),
}


_KERNELS = {}


def kernels():
    """The experiment's Taichi types and kernels, made at the first call (after
    ``backend.init``: a benchmark module creates no Taichi type on import,
    tests/test_backend.py)."""
    if not _KERNELS:
        _KERNELS.update(_build())
    return _KERNELS


def _build():
    from cloth import dynamics

    # -- the row of A p a vertex gathers ---------------------------------------------------
    @ti.func
    def _stencil_vertex(e, n, edge_verts: T, edge_opp: T):
        ev, eo = edge_verts[e], edge_opp[e]
        vid = eo[1]
        if n == 0:
            vid = ev[0]
        elif n == 1:
            vid = ev[1]
        elif n == 2:
            vid = eo[0]
        return vid

    IterPack = ti.types.argpack(**{name: A for names in ITER_MEMBERS.values() for name in names})

    @ti.kernel
    def _iterations(mf: float, sc: float, kw: float, kf: float, ks: float, kb: float, skb: float,
                    skst: float, a: IterPack) -> float:
        """``BLOCK`` CG iterations (module docstring). mf = 1 + h alpha, sc = h (beta + h),
        skb = sc kb, skst = sc kst: the factors the serial ``apply_A`` forms, formed the same
        way on the host; the counts and CG's stopping rule are in ``scal`` (``_begin``)."""
        for _it in ti.static(range(BLOCK)):
            # 1. Each face's membrane K p (``dynamics.face_UW``), a term per corner, each in
            #    its own slot of ``corner``.
            for f in range(ti.cast(a.scal[S_ACTIVE], ti.i32) * ti.cast(a.scal[S_NF], ti.i32)):
                U, W = dynamics.face_UW(f, a.p, sc, kw, kf, ks, 0, a.face_verts, a.face_rest_area,
                                        a.face_fu, a.face_fv, a.face_E, a.face_wa, a.face_wb)
                wa, wb = a.face_wa[f], a.face_wb[f]
                slot = a.face_slot[f]
                for n in ti.static(range(3)):
                    a.corner[slot[n]] = wa[n] * U + wb[n] * W
            # 2. A p, row by row, and each row's term of p.A p.
            for i in range(ti.cast(a.scal[S_ACTIVE], ti.i32) * ti.cast(a.scal[S_NV], ti.i32)):
                acc = ti.Vector([0.0, 0.0, 0.0])
                if a.vert_pinned[i] == 0:
                    pi = a.p[i]
                    acc = mf * a.vert_mass[i] * pi
                    for k in range(a.face_ptr[i], a.face_ptr[i + 1]):
                        acc += a.corner[k]
                    for k in range(a.hinge_ptr[i], a.hinge_ptr[i + 1]):
                        e = a.hinge_idx[k] // 4
                        n = a.hinge_idx[k] - 4 * e
                        kh = kb * a.edge_bend_weight[e]
                        G = a.edge_grad[e]
                        dtheta = 0.0
                        for q in ti.static(range(4)):
                            dtheta += ti.Vector([G[q, 0], G[q, 1], G[q, 2]]).dot(
                                a.p[_stencil_vertex(e, q, a.edge_verts, a.edge_opp)])
                        acc += sc * kh * dtheta * ti.Vector([G[n, 0], G[n, 1], G[n, 2]])
                    if i < a.bend_ptr.shape[0] - 1:
                        acc += skb * dynamics.bend_row(i, a.p, a.bend_ptr, a.bend_col, a.bend_val)
                    for k in range(a.stitch_ptr[i], a.stitch_ptr[i + 1]):
                        s = a.stitch_idx[k] // 2
                        d = a.p[a.stitch[s][0]] - a.p[a.stitch[s][1]]
                        if a.stitch_idx[k] - 2 * s == 0:
                            acc += skst * d
                        else:
                            acc -= skst * d
                a.Ap[i] = acc
                a.part[i] = a.p[i].dot(acc)
            # 3. p.A p in vertex order; the step length, or stop where p.A p <= 0 (stalled).
            ti.loop_config(serialize=True)
            for _ in range(ti.cast(a.scal[S_ACTIVE], ti.i32)):
                pAp = 0.0
                for i in range(ti.cast(a.scal[S_NV], ti.i32)):
                    pAp += a.part[i]
                if pAp > 0.0:
                    a.scal[S_STEP] = a.scal[S_RZ] / pAp
                else:
                    a.scal[S_ACTIVE] = 0.0
            # 4. dv, r, z and each vertex's r.z.
            for i in range(ti.cast(a.scal[S_ACTIVE], ti.i32) * ti.cast(a.scal[S_NV], ti.i32)):
                step = a.scal[S_STEP]
                a.dv[i] += step * a.p[i]
                a.res[i] -= step * a.Ap[i]
                a.z[i] = a.precond[i] @ a.res[i]
                a.part[i] = a.res[i].dot(a.z[i])
            # 5. r.z in vertex order, beta, the relative residual, whether to go on.
            ti.loop_config(serialize=True)
            for _ in range(ti.cast(a.scal[S_ACTIVE], ti.i32)):
                rz_new = 0.0
                for i in range(ti.cast(a.scal[S_NV], ti.i32)):
                    rz_new += a.part[i]
                a.scal[S_BETA] = rz_new / a.scal[S_RZ]
                a.scal[S_RZ] = rz_new
                rel = dynamics.relative(rz_new, a.scal[S_BNORM])
                a.scal[S_REL] = rel
                iters = a.scal[S_ITERS] + 1.0
                a.scal[S_ITERS] = iters
                a.scal[S_P] = 1.0
                if not (iters < a.scal[S_MAX_ITERS] and rel > a.scal[S_TOL]):
                    a.scal[S_ACTIVE] = 0.0
            # 6. p = z + beta p, pinned rows filtered (after the iteration that stopped CG too).
            for i in range(ti.cast(a.scal[S_P], ti.i32) * ti.cast(a.scal[S_NV], ti.i32)):
                if a.vert_pinned[i] != 0:
                    a.p[i] = ti.Vector([0.0, 0.0, 0.0])
                else:
                    a.p[i] = a.z[i] + a.scal[S_BETA] * a.p[i]
            ti.loop_config(serialize=True)
            for _ in range(1):
                a.scal[S_P] = 0.0
        return a.scal[S_ACTIVE]

    @ti.kernel
    def _begin(coef: A, mesh: dynamics.MeshPack, state: dynamics.StatePack,
               elems: dynamics.ElementPack, cg: dynamics.SolvePack, scal: A):
        ti.loop_config(serialize=True)
        for _ in range(1):
            c = dynamics.constants(coef)
            rb = dynamics.cg_begin(c, mesh, state, elems, cg)
            rel = dynamics.relative(rb[0], rb[1])
            scal[S_RZ], scal[S_BNORM], scal[S_REL] = rb[0], rb[1], rel
            scal[S_ITERS], scal[S_P] = 0.0, 0.0
            scal[S_NV], scal[S_NF] = coef[dynamics.C_NV], coef[dynamics.C_NF]
            scal[S_TOL], scal[S_MAX_ITERS] = c.tol, coef[dynamics.C_MAX_ITERS]
            scal[S_ACTIVE] = ti.select(0 < c.max_iters and rel > c.tol, 1.0, 0.0)

    @ti.kernel
    def _finish(coef: A, mesh: dynamics.MeshPack, state: dynamics.StatePack,
                cg: dynamics.SolvePack, scal: A) -> ti.types.vector(2, float):
        ti.loop_config(serialize=True)
        for _ in range(1):
            c = dynamics.constants(coef)
            dynamics.advance(c, mesh, state, cg)
            cg.scalars[0] = scal[S_REL]
            cg.scalars[1] = scal[S_ITERS]
        return ti.Vector([cg.scalars[0], cg.scalars[1]])

    return {"IterPack": IterPack, "iterations": _iterations, "begin": _begin,
            "finish": _finish}


class ParallelCG:
    """The parallel step's own arrays for one ``ImplicitEuler``."""

    def __init__(self, dyn):
        self.part = ti.ndarray(float, dyn.model.v_cap)
        self.scal = ti.ndarray(float, N_SCAL)
        vec3 = ti.types.vector(3, float)
        self.corner = ti.ndarray(vec3, 3 * dyn.model.f_cap)

    def step(self, dyn, h):
        """What ``dyn.step(h)`` does, with the parallel CG: (relative residual, iterations);
        also left in ``dyn.last_cg_residual`` and ``dyn.last_cg_iters``."""
        m, mat, s = dyn.model, dyn.model.material, dyn.settings
        m.mark_step_start()
        coef, mesh, state = dyn._constants(h), dyn._mesh(), dyn._state()
        inc = incidence(dyn)
        k = kernels()
        k["begin"](coef, mesh, state, dyn._elems, dyn._cg, self.scal)
        sc = h * (mat.damp_stiff + h)
        kb = mat.bend_scale()
        own = {"part": self.part, "scal": self.scal, "corner": self.corner}
        src = {"mesh": m, "dyn": dyn, "inc": inc}
        pack = dyn._packs.get("iter", k["IterPack"], **{
            name: own[name] if group == "own" else getattr(src[group], name)
            for group, names in ITER_MEMBERS.items() for name in names})
        args = (1.0 + h * mat.damp_mass, sc, mat.k_warp, mat.k_weft, mat.k_shear, kb, sc * kb,
                sc * s.stitch_stiffness, pack)
        while k["iterations"](*args) != 0.0:
            pass
        rel, iters = k["finish"](coef, mesh, state, dyn._cg, self.scal)
        dyn.last_cg_residual, dyn.last_cg_iters = float(rel), int(iters)
        return dyn.last_cg_residual, dyn.last_cg_iters
