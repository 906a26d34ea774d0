"""The Taichi side of strain limiting, part 1: the work arrays (``Workspace``), the named
groups the kernels take them in (``MeshPack`` ... ``StepPack``), the indices into its
``params``, ``budget`` and ``stats`` arrays, and copies between the model's fields and the arrays.
The solves are in ``al.py`` (augmented Lagrangian, one kernel) and ``direct.py`` (its loop on
the host with Cholesky steps).

Design notes (measured on this 2-core CPU, Taichi 1.7.4, f64):
- Every array is a Taichi *ndarray* passed as a kernel argument, never a field captured by a
  kernel: kernels that capture fields are recompiled for every new field (every model, every
  reallocation), and compiling the mapping constraints plus the Newton kernels costs ~10-40 s.
  With ndarray arguments each kernel compiles once per process (and is then found in Taichi's
  offline cache by later processes).
- Launch overhead is ~15 us per kernel and ~50-60 us per parallel top-level loop, while one
  PCG iteration over 1k triangles costs ~50 us. So each solve phase (a whole PCG solve, a
  whole constraint assembly, a whole Jacobi / Gauss-Seidel run) is one kernel whose top-level
  loop is serialized; all face and vertex loops are then plain serial loops without atomics.
  Launching from Python also costs ~0.1-0.4 ms per kernel in argument handling with ~20
  ndarray arguments (measured with cProfile: half of a 1k-triangle projection), so the whole
  augmented-Lagrangian solve is a single kernel (``solve_al``).
- The constraint loop inside the Newton kernels runs over c < K at run time (not unrolled with
  ti.static): unrolling 8 constraints x 9 gradient entries made one kernel take 30 s to compile.
"""
import numpy as np
import taichi as ti

from ..ndarrays import A, T, PackCache, get_rows  # noqa: F401 (strain kernels import A, T)
from .constraints import K_MAX


# Indices into the ``stats`` array (read back once per solve).
ST_ITERS, ST_VIOL, ST_CONVERGED, ST_CG, ST_NEWTON, ST_COMP, ST_START_VIOL, ST_TRIALS = range(8)
# The stationarity reached (metres): the largest vertex move of the Newton step computed at the
# final point with the final multipliers (the KKT test's measure, ``al.solve_al``).
ST_KKT = 8
N_STATS = 9
# The AL loop's outcome (``al.solve_al``'s ``converged``; stats[ST_CONVERGED] holds 0 or 1):
# still running, converged (the limits hold and, with the kkt stop, the last Newton step is
# below its tolerance), or feasible as given (x_hat within tol: nothing to do).
RUNNING, CONVERGED, FEASIBLE_AS_GIVEN = 0, 1, 2
# Backtracking line searches halve the step at most this many times; the try after the last
# halving takes no step (a = 0) and leaves the constraints assembled at x.
LAST_TRY = 12
# ``al.pcg_direction``'s ``skip_rr`` when no step may be skipped (the first of a round).
NO_SKIP = -1.0
# The PCG's preconditioner (``al.precondition``): H's 3x3 diagonal blocks, a sparse Cholesky
# factor of the implicit step's matrix (factor_precond.py), its aggregation multigrid
# (multigrid.py).
PC_JACOBI, PC_FACTOR, PC_MULTIGRID = 0, 1, 2
PC_NAMES = {PC_JACOBI: "block Jacobi", PC_FACTOR: "factor", PC_MULTIGRID: "multigrid"}
# Indices into the ``params`` array.
P_WARP, P_WEFT, P_SHEAR, P_MARGIN, P_DELTA, P_SVD_DELTA, P_CONTACT_SCALE = 0, 2, 4, 6, 7, 8, 9
P_ISO = 10
# A round's inner loop stops once |grad L_A| fell below this fraction of its first value (0:
# run max_newton steps).
P_INNER_RTOL = 11
# The KKT stop's stationarity tolerance (metres: the largest vertex move of a Newton step at the
# answer); 0 = the fast solve's stop on violation and multiplier change alone.
P_KKT_TOL = 12
# 1: the PCG path's Newton step is the primal-dual active-set step (``al.pdas_resolves``,
# the exact solve in the kernels); 0: the fast (margin) model's.
P_PDAS = 13
N_PARAMS = 14
# Indices into the ``budget`` array: one AL solve's controls (``al.solve_al``), written by the
# host before each launch. Why an array and not kernel arguments: solve_al had 65 parameters,
# and Taichi counts every scalar, ndarray and argpack member against one limit of 64 per
# launch; the integers are exact in a float.
# B_MAX_NEWTON Newton steps a round up to round B_LATE_ROUND, B_LATE_NEWTON after it.
(B_MU0, B_MU_GROW, B_MU_MAX, B_MAX_ROUNDS, B_MAX_NEWTON, B_MAX_CG, B_RTOL, B_TOL, B_STEP_TOL,
 B_FROM_PREV, B_PC_MODE, B_LATE_ROUND, B_LATE_NEWTON) = range(13)
