"""Implicit (backward) Euler cloth dynamics: gravity, anisotropic membrane, dihedral bending,
stitch springs, damping and pins, one Newton step per substep solved by preconditioned CG.

Linearised system (Baraff & Witkin 1998), with K = -df/dx (made positive semi-definite, below),
mass damping ``alpha`` and stiffness damping ``beta``:

    [(1 + h alpha) M + h (beta + h) K] dv = h (f - alpha M v) - h (beta + h) K v

Pinned vertices get the dv that puts them on their target at the end of the step; CG works on
the other vertices only (the pinned rows are filtered, Baraff & Witkin's modified PCG).

Membrane: St. Venant-Kirchhoff in the triangle's grain frame. With F_g = F [e_warp e_weft]
= [f_u f_v] and Green strain E = (F_g^T F_g - I) / 2, the energy of a face of rest area A is
``A (k_warp E11^2 / 2 + k_weft E22^2 / 2 + 2 k_shear E12^2)``: separate warp, weft and shear
stiffness, exact for large rotations.

Bending, one of two energies (``ClothModel.bending``):
- isotropic (the default): ``(k_bend / 2) sum_c x_c^T Q x_c`` with Q a constant matrix built
  from the material mesh and its pins (cloth/bending.py), the plate energy (B / 2) |II|^2 of
  an isometric bend, consistent at free edges and clamps; k_bend is the flexural rigidity B in
  every direction (docs/calibration/calibration.md: back-to-back and ledge cantilevers over
  the calibration's patterns, directions, widths and 0.5-2 cm triangles). Its forces
  are -k_bend Q x and its stiffness k_bend Q, exactly; Q is stored by rows (``bend_ptr``,
  ``bend_col``, ``bend_val``), and it couples vertices two rings apart.
- hinge (discrete shells, for a curved rest shape): ``k_bend w_e (theta - theta_0)^2 / 2``
  per interior edge, theta its dihedral angle, ``w_e = BEND_CONSTANT |e|^2 / (A1 + A2)``
  (cloth/model.py); the dihedral-angle gradient is Bridson et al.'s (2003). B holds within
  5-11 % for strips along the mesh lines, not on the bias (up to 2.7 B).
The model leaves the other energy's arrays empty (zero hinge weights, or rows without
entries); under isotropic bending the kernels get no hinges to loop over (``n_hinges``).

Positive semi-definite K: the solver uses the Gauss-Newton part of every Hessian plus the
curvature terms that are non-negative (the stretch terms in tension). The dropped parts (stretch
curvature under compression, the indefinite shear curvature, the bending angle's curvature) make
the one Newton step robust instead of exact; ``force_jacobian_product(exact=True)`` gives the
exact membrane Jacobian for testing.

Why one long module: forces, their Jacobian product, its diagonal and its assembled
blocks must stay the same K; they share the element kinematics and ``face_block``.

Every kernel is a module-level ``@ti.kernel`` taking all its arrays (the model's and the
solver's work arrays, Taichi ndarrays) as arguments, and the ``@ti.func``s take the arrays they
read as ``ti.template()`` parameters: a kernel that captured fields (or a data_oriented
``self``) was compiled again for every new model and solver, 2.5-10 s per Simulator (issue
#15); these compile once per process (cloth/strain/buffers.py has the measurements). Kernels
that read the mesh take the model's arrays in the order of ``MESH_ARRAYS`` followed by x, v and
the element work arrays in the order of ``ImplicitEuler._elements`` (``*solver._mesh()``,
``*solver._elements()``). The price, measured against the field version (2-core CPU, f64):
~0.27 ms more argument handling per step and CG iterations ~1.35x slower (ndarray addressing;
0.28 -> 0.38 ms per iteration at 4.8k triangles).
"""
from dataclasses import dataclass

import numpy as np
import taichi as ti

from . import backend, ndarrays
from .model import ClothModel
from .ndarrays import A, T
from .settings import COMMON_DEFAULTS

_SIM = COMMON_DEFAULTS["sim"]


# The model's arrays the kernels read, in the order the kernels take them (then x and v).
MESH_ARRAYS = ("vert_mass", "vert_pinned", "vert_pin_target", "face_verts", "face_Dm_inv",
               "face_rest_area", "face_grain", "edge_verts", "edge_faces", "edge_opp",
               "edge_rest_angle", "edge_bend_weight", "bend_ptr", "bend_col", "bend_val")


@dataclass
class DynamicsSettings:
    """The dynamics' share of the ``sim`` settings; the defaults are the settings' (one place:
    cloth/settings.py COMMON_DEFAULTS)."""
    gravity: tuple = tuple(_SIM["gravity"])       # m/s^2
    cg_tol: float = _SIM["cg_tol"]     # relative residual (preconditioned norm) that stops CG
    cg_max_iters: int = _SIM["cg_iters"]
    stitch_stiffness: float = _SIM["stitch_stiffness"]   # N/m of the zero-length stitch springs

    def validate(self):
        if not self.cg_tol > 0:
            raise ValueError(f"dynamics.cg_tol must be > 0 (got {self.cg_tol})")
        if not self.cg_max_iters >= 1:
            raise ValueError(f"dynamics.cg_max_iters must be >= 1 (got {self.cg_max_iters})")


