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
  ``bend_col``, ``bend_val``), and it couples vertices two rings apart. With ``k_bend_warp``
  and ``k_bend_weft`` different, Q is built on mapped material coordinates (the orthotropic
  plate, ``bending.orthotropic_coordinates``) and the factor is
  ``Material.bend_scale()`` = sqrt(B_warp B_weft) instead of k_bend. The hinge energy takes
  that factor too, isotropically.
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


Every kernel is a module-level ``@ti.kernel`` taking all its arrays (the model's and the
solver's work arrays, Taichi ndarrays) as arguments, and the ``@ti.func``s take the arrays they
read as ``ti.template()`` parameters: a kernel that captured fields (or a data_oriented
``self``) was compiled again for every new model and solver, 2.5-10 s per Simulator (issue
#15); these compile once per process (cloth/strain/buffers.py has the measurements). The
price, measured against the field version (2-core CPU, f64): ~0.27 ms more argument handling
per step and CG iterations ~1.35x slower (ndarray addressing; 0.28 -> 0.38 ms per iteration at
4.8k triangles). The arrays come in named argpacks (``MeshPack``, ``StatePack``,
``ElementPack``, ``SolvePack``, ``BlockPack``) and the step's scalars in one float array
(``coef``, read into a ``Constants`` struct by ``constants``), issue #37: a kernel takes 4-8
parameters where it took up to 49 positional ones.
"""
from dataclasses import dataclass

import numpy as np
import taichi as ti

from . import backend, ndarrays
from .model import ClothModel
from .ndarrays import A, T
from .settings import COMMON_DEFAULTS
from .strain import factor_precond, multigrid
from .strain.buffers import PC_FACTOR, PC_JACOBI, PC_MULTIGRID, PC_NAMES

_SIM = COMMON_DEFAULTS["sim"]


# The model's arrays the kernels read (``MeshPack``'s members, by the model's names).
MESH_ARRAYS = ("vert_mass", "vert_pinned", "vert_pin_target", "face_verts", "face_Dm_inv",
               "face_rest_area", "face_grain", "edge_verts", "edge_faces", "edge_opp",
               "edge_rest_angle", "edge_bend_weight", "bend_ptr", "bend_col", "bend_val")

# Named argument groups (issue #37, as the strain solver's in cloth/strain/buffers.py): the
# kernels take their arrays in these argpacks, by name, instead of up to 49 positional
# arguments whose order every call site repeated (a misordered one still compiled). Each pack
# is made once per set of arrays (``ImplicitEuler._packs``, ndarrays.PackCache) and again only
# when one of them was replaced (a remesh's new ``bend_ptr``). Members are ndarrays only, and
# a member's name is unique across the packs (Taichi 1.7.4 cannot take two packs sharing one
# in a kernel).
#   mesh    the model's rest arrays (``MESH_ARRAYS``) and the stitch pairs;
#   state   the model's positions and velocities;
#   elems   per-element kinematics where the step starts (``update_kinematics``);
#   cg      the Newton step's per-vertex vectors, its block-diagonal preconditioner and the
#           step's results (``scalars``);
#   blocks  a system_matrix.BlockMatrix's values and slots (``system_matrix``).
MeshPack = ti.types.argpack(**{name: A for name in MESH_ARRAYS}, stitch=A)
StatePack = ti.types.argpack(x=A, v=A)
ElementPack = ti.types.argpack(face_fu=A, face_fv=A, face_E=A, face_wa=A, face_wb=A,
                               edge_grad=A, edge_theta=A)
SolvePack = ti.types.argpack(force=A, dv=A, rhs=A, res=A, z=A, p=A, Ap=A, precond=A,
                             scalars=A)
BlockPack = ti.types.argpack(val=A, diag=A, face_slot=A, edge_slot=A, stitch_slot=A,
                             bend_slot=A)
#   pc      the preconditioner of A the strain solve keeps: the aggregation multigrid's level
#           arrays (cloth/strain/multigrid.py; its fine level's diagonal blocks are this step's
#           own, ``cg.precond``) and the sparse factor's (cloth/strain/factor_precond.py), each
#           its one-element stub where not in use.
PrecondPack = ti.types.argpack(mg_int=A, mg_real=A, f_perm=A, f_ptr=A, f_idx=A, f_val=A,
                               f_work=A)

# The step's scalars: indices into ``coef``, the float array (numpy) every kernel takes
# (``ImplicitEuler._coef``) and reads once into a ``Constants`` struct (``constants``). They
# were 9-15 scalar arguments per kernel. Why a numpy array: a CPU kernel reads it in place,
# and measured with 33 ndarrays in 4 packs (2-core CPU, Taichi 1.7.4) a launch with it costs
# what one with the 15 loose scalars did (227 vs 231 us), while the same scalars as a Taichi
# struct argument cost ~95 us more per launch (and ~190 us to make the struct on the host).
# The counts are exact in a float.
(C_H, C_G, C_KW, C_KF, C_KS, C_KB, C_ALPHA, C_BETA, C_KST, C_TOL, C_MAX_ITERS, C_NV, C_NF,
 C_NE, C_NST, C_PC, C_PC_ITERS) = (0, 1, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18)
N_COEF = 19                                                                # C_G: 3 components
Constants = ti.types.struct(h=float, g=ti.types.vector(3, float), kw=float, kf=float, ks=float,
                            kb=float, alpha=float, beta=float, kst=float, tol=float,
                            max_iters=ti.i32, nv=ti.i32, nf=ti.i32, ne=ti.i32, nst=ti.i32,
                            pc=ti.i32, pc_iters=ti.i32)
# CG's preconditioner (``C_PC``, the strain solve's PC_* numbering): A's 3x3 diagonal blocks,
# or the aggregation multigrid or the sparse factor of A that the strain solve keeps
# (``ImplicitEuler.set_preconditioner``; each object's ``mode``).
# A factor or multigrid made a few steps earlier goes stale when A moves on (the cloth turns,
# its tension changes): a factor of the hanging sheet's A applied to the same sheet turned a
# quarter turn left CG unconverged after 500 iterations where block Jacobi took 97. So CG
# with either gets STALE_SHARE of the last block-Jacobi step's iterations (``C_PC_ITERS``;
# an iteration with it costs about twice one with block Jacobi); past them it goes on with
# block Jacobi from where it got to, and block Jacobi runs until it is made again
# (``ImplicitEuler.step``).
STALE_SHARE = 0.5


@ti.func
def constants(coef: T):
    """``coef`` as a ``Constants`` struct: h (s), gravity, the warp, weft, shear, bending and
    stitch stiffnesses, mass and stiffness damping alpha and beta, CG's tolerance and
    iteration cap, and the counts of vertices, faces, hinges (``n_hinges``) and stitches.
    Read once per launch into locals: the funcs' inner loops then read no array for them."""
    return Constants(h=coef[C_H], g=ti.Vector([coef[C_G], coef[C_G + 1], coef[C_G + 2]]),
                     kw=coef[C_KW], kf=coef[C_KF], ks=coef[C_KS], kb=coef[C_KB],
                     alpha=coef[C_ALPHA], beta=coef[C_BETA], kst=coef[C_KST], tol=coef[C_TOL],
                     max_iters=ti.cast(coef[C_MAX_ITERS], ti.i32),
                     nv=ti.cast(coef[C_NV], ti.i32), nf=ti.cast(coef[C_NF], ti.i32),
                     ne=ti.cast(coef[C_NE], ti.i32), nst=ti.cast(coef[C_NST], ti.i32),
                     pc=ti.cast(coef[C_PC], ti.i32),
                     pc_iters=ti.cast(coef[C_PC_ITERS], ti.i32))


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
        # The kernels' scalars (``C_*``; written before each launch) and argpacks; the
        # solver's own arrays are never replaced, so their packs are made here.
        rt = ti.lang.impl.get_runtime()
        self._coef = np.zeros(N_COEF, np.float64 if rt.default_fp == ti.f64 else np.float32)
        self._packs = ndarrays.PackCache()
        self._elems = ElementPack(face_fu=self.face_fu, face_fv=self.face_fv,
                                  face_E=self.face_E, face_wa=self.face_wa,
                                  face_wb=self.face_wb, edge_grad=self.edge_grad,
                                  edge_theta=self.edge_theta)
        self._cg = SolvePack(force=self.force, dv=self.dv, rhs=self.rhs, res=self.res,
                             z=self.z, p=self.p, Ap=self.Ap, precond=self.precond,
                             scalars=self.scalars)
        self._pc = None                 # set_preconditioner
        self._stale = None              # (pc, its ``made``) that went stale (STALE_SHARE)
        self._jacobi_iters = None       # the last block-Jacobi step's CG iterations
        self._mg_stub = multigrid.MultigridStub()
        self._factor_stub = factor_precond.FactorStub()
        self.last_preconditioner = "block Jacobi"
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

    def set_preconditioner(self, pc):
        """Precondition CG with ``pc`` while it is ready for the current pins: the strain
        solve's multigrid (strain.multigrid.MultigridPreconditioner) or sparse factor
        (strain.factor_precond.FactorPreconditioner) of this model's implicit matrix A, pins
        as the identity; None: block Jacobi. Either may lag A by a few steps (it is remade
        every few solves; STALE_SHARE bounds what a stale one costs): CG stops on the same
        test, only its iteration count depends on it. The hanging sheet at rest, CG iterations
        a step: 6 with the factor against 47 (1.2k faces, docs/speed/dynamics_cg.md); 39
        with the multigrid against 114 (4k faces). The one-launch step only; the host loop
        (Vulkan, Metal) keeps block Jacobi."""
        self._pc = pc

    def _preconditioner(self):
        """(mode, its arrays' pack) for this step."""
        pc = self._pc
        n = self.model.n_verts
        mode = PC_JACOBI
        if pc is not None and not self.host_loop and pc.metric.n == n and \
                pc.usable(self.model.pinned[:n]) and self._stale != (pc, pc.made):
            mode = pc.mode
        mg = pc if mode == PC_MULTIGRID else self._mg_stub
        fp = pc if mode == PC_FACTOR else self._factor_stub
        self.last_preconditioner = PC_NAMES[mode]
        return mode, self._packs.get("pc", PrecondPack, mg_int=mg.ints, mg_real=mg.reals,
                                     f_perm=fp.perm, f_ptr=fp.ptr, f_idx=fp.idx, f_val=fp.val,
                                     f_work=fp.work)

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
        """The model's arrays (``MESH_ARRAYS``) and the stitch pairs (``MeshPack``)."""
        m = self.model
        return self._packs.get("mesh", MeshPack, **{name: getattr(m, name)
                                                    for name in MESH_ARRAYS},
                               stitch=self.stitch)

    def _state(self):
        x, v = self.model.state.x, self.model.state.v
        return self._packs.get("state", StatePack, x=x, v=v)

    def _constants(self, h=0.0):
        """``coef`` (``C_*``) for a launch: the step ``h`` (0 where the kernel has none), the
        material's and settings' values now, and the model's counts."""
        m, mat, s = self.model, self.model.material, self.settings
        self._coef[:] = (h, *s.gravity, mat.k_warp, mat.k_weft, mat.k_shear, mat.bend_scale(),
                         mat.damp_mass, mat.damp_stiff, s.stitch_stiffness, s.cg_tol,
                         s.cg_max_iters, m.n_verts, m.n_faces, self.n_hinges,
                         self.n_stitches, PC_JACOBI, s.cg_max_iters)
        return self._coef

    # -- public API ---------------------------------------------------------------------------
    def step(self, h):
        """Advance model.state by one backward-Euler step of ``h`` seconds."""
        self.model.mark_step_start()
        if self.host_loop:
            return self._step_host_loop(h)
        coef = self._constants(h)
        coef[C_PC], pc = self._preconditioner()
        if coef[C_PC] != PC_JACOBI and self._jacobi_iters is not None:
            coef[C_PC_ITERS] = max(1, int(STALE_SHARE * self._jacobi_iters))
        rel, iters, left = _step(coef, self._mesh(), self._state(), self._elems, self._cg, pc)
        self.last_cg_iters = int(iters)
        self.last_cg_residual = float(rel)
        if coef[C_PC] == PC_JACOBI:
            self._jacobi_iters = self.last_cg_iters
        elif left:
            self._stale = (self._pc, self._pc.made)
        return self.last_cg_iters

    def _step_host_loop(self, h):
        """``step`` with the CG loop on the host, one launch per iteration (Vulkan, Metal:
        see ``_linearise``). The same arithmetic as the one-launch kernel."""
        s = self.settings
        coef, mesh, state = self._constants(h), self._mesh(), self._state()
        self._check_loops(_linearise(2, coef, mesh, state, self._elems, self._cg), "linearise")
        rz, bnorm, ran = _start(2, coef, mesh, state, self._elems, self._cg)
        self._check_loops(ran, "start")
        rel = float(np.sqrt(abs(rz) / max(bnorm, 1e-300)))
        iters = 0
        while iters < s.cg_max_iters and rel > s.cg_tol:
            rz_new, stalled, ran = _iteration(2, rz, coef, mesh, self._elems, self._cg)
            self._check_loops(ran, "CG iteration")
            if stalled:
                break
            rz = rz_new
            rel = float(np.sqrt(abs(rz) / max(bnorm, 1e-300)))
            iters += 1
        self._check_loops(_advance(2, coef, mesh, state, self._cg), "advance")
        self.last_cg_iters, self.last_cg_residual = iters, rel
        return iters

    def _check_loops(self, ran, phase):
        """Raise backend.LoopCapError unless the launch's ``loop_probe`` ran in full: a driver
        that caps loops (lavapipe) ends every loop of the launch once the cap is hit, and the
        step would be silently wrong (measured with a probe since removed, `git log --
        benchmarks/loop_cap.py`: linearise runs ~50
        loop iterations a vertex, so it is cut short from ~1300 vertices, a CG iteration ~26
        a vertex)."""
        backend.check_loop_probe(ran, f"dynamics kernel {phase}",
                                 f"{self.model.n_verts} vertices", 35)

    def energy(self):
        """Elastic energy (membrane + bending + stitches) of the current positions, J."""
        return float(_energy(self._constants(), self._mesh(), self._state(), self._elems))

    def forces(self):
        """Elastic forces (no gravity, no damping) at the current positions, (V, 3) numpy."""
        _elastic_forces(self._constants(), self._mesh(), self._state(), self._elems, self._cg)
        return self.force.to_numpy()[: self.model.n_verts].astype(np.float64)

    def force_jacobian_product(self, p, exact=True):
        """(df/dx) p at the current positions for a (V, 3) direction ``p``: exact membrane
        Jacobian when ``exact`` (bending: Gauss-Newton part, exact where theta = theta_0),
        otherwise minus the positive semi-definite K the solver uses."""
        m = self.model
        full = np.zeros((m.v_cap, 3))
        full[: m.n_verts] = p
        self.p.from_numpy(full.astype(self.p.to_numpy().dtype))
        _jacobian_product(1 if exact else 0, self._constants(), self._mesh(), self._state(),
                          self._elems, self._cg)
        return -self.Ap.to_numpy()[: m.n_verts].astype(np.float64)

    def system_matrix(self, h, B):
        """Fill the BlockMatrix ``B`` (cloth/system_matrix.py, built over this model's mesh and
        stitches) with the matrix of the last ``step(h)``: A = (1 + h alpha) M + h (beta + h)
        K_psd, linearised where that step started (the element data its ``linearise`` left).
        Pinned rows are not filtered (the strain solver keeps pins fixed itself)."""
        m = self.model
        if B.n_bend != m.n_bend:
            raise ValueError(f"the block pattern holds {B.n_bend} bending entries, the model "
                             f"{m.n_bend}: build it with system_matrix.pattern_of")
        blocks = self._packs.get("blocks", BlockPack, val=B.val, diag=B.diag,
                                 face_slot=B.face_slot, edge_slot=B.edge_slot,
                                 stitch_slot=B.stitch_slot, bend_slot=B.bend_slot)
        _fill_blocks(self._constants(h), B.nnz, blocks, self._mesh(), self._elems)


@ti.kernel
def _fill_blocks(coef: A, nnz: ti.i32, blocks: BlockPack, mesh: MeshPack, elems: ElementPack):
    # The blocks of add_K_product (exact = 0) written out: serial, as elements share blocks.
    ti.loop_config(serialize=True)
    for _ in range(1):
        c = constants(coef)
        scale = c.h * (c.beta + c.h)
        I = ti.Matrix.identity(float, 3)
        for k in range(nnz):
            blocks.val[k] = ti.Matrix.zero(float, 3, 3)
        for i in range(c.nv):
            blocks.val[blocks.diag[i]] += (1.0 + c.h * c.alpha) * mesh.vert_mass[i] * I
        for f in range(c.nf):
            A = mesh.face_rest_area[f]
            for n in ti.static(range(3)):
                for q in ti.static(range(3)):
                    blocks.val[blocks.face_slot[f, 3 * n + q]] += scale * A * \
                        face_block(f, n, q, c, elems)
        for e in range(c.ne):
            if mesh.edge_faces[e][1] >= 0:
                k = scale * c.kb * mesh.edge_bend_weight[e]
                G = elems.edge_grad[e]
                for n in ti.static(range(4)):
                    gn = ti.Vector([G[n, 0], G[n, 1], G[n, 2]])
                    for q in ti.static(range(4)):
                        gq = ti.Vector([G[q, 0], G[q, 1], G[q, 2]])
                        blocks.val[blocks.edge_slot[e, 4 * n + q]] += k * gn.outer_product(gq)
        for i in range(mesh.bend_ptr.shape[0] - 1):
            for kq in range(mesh.bend_ptr[i], mesh.bend_ptr[i + 1]):
                blocks.val[blocks.bend_slot[kq]] += scale * c.kb * mesh.bend_val[kq] * I
        for s in range(c.nst):
            k = scale * c.kst
            blocks.val[blocks.stitch_slot[s, 0]] += k * I
            blocks.val[blocks.stitch_slot[s, 1]] -= k * I
            blocks.val[blocks.stitch_slot[s, 2]] -= k * I
            blocks.val[blocks.stitch_slot[s, 3]] += k * I


@ti.func
def face_block(f, n, q, c, elems: T):
    """Block (n, q) of face f's membrane stiffness K = -d2E / dx_n dx_q per unit rest area,
    made positive semi-definite: the curvature terms kept where the warp or weft is in
    tension, the shear's dropped (``add_K_product`` with exact = 0 applies the same K).
    The one definition of the block: the CG preconditioner, the assembled matrix and the
    sparse direct solver all take it from here. ``c``: the ``constants`` (kw, kf, ks)."""
    fu, fv, E = elems.face_fu[f], elems.face_fv[f], elems.face_E[f]
    wa, wb = elems.face_wa[f], elems.face_wb[f]
    gn = wa[n] * fv + wb[n] * fu
    gq = wa[q] * fv + wb[q] * fu
    aa, bb = wa[n] * wa[q], wb[n] * wb[q]
    return c.kw * aa * fu.outer_product(fu) + c.kf * bb * fv.outer_product(fv) \
        + c.ks * gn.outer_product(gq) \
        + (c.kw * ti.max(E[0], 0.0) * aa + c.kf * ti.max(E[1], 0.0) * bb) * \
        ti.Matrix.identity(float, 3)


# -- element kinematics -----------------------------------------------------------------------
@ti.func
def face_weights(f, mesh: T):
    """Warp and weft weights a_n, b_n of the face's vertices: F e_warp = sum a_n x_n."""
    D = mesh.face_Dm_inv[f] @ mesh.face_grain[f]   # rows: M_j, M_k in grain
    wa = ti.Vector([-D[0, 0] - D[1, 0], D[0, 0], D[1, 0]])
    wb = ti.Vector([-D[0, 1] - D[1, 1], D[0, 1], D[1, 1]])
    return wa, wb


@ti.func
def update_face(f, mesh: T, state: T, elems: T):
    tri = mesh.face_verts[f]
    wa, wb = face_weights(f, mesh)
    fu = ti.Vector([0.0, 0.0, 0.0], dt=float)
    fv = ti.Vector([0.0, 0.0, 0.0], dt=float)
    for n in ti.static(range(3)):
        fu += wa[n] * state.x[tri[n]]
        fv += wb[n] * state.x[tri[n]]
    elems.face_fu[f], elems.face_fv[f] = fu, fv
    elems.face_wa[f], elems.face_wb[f] = wa, wb
    elems.face_E[f] = ti.Vector([0.5 * (fu.dot(fu) - 1.0), 0.5 * (fv.dot(fv) - 1.0),
                                 0.5 * fu.dot(fv)])


@ti.func
def update_edge(e, mesh: T, state: T, elems: T):
    """Dihedral angle and its gradient (Bridson et al. 2003) for edge x0-x1 with opposite
    vertices x2 (face 0, order x0 x1 x2) and x3 (face 1, order x1 x0 x3)."""
    theta = 0.0
    G = ti.Matrix.zero(float, 4, 3)
    if mesh.edge_faces[e][1] >= 0:
        ev, eo = mesh.edge_verts[e], mesh.edge_opp[e]
        x0, x1 = state.x[ev[0]], state.x[ev[1]]
        x2, x3 = state.x[eo[0]], state.x[eo[1]]
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
    elems.edge_theta[e] = theta
    elems.edge_grad[e] = G


@ti.func
def edge_vertex(e, n, mesh: T):
    """Vertex n (0..3) of edge e's bending stencil: x0, x1, x2, x3."""
    ev, eo = mesh.edge_verts[e], mesh.edge_opp[e]
    vid = eo[1]
    if n == 0:
        vid = ev[0]
    elif n == 1:
        vid = ev[1]
    elif n == 2:
        vid = eo[0]
    return vid


@ti.func
def update_kinematics(c, mesh: T, state: T, elems: T):
    for f in range(c.nf):
        update_face(f, mesh, state, elems)
    for e in range(c.ne):
        update_edge(e, mesh, state, elems)


@ti.func
def bend_apply(src: T, dst: T, scale, mesh: T):
    """dst += scale * Q src, Q the isotropic bending matrix (cloth/bending.py; its rows are
    empty when the model uses the hinge energy). Row by row: no atomics. Q's rows sum to
    zero, so row i applies to src_k - src_i: exact for a translated cloth, and without the
    round-off of large positions (1e-16 |x| |Q| per entry)."""
    for i in range(mesh.bend_ptr.shape[0] - 1):
        si = src[i]
        acc = ti.Vector([0.0, 0.0, 0.0])
        for k in range(mesh.bend_ptr[i], mesh.bend_ptr[i + 1]):
            acc += mesh.bend_val[k] * (src[mesh.bend_col[k]] - si)
        dst[i] += scale * acc


# -- forces -----------------------------------------------------------------------------------
@ti.func
def add_elastic_forces(force: T, c, mesh: T, state: T, elems: T):
    for f in range(c.nf):
        tri = mesh.face_verts[f]
        A = mesh.face_rest_area[f]
        fu, fv, E = elems.face_fu[f], elems.face_fv[f], elems.face_E[f]
        wa, wb = elems.face_wa[f], elems.face_wb[f]
        for n in ti.static(range(3)):
            grad = A * (c.kw * E[0] * wa[n] * fu + c.kf * E[1] * wb[n] * fv
                        + 2.0 * c.ks * E[2] * (wa[n] * fv + wb[n] * fu))
            force[tri[n]] -= grad
    for e in range(c.ne):
        if mesh.edge_faces[e][1] >= 0:
            w = c.kb * mesh.edge_bend_weight[e] * (elems.edge_theta[e] -
                                                   mesh.edge_rest_angle[e])
            G = elems.edge_grad[e]
            for n in ti.static(range(4)):
                vid = edge_vertex(e, n, mesh)
                force[vid] -= w * ti.Vector([G[n, 0], G[n, 1], G[n, 2]])
    bend_apply(state.x, force, -c.kb, mesh)
    for s in range(c.nst):
        a, b = mesh.stitch[s][0], mesh.stitch[s][1]
        d = state.x[a] - state.x[b]
        force[a] -= c.kst * d
        force[b] += c.kst * d


@ti.func
def add_K_product(src: T, dst: T, scale, c, exact: ti.i32, mesh: T, elems: T):
    """dst += scale * K src, with K = -df/dx (PSD-projected unless ``exact``)."""
    for f in range(c.nf):
        tri = mesh.face_verts[f]
        wa, wb = elems.face_wa[f], elems.face_wb[f]
        U, W = face_UW(f, src, scale, c, exact, mesh, elems)
        for n in ti.static(range(3)):
            dst[tri[n]] += wa[n] * U + wb[n] * W
    for e in range(c.ne):
        if mesh.edge_faces[e][1] >= 0:
            k = c.kb * mesh.edge_bend_weight[e]
            G = elems.edge_grad[e]
            dtheta = 0.0
            for n in ti.static(range(4)):
                dtheta += ti.Vector([G[n, 0], G[n, 1], G[n, 2]]).dot(
                    src[edge_vertex(e, n, mesh)])
            for n in ti.static(range(4)):
                dst[edge_vertex(e, n, mesh)] += scale * k * dtheta * \
                    ti.Vector([G[n, 0], G[n, 1], G[n, 2]])
    bend_apply(src, dst, scale * c.kb, mesh)
    for s in range(c.nst):
        a, b = mesh.stitch[s][0], mesh.stitch[s][1]
        d = src[a] - src[b]
        dst[a] += scale * c.kst * d
        dst[b] -= scale * c.kst * d


@ti.func
def face_UW(f, src: T, scale, c, exact, mesh: T, elems: T):
    """Face f's membrane K src, times ``scale``, as two vectors (U, W): its term at corner n
    is a_n U + b_n W (a, b the warp and weft weights, ``face_weights``). K = -d2E/dx2 is
    PSD-projected unless ``exact``. With F_g's columns fu, fv and their changes dfu = sum a_n
    src_n, dfv = sum b_n src_n, and dE the Green strain's change,
    U = A (k_w (dE0 fu + E0 dfu) + 2 k_s (dE2 fv + E2 dfv)) and
    W = A (k_f (dE1 fv + E1 dfv) + 2 k_s (dE2 fu + E2 dfu)).
    Written this way (U and W once per face, then two products per corner) the serial CG
    iteration takes 0.56 ms instead of 0.67 at 16k triangles (docs/speed/parallel.md)."""
    tri = mesh.face_verts[f]
    fu, fv, E = elems.face_fu[f], elems.face_fv[f], elems.face_E[f]
    wa, wb = elems.face_wa[f], elems.face_wb[f]
    dfu = wa[0] * src[tri[0]] + wa[1] * src[tri[1]] + wa[2] * src[tri[2]]
    dfv = wb[0] * src[tri[0]] + wb[1] * src[tri[1]] + wb[2] * src[tri[2]]
    dE0, dE1 = fu.dot(dfu), fv.dot(dfv)
    dE2 = 0.5 * (fu.dot(dfv) + fv.dot(dfu))
    # Curvature terms: kept where they are non-negative (stretch in tension) unless exact.
    E0, E1, E2 = E[0], E[1], E[2]
    if exact == 0:
        E0, E1, E2 = ti.max(E0, 0.0), ti.max(E1, 0.0), 0.0
    sA = scale * mesh.face_rest_area[f]
    U = sA * (c.kw * (dE0 * fu + E0 * dfu) + 2.0 * c.ks * (dE2 * fv + E2 * dfv))
    W = sA * (c.kf * (dE1 * fv + E1 * dfv) + 2.0 * c.ks * (dE2 * fu + E2 * dfu))
    return U, W


@ti.func
def add_K_diagonal(precond: T, scale, c, mesh: T, elems: T):
    """precond += scale * (3x3 diagonal blocks of the PSD K)."""
    for f in range(c.nf):
        tri = mesh.face_verts[f]
        A = mesh.face_rest_area[f]
        for n in ti.static(range(3)):
            precond[tri[n]] += scale * A * face_block(f, n, n, c, elems)
    for e in range(c.ne):
        if mesh.edge_faces[e][1] >= 0:
            k = c.kb * mesh.edge_bend_weight[e]
            G = elems.edge_grad[e]
            for n in ti.static(range(4)):
                g = ti.Vector([G[n, 0], G[n, 1], G[n, 2]])
                precond[edge_vertex(e, n, mesh)] += scale * k * g.outer_product(g)
    for i in range(mesh.bend_ptr.shape[0] - 1):
        if mesh.bend_ptr[i + 1] > mesh.bend_ptr[i]:   # the row's diagonal entry comes first
            precond[i] += scale * c.kb * mesh.bend_val[mesh.bend_ptr[i]] * \
                ti.Matrix.identity(float, 3)
    for s in range(c.nst):
        I = ti.Matrix.identity(float, 3)
        precond[mesh.stitch[s][0]] += scale * c.kst * I
        precond[mesh.stitch[s][1]] += scale * c.kst * I


# -- kernels ----------------------------------------------------------------------------------
# The kernels without a serial loop read the constants at their top: Taichi hands them to the
# parallel loops that follow through its global temporaries.
@ti.kernel
def _elastic_forces(coef: A, mesh: MeshPack, state: StatePack, elems: ElementPack,
                    cg: SolvePack):
    c = constants(coef)
    for i in range(c.nv):
        cg.force[i] = ti.Vector([0.0, 0.0, 0.0])
    update_kinematics(c, mesh, state, elems)
    add_elastic_forces(cg.force, c, mesh, state, elems)


@ti.kernel
def _jacobian_product(exact: ti.i32, coef: A, mesh: MeshPack, state: StatePack,
                      elems: ElementPack, cg: SolvePack):
    c = constants(coef)
    for i in range(c.nv):
        cg.Ap[i] = ti.Vector([0.0, 0.0, 0.0])
    update_kinematics(c, mesh, state, elems)
    add_K_product(cg.p, cg.Ap, 1.0, c, exact, mesh, elems)


@ti.kernel
def _energy(coef: A, mesh: MeshPack, state: StatePack, elems: ElementPack) -> float:
    c = constants(coef)
    update_kinematics(c, mesh, state, elems)
    total = 0.0
    for f in range(c.nf):
        E = elems.face_E[f]
        total += mesh.face_rest_area[f] * (0.5 * c.kw * E[0] ** 2 + 0.5 * c.kf * E[1] ** 2
                                           + 2.0 * c.ks * E[2] ** 2)
    for e in range(c.ne):
        if mesh.edge_faces[e][1] >= 0:
            d = elems.edge_theta[e] - mesh.edge_rest_angle[e]
            total += 0.5 * c.kb * mesh.edge_bend_weight[e] * d * d
    # x.Qx = -1/2 sum_ik Q_ik |x_i - x_k|^2 (rows summing to zero): terms the size of the
    # bends themselves. The plain sum of Q_ik x_i.x_k cancels terms ~1e4 times larger, and its
    # round-off (the parallel sum's order varies) stalled the calibration's energy descent.
    for i in range(mesh.bend_ptr.shape[0] - 1):
        for k in range(mesh.bend_ptr[i], mesh.bend_ptr[i + 1]):
            d = state.x[i] - state.x[mesh.bend_col[k]]
            total -= 0.25 * c.kb * mesh.bend_val[k] * d.dot(d)
    for s in range(c.nst):
        d = state.x[mesh.stitch[s][0]] - state.x[mesh.stitch[s][1]]
        total += 0.5 * c.kst * d.dot(d)
    return total


@ti.func
def free_residual(c, mesh: T, cg: T):
    """res = rhs - Ap on the free rows and 0 on the pinned ones: CG's starting residual."""
    for i in range(c.nv):
        cg.res[i] = cg.rhs[i] - cg.Ap[i]
        if mesh.vert_pinned[i] != 0:
            cg.res[i] = ti.Vector([0.0, 0.0, 0.0])


@ti.func
def apply_A(src: T, dst: T, c, mesh: T, elems: T):
    """dst = A src with A = (1 + h alpha) M + h (beta + h) K, pinned rows filtered."""
    for i in range(c.nv):
        dst[i] = (1.0 + c.h * c.alpha) * mesh.vert_mass[i] * src[i]
    add_K_product(src, dst, c.h * (c.beta + c.h), c, 0, mesh, elems)
    for i in range(c.nv):
        if mesh.vert_pinned[i] != 0:
            dst[i] = ti.Vector([0.0, 0.0, 0.0])


@ti.func
def linearise(c, mesh: T, state: T, elems: T, cg: T):
    """Forces and element quantities at the start of the step, the diagonal blocks of A
    (in ``cg.precond``) and the right-hand side h (f - alpha M v) - h (beta + h) K v."""
    for i in range(c.nv):
        cg.force[i] = mesh.vert_mass[i] * c.g
        cg.precond[i] = (1.0 + c.h * c.alpha) * mesh.vert_mass[i] * ti.Matrix.identity(float, 3)
    update_kinematics(c, mesh, state, elems)
    add_elastic_forces(cg.force, c, mesh, state, elems)
    add_K_diagonal(cg.precond, c.h * (c.beta + c.h), c, mesh, elems)
    for i in range(c.nv):
        cg.rhs[i] = c.h * (cg.force[i] - c.alpha * mesh.vert_mass[i] * state.v[i])
    add_K_product(state.v, cg.rhs, -c.h * (c.beta + c.h), c, 0, mesh, elems)


# The step's phases, shared by the one-launch kernel and the host-loop kernels.
@ti.func
def cg_prepare(c, mesh: T, state: T, cg: T):
    """After ``linearise``: prescribe the pinned dv, invert the diagonal blocks, and leave dv
    in p for ``cg_pass``'s first pass (r = b - A dv)."""
    # Pinned vertices: the dv that lands them on their target at the end of the step.
    # Free vertices start CG from the last step's dv (warm start: near rest, successive
    # velocity changes are alike); on_mesh_changed zeroes it after a remesh.
    for i in range(c.nv):
        if mesh.vert_pinned[i] != 0:
            cg.dv[i] = (mesh.vert_pin_target[i] - state.x[i]) / c.h - state.v[i]
        cg.precond[i] = cg.precond[i].inverse()
        cg.p[i] = cg.dv[i]


@ti.func
def cg_pass(with_pc: ti.template(), mode, first, rz, c, mesh: T, elems: T, cg: T, pc: T):
    """One pass of preconditioned CG on the free vertices. The first (``first`` = 1, after
    ``cg_prepare``) starts CG: r = b - A dv over the free vertices (pinned dv enters through
    the coupling); the others are an iteration: p.A p, then dv and r updated. Both end with
    z = P r and the next p, P by ``mode`` (PC_*) where the launch compiles the multigrid and
    the factor in (``with_pc``, their arrays in ``pc``), else block Jacobi.

    Returns (new r.z, 1 if the iteration stalled on p.A p <= 0 and changed nothing, new
    r.D r, b.D b on the first pass) with D the inverse diagonal blocks (block Jacobi): CG
    stops on sqrt(r.D r / b.D b), the free rows only, whichever preconditioner it uses, so
    that ``cg_tol`` means one accuracy (measured at 4k faces: in the multigrid's own norm the
    same tolerance left a step 10x further from the tight one).

    One pass for both, so that the product with A and the preconditioner have one call site
    each: a ti.func is inlined wherever it is called, and each copy made the step's compile
    longer."""
    apply_A(cg.p, cg.Ap, c, mesh, elems)
    rz_new, rd_new, bnorm, stalled = rz, 0.0, 0.0, 0.0
    if first == 1:
        free_residual(c, mesh, cg)
    else:
        pAp = 0.0
        for i in range(c.nv):
            pAp += cg.p[i].dot(cg.Ap[i])
        if pAp > 0.0:
            step = rz / pAp
            for i in range(c.nv):
                cg.dv[i] += step * cg.p[i]
                cg.res[i] -= step * cg.Ap[i]
        else:
            stalled = 1.0
    if stalled == 0.0:
        if ti.static(with_pc):
            if mode == PC_MULTIGRID:
                # z = P r. The fine level's damped block Jacobi uses this step's diagonal
                # blocks (cg.precond, inverted by cg_prepare), not the ones the hierarchy was
                # made with: made a few steps earlier, they slowed the pull scene's CG (4.8k
                # faces, the corner dragged: 49-183 iterations a step against block Jacobi's
                # 119-164; with these, 48-90).
                multigrid.apply(c.nv, pc.mg_int, pc.mg_real, cg.precond, cg.res, cg.z)
            elif mode == PC_FACTOR:
                factor_precond.apply(c.nv, pc.f_perm, pc.f_ptr, pc.f_idx, pc.f_val,
                                     pc.f_work, cg.res, cg.z)
        rz_new = 0.0
        for i in range(c.nv):
            Dr = cg.precond[i] @ cg.res[i]
            if mode == PC_JACOBI or not ti.static(with_pc):
                cg.z[i] = Dr
            if mesh.vert_pinned[i] != 0:
                cg.z[i] = ti.Vector([0.0, 0.0, 0.0])
            rz_new += cg.res[i].dot(cg.z[i])
            rd_new += cg.res[i].dot(Dr)
            if first == 1 and mesh.vert_pinned[i] == 0:
                bnorm += cg.rhs[i].dot(cg.precond[i] @ cg.rhs[i])
        if first == 1:
            for i in range(c.nv):
                cg.p[i] = cg.z[i]          # pinned z is 0
        else:
            beta_cg = rz_new / rz
            for i in range(c.nv):
                cg.p[i] = cg.z[i] + beta_cg * cg.p[i]
                if mesh.vert_pinned[i] != 0:
                    cg.p[i] = ti.Vector([0.0, 0.0, 0.0])
    return ti.Vector([rz_new, stalled, rd_new, bnorm])


@ti.func
def advance(c, mesh: T, state: T, cg: T):
    """v += dv, x += h v; pins exactly on target."""
    for i in range(c.nv):
        state.v[i] += cg.dv[i]
        state.x[i] += c.h * state.v[i]
        if mesh.vert_pinned[i] != 0:
            state.x[i] = mesh.vert_pin_target[i]


@ti.func
def relative(rz, bnorm):
    return ti.sqrt(ti.abs(rz) / ti.max(bnorm, 1e-300))


@ti.kernel
def _step(coef: A, mesh: MeshPack, state: StatePack, elems: ElementPack,
          cg: SolvePack, pc: PrecondPack) -> ti.types.vector(3, float):
    """(relative residual, CG iterations, 1 if CG left the chosen preconditioner for block
    Jacobi after ``c.pc_iters`` iterations), the first two also left in scalars[0] and
    scalars[1]."""
    # The whole step runs in one serial kernel: on a 2-core CPU, launching a kernel per CG
    # phase costs more than the work below ~50k triangles (docs/method.md §4, cost notes).
    # A parallel CG was built and measured twice and lost on this machine
    # (docs/speed/parallel.md).
    # Returning the numbers costs less than reading them back (~0.05 vs ~0.17 ms).
    ti.loop_config(serialize=True)
    left = 0.0
    for _ in range(1):
        c = constants(coef)
        linearise(c, mesh, state, elems, cg)
        cg_prepare(c, mesh, state, cg)
        mode = c.pc
        first = 1
        rz, bnorm, rel = 0.0, 0.0, 0.0
        iters = 0
        stalled = 0.0
        while True:
            out = cg_pass(True, mode, first, rz, c, mesh, elems, cg, pc)
            if first == 1:
                first = 0
                bnorm = out[3]
                rz = out[0]
                rel = relative(out[2], bnorm)
            else:
                stalled = out[1]
                if stalled == 0.0:
                    rz = out[0]
                    rel = relative(out[2], bnorm)
                    iters += 1
            if not (iters < c.max_iters and rel > c.tol and stalled == 0.0):
                break
            if mode != PC_JACOBI and iters >= c.pc_iters:
                # Stale (STALE_SHARE): CG starts again with block Jacobi from this dv.
                mode = PC_JACOBI
                left = 1.0
                first = 1
                for i in range(c.nv):
                    cg.p[i] = cg.dv[i]
        cg.scalars[0] = rel
        advance(c, mesh, state, cg)
        cg.scalars[1] = iters
    return ti.Vector([cg.scalars[0], cg.scalars[1], left])


# The same step as three kinds of launch with the CG loop on the host, for Vulkan and Metal
# (backend.HOST_LOOP_AL). Measured on lavapipe (Debian's software Vulkan), f32, hanging res 20:
# the one-launch step computed dv but never wrote v and x once it ran 14 CG iterations or more
# (13 were fine; KE stayed exactly 0 and the cloth never fell), like the strain solver's
# one-launch solve, which crashed that driver.
# Two launches where the one-launch step has linearise, cg_prepare and the first cg_pass:
# Vulkan and Metal bind at most ~31 arrays per kernel (measured on lavapipe: with 32 loose
# ndarray arguments one was silently dropped, 33 crashed). What counts is the arrays a kernel
# uses, not the pack members it is given (measured: a 40-member pack of which 31 are used
# runs right, 32 used does not, with one loose array besides); _linearise uses 27 (with
# ``coef``), _start 29, _iteration 25.
# Each launch ends with ``backend.loop_probe`` and returns it (``ImplicitEuler._check_loops``).
@ti.kernel
def _linearise(two: int, coef: A, mesh: MeshPack, state: StatePack, elems: ElementPack,
               cg: SolvePack) -> float:
    ti.loop_config(serialize=True)
    ran = 0.0
    for _ in range(1):
        c = constants(coef)
        linearise(c, mesh, state, elems, cg)
        ran = backend.loop_probe(two)
    return ran


@ti.kernel
def _start(two: int, coef: A, mesh: MeshPack, state: StatePack, elems: ElementPack,
           cg: SolvePack) -> ti.types.vector(3, float):
    ti.loop_config(serialize=True)
    out = ti.Vector([0.0, 0.0, 0.0])
    for _ in range(1):
        c = constants(coef)
        cg_prepare(c, mesh, state, cg)
        rb = cg_pass(False, PC_JACOBI, 1, 0.0, c, mesh, elems, cg, cg)
        out = ti.Vector([rb[0], rb[3], backend.loop_probe(two)])
    return out


@ti.kernel
def _iteration(two: int, rz: float, coef: A, mesh: MeshPack, elems: ElementPack,
               cg: SolvePack) -> ti.types.vector(3, float):
    ti.loop_config(serialize=True)
    out = ti.Vector([0.0, 0.0, 0.0])
    for _ in range(1):
        c = constants(coef)
        it = cg_pass(False, PC_JACOBI, 0, rz, c, mesh, elems, cg, cg)
        out = ti.Vector([it[0], it[1], backend.loop_probe(two)])
    return out


@ti.kernel
def _advance(two: int, coef: A, mesh: MeshPack, state: StatePack, cg: SolvePack) -> float:
    ti.loop_config(serialize=True)
    ran = 0.0
    for _ in range(1):
        c = constants(coef)
        advance(c, mesh, state, cg)
        ran = backend.loop_probe(two)
    return ran