N_BUDGET = 13
# A vertex without a contact half-space: n = 0 and d far below any position, so d - n.x never
# comes near activating.
NO_CONTACT = -1e30
# Contact half-spaces per vertex: the two nearest obstacle parts' planes (in a concave corner of
# a body, keeping out of one primitive's plane alone walks into the next primitive).
CONTACT_SLOTS = 2


# Named argument groups: the kernels take their arrays in these packs, by name,
# instead of ~50 positional ndarrays whose order every call site had to repeat (a misordered
# argument still compiled). A member's name is unique across the packs: in Taichi 1.7.4 two
# packs passed to one kernel cannot share a member name, and a kernel cannot assign a local of
# a member's name (``K, nv, nf, ns = cons.n_per_face, ...``). Besides arrays a pack holds the
# counts that say how much of them is in use, so no kernel takes a size apart from its
# arrays; other scalars (the penalty, tolerances, flags) are kernel arguments or in
# ``budget``. Packs do not lift Taichi's limit of 64 per launch: each pack counts one, and
# each member one more (solve_al: 60). A pack is made once per set of arrays and counts
# (``Workspace.pack``), so a launch costs what the loose arguments cost, and a kernel still
# compiles once per process (Taichi keys a pack by its members' types, not their values).
# A pack is never changed after it is made: a count that changed makes a new pack. Why: on
# Vulkan a launch reads its packs when it runs, not when it is queued; setting a member of a
# pack that a queued launch holds changed what that launch saw (measured on lavapipe: 59
# launches of one pack, its count set before each, saw later counts). Making a pack of 9
# costs ~0.2-0.4 ms; counts change with a remesh, a new seam set or another method.
#   mesh      the rest state the constraints are defined on, their parameters, and the
#             active vertex and face counts;
#   metric    the projection's metric W in its block pattern, and the Newton matrix H there;
#   cons      the strain constraints at the iterate and their multipliers, and how many of
#             them a face has under the method in use (constraints.N_CONSTRAINTS);
#   contacts  contact half-spaces, friction and the seams in use, and their multipliers;
#   vec       the solve's per-vertex vectors (iterate, x_hat, Newton and PCG vectors);
#   pc        the PCG preconditioners' arrays (block Jacobi, factor, multigrid);
#   io        the model's state a projection starts from and returns to.
MeshPack = ti.types.argpack(face_verts=A, Dm_inv=A, grain=A, rest_area=A, mass=A, pinned=A,
                            params=A, n_verts=ti.i32, n_faces=ti.i32)
MetricPack = ti.types.argpack(w_ptr=A, w_col=A, w_val=A, w_diag=A, face_slot=A,
                              stitch_slot=A, H=A)
ConstraintPack = ti.types.argpack(lam=A, g=A, grad=A, cm=A, what=A, kappa=A, twist=A,
                                  n_per_face=ti.i32)
ContactPack = ti.types.argpack(contact=A, contact_mu=A, lam_c=A, fric=A, lam_t=A, stitch=A,
                               lam_s=A, n_stitches=ti.i32)