class ImplicitEuler:
    """One backward-Euler Newton step per call of ``step(h)``.

    After a step: ``last_cg_iters`` and ``last_cg_residual`` (relative)."""

    def __init__(self, model: ClothModel, settings: DynamicsSettings = None, stitches=None):
        self.model = model
        self.settings = settings or DynamicsSettings()
        self.settings.validate()
        self.stitches_np = np.zeros((0, 2), np.int32) if stitches is None else \
            np.asarray(stitches, np.int32).reshape(-1, 2)
        self.last_cg_iters = 0
        self.last_cg_residual = 0.0
        # The CG loop on the host, a launch per iteration, where one long launch fails
        # (backend.HOST_LOOP_AL: Vulkan, Metal; see ``_linearise``). Settable, for tests.
        self.host_loop = backend.arch() in backend.HOST_LOOP_AL
        # Every work array is allocated once, here, sized from the model's capacities (the
        # model never grows in place: the simulator builds a new model and new solvers). They
        # are kernel arguments, so a new solver compiles nothing.
        V, F, E = model.v_cap, model.f_cap, model.e_cap
        vec3 = ti.types.vector(3, float)
        vec = lambda n: ti.ndarray(vec3, n)  # noqa: E731
        self.force, self.dv, self.rhs, self.res = vec(V), vec(V), vec(V), vec(V)
        self.z, self.p, self.Ap = vec(V), vec(V), vec(V)
        self.precond = ti.ndarray(ti.types.matrix(3, 3, float), V)
        self.face_fu, self.face_fv, self.face_E = vec(F), vec(F), vec(F)
        self.face_wa, self.face_wb = vec(F), vec(F)   # warp / weft weights of the 3 verts
        self.edge_grad = ti.ndarray(ti.types.matrix(4, 3, float), E)
        self.edge_theta = ti.ndarray(float, E)
        self.scalars = ti.ndarray(float, 4)
        self.stitch_cap = max(len(self.stitches_np), 1)
        self.stitch = ti.ndarray(ti.types.vector(2, ti.i32), self.stitch_cap)
        self.on_mesh_changed()

    # -- allocation ---------------------------------------------------------------------------
    def on_mesh_changed(self):
        """Call after the model's arrays were refilled (remeshing): forget the warm start and
        upload the (remapped) stitch pairs."""
        if len(self.stitches_np) > self.stitch_cap:
            raise ValueError(f"{len(self.stitches_np)} stitches exceed the {self.stitch_cap} "
                             "this solver was built for: build a new ImplicitEuler")
        ndarrays.zero(self.dv)
        self.stitch.from_numpy(np.resize(self.stitches_np, (self.stitch_cap, 2)).astype(np.int32)
                               if len(self.stitches_np) else np.zeros((1, 2), np.int32))
        self.n_stitches = len(self.stitches_np)

    def warm_start(self):
        """The last step's velocity change per vertex (n_verts, 3): where the next step's CG
        starts. A remesh carries it to the new mesh (``set_warm_start``)."""
        return ndarrays.get_rows(self.dv, self.model.n_verts)

    def set_warm_start(self, dv):
        """Start the next step's CG from ``dv`` (n_verts, 3) instead of zero."""
        ndarrays.put_rows(self.dv, np.asarray(dv, np.float64).reshape(self.model.n_verts, 3))

    def set_stitches(self, pairs):
        self.stitches_np = np.asarray(pairs, np.int32).reshape(-1, 2)
        self.on_mesh_changed()

    @property
    def n_hinges(self):
        """Edges the kernels' hinge loops run over: all under the hinge energy, none under
        isotropic bending (its edges carry no weight, and their dihedral angles and gradients
        would be computed every step for nothing)."""
        return self.model.n_edges if self.model.bending == "hinge" else 0

    # -- kernel arguments ---------------------------------------------------------------------
    def _mesh(self):
        """The model's arrays (``MESH_ARRAYS``), then x and v."""
        m = self.model
        return tuple(getattr(m, name) for name in MESH_ARRAYS) + (m.state.x, m.state.v)

    def _elements(self):
        """The per-element work arrays and the stitch pairs."""
        return (self.face_fu, self.face_fv, self.face_E, self.face_wa, self.face_wb,
                self.edge_grad, self.edge_theta, self.stitch)

    # -- public API ---------------------------------------------------------------------------
    def step(self, h):
        """Advance model.state by one backward-Euler step of ``h`` seconds."""
        self.model.mark_step_start()
        if self.host_loop:
            return self._step_host_loop(h)
        m, mat, s = self.model, self.model.material, self.settings
        rel, iters = _step(h, ti.Vector(list(s.gravity)), mat.k_warp, mat.k_weft, mat.k_shear,
                           mat.k_bend, mat.damp_mass, mat.damp_stiff, s.stitch_stiffness,
                           m.n_verts, m.n_faces, self.n_hinges, self.n_stitches, s.cg_tol,
                           s.cg_max_iters, *self._mesh(), *self._elements(), self.force,
                           self.dv, self.rhs, self.res, self.z, self.p, self.Ap, self.precond,
                           self.scalars)
        self.last_cg_iters = int(iters)
        self.last_cg_residual = float(rel)
        return self.last_cg_iters

    def _step_host_loop(self, h):
        """``step`` with the CG loop on the host, one launch per iteration (Vulkan, Metal:
        see ``_linearise``). The same arithmetic as the one-launch kernel."""
        m, mat, s = self.model, self.model.material, self.settings
        k = (mat.k_warp, mat.k_weft, mat.k_shear, mat.k_bend)
        alpha, beta, kst = mat.damp_mass, mat.damp_stiff, s.stitch_stiffness
        counts = (m.n_verts, m.n_faces, self.n_hinges, self.n_stitches)
        _linearise(h, ti.Vector(list(s.gravity)), *k, alpha, beta, kst, *counts, *self._mesh(),
                   *self._elements(), self.force, self.rhs, self.precond)
        rz, bnorm = _start(h, alpha, beta, *k, kst, *counts, m.vert_mass, m.vert_pinned,
                           m.vert_pin_target, m.face_verts, m.face_rest_area, m.edge_verts,
                           m.edge_faces, m.edge_opp, m.edge_bend_weight, m.bend_ptr, m.bend_col,
                           m.bend_val, m.state.x, m.state.v, self.face_fu, self.face_fv,
                           self.face_E, self.face_wa, self.face_wb, self.edge_grad,
                           self.stitch, self.dv, self.rhs, self.res, self.z, self.p, self.Ap,
                           self.precond)
        rel = float(np.sqrt(abs(rz) / max(bnorm, 1e-300)))
        iters = 0
        while iters < s.cg_max_iters and rel > s.cg_tol:
            rz_new, stalled = _iteration(
                rz, h, alpha, beta, *k, kst, *counts, m.vert_mass, m.vert_pinned, m.face_verts,
                m.face_rest_area, m.edge_verts, m.edge_faces, m.edge_opp, m.edge_bend_weight,
                m.bend_ptr, m.bend_col, m.bend_val,
                self.face_fu, self.face_fv, self.face_E, self.face_wa, self.face_wb,
                self.edge_grad, self.stitch, self.dv, self.res, self.z, self.p, self.Ap,
                self.precond)
            if stalled:
                break
            rz = rz_new
            rel = float(np.sqrt(abs(rz) / max(bnorm, 1e-300)))
            iters += 1
        _advance(h, m.n_verts, m.vert_pinned, m.vert_pin_target, m.state.x, m.state.v, self.dv)
        self.last_cg_iters, self.last_cg_residual = iters, rel
        return iters

    def energy(self):
        """Elastic energy (membrane + bending + stitches) of the current positions, J."""
        mat = self.model.material
        return float(_energy(mat.k_warp, mat.k_weft, mat.k_shear, mat.k_bend,
                             self.settings.stitch_stiffness, self.model.n_faces,
                             self.n_hinges, self.n_stitches, *self._mesh(),
                             *self._elements()))

    def forces(self):
        """Elastic forces (no gravity, no damping) at the current positions, (V, 3) numpy."""
        mat = self.model.material
        _elastic_forces(mat.k_warp, mat.k_weft, mat.k_shear, mat.k_bend,
                        self.settings.stitch_stiffness, self.model.n_verts, self.model.n_faces,
                        self.n_hinges, self.n_stitches, *self._mesh(), *self._elements(),
                        self.force)
        return self.force.to_numpy()[: self.model.n_verts].astype(np.float64)

    def force_jacobian_product(self, p, exact=True):
        """(df/dx) p at the current positions for a (V, 3) direction ``p``: exact membrane
        Jacobian when ``exact`` (bending: Gauss-Newton part, exact where theta = theta_0),
        otherwise minus the positive semi-definite K the solver uses."""
        mat, m = self.model.material, self.model
        full = np.zeros((m.v_cap, 3))
        full[: m.n_verts] = p
        self.p.from_numpy(full.astype(self.p.to_numpy().dtype))
        _jacobian_product(mat.k_warp, mat.k_weft, mat.k_shear, mat.k_bend,
                          self.settings.stitch_stiffness, m.n_verts, m.n_faces, self.n_hinges,
                          self.n_stitches, 1 if exact else 0, *self._mesh(), *self._elements(),
                          self.p, self.Ap)
        return -self.Ap.to_numpy()[: m.n_verts].astype(np.float64)

    def system_matrix(self, h, B):
        """Fill the BlockMatrix ``B`` (cloth/system_matrix.py, built over this model's mesh and
        stitches) with the matrix of the last ``step(h)``: A = (1 + h alpha) M + h (beta + h)
        K_psd, linearised where that step started (the element data its ``linearise`` left).
        Pinned rows are not filtered (the strain solver keeps pins fixed itself)."""
        mat, s, m = self.model.material, self.settings, self.model
        if B.n_bend != m.n_bend:
            raise ValueError(f"the block pattern holds {B.n_bend} bending entries, the model "
                             f"{m.n_bend}: build it with system_matrix.pattern_of")
        _fill_blocks(h, mat.damp_mass, mat.damp_stiff, mat.k_warp, mat.k_weft, mat.k_shear,
                     mat.k_bend, s.stitch_stiffness, m.n_verts, m.n_faces, self.n_hinges,
                     self.n_stitches, B.nnz, B.val, B.diag, B.face_slot, B.edge_slot,
                     B.stitch_slot, B.bend_slot, *self._mesh(), *self._elements())


