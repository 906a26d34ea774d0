"""Strain limiting as a projection in the implicit step's metric (docs/method.md §4).

    min_x 1/2 (x - x_hat)^T A (x - x_hat)   subject to every g(x) <= 0 (constraints.py),

with A the implicit step's matrix (the masses when there is no step, h = 0), solved by the
augmented Lagrangian for inequalities: with lambda >= 0 and penalty mu,
    L_A = f + sum (mu/2) max(0, g + lambda/mu)^2 - lambda^2/(2 mu);
repeat { minimise L_A over x (projected Newton, PCG); lambda <- max(0, lambda + mu g);
mu <- min(4 mu, mu_max) } until the largest violation and the largest multiplier change
(complementarity) are below ``tol`` in strain units. Pinned vertices never move; velocities get
the projection's correction v += dx/h. Contacts (half-spaces) and seams (equalities) are
constraints of the same projection.

``StrainLimiter`` is the host side: it takes the ``strain`` settings, keeps the bands and the
work arrays in step with the mesh, chooses the path (the one-kernel PCG solve in ``al.py``, or
the host loop with Cholesky steps in ``direct.py``) and reports each solve. Its tuned constants
live in ``defaults.py``.
"""
import sys
import time

import numpy as np

from .. import backend, linalg, metrics, ndarrays
from .. import system_matrix
from .constraints import MAPPING_DELTA, METHOD_IDS, N_CONSTRAINTS, SVD_DELTA
from .families import STRAIN_METHODS
from . import al, buffers
from .defaults import (ACTIVE_MARGIN, ACTIVE_SET_MU, CG_BUDGET, CG_RTOL,
                       EXACT_FACTOR_MAX_FACES, FACTOR_CG, FACTOR_CG_MAX, FACTOR_CG_WORK,
                       FACTOR_MAX_FACES, FACTOR_NEWTON, INNER_RTOL, KKT_VELOCITY, LATE_ROUND,
                       MAX_NEWTON, MU_GROW, MU_MAX_SCALE, MU_SCALE,
                       MULTIGRID_CG, MULTIGRID_NEWTON, PDAS_CG_RTOL, PDAS_NEWTON, RESTING_SPEED,
                       SETTLE_SPEED, SOLVES)
from .factor_precond import FIRST_AFTER, LASTING_SOLVES, FactorPreconditioner, FactorStub
from .multigrid import HAVE_PYAMG, MAX_COARSE, MultigridPreconditioner, MultigridStub
from .buffers import (PC_FACTOR, PC_JACOBI, PC_MULTIGRID, PC_NAMES, ST_CG, ST_CONVERGED,
                      ST_ITERS, ST_KKT, ST_NEWTON, ST_START_VIOL, ST_TRIALS, ST_VIOL,
                      Workspace)

_host_loop_noted = False
_no_pyamg_noted = False


def _note_no_pyamg():
    """Say once, in one line, that the multigrid preconditioner is unavailable and why."""
    global _no_pyamg_noted
    if not _no_pyamg_noted:
        _no_pyamg_noted = True
        print("loom: pyamg is not installed, so strain solves above 2000 faces use block "
              "Jacobi (slower on large meshes); `make test` installs it (requirements.txt)",
              file=sys.stderr)


def _host_loop_only():
    """On Vulkan and Metal the one-launch PCG solve is replaced by the Cholesky path, whose AL
    loop runs on the host (``backend.HOST_LOOP_AL``); said once per process."""
    global _host_loop_noted
    from .. import backend
    if backend.arch() not in backend.HOST_LOOP_AL:
        return False
    if not _host_loop_noted:
        _host_loop_noted = True
        import sys
        print(f"loom: on --arch {backend.arch()} strain limiting uses the Cholesky Newton path "
              "(its AL loop runs on the host; the one-kernel PCG solve crashed Debian's software "
              "Vulkan driver)",
              file=sys.stderr)
    return True


class StrainLimitError(ValueError):
    """Bad strain-limiting settings; the message names the fix."""