VectorPack = ti.types.argpack(x=A, x_hat=A, x_trial=A, Wdx=A, b=A, d=A, r=A, z=A, p=A, Ap=A)
PrecondPack = ti.types.argpack(P_inv=A, f_ptr=A, f_idx=A, f_val=A, f_perm=A, f_work=A,
                               mg_int=A, mg_real=A, mg_block=A)
StepPack = ti.types.argpack(x_in=A, v_in=A, x_step=A, v=A, x_start=A, v_last=A)


class Workspace:
    """Per-limiter arrays sized from the model's capacities (f_cap faces, v_cap vertices)."""

    def __init__(self, model):
        self.model = model
        self.f_cap, self.v_cap = model.f_cap, model.v_cap
        F, V, K = model.f_cap, model.v_cap, K_MAX
        vec3, vec9 = ti.types.vector(3, float), ti.types.vector(9, float)
        # The model's rest arrays themselves (not copies: a re-pinned vertex or a refilled
        # mesh is seen without a copy to keep in step).
        self.face_verts, self.Dm_inv = model.face_verts, model.face_Dm_inv
        self.grain, self.rest_area = model.face_grain, model.face_rest_area
        self.mass, self.pinned = model.vert_mass, model.vert_pinned
        # Multipliers lambda >= 0, one per constraint (warm-started across calls).
        self.lam = ti.ndarray(float, (F, K))
        # Contact half-spaces n.x >= d per vertex as (n, d) (see ``contact_g``) and their
        # multipliers: the obstacles are constraints of the same projection, so a contact
        # cannot undo the limits afterwards.
        self.contact = ti.ndarray(ti.types.vector(4, float), (V, CONTACT_SLOTS))
        self.lam_c = ti.ndarray(float, (V, CONTACT_SLOTS))
        # Coulomb friction at contacts (see ``friction_state``): the obstacle's friction
        # coefficient per vertex (filled with the planes), the substep's start position and
        # coefficient as (x_prev, mu), and the tangential multipliers (warm-started).
        self.contact_mu = ti.ndarray(float, V)
        self.fric = ti.ndarray(ti.types.vector(4, float), V)
        self.lam_t = ti.ndarray(vec3, V)
        # Constraint data at the current iterate (see constraints.py for the meaning).
        self.g = ti.ndarray(float, (F, K))
        self.grad = ti.ndarray(vec9, (F, K))
        self.cm = ti.ndarray(vec3, (F, K))
        self.what = ti.ndarray(vec3, (F, K))
        self.kappa = ti.ndarray(float, (F, K))
        self.twist = ti.ndarray(vec9, (F, K))     # extra rank-1 curvature (svd only)
        # Per-vertex vectors: positions (x), unconstrained x_hat, start of the call, line-search
        # trial, Newton direction and PCG vectors, W (x - x_hat) (before solve_al's start: the
        # start candidate); Jacobi accumulators; the last projection's velocities.
        names = ("x", "v", "x_hat", "x_start", "x_trial", "b", "d", "r", "z", "p", "Ap",
                 "Wdx", "acc", "force", "v_last")
        for name in names:
            setattr(self, name, ti.ndarray(vec3, V))
        self.P_inv = ti.ndarray(ti.types.matrix(3, 3, float), V)
        self.cnt = ti.ndarray(float, V)
        self.params = ti.ndarray(float, N_PARAMS)  # bands (warp, weft, shear), margin, deltas
        self.stats = ti.ndarray(float, N_STATS)
        self.info = ti.ndarray(float, 8)          # the direct solver's per-kernel results
        # solve_al's controls (B_* indices): a numpy array, which a CPU kernel reads in place
        # (as a Taichi ndarray, its upload cost ~60 us a solve: a third of what the argpacks
        # and the budget had added to a launch, measured on hanging at resolution 25).
        self.budget = np.zeros(N_BUDGET)
        self.H = None                             # the Newton matrix's values (per pattern)
        self._packs = PackCache()
        self.set_stitch_capacity(1)

    def pack(self, kind, pack_type, **members):
        """The argpack of ``members`` (ndarrays.PackCache: made again only when one of its
        arrays was replaced, e.g. a new stitch capacity, a larger H, a new pattern, or one of
        its counts changed)."""
        return self._packs.get(kind, pack_type, **members)

    def mesh_pack(self):
        """The rest arrays with the model's active counts at this call (a remesh changes
        them in place)."""
        m = self.model
        return self.pack("mesh", MeshPack, face_verts=self.face_verts, Dm_inv=self.Dm_inv,
                         grain=self.grain, rest_area=self.rest_area, mass=self.mass,
                         pinned=self.pinned, params=self.params, n_verts=int(m.n_verts),
                         n_faces=int(m.n_faces))

    def metric_pack(self, metric):
        """W = ``metric`` (a system_matrix.BlockMatrix) and the Newton matrix in its pattern."""
        return self.pack("metric", MetricPack, w_ptr=metric.ptr, w_col=metric.col,
                         w_val=metric.val, w_diag=metric.diag, face_slot=metric.face_slot,
                         stitch_slot=metric.stitch_slot, H=self.newton_matrix(metric.nnz))

    def constraint_pack(self, K):
        """The constraint arrays, of which the method in use fills K per face
        (constraints.N_CONSTRAINTS)."""
        return self.pack("cons", ConstraintPack, lam=self.lam, g=self.g, grad=self.grad,
                         cm=self.cm, what=self.what, kappa=self.kappa, twist=self.twist,
                         n_per_face=int(K))

    def contact_pack(self):
        return self.pack("contacts", ContactPack, contact=self.contact,
                         contact_mu=self.contact_mu, lam_c=self.lam_c, fric=self.fric,
                         lam_t=self.lam_t, stitch=self.stitch, lam_s=self.lam_s,
                         n_stitches=self.n_stitches)

    def vector_pack(self):
        return self.pack("vec", VectorPack, x=self.x, x_hat=self.x_hat, x_trial=self.x_trial,
                         Wdx=self.Wdx, b=self.b, d=self.d, r=self.r, z=self.z, p=self.p,
                         Ap=self.Ap)

    def precond_pack(self, fp, mg):
        """Block Jacobi's P_inv, the factor ``fp``'s and the multigrid ``mg``'s arrays (the
        preconditioner in use or its one-element stub: factor_precond.FactorStub)."""
        return self.pack("pc", PrecondPack, P_inv=self.P_inv, f_ptr=fp.ptr, f_idx=fp.idx,
                         f_val=fp.val, f_perm=fp.perm, f_work=fp.work, mg_int=mg.ints,
                         mg_real=mg.reals, mg_block=mg.blocks)

    def read_stats(self):
        """The last solve's ``stats`` (ST_*) as numpy."""
        return get_rows(self.stats, N_STATS)

    def step_pack(self, state):
        """The model's ``state`` (x, v and the substep's start x_step) and this projection's
        own start and velocities."""
        return self.pack("io", StepPack, x_in=state.x, v_in=state.v, x_step=state.x_step,
                         v=self.v, x_start=self.x_start, v_last=self.v_last)

    def newton_matrix(self, nnz):
        """The Newton matrix's values (both Newton paths), sized for nnz blocks."""
        if self.H is None or self.H.shape[0] < nnz:
            self.H = ti.ndarray(ti.types.matrix(3, 3, float), nnz)
        return self.H

    def set_stitch_capacity(self, n):
        """Seams: vertex pairs (a, b) held together, x_a = x_b, and their multipliers
        (vectors: an equality has a multiplier of either sign per component); the first
        ``n_stitches`` rows are in use (``StrainLimiter.set_stitches``)."""
        self.n_stitches = 0
        self.s_cap = max(int(n), 1)
        self.stitch = ti.ndarray(ti.types.vector(2, ti.i32), self.s_cap)
        self.lam_s = ti.ndarray(ti.types.vector(3, float), self.s_cap)


@ti.kernel
def clear_contacts(n: int, contact: A):
    for i in range(n):
        for j in ti.static(range(CONTACT_SLOTS)):
            contact[i, j] = ti.Vector([0.0, 0.0, 0.0, NO_CONTACT])