@ti.kernel
def _fill_blocks(h: float, alpha: float, beta: float, kw: float, kf: float, ks: float,
                 kb: float, kst: float, nv: ti.i32, nf: ti.i32, ne: ti.i32, nst: ti.i32,
                 nnz: ti.i32, val: A, diag: A, face_slot: A, edge_slot: A, stitch_slot: A,
                 bend_slot: A,
                 vert_mass: A, vert_pinned: A, vert_pin_target: A, face_verts: A,
                 face_Dm_inv: A, face_rest_area: A, face_grain: A, edge_verts: A,
                 edge_faces: A, edge_opp: A, edge_rest_angle: A, edge_bend_weight: A, bend_ptr: A,
                 bend_col: A, bend_val: A, x: A,
                 v: A, face_fu: A, face_fv: A, face_E: A, face_wa: A, face_wb: A,
                 edge_grad: A, edge_theta: A, stitch: A):
    # The blocks of add_K_product (exact = 0) written out: serial, as elements share blocks.
    ti.loop_config(serialize=True)
    for _ in range(1):
        scale = h * (beta + h)
        I = ti.Matrix.identity(float, 3)
        for k in range(nnz):
            val[k] = ti.Matrix.zero(float, 3, 3)
        for i in range(nv):
            val[diag[i]] += (1.0 + h * alpha) * vert_mass[i] * I
        for f in range(nf):
            A = face_rest_area[f]
            for n in ti.static(range(3)):
                for q in ti.static(range(3)):
                    val[face_slot[f, 3 * n + q]] += scale * A * \
                        face_block(f, n, q, kw, kf, ks, face_fu, face_fv, face_E, face_wa,
                                   face_wb)
        for e in range(ne):
            if edge_faces[e][1] >= 0:
                k = scale * kb * edge_bend_weight[e]
                G = edge_grad[e]
                for n in ti.static(range(4)):
                    gn = ti.Vector([G[n, 0], G[n, 1], G[n, 2]])
                    for q in ti.static(range(4)):
                        gq = ti.Vector([G[q, 0], G[q, 1], G[q, 2]])
                        val[edge_slot[e, 4 * n + q]] += k * gn.outer_product(gq)
        for i in range(bend_ptr.shape[0] - 1):
            for kq in range(bend_ptr[i], bend_ptr[i + 1]):
                val[bend_slot[kq]] += scale * kb * bend_val[kq] * I
        for s in range(nst):
            k = scale * kst
            val[stitch_slot[s, 0]] += k * I
            val[stitch_slot[s, 1]] -= k * I
            val[stitch_slot[s, 2]] -= k * I
            val[stitch_slot[s, 3]] += k * I


@ti.func
def face_block(f, n, q, kw, kf, ks, face_fu: T, face_fv: T, face_E: T, face_wa: T,
               face_wb: T):
    """Block (n, q) of face f's membrane stiffness K = -d2E / dx_n dx_q per unit rest area,
    made positive semi-definite: the curvature terms kept where the warp or weft is in
    tension, the shear's dropped (``add_K_product`` with exact = 0 applies the same K).
    The one definition of the block: the CG preconditioner, the assembled matrix and the
    sparse direct solver all take it from here."""
    fu, fv, E = face_fu[f], face_fv[f], face_E[f]
    wa, wb = face_wa[f], face_wb[f]
    gn = wa[n] * fv + wb[n] * fu
    gq = wa[q] * fv + wb[q] * fu
    aa, bb = wa[n] * wa[q], wb[n] * wb[q]
    return kw * aa * fu.outer_product(fu) + kf * bb * fv.outer_product(fv) \
        + ks * gn.outer_product(gq) \
        + (kw * ti.max(E[0], 0.0) * aa + kf * ti.max(E[1], 0.0) * bb) * ti.Matrix.identity(float, 3)


# -- element kinematics -----------------------------------------------------------------------
@ti.func
def face_weights(f, face_Dm_inv: T, face_grain: T):
    """Warp and weft weights a_n, b_n of the face's vertices: F e_warp = sum a_n x_n."""
    D = face_Dm_inv[f] @ face_grain[f]   # rows: M_j, M_k in grain
    wa = ti.Vector([-D[0, 0] - D[1, 0], D[0, 0], D[1, 0]])
    wb = ti.Vector([-D[0, 1] - D[1, 1], D[0, 1], D[1, 1]])
    return wa, wb