def _check_band(name, band, lower_limit=-1.0):
    """A (min, max) strain band: finite, min <= max, min > -1 (a stretch must stay positive)."""
    try:
        lo, hi = (float(b) for b in band)
    except (TypeError, ValueError):
        raise StrainLimitError(f"{name} band must be a pair (min, max) of strains, e.g. "
                               f"(-0.01, 0.01); got {band!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi)):
        raise StrainLimitError(f"{name} band must be finite (got {band!r})")
    if lo > hi:
        raise StrainLimitError(f"{name} band has min > max ({lo} > {hi}): swap the two values")
    if lo <= lower_limit:
        raise StrainLimitError(f"{name} band min must be > {lower_limit} (a strain of -1 is a "
                               f"collapsed triangle); got {lo}")
    return lo, hi


def _check_method(name):
    if name not in STRAIN_METHODS:
        raise StrainLimitError(f"unknown strain-limiting method '{name}': use one of "
                               f"{', '.join(STRAIN_METHODS)}")


def _check_settings(st):
    """The checks of a ``strain`` settings section (the Settings check ranges and choices
    already; a limiter may be given a section built by hand), each failure one
    ``StrainLimitError`` that names the fix. Returns the checked bands."""
    _check_method(st.method)
    if st.solve not in SOLVES:
        raise StrainLimitError(f"unknown strain solve '{st.solve}': use one of "
                               f"{', '.join(SOLVES)}")
    if not st.tol > 0:
        raise StrainLimitError(f"tol must be > 0 (got {st.tol}); 1e-4 is 0.01 % strain")
    if int(st.rounds) < 1:
        raise StrainLimitError(f"rounds must be >= 1 (got {st.rounds})")
    if not st.isotropy >= 0:
        raise StrainLimitError(f"isotropy must be >= 0 (got {st.isotropy}); 0 is the "
                               "paper's constraint")
    warp, weft = _check_band("warp", st.warp), _check_band("weft", st.weft)
    bias = None if isinstance(st.bias, (list, tuple)) and len(st.bias) == 0 else \
        _check_band("bias", st.bias)
    return warp, weft, bias


class StrainLimiter:
    """Strain-limiting projection of a ``ClothModel``'s state, set up by a ``strain`` settings
    section (``Settings.strain``; ``cloth.settings.section("strain", ...)`` builds one on its
    own) and by the seams (``stitches``, vertex pairs held together).

    After each ``project`` call: ``last_iterations`` (AL rounds), ``last_violation_max``
    (strain units), ``last_converged``, ``last_ms``, ``last_newton`` / ``last_cg`` /
    ``last_trials`` (line-search trials) totals, ``rounds_total`` (AL rounds of every
    projection so far), ``last_factorizations`` (numeric
    factorisations or preconditioner refreshes) and, under ``solve = "exact"``,
    ``last_stationarity`` (m/s).
    """

    def __init__(self, model, strain=None, stitches=None):
        from ..settings import section
        self.model = model
        self._system = None        # the implicit step's matrix (system_metric)
        self._full_mass = None     # the masses in the same block pattern (h = 0)
        self._chol = None          # SparseCholesky of this mesh's block pattern
        self._pattern = None       # the block pattern both metrics share (_build_pattern)
        self._spare_patterns = []  # the last mesh's patterns, whose arrays a new one reuses
        self._system_ready = False
        self._pc = None            # Factor- or MultigridPreconditioner of the implicit metric
        self._last_pattern_solves = 0   # solves the last mesh's preconditioner saw
        self._spare_pc = None
        self._stubs = None         # placeholder arrays for the preconditioners not in use
        self._last_pc_mode = PC_JACOBI   # the last AL solve's preconditioner (PC_*)
        self._resting = False      # under contacts: still enough for the factor (RESTING_SPEED)
        self._v_last_valid = False    # v_last belongs to this mesh's vertices
        self._start_args = (0.0, 0, 0.0, 0)   # (h, extrapolate, settle, step_start)
        self.kkt_length = 0.0          # metres, this projection's stationarity tolerance
        # The AL's fixed tuning (defaults.py); mu_scale follows the solve (configure).
        self.mu_scale, self.mu_grow, self.mu_max_scale = MU_SCALE, MU_GROW, MU_MAX_SCALE
        self.cg_rtol, self.inner_rtol, self.active_margin = CG_RTOL, INNER_RTOL, ACTIVE_MARGIN
        self.mapping_delta, self.svd_delta = MAPPING_DELTA, SVD_DELTA
        self._host_loop_always = False   # set_host_loop: the reference path on any back end
        self._stitches = np.zeros((0, 2), np.int32) if stitches is None else \
            np.asarray(stitches, np.int32).reshape(-1, 2)
        self.method = self.solve = None
        self.warp = self.weft = self.bias = None
        self._ws = None
        self._mesh_key = None
        self.on_mesh_changed()
        self.configure(strain if strain is not None else section("strain"))
        self.last_iterations, self.last_violation_max = 0, 0.0
        self.last_converged, self.last_ms = True, 0.0
        self.last_newton = self.last_cg = self.last_factorizations = self.last_trials = 0
        self.last_solves = 0          # linear solves (exact: several per Newton step)
        self.last_fallback = False    # solved again: exact with the fast model, fast on the
        #                               multigrid with five Newton steps a round
        self.last_stationarity, self._kkt_h = 0.0, 1.0 / 30.0
        self.last_reverted, self.reverted_count = False, 0
        self.last_slid, self.slid_count = False, 0   # solved again without friction
        self.rounds_total = 0         # AL rounds over every projection so far

    # ---- settings ------------------------------------------------------------------------
    def configure(self, st):
        """Adopt the ``strain`` settings section ``st``: the one function that sets the
        limiter's method, bands, budget and solve and, through ``_upload_params``, the
        kernels' ``params``. The Simulator calls it after every change of its settings. Every
        value is checked before any is adopted, so a refused change leaves the limiter as it
        was. A changed method starts its multipliers cold."""
        warp, weft, bias = _check_settings(st)
        self.settings = st
        if st.method != self.method:
            ndarrays.zero(self._ws.lam)   # multipliers belong to the constraints of one method
        self.method, self.solve, self.tol = st.method, st.solve, float(st.tol)
        self.max_rounds = int(st.rounds)
        self.isotropy = float(st.isotropy)
        self.mu_scale = MU_SCALE * (ACTIVE_SET_MU if self._exact() else 1.0)
        self.warp, self.weft = warp, weft
        self.bias = bias if bias is not None else metrics.default_bias_band(warp, weft)
        self._upload_params()

    def _exact(self):
        return self.solve == "exact"

    def shear_band(self):
        """The bias band in ||w_u + w_v|| units (sqrt 2 at rest), as the constraints use it."""
        return tuple(float(np.sqrt(2.0) * (1.0 + b)) for b in self.bias)

    def newton_margin(self):
        """How close to its band (strain) a constraint enters the fast Newton matrix:
        ``active_margin``, or w^2 / ``active_margin`` where w, the nearest band end's
        distance from rest (strain 0), is below it (tight bands, e.g. a measured woven's:
        defaults.py says why). An end on the near side of rest (a band [0, hi]) does not
        count: it binds at rest whatever the margin."""
        bands = [self.warp, self.weft] + ([self.bias] if self.method == "warp-weft" else [])
        ends = [e for lo, hi in bands for e in (-lo, hi) if e > 0.0]
        w = min(ends) if ends else self.active_margin
        return self.active_margin if w >= self.active_margin else w * w / self.active_margin

    def uses_host_loop(self):
        """The AL loop on the host with Cholesky steps (direct.py) instead of the one-kernel
        PCG solve: on Vulkan and Metal, and for the exact solve of a cloth with seams (the
        kernels' active-set step does not converge at the seams' equalities); everywhere after
        ``set_host_loop(True)``."""
        return self._host_loop_always or _host_loop_only() or \
            (self._exact() and len(self._stitches) > 0)

    def set_host_loop(self, always):
        """Solve every projection in the host loop (Newton steps solved exactly by sparse
        Cholesky) when ``always``, on any back end: the reference a benchmark measures the
        kernels' PCG steps against (``benchmarks.cusick_diagnose substep``)."""
        self._host_loop_always = bool(always)
        self._upload_params()          # the kernels' parameters depend on the path

    def _kernel_pdas(self):
        """The exact solve's active-set model in the kernels (PCG, ``al.pdas_resolves``)."""
        return self._exact() and not self.uses_host_loop()

    def _upload_params(self, margin_fallback=False):
        """The kernels' ``params`` from the settings (the one place that writes them). With
        ``margin_fallback`` for the solve again with the fast (margin) model after the
        exact solve's active-set model did not converge (``_solve_al_with_fallback``,
        ``direct.solve``): the margin model's matrix and step, the rest as the settings say."""
        if self._ws is None or self.warp is None or self.weft is None:
            return
        active_set = self._exact() and not margin_fallback
        params = np.zeros(buffers.N_PARAMS)
        params[buffers.P_WARP:buffers.P_WARP + 2] = self.warp
        params[buffers.P_WEFT:buffers.P_WEFT + 2] = self.weft
        params[buffers.P_SHEAR:buffers.P_SHEAR + 2] = self.shear_band()
        # The active-set model's matrix is the Hessian: no constraint enters it early.
        params[buffers.P_MARGIN] = 0.0 if active_set else self.newton_margin()
        params[buffers.P_INNER_RTOL] = 0.0 if self._kernel_pdas() else self.inner_rtol
        params[buffers.P_KKT_TOL] = self.kkt_length
        params[buffers.P_PDAS] = 1.0 if self._kernel_pdas() and active_set else 0.0
        params[buffers.P_DELTA] = self.mapping_delta
        params[buffers.P_SVD_DELTA] = self.svd_delta
        params[buffers.P_ISO] = self.isotropy
        # Contact violations are metres; divided by the typical edge they read like strains.
        params[buffers.P_CONTACT_SCALE] = self.model.typical_edge()
        self._ws.params.from_numpy(params)

    def set_stitches(self, pairs):
        """Seams as vertex pairs (S, 2): the projection holds each pair together (a seam
        held only by the dynamics' stitch springs is torn open by the projection, which is
        infinitely stiff against them; measured on tshirt with mapping: seams 26 cm open
        after 10 frames). Call again when a remesh renumbers the vertices."""
        self._stitches = np.asarray(pairs, np.int32).reshape(-1, 2)
        ws = self._ws
        if len(self._stitches) > ws.s_cap:
            ws.set_stitch_capacity(len(self._stitches))
        ws.n_stitches = len(self._stitches)
        ndarrays.zero(ws.lam_s)
        self._retire_patterns()                # the stitches are part of the pattern
        self._chol = None
        self._system_ready = False
        if len(self._stitches):
            ws.stitch.from_numpy(np.resize(self._stitches, (ws.s_cap, 2)).astype(np.int32))

    def _retire_patterns(self):
        """Drop this mesh's block patterns, keeping their Taichi arrays for the next mesh's
        (``_build_pattern``): a remesh every frame otherwise allocated sixteen arrays per
        frame."""
        old = [p for p in (self._system, self._full_mass) if p is not None]
        if old:
            self._spare_patterns = old
        self._system = self._full_mass = self._pattern = None

    # ---- mesh changes --------------------------------------------------------------------
    def _current_mesh_key(self):
        m = self.model
        return (m.f_cap, m.v_cap, m.n_faces, m.n_verts, id(m._np_cache))

    def on_mesh_changed(self):
        """Call after the model's arrays were refilled (remesh). Faces are renumbered by a
        remesh, so per-face multipliers no longer belong to their faces: they are reset (the
        next projection starts cold). The work arrays are reallocated only for a new model;
        only their active rows are cleared (they are sized for the finest mesh a remesh may
        make, and the kernels read no further)."""
        m = self.model
        ws = self._ws
        if ws is None or ws.face_verts is not m.face_verts:    # a new model
            self._ws = ws = Workspace(m)
            self._spare_patterns = []
        nv, nf = m.n_verts, m.n_faces
        self._v_last_valid = False             # vertices renumbered: no last velocity
        ndarrays.put_rows(ws.lam, np.zeros((nf, ws.lam.shape[1])))
        ndarrays.put_rows(ws.lam_c, np.zeros((nv, ws.lam_c.shape[1])))   # vertices renumbered
        ndarrays.put_rows(ws.lam_t, np.zeros((nv, 3)))
        ndarrays.put_rows(ws.contact_mu, np.zeros(nv))
        self.set_stitches(self._stitches)
        buffers.clear_contacts(nv, ws.contact)
        self._upload_params()                  # the contact scale follows the mesh
        self._retire_patterns()
        self._chol = None
        if self._pc is not None:
            self._last_pattern_solves = self._pc.solves
            self._spare_pc = self._pc           # its arrays serve the next mesh's
        self._pc = None
        self._system_ready = False
        self._mesh_key = self._current_mesh_key()

    def own_violation_max(self):
        """The largest violation of the method's own constraints at the model's positions
        (strain units, 0 when they hold; 0 for "none"): whether a remesh left the limits
        broken and the projection must run again (``Simulator._remesh``)."""
        if self.method == "none":
            return 0.0
        self._sync_mesh()
        ws, m = self._ws, self.model
        self._assemble_values()
        return max(float(al.max_violation(N_CONSTRAINTS[self.method], m.n_faces, ws.rest_area,
                                          ws.g)), 0.0)

    def system_metric(self):
        """The BlockMatrix the implicit step's matrix goes into: the
        caller fills it after each dynamics step (``ImplicitEuler.system_matrix``); the next
        projection with h > 0 then uses it as its metric. Its pattern is rebuilt after a mesh
        or seam change (and the projection falls back to the masses until it is filled)."""
        self._sync_mesh()
        if self._system is None:
            self._system = self._build_pattern()
        self._system_ready = True
        return self._system

    def _build_pattern(self):
        """The block pattern of this mesh and its seams. Both metrics (the implicit step's
        matrix and the masses) have the same one: it is built once per mesh, the second
        metric gets its own values over it (``sibling``); the arrays of the last mesh's
        patterns are reused (``_retire_patterns``). Built twice, it was 10 ms of a remeshed
        900-face frame."""
        spare = getattr(self, "_spare_patterns", [])
        if self._pattern is None:
            self._pattern = system_matrix.pattern_of(self.model, self._stitches,
                                                     reuse=spare[0] if spare else None)
            self._spare_patterns = spare[1:]
            return self._pattern
        twin = self._pattern.sibling(reuse_val=spare[0].val if spare else None)
        self._spare_patterns = []
        return twin

    def _newton_metric(self, use_system):
        """The projection's metric in the full block pattern (every face and seam pair), which
        both Newton paths write their matrix into (``al.newton_matrix``): the implicit step's
        matrix, or M spread over that pattern."""
        if use_system:
            metric = self._system
        else:
            if self._full_mass is None:
                self._full_mass = self._build_pattern()
                ndarrays.zero(self._full_mass.val)
                system_matrix.fill_diagonal(self.model.n_verts, self._full_mass.diag,
                                            self._full_mass.val, self.model.mass)
            metric = self._full_mass
        return metric

    def _direct_metric(self, use_system):
        """The metric for the Cholesky path, with the factorisation object of its pattern."""
        from .. import linalg
        metric = self._newton_metric(use_system)
        if self._chol is None:
            # Both metrics of a mesh are built by _build_pattern, so one analysis serves both
            # (it is dropped with them on a mesh or seam change).
            self._chol = linalg.SparseCholesky(metric.ptr_np, metric.col_np, metric.n,
                                               core=metric.core_np)
        return metric, self._chol

    def face_state(self):
        """The per-face solver state a remesh carries to the new faces (``remesh``'s
        ``face_data``): the multipliers and the rest area of the face they belong to."""
        n = self.model.n_faces
        return {"lam": ndarrays.get_rows(self._ws.lam, n),
                "area": np.asarray(self.model.rest_area[:n], np.float64).copy()}

    def solve_state(self):
        """What the next projection depends on besides the positions and velocities: the
        faces' multipliers, the vertices' (contacts, seams, friction: all warm-started) and
        the last projection's velocities (where its start moves each vertex on to,
        ``al.begin_solve``). With ``set_solve_state``: one substep tried several ways from the
        same state (``Simulator.substep_state``); without the vertices' multipliers a
        projection with contacts or seams, solved again, started from the last try's."""
        ws = self._ws
        return (self.face_state(), ws.v_last.to_numpy(), self._v_last_valid,
                [a.to_numpy() for a in (ws.lam_c, ws.lam_s, ws.lam_t)])

    def set_solve_state(self, state):
        faces, v_last, valid, vertex_multipliers = state
        self.set_face_state(faces)
        ws = self._ws
        ws.v_last.from_numpy(v_last)
        self._v_last_valid = valid
        for a, val in zip((ws.lam_c, ws.lam_s, ws.lam_t), vertex_multipliers):
            a.from_numpy(val)

    def set_face_state(self, data):
        """After a remesh (and ``on_mesh_changed``): each new face starts from the multipliers
        of the face it was cut from. A multiplier acts as a force lam grad g with |grad g| ~
        sqrt(area) (g is strain x sqrt(area)), so it is scaled by sqrt(new area / old area):
        two halves of a split face then carry the parent's force between them, not twice
        it."""
        n = self.model.n_faces
        lam, area = np.asarray(data["lam"]), np.asarray(data["area"])
        if len(lam) != n or len(area) != n:
            raise StrainLimitError(f"face state has {len(lam)} rows, the mesh {n} faces")
        full = self._ws.lam.to_numpy()
        full[:n] = lam * np.sqrt(self.model.rest_area[:n] / area)[:, None]
        self._ws.lam.from_numpy(full)

    def _sync_mesh(self):
        if self._mesh_key != self._current_mesh_key():
            self.on_mesh_changed()

    # ---- solving -------------------------------------------------------------------------
    def _mean_mass(self, metric=None):
        """The penalty's unit: the mean lumped vertex mass, or with the implicit step's metric the
        mean diagonal of the implicit step's matrix (on the soft cloth h^2 K is 10-100 x M
        there, growing with the resolution: a penalty scaled by the mass alone was 100 x too
        weak at resolution 25, and the mapping family never came to rest)."""
        if metric is not None and metric is self._system:
            return float(system_matrix.mean_diagonal(self.model.n_verts, metric.diag,
                                                     metric.val, self._ws.pinned))
        free = ~self.model.pinned
        mass = self.model.mass
        return float(mass[free].mean() if free.any() else mass.mean())

    @property
    def contact_planes(self):
        """The per-vertex contact half-spaces (n, d), n.x >= d, as a Taichi ndarray of vec4 to
        be filled by the caller (``Collider.contact_planes``) before ``project(h,
        contacts=True)``; (0, 0, 0, buffers.NO_CONTACT) where a vertex has none."""
        self._sync_mesh()
        return self._ws.contact

    @property
    def contact_friction(self):
        """Per-vertex Coulomb coefficient of the contact in slot 0 of ``contact_planes``
        (a Taichi ndarray, filled by ``Collider.contact_planes`` with the planes)."""
        self._sync_mesh()
        return self._ws.contact_mu

    def project(self, h, contacts=False, warm=True, friction=True):
        """Project model.state.x (holding x_hat on entry) onto the strain limits in place and
        add the correction to the velocities (v += dx / h; h <= 0 leaves v alone). With
        ``contacts`` the half-spaces in ``contact_planes`` are constraints of the same
        projection (else they are cleared first), with the friction of ``contact_friction``
        unless ``friction`` is False or h <= 0 (friction holds a displacement over a time
        step).

        ``warm=False`` solves from zero multipliers and then puts the previous ones back: for
        a second projection within a substep (after a contact fix-up), whose x_hat is already
        projected, so the substep's multipliers (the forces that held the cloth against
        inertia) are far from its own (measured on tshirt: warm, such re-projections failed
        to converge in 50 rounds and the cloth blew up; cold, 24 rounds).

        An AL solve that ends unconverged *and* further from feasible than it started is not
        applied (x and v are left as they came, ``last_reverted`` is set). An unconverged
        solve that did improve is applied, but its velocity change per vertex is capped at
        half a typical edge per substep: an unconverged Newton iterate can have moved a vertex
        far, and dx / h would become a kick (measured on tshirt: an unconverged solve with a
        final violation of 2e-3 had moved one vertex 18 cm, 11 m/s, and the shirt blew up;
        reverting such solves instead left the cloth stuck outside its limits).

        A projection with friction that ends unconverged is solved once more from its start
        without friction (``last_slid``; docs/method.md §7)."""
        t0 = time.perf_counter()
        if self.method == "none":
            self.last_iterations, self.last_violation_max = 0, 0.0
            self.last_converged, self.last_ms = True, 0.0
            return
        self._sync_mesh()
        self._set_kkt_length(h)
        ws, m = self._ws, self.model
        nv = m.n_verts
        mid, K = METHOD_IDS[self.method], N_CONSTRAINTS[self.method]
        # Friction holds contact vertices against sliding over the substep (from x - h v).
        self._start_args = (float(h), int(self._v_last_valid), float(SETTLE_SPEED),
                            int(m.state.step_start_valid))
        friction = friction and contacts and h > 0
        if contacts and not self._exact():
            self._update_resting()
        al.begin_solve(nv, float(h), int(friction),
                       int(not contacts), *self._start_args[1:], ws.step_pack(m.state),
                       ws.vector_pack(), ws.contact_pack(), ws.stats)
        self.last_reverted = self.last_slid = False
        saved = None
        if not warm:
            saved = self.multipliers()
            self._zero_multipliers()
        use_system = h > 0 and self._system_ready
        rounds, newton, converged, stats = self._solve(mid, K, use_system, contacts)
        if not converged and friction:
            # Friction could not hold the cloth within its limits: its bound mu lam_n grows
            # with the contact multipliers that the limits' own pull raises (a capstan), so
            # the rounds can lock. Measured on the garment example's shoulders: 100 rounds
            # without moving, and the grown multipliers made the next projections throw the
            # tabard 28 cm (16 m/s); without friction the same projection met the limits in
            # 9 rounds. The cloth slides this substep instead: solved again from its start,
            # without friction and from zero multipliers.
            al.begin_solve(nv, float(h), 0, 0, *self._start_args[1:], ws.step_pack(m.state),
                           ws.vector_pack(), ws.contact_pack(), ws.stats)
            self._zero_multipliers()
            more = self._solve(mid, K, use_system, contacts)
            rounds, newton, converged, stats = rounds + more[0], newton + more[1], more[2], more[3]
            self.last_slid = True
            self.slid_count += 1
        if saved is not None:
            for a, val in zip((ws.lam, ws.lam_c, ws.lam_s, ws.lam_t), saved):
                a.from_numpy(val)
        if not converged and stats[ST_VIOL] > max(stats[ST_START_VIOL], self.tol):
            al.copy_vectors(nv, ws.x_start, ws.x)
            stats[ST_VIOL] = stats[ST_START_VIOL]
            self.last_reverted = True
            self.reverted_count += 1
        # Only an unconverged AL iterate is capped, and only where it moved a vertex further
        # than half a typical edge (a budget-limited solve is a legitimate answer; capping
        # every unconverged one raised the band error of 8-round svd from 3.6e-4 to 6.9e-2).
        kick = 0.5 * self.model.typical_edge() / h if (not converged and h > 0) else -1.0
        al.finish_solve(nv, float(h), kick, *self._start_args[1:], ws.x, ws.step_pack(m.state),
                        ws.contact_pack())
        self._v_last_valid = h > 0
        self.last_iterations = int(rounds)
        self.rounds_total += int(rounds)
        self.last_violation_max = float(max(stats[ST_VIOL], 0.0))
        self.last_converged = bool(converged)
        self.last_newton, self.last_cg = int(newton), int(stats[ST_CG])
        self.last_trials = int(stats[ST_TRIALS])
        # The stationarity reached, as a velocity (m/s): the Newton step at the answer over h
        # (0 when nothing needed solving; NaN under the fast solve, which does not compute
        # that step).
        self.last_stationarity = float(stats[ST_KKT]) / self._kkt_h if self._exact() else \
            (0.0 if rounds == 0 else float("nan"))
        self.last_ms = 1e3 * (time.perf_counter() - t0)

    def _zero_multipliers(self):
        ws = self._ws
        for a in (ws.lam, ws.lam_c, ws.lam_s, ws.lam_t):
            ndarrays.zero(a)

    def _solve(self, mid, K, use_system, contacts):
        """One solve of the projection set up by ``begin_solve``: (rounds, Newton steps,
        converged, the stats array)."""
        if self.uses_host_loop():
            rounds, newton, converged = self._solve_direct(mid, K, use_system)
            return rounds, newton, converged, self._ws.read_stats()
        # (_solve_al read the stats already: a read-back costs ~0.2 ms.)
        return self._solve_al_with_fallback(mid, K, self._newton_metric(use_system), contacts)

    def _set_kkt_length(self, h):
        """This projection's stationarity tolerance in metres: ``KKT_VELOCITY`` x h (a
        projection without a time step, h = 0, uses 1/30 s) under the exact solve, else 0."""
        self._kkt_h = h if h > 0 else 1.0 / 30.0
        length = KKT_VELOCITY * self._kkt_h if self._exact() else 0.0
        if length != self.kkt_length:
            self.kkt_length = length
            self._upload_params()

    def _assemble(self, mid, pos):
        """The constraints of the method ``mid`` at ``pos`` into the work arrays (ws.g,
        ws.grad, ...)."""
        ws = self._ws
        al.assemble(mid, pos, ws.mesh_pack(), ws.constraint_pack(N_CONSTRAINTS[self.method]))

    def _assemble_values(self):
        """The method's constraint values at the model's positions into ws.g (ws.x_trial
        holds those positions after)."""
        ws, m = self._ws, self.model
        al.copy_vectors(m.n_verts, m.state.x, ws.x_trial)
        al.assemble_g(METHOD_IDS[self.method], ws.x_trial, ws.mesh_pack(),
                      ws.constraint_pack(N_CONSTRAINTS[self.method]))

    def _solve_direct(self, mid, K, use_system):
        from . import direct
        metric, chol = self._direct_metric(use_system)
        m = self.model
        mean_mass = self._mean_mass(metric)
        mu, mu_max = self.mu_scale * mean_mass, self.mu_max_scale * mean_mass
        step_tol = 0.01 * self.tol * m.typical_edge()
        return direct.solve(self, mid, K, metric, chol, mu, mu_max, step_tol,
                            margin_mu=mu / ACTIVE_SET_MU)

    def newton_budget(self, pc_mode):
        """Newton steps per AL round: PDAS_NEWTON for the exact solve in the kernels, else
        FACTOR_NEWTON with the factor, MULTIGRID_NEWTON with the multigrid (up to MAX_NEWTON
        in rounds past LATE_ROUND: ``_solve_al``) and MAX_NEWTON with block Jacobi."""
        if self._kernel_pdas():
            return PDAS_NEWTON
        if pc_mode == PC_MULTIGRID:
            return MULTIGRID_NEWTON
        return MAX_NEWTON if pc_mode == PC_JACOBI else FACTOR_NEWTON

    def pcg_budget(self, pc_mode):
        """PCG iterations per Newton step for this preconditioner: the factor's
        (FACTOR_CG_WORK / faces clipped to [FACTOR_CG, FACTOR_CG_MAX]), the multigrid's
        (MULTIGRID_CG), or block Jacobi's: the method's CG_BUDGET per 1000 faces,
        growing like sqrt(n_faces / 1000) above (corrections travel across the cloth)."""
        n = max(self.model.n_faces, 1)
        if pc_mode == PC_FACTOR:
            return int(np.clip(round(FACTOR_CG_WORK / n), FACTOR_CG, FACTOR_CG_MAX))
        if pc_mode == PC_MULTIGRID:
            return MULTIGRID_CG
        return int(round(CG_BUDGET[self.method] * max(1.0, np.sqrt(n / 1000.0))))

    def last_velocity(self):
        """(v_last (V, 3), valid): the last projection's velocities, where the next
        projection's start moves each vertex on to (``al.start_candidate``), for a remesh to
        carry to the new vertices with ``set_last_velocity``."""
        self._sync_mesh()
        return ndarrays.get_rows(self._ws.v_last, self.model.n_verts), self._v_last_valid

    def set_last_velocity(self, v_last, valid):
        """The last velocities for the model's (new) vertices: a remesh renumbers them, and
        without them the next projection would start from the substep's start, not moved
        on, which holds a landing sheet in the air (its kinetic energy fell from 0.122 J to
        0.006 J in the frame after the remesh that refined it)."""
        self._sync_mesh()
        ndarrays.put_rows(self._ws.v_last, np.asarray(v_last, np.float64))
        self._v_last_valid = bool(valid)

    def forget_last_velocity(self):
        """The next projection starts from the substep's start, not moved on at the last
        projection's velocities (``SETTLE_SPEED``): after a correction that is not motion."""
        self._v_last_valid = False

    def multipliers(self):
        """The AL multipliers (faces, contacts, seams, friction) as numpy copies."""
        ws = self._ws
        return [a.to_numpy() for a in (ws.lam, ws.lam_c, ws.lam_s, ws.lam_t)]

    def restart_from(self, multipliers):
        """A projection solved again from its start: x back to x_start, the multipliers to
        ``multipliers`` (``multipliers()`` taken before; None: zero), ``last_fallback`` set."""
        ws = self._ws
        self.last_fallback = True
        al.copy_vectors(self.model.n_verts, ws.x_start, ws.x)
        al.reset_start(self.model.n_verts, *self._start_args, ws.step_pack(self.model.state),
                       ws.vector_pack(), ws.contact_pack())
        if multipliers is None:
            self._zero_multipliers()
            return
        for a, val in zip((ws.lam, ws.lam_c, ws.lam_s, ws.lam_t), multipliers):
            a.from_numpy(val)

    def _solve_al_with_fallback(self, mid, K, metric, contacts):
        """``_solve_al``; under the exact solve in the kernels (``_kernel_pdas``) a projection
        not converged in ``direct.ACTIVE_SET_ROUNDS`` rounds is solved again from its start
        with the fast (margin) model (``last_fallback``), as the host loop does
        (direct.solve). Under the fast solve, one that did not converge on the multigrid is
        solved again from its start and zero multipliers with MAX_NEWTON Newton steps in
        every round (LATE_ROUND in defaults.py says why)."""
        self.last_fallback, self.last_solves = False, 0      # (host solves: direct.py)
        if not self._kernel_pdas():
            out = self._solve_al(mid, K, metric, contacts)
            if out[2] or self._last_pc_mode != PC_MULTIGRID:
                return out
            self.restart_from(None)
            more = self._solve_al(mid, K, metric, contacts, late_round=0)
            return out[0] + more[0], out[1] + more[1], more[2], more[3]
        from .direct import ACTIVE_SET_ROUNDS
        multipliers_in = self.multipliers()
        out = self._solve_al(mid, K, metric, contacts,
                             rounds=min(ACTIVE_SET_ROUNDS, self.max_rounds))
        if out[2]:
            return out
        self.restart_from(multipliers_in)
        mu_scale = self.mu_scale
        self._upload_params(margin_fallback=True)
        self.mu_scale = MU_SCALE
        try:
            rounds, newton, converged, stats = self._solve_al(mid, K, metric, contacts)
        finally:
            self._upload_params()
            self.mu_scale = mu_scale
        return out[0] + rounds, out[1] + newton, converged, stats

    def _solve_al(self, mid, K, metric, contacts=False, rounds=None, late_round=None):
        """The AL loop (docs/method.md §4), one kernel launch (al.solve_al): rounds of inexact
        minimisation of L_A by projected Newton with a backtracking line search, then the
        multiplier step and mu *= mu_grow, at most ``rounds`` (None: ``max_rounds``) of them;
        on the multigrid, rounds from ``late_round`` (None: LATE_ROUND) on take up to
        MAX_NEWTON Newton steps.
        Returns (rounds, Newton steps, converged, the stats array)."""
        ws, m = self._ws, self.model
        mean_mass = self._mean_mass(metric)
        mu, mu_max = self.mu_scale * mean_mass, self.mu_max_scale * mean_mass
        # An inner loop stops once its steps are far below the tolerance (in metres).
        step_tol = 0.01 * self.tol * m.typical_edge()
        # Solves with contacts use block Jacobi while the cloth moves (RESTING_SPEED), where
        # the factor would not be taken (the multigrid under contacts ran the drape's
        # projections to their round budget, docs/speed/solve_cost.md), and in the exact
        # solve (with the factor at rest its active-set rounds ran out on the drape at
        # resolution 13: 31 rounds and 1.2-1.7 s a frame where block Jacobi took 5-6 rounds;
        # the factor of A lacks the contacts' terms, block Jacobi's diagonal has them).
        pc = self._pcg_preconditioner(metric) if not contacts or (
            self._resting and not self._exact() and self._pcg_kind() == "factor") else None
        made_before = pc is not None and pc.before_solve(m.pinned[: m.n_verts])
        pc_mode = pc.mode if pc is not None and pc.usable(m.pinned[: m.n_verts]) else PC_JACOBI
        self._last_pc_mode = pc_mode
        if self._stubs is None:
            self._stubs = {PC_FACTOR: FactorStub(), PC_MULTIGRID: MultigridStub()}
        fp = pc if pc_mode == PC_FACTOR else self._stubs[PC_FACTOR]
        mg = pc if pc_mode == PC_MULTIGRID else self._stubs[PC_MULTIGRID]
        budget = ws.budget
        budget[buffers.B_MU0], budget[buffers.B_MU_GROW] = mu, self.mu_grow
        budget[buffers.B_MU_MAX], budget[buffers.B_MAX_ROUNDS] = mu_max, \
            self.max_rounds if rounds is None else rounds
        budget[buffers.B_MAX_NEWTON] = newton = self.newton_budget(pc_mode)
        budget[buffers.B_LATE_ROUND] = LATE_ROUND if late_round is None else late_round
        budget[buffers.B_LATE_NEWTON] = max(newton, MAX_NEWTON) if pc_mode == PC_MULTIGRID \
            and not self._kernel_pdas() else newton
        budget[buffers.B_MAX_CG] = self.pcg_budget(pc_mode)
        budget[buffers.B_RTOL] = min(self.cg_rtol, PDAS_CG_RTOL) if self._kernel_pdas() \
            else self.cg_rtol
        budget[buffers.B_TOL], budget[buffers.B_STEP_TOL] = self.tol, step_tol
        budget[buffers.B_FROM_PREV] = float(metric is self._system)
        budget[buffers.B_PC_MODE] = pc_mode
        al.solve_al(mid, self._kernel_pdas(), ws.budget, ws.mesh_pack(),
                    ws.metric_pack(metric), ws.constraint_pack(K), ws.contact_pack(),
                    ws.vector_pack(), ws.precond_pack(fp, mg), ws.stats)
        stats = ws.read_stats()
        rounds, newton = int(stats[ST_ITERS]), int(stats[ST_NEWTON])
        self.last_factorizations = int(made_before)
        if pc is not None:
            self.last_factorizations += int(pc.after_solve(m.pinned))
        return rounds, newton, bool(stats[ST_CONVERGED] > 0), stats

    def _update_resting(self):
        """Whether the cloth rests for RESTING_SPEED: the root mean square of the last
        projection's vertex velocities (the dynamics' own include the substep's fall, which
        the contacts take back). Leaving rest drops the factor; it is made again when the
        cloth rests again."""
        m = self.model
        was = self._resting
        self._resting = False
        if self._v_last_valid and m.n_verts:
            v = ndarrays.get_rows(self._ws.v_last, m.n_verts)
            rms = float(np.sqrt((v * v).sum(axis=1).mean()))
            self._resting = rms < (2.0 if was else 1.0) * RESTING_SPEED
        if was and not self._resting and self._pc is not None:
            self._pc.ready = False

    def _pcg_kind(self):
        """"factor" or "multigrid": the factor up to FACTOR_MAX_FACES faces
        (EXACT_FACTOR_MAX_FACES under the exact solve) where CHOLMOD is installed."""
        most = EXACT_FACTOR_MAX_FACES if self._exact() else FACTOR_MAX_FACES
        return "factor" if self.model.n_faces <= most and linalg.HAVE_CHOLMOD else "multigrid"

    def _pcg_preconditioner(self, metric):
        """The preconditioner object of this metric's pattern when the PCG solve uses one
        (the implicit step's metric on a CPU backend, where both run serially in the solve's
        kernel); else None (block Jacobi). The factor (factor_precond.py) up to
        FACTOR_MAX_FACES faces (EXACT_FACTOR_MAX_FACES under the exact solve, which needs
        its Newton steps' length), the multigrid (multigrid.py) above; the factor needs CHOLMOD
        (else the multigrid is taken), the multigrid pyamg and more than MAX_COARSE
        unknowns."""
        if not (metric is self._system and backend.arch() == "cpu"):
            return None
        kind = self._pcg_kind()
        if kind == "multigrid" and not HAVE_PYAMG:
            _note_no_pyamg()
            return None
        if kind == "multigrid" and not 3 * self.model.n_verts > MAX_COARSE:
            return None
        cls = FactorPreconditioner if kind == "factor" else MultigridPreconditioner
        if not isinstance(self._pc, cls) or self._pc.metric is not metric:
            # Made before its first solve when the last mesh's lasted (LASTING_SOLVES).
            lasting = self._last_pattern_solves >= LASTING_SOLVES
            first = 0 if lasting else FIRST_AFTER
            self._pc = cls(metric, first, self._spare_pc) if cls is FactorPreconditioner \
                else cls(metric, first)
            self._spare_pc = None
        return self._pc

    @property
    def last_preconditioner(self):
        """The last AL solve's PCG preconditioner: "block Jacobi", "factor" or "multigrid"."""
        return PC_NAMES[self._last_pc_mode]

    def implicit_preconditioner(self):
        """The preconditioner of the implicit step's matrix this solve keeps
        (``_pcg_preconditioner``: the factor up to FACTOR_MAX_FACES faces, the multigrid
        above; on the CPU; under contacts only the fast solve's factor while the cloth rests),
        for the dynamics' CG (``ImplicitEuler.set_preconditioner``); None where it keeps none.
        None is made for the dynamics alone: under contacts on tshirt and the remeshed drape
        its refreshes (50-55 ms each) cost what the dynamics' CG saved
        (docs/speed/dynamics_cg.md)."""
        self._sync_mesh()
        return self._pc if self._pc is not None and self._pc.metric is self._system else None

    def constraint_values(self):
        """(n_faces, k) constraint values g / sqrt(a) (strain units, <= 0 satisfied) of the
        active method at the current positions, in the order of constraints.py, except that
        the mapping family's principal pairs are ordered by alignment with the warp (the
        solver's order). Empty (n_faces, 0) for method "none"."""
        n = self.model.n_faces
        if self.method == "none":
            return np.zeros((n, 0))
        self._sync_mesh()
        ws, K = self._ws, N_CONSTRAINTS[self.method]
        self._assemble_values()
        g = ndarrays.get_rows(ws.g, n)[:, :K]        # the active rows only (capacity: remeshing)
        return g / np.sqrt(self.model.rest_area[:n])[:, None]