@ti.func
def update_face(f, x: T, face_verts: T, face_Dm_inv: T, face_grain: T, face_fu: T,
                face_fv: T, face_E: T, face_wa: T, face_wb: T):
    tri = face_verts[f]
    wa, wb = face_weights(f, face_Dm_inv, face_grain)
    fu = ti.Vector([0.0, 0.0, 0.0], dt=float)
    fv = ti.Vector([0.0, 0.0, 0.0], dt=float)
    for n in ti.static(range(3)):
        fu += wa[n] * x[tri[n]]
        fv += wb[n] * x[tri[n]]
    face_fu[f], face_fv[f] = fu, fv
    face_wa[f], face_wb[f] = wa, wb
    face_E[f] = ti.Vector([0.5 * (fu.dot(fu) - 1.0), 0.5 * (fv.dot(fv) - 1.0), 0.5 * fu.dot(fv)])


@ti.func
def update_edge(e, x: T, edge_verts: T, edge_faces: T, edge_opp: T, edge_grad: T,
                edge_theta: T):
    """Dihedral angle and its gradient (Bridson et al. 2003) for edge x0-x1 with opposite
    vertices x2 (face 0, order x0 x1 x2) and x3 (face 1, order x1 x0 x3)."""
    theta = 0.0
    G = ti.Matrix.zero(float, 4, 3)
    if edge_faces[e][1] >= 0:
        ev, eo = edge_verts[e], edge_opp[e]
        x0, x1 = x[ev[0]], x[ev[1]]
        x2, x3 = x[eo[0]], x[eo[1]]
        ed = x1 - x0
        n1 = ed.cross(x2 - x0)
        n2 = (x3 - x0).cross(ed)
        el = ed.norm()
        n1s, n2s = n1.dot(n1), n2.dot(n2)
        if el > 1e-12 and n1s > 1e-24 and n2s > 1e-24:
            eh = ed / el
            theta = ti.atan2(n1.cross(n2).dot(eh), n1.dot(n2))
            u1, u2 = n1 / n1s, n2 / n2s
            g2 = -el * u1
            g3 = -el * u2
            g0 = -((x2 - x1).dot(eh) * u1 + (x3 - x1).dot(eh) * u2)
            g1 = (x2 - x0).dot(eh) * u1 + (x3 - x0).dot(eh) * u2
            for c in ti.static(range(3)):
                G[0, c], G[1, c], G[2, c], G[3, c] = g0[c], g1[c], g2[c], g3[c]
    edge_theta[e] = theta
    edge_grad[e] = G


@ti.func
def edge_vertex(e, n, edge_verts: T, edge_opp: T):
    """Vertex n (0..3) of edge e's bending stencil: x0, x1, x2, x3."""
    ev, eo = edge_verts[e], edge_opp[e]
    vid = eo[1]
    if n == 0:
        vid = ev[0]
    elif n == 1:
        vid = ev[1]
    elif n == 2:
        vid = eo[0]
    return vid


@ti.func
def update_kinematics(nf: ti.i32, ne: ti.i32, x: T, face_verts: T, face_Dm_inv: T,
                      face_grain: T, edge_verts: T, edge_faces: T, edge_opp: T, face_fu: T,
                      face_fv: T, face_E: T, face_wa: T, face_wb: T, edge_grad: T,
                      edge_theta: T):
    for f in range(nf):
        update_face(f, x, face_verts, face_Dm_inv, face_grain, face_fu, face_fv, face_E,
                    face_wa, face_wb)
    for e in range(ne):
        update_edge(e, x, edge_verts, edge_faces, edge_opp, edge_grad, edge_theta)


@ti.func
def bend_apply(src: T, dst: T, scale, bend_ptr: T, bend_col: T, bend_val: T):
    """dst += scale * Q src, Q the isotropic bending matrix (cloth/bending.py; its rows are
    empty when the model uses the hinge energy). Row by row: no atomics. Q's rows sum to
    zero, so row i applies to src_k - src_i: exact for a translated cloth, and without the
    round-off of large positions (1e-16 |x| |Q| per entry)."""
    for i in range(bend_ptr.shape[0] - 1):
        acc = ti.Vector([0.0, 0.0, 0.0])
        for k in range(bend_ptr[i], bend_ptr[i + 1]):
            acc += bend_val[k] * (src[bend_col[k]] - src[i])
        dst[i] += scale * acc


# -- forces -----------------------------------------------------------------------------------
@ti.func
def add_elastic_forces(force: T, kw, kf, ks, kb, kst, nf: ti.i32, ne: ti.i32, nst: ti.i32,
                       x: T, face_verts: T, face_rest_area: T, edge_verts: T, edge_faces: T,
                       edge_opp: T, edge_rest_angle: T, edge_bend_weight: T, bend_ptr: T,
                       bend_col: T, bend_val: T, face_fu: T,
                       face_fv: T, face_E: T, face_wa: T, face_wb: T, edge_grad: T,
                       edge_theta: T, stitch: T):
    for f in range(nf):
        tri = face_verts[f]
        A = face_rest_area[f]
        fu, fv, E = face_fu[f], face_fv[f], face_E[f]
        wa, wb = face_wa[f], face_wb[f]
        for n in ti.static(range(3)):
            grad = A * (kw * E[0] * wa[n] * fu + kf * E[1] * wb[n] * fv
                        + 2.0 * ks * E[2] * (wa[n] * fv + wb[n] * fu))
            force[tri[n]] -= grad
    for e in range(ne):
        if edge_faces[e][1] >= 0:
            coef = kb * edge_bend_weight[e] * (edge_theta[e] - edge_rest_angle[e])
            G = edge_grad[e]
            for n in ti.static(range(4)):
                vid = edge_vertex(e, n, edge_verts, edge_opp)
                force[vid] -= coef * ti.Vector([G[n, 0], G[n, 1], G[n, 2]])
    bend_apply(x, force, -kb, bend_ptr, bend_col, bend_val)
    for s in range(nst):
        a, b = stitch[s][0], stitch[s][1]
        d = x[a] - x[b]
        force[a] -= kst * d
        force[b] += kst * d


@ti.func
def add_K_product(src: T, dst: T, scale, kw, kf, ks, kb, kst, nf: ti.i32, ne: ti.i32,
                  nst: ti.i32, exact: ti.i32, face_verts: T, face_rest_area: T, edge_verts: T,
                  edge_faces: T, edge_opp: T, edge_bend_weight: T, bend_ptr: T, bend_col: T,
                  bend_val: T, face_fu: T, face_fv: T,
                  face_E: T, face_wa: T, face_wb: T, edge_grad: T, stitch: T):
    """dst += scale * K src, with K = -df/dx (PSD-projected unless ``exact``)."""
    for f in range(nf):
        tri = face_verts[f]
        A = face_rest_area[f]
        fu, fv, E = face_fu[f], face_fv[f], face_E[f]
        wa, wb = face_wa[f], face_wb[f]
        dfu = wa[0] * src[tri[0]] + wa[1] * src[tri[1]] + wa[2] * src[tri[2]]
        dfv = wb[0] * src[tri[0]] + wb[1] * src[tri[1]] + wb[2] * src[tri[2]]
        dE0, dE1 = fu.dot(dfu), fv.dot(dfv)
        dE2 = 0.5 * (fu.dot(dfv) + fv.dot(dfu))
        # Curvature terms: kept where they are non-negative (stretch in tension) unless exact.
        E0, E1, E2 = E[0], E[1], E[2]
        if exact == 0:
            E0, E1, E2 = ti.max(E0, 0.0), ti.max(E1, 0.0), 0.0
        for n in ti.static(range(3)):
            out = kw * (dE0 * wa[n] * fu + E0 * wa[n] * dfu) \
                + kf * (dE1 * wb[n] * fv + E1 * wb[n] * dfv) \
                + 2.0 * ks * (dE2 * (wa[n] * fv + wb[n] * fu) + E2 * (wa[n] * dfv + wb[n] * dfu))
            dst[tri[n]] += scale * A * out
    for e in range(ne):
        if edge_faces[e][1] >= 0:
            k = kb * edge_bend_weight[e]
            G = edge_grad[e]
            dtheta = 0.0
            for n in ti.static(range(4)):
                dtheta += ti.Vector([G[n, 0], G[n, 1], G[n, 2]]).dot(
                    src[edge_vertex(e, n, edge_verts, edge_opp)])
            for n in ti.static(range(4)):
                dst[edge_vertex(e, n, edge_verts, edge_opp)] += scale * k * dtheta * \
                    ti.Vector([G[n, 0], G[n, 1], G[n, 2]])
    bend_apply(src, dst, scale * kb, bend_ptr, bend_col, bend_val)
    for s in range(nst):
        a, b = stitch[s][0], stitch[s][1]
        d = src[a] - src[b]
        dst[a] += scale * kst * d
        dst[b] -= scale * kst * d


@ti.func
def add_K_diagonal(precond: T, scale, kw, kf, ks, kb, kst, nf: ti.i32, ne: ti.i32,
                   nst: ti.i32, face_verts: T, face_rest_area: T, edge_verts: T,
                   edge_faces: T, edge_opp: T, edge_bend_weight: T, bend_ptr: T, bend_col: T,
                   bend_val: T, face_fu: T, face_fv: T,
                   face_E: T, face_wa: T, face_wb: T, edge_grad: T, stitch: T):
    """precond += scale * (3x3 diagonal blocks of the PSD K)."""
    for f in range(nf):
        tri = face_verts[f]
        A = face_rest_area[f]
        for n in ti.static(range(3)):
            precond[tri[n]] += scale * A * face_block(f, n, n, kw, kf, ks, face_fu, face_fv,
                                                      face_E, face_wa, face_wb)
    for e in range(ne):
        if edge_faces[e][1] >= 0:
            k = kb * edge_bend_weight[e]
            G = edge_grad[e]
            for n in ti.static(range(4)):
                g = ti.Vector([G[n, 0], G[n, 1], G[n, 2]])
                precond[edge_vertex(e, n, edge_verts, edge_opp)] += scale * k * g.outer_product(g)
    for i in range(bend_ptr.shape[0] - 1):
        if bend_ptr[i + 1] > bend_ptr[i]:          # the row's diagonal entry comes first
            precond[i] += scale * kb * bend_val[bend_ptr[i]] * ti.Matrix.identity(float, 3)
    for s in range(nst):
        I = ti.Matrix.identity(float, 3)
        precond[stitch[s][0]] += scale * kst * I
        precond[stitch[s][1]] += scale * kst * I


# -- kernels ----------------------------------------------------------------------------------
@ti.kernel
def _elastic_forces(kw: float, kf: float, ks: float, kb: float, kst: float, nv: ti.i32,
                    nf: ti.i32, ne: ti.i32, nst: ti.i32, vert_mass: A, vert_pinned: A,
                    vert_pin_target: A, face_verts: A, face_Dm_inv: A, face_rest_area: A,
                    face_grain: A, edge_verts: A, edge_faces: A, edge_opp: A,
                    edge_rest_angle: A, edge_bend_weight: A, bend_ptr: A, bend_col: A, bend_val: A,
                    x: A, v: A, face_fu: A,
                    face_fv: A, face_E: A, face_wa: A, face_wb: A, edge_grad: A,
                    edge_theta: A, stitch: A, force: A):
    for i in range(nv):
        force[i] = ti.Vector([0.0, 0.0, 0.0])
    update_kinematics(nf, ne, x, face_verts, face_Dm_inv, face_grain, edge_verts, edge_faces,
                      edge_opp, face_fu, face_fv, face_E, face_wa, face_wb, edge_grad,
                      edge_theta)
    add_elastic_forces(force, kw, kf, ks, kb, kst, nf, ne, nst, x, face_verts, face_rest_area,
                       edge_verts, edge_faces, edge_opp, edge_rest_angle, edge_bend_weight,
                       bend_ptr, bend_col, bend_val,
                       face_fu, face_fv, face_E, face_wa, face_wb, edge_grad, edge_theta,
                       stitch)


@ti.kernel
def _jacobian_product(kw: float, kf: float, ks: float, kb: float, kst: float, nv: ti.i32,
                      nf: ti.i32, ne: ti.i32, nst: ti.i32, exact: ti.i32, vert_mass: A,
                      vert_pinned: A, vert_pin_target: A, face_verts: A, face_Dm_inv: A,
                      face_rest_area: A, face_grain: A, edge_verts: A, edge_faces: A,
                      edge_opp: A, edge_rest_angle: A, edge_bend_weight: A, bend_ptr: A,
                      bend_col: A, bend_val: A, x: A, v: A,
                      face_fu: A, face_fv: A, face_E: A, face_wa: A, face_wb: A,
                      edge_grad: A, edge_theta: A, stitch: A, p: A, Ap: A):
    for i in range(nv):
        Ap[i] = ti.Vector([0.0, 0.0, 0.0])
    update_kinematics(nf, ne, x, face_verts, face_Dm_inv, face_grain, edge_verts, edge_faces,
                      edge_opp, face_fu, face_fv, face_E, face_wa, face_wb, edge_grad,
                      edge_theta)
    add_K_product(p, Ap, 1.0, kw, kf, ks, kb, kst, nf, ne, nst, exact, face_verts,
                  face_rest_area, edge_verts, edge_faces, edge_opp, edge_bend_weight, bend_ptr,
                  bend_col, bend_val, face_fu,
                  face_fv, face_E, face_wa, face_wb, edge_grad, stitch)


@ti.kernel
def _energy(kw: float, kf: float, ks: float, kb: float, kst: float, nf: ti.i32, ne: ti.i32,
            nst: ti.i32, vert_mass: A, vert_pinned: A, vert_pin_target: A, face_verts: A,
            face_Dm_inv: A, face_rest_area: A, face_grain: A, edge_verts: A, edge_faces: A,
            edge_opp: A, edge_rest_angle: A, edge_bend_weight: A, bend_ptr: A, bend_col: A,
            bend_val: A, x: A, v: A, face_fu: A,
            face_fv: A, face_E: A, face_wa: A, face_wb: A, edge_grad: A, edge_theta: A,
            stitch: A) -> float:
    update_kinematics(nf, ne, x, face_verts, face_Dm_inv, face_grain, edge_verts, edge_faces,
                      edge_opp, face_fu, face_fv, face_E, face_wa, face_wb, edge_grad,
                      edge_theta)
    total = 0.0
    for f in range(nf):
        E = face_E[f]
        total += face_rest_area[f] * (0.5 * kw * E[0] ** 2 + 0.5 * kf * E[1] ** 2
                                      + 2.0 * ks * E[2] ** 2)
    for e in range(ne):
        if edge_faces[e][1] >= 0:
            d = edge_theta[e] - edge_rest_angle[e]
            total += 0.5 * kb * edge_bend_weight[e] * d * d
    # x.Qx = -1/2 sum_ik Q_ik |x_i - x_k|^2 (rows summing to zero): terms the size of the
    # bends themselves. The plain sum of Q_ik x_i.x_k cancels terms ~1e4 times larger, and its
    # round-off (the parallel sum's order varies) stalled the calibration's energy descent.
    for i in range(bend_ptr.shape[0] - 1):
        for k in range(bend_ptr[i], bend_ptr[i + 1]):
            d = x[i] - x[bend_col[k]]
            total -= 0.25 * kb * bend_val[k] * d.dot(d)
    for s in range(nst):
        d = x[stitch[s][0]] - x[stitch[s][1]]
        total += 0.5 * kst * d.dot(d)
    return total


@ti.func
def free_residual(res: T, rhs: T, Ap: T, vert_pinned: T, nv: ti.i32):
    """res = rhs - Ap on the free rows and 0 on the pinned ones: CG's starting residual."""
    for i in range(nv):
        res[i] = rhs[i] - Ap[i]
        if vert_pinned[i] != 0:
            res[i] = ti.Vector([0.0, 0.0, 0.0])


@ti.func
def apply_A(src: T, dst: T, h, alpha, beta, kw, kf, ks, kb, kst, nv: ti.i32, nf: ti.i32,
            ne: ti.i32, nst: ti.i32, vert_mass: T, vert_pinned: T, face_verts: T,
            face_rest_area: T, edge_verts: T, edge_faces: T, edge_opp: T,
            edge_bend_weight: T, bend_ptr: T, bend_col: T, bend_val: T, face_fu: T, face_fv: T,
            face_E: T, face_wa: T, face_wb: T,
            edge_grad: T, stitch: T):
    """dst = A src with A = (1 + h alpha) M + h (beta + h) K, pinned rows filtered."""
    for i in range(nv):
        dst[i] = (1.0 + h * alpha) * vert_mass[i] * src[i]
    add_K_product(src, dst, h * (beta + h), kw, kf, ks, kb, kst, nf, ne, nst, 0, face_verts,
                  face_rest_area, edge_verts, edge_faces, edge_opp, edge_bend_weight, bend_ptr,
                  bend_col, bend_val, face_fu,
                  face_fv, face_E, face_wa, face_wb, edge_grad, stitch)
    for i in range(nv):
        if vert_pinned[i] != 0:
            dst[i] = ti.Vector([0.0, 0.0, 0.0])


@ti.func
def linearise(h, g, kw, kf, ks, kb, alpha, beta, kst, nv: ti.i32, nf: ti.i32, ne: ti.i32,
              nst: ti.i32, force: T, precond: T, rhs: T, vert_mass: T, face_verts: T,
              face_Dm_inv: T, face_rest_area: T, face_grain: T, edge_verts: T, edge_faces: T,
              edge_opp: T, edge_rest_angle: T, edge_bend_weight: T, bend_ptr: T, bend_col: T,
              bend_val: T, x: T, v: T, face_fu: T,
              face_fv: T, face_E: T, face_wa: T, face_wb: T, edge_grad: T, edge_theta: T,
              stitch: T):
    """Forces and element quantities at the start of the step, the diagonal blocks of A
    (in ``precond``) and the right-hand side h (f - alpha M v) - h (beta + h) K v."""
    for i in range(nv):
        force[i] = vert_mass[i] * g
        precond[i] = (1.0 + h * alpha) * vert_mass[i] * ti.Matrix.identity(float, 3)
    update_kinematics(nf, ne, x, face_verts, face_Dm_inv, face_grain, edge_verts, edge_faces,
                      edge_opp, face_fu, face_fv, face_E, face_wa, face_wb, edge_grad,
                      edge_theta)
    add_elastic_forces(force, kw, kf, ks, kb, kst, nf, ne, nst, x, face_verts, face_rest_area,
                       edge_verts, edge_faces, edge_opp, edge_rest_angle, edge_bend_weight,
                       bend_ptr, bend_col, bend_val,
                       face_fu, face_fv, face_E, face_wa, face_wb, edge_grad, edge_theta,
                       stitch)
    add_K_diagonal(precond, h * (beta + h), kw, kf, ks, kb, kst, nf, ne, nst, face_verts,
                   face_rest_area, edge_verts, edge_faces, edge_opp, edge_bend_weight, bend_ptr,
                   bend_col, bend_val, face_fu,
                   face_fv, face_E, face_wa, face_wb, edge_grad, stitch)
    for i in range(nv):
        rhs[i] = h * (force[i] - alpha * vert_mass[i] * v[i])
    add_K_product(v, rhs, -h * (beta + h), kw, kf, ks, kb, kst, nf, ne, nst, 0, face_verts,
                  face_rest_area, edge_verts, edge_faces, edge_opp, edge_bend_weight, bend_ptr,
                  bend_col, bend_val, face_fu,
                  face_fv, face_E, face_wa, face_wb, edge_grad, stitch)


# The step's phases, shared by the one-launch kernel and the host-loop kernels.
@ti.func
def cg_begin(h, g, kw, kf, ks, kb, alpha, beta, kst, nv: ti.i32, nf: ti.i32, ne: ti.i32,
             nst: ti.i32, vert_mass: T, vert_pinned: T, vert_pin_target: T, face_verts: T,
             face_Dm_inv: T, face_rest_area: T, face_grain: T, edge_verts: T, edge_faces: T,
             edge_opp: T, edge_rest_angle: T, edge_bend_weight: T, bend_ptr: T, bend_col: T,
             bend_val: T, x: T, v: T, face_fu: T, face_fv: T, face_E: T, face_wa: T,
             face_wb: T, edge_grad: T, edge_theta: T, stitch: T, force: T, dv: T, rhs: T,
             res: T, z: T, p: T, Ap: T, precond: T):
    """Linearise, prescribe the pinned dv, and start PCG: returns (r.z, b.P b) (CG's scale:
    the free rows only)."""
    linearise(h, g, kw, kf, ks, kb, alpha, beta, kst, nv, nf, ne, nst, force, precond, rhs,
              vert_mass, face_verts, face_Dm_inv, face_rest_area, face_grain, edge_verts,
              edge_faces, edge_opp, edge_rest_angle, edge_bend_weight, bend_ptr, bend_col,
              bend_val, x, v, face_fu, face_fv, face_E, face_wa, face_wb, edge_grad,
              edge_theta, stitch)
    return cg_start(h, alpha, beta, kw, kf, ks, kb, kst, nv, nf, ne, nst, vert_mass,
                    vert_pinned, vert_pin_target, face_verts, face_rest_area, edge_verts,
                    edge_faces, edge_opp, edge_bend_weight, bend_ptr, bend_col, bend_val, x,
                    v, face_fu, face_fv, face_E, face_wa, face_wb, edge_grad, stitch, dv, rhs,
                    res, z, p, Ap, precond)


@ti.func
def cg_start(h, alpha, beta, kw, kf, ks, kb, kst, nv: ti.i32, nf: ti.i32, ne: ti.i32,
             nst: ti.i32, vert_mass: T, vert_pinned: T, vert_pin_target: T, face_verts: T,
             face_rest_area: T, edge_verts: T, edge_faces: T, edge_opp: T,
             edge_bend_weight: T, bend_ptr: T, bend_col: T, bend_val: T, x: T, v: T,
             face_fu: T, face_fv: T, face_E: T, face_wa: T, face_wb: T, edge_grad: T,
             stitch: T, dv: T, rhs: T, res: T, z: T, p: T, Ap: T, precond: T):
    """After ``linearise``: prescribe the pinned dv and start PCG."""
    # Pinned vertices: the dv that lands them on their target at the end of the step.
    # Free vertices start CG from the last step's dv (warm start: near rest, successive
    # velocity changes are alike); on_mesh_changed zeroes it after a remesh.
    for i in range(nv):
        if vert_pinned[i] != 0:
            dv[i] = (vert_pin_target[i] - x[i]) / h - v[i]
        precond[i] = precond[i].inverse()
    # r = b - A dv over the free vertices (pinned dv enters through the coupling).
    apply_A(dv, Ap, h, alpha, beta, kw, kf, ks, kb, kst, nv, nf, ne, nst, vert_mass,
            vert_pinned, face_verts, face_rest_area, edge_verts, edge_faces, edge_opp,
            edge_bend_weight, bend_ptr, bend_col, bend_val, face_fu, face_fv, face_E, face_wa,
            face_wb, edge_grad, stitch)
    free_residual(res, rhs, Ap, vert_pinned, nv)
    rz = 0.0
    bnorm = 0.0
    for i in range(nv):
        z[i] = precond[i] @ res[i]
        p[i] = z[i]
        rz += res[i].dot(z[i])
        if vert_pinned[i] == 0:
            bnorm += rhs[i].dot(precond[i] @ rhs[i])
    return ti.Vector([rz, bnorm])


@ti.func
def cg_iteration(rz, h, alpha, beta, kw, kf, ks, kb, kst, nv: ti.i32, nf: ti.i32,
                 ne: ti.i32, nst: ti.i32, vert_mass: T, vert_pinned: T, face_verts: T,
                 face_rest_area: T, edge_verts: T, edge_faces: T, edge_opp: T,
                 edge_bend_weight: T, bend_ptr: T, bend_col: T, bend_val: T, face_fu: T,
                 face_fv: T, face_E: T, face_wa: T,
                 face_wb: T, edge_grad: T, stitch: T, dv: T, res: T, z: T, p: T, Ap: T,
                 precond: T):
    """One preconditioned CG iteration on the free vertices: returns (new r.z, 1 if it
    stalled on p.A p <= 0 and changed nothing)."""
    apply_A(p, Ap, h, alpha, beta, kw, kf, ks, kb, kst, nv, nf, ne, nst, vert_mass,
            vert_pinned, face_verts, face_rest_area, edge_verts, edge_faces, edge_opp,
            edge_bend_weight, bend_ptr, bend_col, bend_val, face_fu, face_fv, face_E, face_wa,
            face_wb, edge_grad, stitch)
    pAp = 0.0
    for i in range(nv):
        pAp += p[i].dot(Ap[i])
    rz_new = rz
    stalled = 1.0
    if pAp > 0.0:
        stalled = 0.0
        step = rz / pAp
        rz_new = 0.0
        for i in range(nv):
            dv[i] += step * p[i]
            res[i] -= step * Ap[i]
            z[i] = precond[i] @ res[i]
            rz_new += res[i].dot(z[i])
        beta_cg = rz_new / rz
        for i in range(nv):
            p[i] = z[i] + beta_cg * p[i]
            if vert_pinned[i] != 0:
                p[i] = ti.Vector([0.0, 0.0, 0.0])
    return ti.Vector([rz_new, stalled])


@ti.func
def advance(h, nv: ti.i32, vert_pinned: T, vert_pin_target: T, x: T, v: T, dv: T):
    """v += dv, x += h v; pins exactly on target."""
    for i in range(nv):
        v[i] += dv[i]
        x[i] += h * v[i]
        if vert_pinned[i] != 0:
            x[i] = vert_pin_target[i]


@ti.func
def relative(rz, bnorm):
    return ti.sqrt(ti.abs(rz) / ti.max(bnorm, 1e-300))


@ti.kernel
def _step(h: float, g: ti.types.vector(3, float), kw: float, kf: float, ks: float, kb: float,
          alpha: float, beta: float, kst: float, nv: ti.i32, nf: ti.i32, ne: ti.i32,
          nst: ti.i32, tol: float, max_iters: ti.i32, vert_mass: A, vert_pinned: A,
          vert_pin_target: A, face_verts: A, face_Dm_inv: A, face_rest_area: A,
          face_grain: A, edge_verts: A, edge_faces: A, edge_opp: A, edge_rest_angle: A,
          edge_bend_weight: A, bend_ptr: A, bend_col: A, bend_val: A, x: A, v: A, face_fu: A,
          face_fv: A, face_E: A, face_wa: A,
          face_wb: A, edge_grad: A, edge_theta: A, stitch: A, force: A, dv: A, rhs: A,
          res: A, z: A, p: A, Ap: A, precond: A, scalars: A) -> ti.types.vector(2, float):
    """(relative residual, CG iterations), also left in scalars[0] and scalars[1]."""
    # The whole step runs in one serial kernel: on a 2-core CPU, launching a kernel per CG
    # phase costs more than the work below ~50k triangles (METHOD.md section 4 hints).
    # Returning both numbers costs less than reading them back (~0.05 vs ~0.17 ms).
    ti.loop_config(serialize=True)
    for _ in range(1):
        rb = cg_begin(h, g, kw, kf, ks, kb, alpha, beta, kst, nv, nf, ne, nst, vert_mass,
                      vert_pinned, vert_pin_target, face_verts, face_Dm_inv, face_rest_area,
                      face_grain, edge_verts, edge_faces, edge_opp, edge_rest_angle,
                      edge_bend_weight, bend_ptr, bend_col, bend_val, x, v, face_fu, face_fv,
                      face_E, face_wa, face_wb,
                      edge_grad, edge_theta, stitch, force, dv, rhs, res, z, p, Ap, precond)
        rz, bnorm = rb[0], rb[1]
        iters = 0
        stalled = 0.0
        rel = relative(rz, bnorm)
        while iters < max_iters and rel > tol and stalled == 0.0:
            out = cg_iteration(rz, h, alpha, beta, kw, kf, ks, kb, kst, nv, nf, ne, nst,
                               vert_mass, vert_pinned, face_verts, face_rest_area, edge_verts,
                               edge_faces, edge_opp, edge_bend_weight, bend_ptr, bend_col,
                               bend_val, face_fu, face_fv, face_E,
                               face_wa, face_wb, edge_grad, stitch, dv, res, z, p, Ap, precond)
            stalled = out[1]
            if stalled == 0.0:
                rz = out[0]
                rel = relative(rz, bnorm)
                iters += 1
        scalars[0] = rel
        advance(h, nv, vert_pinned, vert_pin_target, x, v, dv)
        scalars[1] = iters
    return ti.Vector([scalars[0], scalars[1]])


# The same step as three kinds of launch with the CG loop on the host, for Vulkan and Metal
# (backend.HOST_LOOP_AL). Measured on lavapipe (Debian's software Vulkan), f32, hanging res 20:
# the one-launch step computed dv but never wrote v and x once it ran 14 CG iterations or more
# (13 were fine; KE stayed exactly 0 and the cloth never fell), like the strain solver's
# one-launch solve, which crashed that driver.
# Two launches where the one-launch step has cg_begin: Vulkan and Metal take at most 31
# ndarray arguments per kernel (measured on lavapipe: 32 silently drops one, 33 crashes).
@ti.kernel
def _linearise(h: float, g: ti.types.vector(3, float), kw: float, kf: float, ks: float,
               kb: float, alpha: float, beta: float, kst: float, nv: ti.i32, nf: ti.i32,
               ne: ti.i32, nst: ti.i32, vert_mass: A, vert_pinned: A, vert_pin_target: A,
               face_verts: A, face_Dm_inv: A, face_rest_area: A, face_grain: A, edge_verts: A,
               edge_faces: A, edge_opp: A, edge_rest_angle: A, edge_bend_weight: A,
               bend_ptr: A, bend_col: A, bend_val: A, x: A, v: A, face_fu: A, face_fv: A,
               face_E: A, face_wa: A, face_wb: A, edge_grad: A, edge_theta: A, stitch: A,
               force: A, rhs: A, precond: A):
    ti.loop_config(serialize=True)
    for _ in range(1):
        linearise(h, g, kw, kf, ks, kb, alpha, beta, kst, nv, nf, ne, nst, force, precond, rhs,
                  vert_mass, face_verts, face_Dm_inv, face_rest_area, face_grain, edge_verts,
                  edge_faces, edge_opp, edge_rest_angle, edge_bend_weight, bend_ptr, bend_col,
                  bend_val, x, v, face_fu, face_fv, face_E, face_wa, face_wb, edge_grad,
                  edge_theta, stitch)


@ti.kernel
def _start(h: float, alpha: float, beta: float, kw: float, kf: float, ks: float, kb: float,
           kst: float, nv: ti.i32, nf: ti.i32, ne: ti.i32, nst: ti.i32, vert_mass: A,
           vert_pinned: A, vert_pin_target: A, face_verts: A, face_rest_area: A,
           edge_verts: A, edge_faces: A, edge_opp: A, edge_bend_weight: A, bend_ptr: A,
           bend_col: A, bend_val: A, x: A, v: A, face_fu: A, face_fv: A, face_E: A, face_wa: A,
           face_wb: A, edge_grad: A, stitch: A, dv: A, rhs: A, res: A, z: A, p: A, Ap: A,
           precond: A) -> ti.types.vector(2, float):
    ti.loop_config(serialize=True)
    out = ti.Vector([0.0, 0.0])
    for _ in range(1):
        out = cg_start(h, alpha, beta, kw, kf, ks, kb, kst, nv, nf, ne, nst, vert_mass,
                       vert_pinned, vert_pin_target, face_verts, face_rest_area, edge_verts,
                       edge_faces, edge_opp, edge_bend_weight, bend_ptr, bend_col, bend_val, x,
                       v, face_fu, face_fv, face_E, face_wa, face_wb, edge_grad, stitch, dv,
                       rhs, res, z, p, Ap, precond)
    return out


@ti.kernel
def _iteration(rz: float, h: float, alpha: float, beta: float, kw: float, kf: float,
               ks: float, kb: float, kst: float, nv: ti.i32, nf: ti.i32, ne: ti.i32,
               nst: ti.i32, vert_mass: A, vert_pinned: A, face_verts: A, face_rest_area: A,
               edge_verts: A, edge_faces: A, edge_opp: A, edge_bend_weight: A, bend_ptr: A,
               bend_col: A, bend_val: A, face_fu: A,
               face_fv: A, face_E: A, face_wa: A, face_wb: A, edge_grad: A, stitch: A, dv: A,
               res: A, z: A, p: A, Ap: A, precond: A) -> ti.types.vector(2, float):
    ti.loop_config(serialize=True)
    out = ti.Vector([0.0, 0.0])
    for _ in range(1):
        out = cg_iteration(rz, h, alpha, beta, kw, kf, ks, kb, kst, nv, nf, ne, nst, vert_mass,
                           vert_pinned, face_verts, face_rest_area, edge_verts, edge_faces,
                           edge_opp, edge_bend_weight, bend_ptr, bend_col, bend_val, face_fu,
                           face_fv, face_E, face_wa,
                           face_wb, edge_grad, stitch, dv, res, z, p, Ap, precond)
    return out


@ti.kernel
def _advance(h: float, nv: ti.i32, vert_pinned: A, vert_pin_target: A, x: A, v: A, dv: A):
    ti.loop_config(serialize=True)
    for _ in range(1):
        advance(h, nv, vert_pinned, vert_pin_target, x, v, dv)
