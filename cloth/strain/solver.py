"""Strain limiting as a projection (METHOD.md section 4; paper eqs. 6 and 24-27).

    min_x 1/2 sum_n m_n |x_n - x_hat_n|^2   subject to every g(x) <= 0 (constraints.py),

solved by the augmented Lagrangian for inequalities (the paper's "improved multiplier
method"): with lambda >= 0 and penalty mu,
    L_A = f + sum (mu/2) max(0, g + lambda/mu)^2 - lambda^2/(2 mu);
repeat { minimise L_A over x (projected Newton, PCG); lambda <- max(0, lambda + mu g);
mu <- min(4 mu, mu_max) } until the largest violation and the largest multiplier change
(complementarity) are below ``tol`` in strain units. Pinned vertices never move; velocities get
the projection's correction v += dx/h.

``solver="jacobi"`` / ``"gauss-seidel"`` run the classic per-triangle projection (Provot /
PBD style) of the same constraints, the baseline the paper calls traditional.

Why one long module: ``StrainLimiter`` is the host side of every path (settings,
bands, mesh changes, metrics, the choice of kernel); the kernels themselves live in
``al.py``, ``direct.py`` and ``pbd.py``.
"""
import sys
import time

import numpy as np
import taichi as ti

from .. import backend, linalg, metrics, ndarrays
from .. import system_matrix
from .constraints import MAPPING_DELTA, METHOD_IDS, METHODS, N_CONSTRAINTS, SVD_DELTA
from . import al, buffers, pbd
from .factor_precond import FIRST_AFTER, LASTING_SOLVES, FactorPreconditioner, FactorStub
from .multigrid import HAVE_PYAMG, MAX_COARSE, MultigridPreconditioner, MultigridStub
from .c_curvature import C_STEP_F32, C_STEP_F64
from .buffers import (PC_FACTOR, PC_JACOBI, PC_MULTIGRID, ST_CG, ST_CONVERGED, ST_ITERS,
                      ST_KKT, ST_NEWTON, ST_START_VIOL, ST_TRIALS, ST_VIOL,
                      Workspace)

METHOD_NAMES = METHODS + ("none",)
SOLVERS = ("al", "jacobi", "gauss-seidel")
COUPLINGS = ("implicit", "projection")
# How a projection decides it is done: "kkt" also asks for stationarity (the Newton step at the
# answer, with the final multipliers, moves no vertex by more than ``kkt_velocity`` x h), so the
# answer is the minimiser to that accuracy; "violation" stops on feasibility and multiplier
# change alone (the rule before issue #32: the answer then depends on where the solve started
# and on the solver's settings, and a landing sheet was damped to a stop).
STOPS = ("kkt", "violation")

# Initial AL penalty per coupling, x the metric's mean diagonal (``_mean_mass``). Under
# "implicit" the warm multipliers are the ones a resting cloth needs, and a stiffer start lets
# the first round end the solve. Measured on hanging, mapping, mean kinetic energy over frames
# 120-150, with the penalty in units of the mean vertex mass m (A's diagonal is ~10 m at
# resolution 9, ~100 m at 25): resolution 9: 1e2 m 2.9e-5 J (5 rounds per substep, never
# settles), 1e3 m 2.1e-9 J (1 round); resolution 25: 1e3 m 2.3e-5 J, 1e4 m 3e-6 J, 1e5 m
# 4e-8 J. svd and warp-weft rest at 1e2-1e3 m. The split projection keeps 1e2 x the mass.
MU_SCALE = {"implicit": 1e3, "projection": 1e2}
LINEAR_SOLVERS = ("cholesky", "pcg")
# The AL's Newton model (settings strain.newton_model): "margin" puts every constraint within
# ``active_margin`` of its band into the Newton matrix (the PCG kernels' model); "active-set"
# predicts the step's active set primal-dual style and solves again until it settles
# (active_set.py: in the host loop of direct.py with exact solves under linear_solver
# "cholesky", in the kernels with PCG (al.pdas_resolves) under "pcg").
NEWTON_MODELS = ("margin", "active-set")
# The active-set model's initial penalty relative to MU_SCALE: with the Hessian as its matrix
# it needs no stiff penalty to keep steps short, and a soft one lets the line search cross a
# constraint's kink at less cost (10 x the implicit metric's mean diagonal: the prototype's
# best in docs/speed/motion.md).
ACTIVE_SET_MU = 1e-2
# The constraints' curvature in the Newton matrix (c_curvature.py): "exact" through
# C = F^T F, or "model", the curvature of ||F e|| with e frozen (constraints.py).
CURVATURES = ("exact", "model")
# The families whose "exact" curvature replaces the model. svd's and warp-weft's model already
# is their curvature (finite differences along the Newton direction agree within 4 %,
# docs/speed/curvature.md), while the split through C, being projected in two parts, is
# stiffer for a convex constraint such as ||F e||: measured with it, warp-weft's tight
# projection landed 1.5 mm from the exact one instead of 0.4 mm, and svd rested at 1e-6 J
# instead of 3e-7 J (hanging res 9 and 25).
EXACT_CURVATURE_FOR = ("mapping",)


# PCG iterations per Newton step at 1000 faces (``StrainLimiter.cg_budget``). The split
# projection: measured on hanging at 3.9k faces, 50 left 3-7 of 20 substeps unconverged, ~100
# none (mapping) and 2 (warp-weft), at half the time of the older defaults.
CG_BUDGET_PROJECTION = 50
# Under coupling "implicit", per method (``python -m benchmarks.solver --budget-sweep``,
# docs/speed/cg_budget.md, 2026-12-02): an inexact Newton step costs less than an accurate one
# and the AL rounds absorb the difference, but too few iterations leave the resting cloth
# shimmering. Against 50: mapping at 15 takes resolution 46 from 248 to 95 ms per frame, 91
# from 3.1 to 1.6 s, 25 (at rest) from 35 to 21 ms, with the rest KE 2.0e-7 -> 3.0e-7 J at 25
# and 9.2e-8 -> 6.4e-7 J at 9 (at 8 it shimmers: 1.8e-6 J at 25). svd and warp-weft rest at
# 25 (7.5e-8 and 1.1e-7 J at resolution 9; warp-weft at 15: 5e-6 J), and run resolution 46 in
# 53 and 128 ms instead of 80 and 205. Single runs of a chaotic sweep: neighbouring budgets
# can differ by a round (e.g. svd at 15 needs 3 where 25 needs 1).
CG_BUDGET = {"mapping": 15, "svd": 25, "warp-weft": 25}
# A round's inner loop (PCG path) stops once |grad L_A| is below this fraction of its value at
# the round's first Newton step. Under coupling "implicit" the rounds are set by the
# multiplier updates, not by how far each round's minimisation gets: on hanging at resolution
# 46 (mapping, from the start, 30 frames) max_newton 1, 2, 3, 4, 5, 8 all took a median of 3-4
# rounds, at 29, 49, 67, 87, 119, 169 ms per frame. But the resting cloth needs the inner
# steps: at resolution 25 (mean KE over frames 120-150) max_newton 1 blew up, 2 shimmered at
# 6.9e-6 J, 3 at 1.8e-6 J, 5 rested at 4.5e-7 J. Stopping on the residual instead keeps the
# steps where they matter (``python -m benchmarks.solver --probe RES mapping --set
# inner_rtol=E``, 2026-12-02): E = 0.2 / 0.25 / 0.3 / 0.35 / 0.5 rested at 4.0e-7 / 3.3e-7 /
# 3.4e-7 / 5.7e-6 / 3.8e-6 J at resolution 25 (off: 4.5e-7), and 0.3 ran resolution 46 in 72
# instead of 119 ms and 91 in 377 instead of 827 ms. The split projection keeps full rounds
# (0): it is the paper's method and the benchmarks' baseline (with 0.3 its rounds at
# resolution 46 went from 22 to 34).
INNER_RTOL = {"implicit": 0.3, "projection": 0.0}
# The PCG solve's preconditioner under coupling "implicit" (``precondition`` "auto"): a
# sparse Cholesky factor of the implicit step's matrix (factor_precond.py) up to
# FACTOR_MAX_FACES faces, its aggregation multigrid (multigrid.py) above (the factor's serial
# triangular solves and its factorisation grow faster than the mesh: at 64.8k faces one
# application cost ~20 ms and a factorisation ~2.6 s), block Jacobi in solves with contacts.
FACTOR_MAX_FACES = 2000
# PCG iterations per Newton step with the multigrid preconditioner, per method (it finds a
# fixed share of the step per iteration at every size, multigrid.py). Hanging, frames 2-6
# from the start, median ms per frame (one run each, 2026-12-03): mapping with 3 / 4 / 6
# iterations at 4050 faces 52.6 / 50.5 / 48.5, at 32.8k 677 / 788 / 665, at 64.8k 1530 /
# 1512 / 1648 (8: 1723; block Jacobi ~60, ~1100, ~3900). warp-weft needs more: at 64.8k 4
# took 2417 ms (6.5 rounds, up to 11), 8 took 1631 ms (4.5 rounds); at 16.2k 389 / 345 ms
# (block Jacobi 461). svd with 4 took 1370 ms at 64.8k (4 rounds; block Jacobi 3800).
MULTIGRID_CG = {"mapping": 4, "svd": 4, "warp-weft": 8}
# PCG iterations per Newton step with the factor: FACTOR_CG_WORK / faces, between FACTOR_CG
# and FACTOR_CG_MAX (an iteration's triangular solves cost ~ the faces, so small meshes can
# afford more). The factor finds most of the step in a few iterations (factor_precond.py);
# its residual falls slowly on the stiff constraint directions, so cg_rtol rarely stops it.
# Measured on hanging (mean KE over frames 121-150, ensembles of 8 runs at resolution 25,
# docs/speed/rest_ensemble.md): 4 / 6 / 8 iterations at 1152 faces rested at a median of
# 2.5e-7 / 6.6e-8 / 1.1e-7 J; at 128 faces (mapping) 6 / 12 / 20 rested at 2.2e-6 / 3.8e-8 /
# 1.6e-9 J at the same cost (2.5-2.7 ms a frame).
FACTOR_CG, FACTOR_CG_MAX, FACTOR_CG_WORK = 6, 20, 6000
# The projection's start moves each vertex on at its last velocity, in full from 4 x
# SETTLE_SPEED (m/s), not at all below SETTLE_SPEED (al.begin_solve, al.choose_start): the
# default solve stops once the limits hold, so it answers near its start, and from where the
# vertices were a landing sheet was held in the air (drape: 0.3 % of its kinetic energy kept
# through the landing, 3 of 7 drops draped); carried on at all speeds, the resting cloth kept
# jittering (drape: 1.6-3.9e-3 J over frames 60-120 against 1-2e-5). Measured on hanging at
# resolution 9, mean kinetic energy over frames 120-150 (svd / warp-weft / mapping): 0.05
# m/s 5.7e-10 / 2.3e-6 / 1.2e-7 J, 0.1 m/s 5.7e-9 / 7.7e-8 / 1.2e-8 J (without: 2.9e-8 /
# 3.6e-8 / 3.0e-9); drape at 0.1 m/s keeps 69 % through the landing and rests at 0.7-1.1e-5 J.
SETTLE_SPEED = 0.1
# Newton steps per AL round (``max_newton`` None): with the factor a step finds most of the
# exact one, and a round needs fewer. Chosen on hanging at resolution 25 (mapping, ensembles
# of 8 runs, KE over frames 121-150, two runs at a time, 2026-12-03, with the constraints
# still in f32 structs): 4 steps rested at a median of 1.3e-7 J (8 of 8 under 3e-7) in 11.1
# ms a frame, 5 at 8.8e-8 J in 14.8 ms. Re-measured in f64 (57b5767): 4 steps rest at a
# median of 5.0e-8 J (8 of 8 under), 13.5-13.7 ms a frame alone; resolution 9 at 1.4-3.8e-8
# J for all three methods. Block Jacobi keeps 5 (tenth session: 3 shimmered at 1.8e-6 J).
MAX_NEWTON, FACTOR_NEWTON = 5, 4
# The active-set model in the kernels (``_kernel_pdas``): its step predicts the active set from
# the PCG's answer, so the PCG runs to a tighter tolerance, and a round takes more Newton steps
# (each runs to a tenth of the kkt tolerance). Measured on hanging at resolution 25 (svd, 8
# frames from the start): with the margin model's settings (rtol 0.1, 4 steps) 2 of 8 frames
# ran 100 rounds; with these every frame converged (docs/speed/motion.md section 8).
PDAS_CG_RTOL, PDAS_NEWTON = 1e-2, 10
# Newton steps per AL round with the multigrid (above FACTOR_MAX_FACES faces). Its rounds ran
# their 4 steps in full (inner_rtol rarely stopped them), and the rounds are set by the
# multiplier updates: hanging from the start, frames 2-11, median ms per frame with 4 / 3 / 2
# steps (2026-12-03, 379a715, one run each): mapping at 64.8k faces 1822 / 1327 / 884 (5 / 5 /
# 4 rounds), svd 1478 / - / 828 (4 / 4), warp-weft 1600 / 1242 / 1058 (5 / 5 / 5.5, up to
# 15); at resolution 46 mapping 74 / 54 / 40. Every solve converged. At rest (resolution 46,
# mean KE over frames 120-150) mapping 1.0e-7 / 3.5e-8 / 1.4e-7 J, svd 4.9e-9 / - / 6.8e-8 J;
# warp-weft shimmers at 46 with any of them (1.6e-6 / 9.3e-6 / 3.2e-6 J).
MULTIGRID_NEWTON = 2

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


def _default_mu_scale(coupling, newton_model):
    """The initial penalty's scale for a coupling and Newton model (``MU_SCALE``,
    ``ACTIVE_SET_MU``)."""
    scale = MU_SCALE.get(coupling, 1e2)
    return scale * ACTIVE_SET_MU if newton_model == "active-set" else scale


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


from ..settings import COMMON_DEFAULTS  # noqa: E402
from .defaults import AL_ROUNDS  # noqa: E402

# Every strain setting's one default (cloth/settings.py): the limiter's keyword defaults are
# read from there, so a script, a test and a scene start from the same values.
_DEFAULT = COMMON_DEFAULTS["strain"]
PRECONDITIONERS = ("auto", "factor", "multigrid", "jacobi")


def _rounds_default(solver):
    """``max_iters`` None: the AL's round budget (settings strain.iters), or 2000 sweeps for
    the per-triangle baselines."""
    return AL_ROUNDS if solver == "al" else 2000


def _check_method(name):
    if name not in METHOD_NAMES:
        raise StrainLimitError(f"unknown strain-limiting method '{name}': use one of "
                               f"{', '.join(METHOD_NAMES)}")


def _check_choices(solver, coupling, linear_solver, curvature, tol, stop, newton_model,
                   kkt_velocity, mapping_iso, precondition):
    """The limiter's checks of its settings (the constructor's and ``configure``'s), each
    failure one ``StrainLimitError`` that names the fix."""
    for what, value, allowed in (("strain-limiting solver", solver, SOLVERS),
                                 ("strain coupling", coupling, COUPLINGS),
                                 ("strain linear solver", linear_solver, LINEAR_SOLVERS),
                                 ("strain curvature", curvature, CURVATURES),
                                 ("strain stop rule", stop, STOPS),
                                 ("strain newton_model", newton_model, NEWTON_MODELS),
                                 ("strain precondition", precondition, PRECONDITIONERS)):
        if value not in allowed:
            raise StrainLimitError(f"unknown {what} '{value}': use one of "
                                   f"{', '.join(allowed)}")
    if not tol > 0:
        raise StrainLimitError(f"tol must be > 0 (got {tol}); 1e-4 is 0.01 % strain")
    if not kkt_velocity > 0:
        raise StrainLimitError(f"kkt_velocity must be > 0 m/s (got {kkt_velocity}); "
                               f"{_DEFAULT['kkt_velocity']} is 1 cm/s")
    if not mapping_iso >= 0:
        raise StrainLimitError(f"mapping_iso must be >= 0 (got {mapping_iso}); 0 is the "
                               "paper's constraint")


class StrainLimiter:
    """Strain-limiting projection of a ``ClothModel``'s state.

    method: "svd" | "warp-weft" | "mapping" | "none"; warp, weft: (min, max) strain bands;
    bias: (min, max) band of the 45-degree bias strain ||w_u + w_v||/sqrt 2 - 1 used by
    warp-weft (None: ``metrics.default_bias_band``, METHOD 3.2 [fix]); solver: "al",
    "jacobi" or "gauss-seidel"; tol: stopping tolerance in strain units; max_iters: AL rounds
    (or projection sweeps for the baselines).

    After each ``project`` call: ``last_iterations``, ``last_violation_max`` (strain units),
    ``last_converged``, ``last_ms``, and for the AL ``last_newton`` / ``last_cg`` /
    ``last_trials`` (line-search trials) totals (on the Cholesky path ``last_cg`` counts the
    CG iterations preconditioned by a reused factor, and ``last_factorizations`` the numeric
    factorisations; on the PCG path it counts the preconditioner's refreshes: a
    factorisation or a multigrid hierarchy).

    AL settings: ``max_newton`` Newton steps per round (None: ``newton_budget``), each a
    PCG solve of at most
    ``max_cg`` iterations (times sqrt(n_faces / 1000) above 1000 faces; None: per method,
    ``CG_BUDGET``) to the relative residual ``cg_rtol``; penalty ``mu_scale`` x the
    mean vertex mass, x ``mu_grow`` per round, capped at ``mu_max_scale`` x the mean mass.
    ``active_margin`` (strain): constraints this close to activating are already in the
    Newton model. ``adaptive_margin`` adapts that margin like a trust region (a full step
    divides it by 4, a short one multiplies it by 4): with a fixed 1e-2 margin the inner
    solves converge only linearly near the solution, so tight solves (the KKT test) use it;
    on 1k-triangle projections it was not better than the fixed margin, so it is off by
    default. ``svd_delta`` (attribute, default ``constraints.SVD_DELTA``; 0 disables) is the
    regularisation of the svd family's principal-frame curvature. ``mapping_iso`` (default
    settings strain.isotropy; 0 = the paper's constraint) closes the mapping family's
    feasible set at isotropy.

    Measured on the hanging scene (about 1k triangles, one substep per frame): the whole AL
    solve runs as one kernel launch (with one launch per phase, Python's handling of the
    kernel arguments cost as much as the solve), ``cg_rtol`` = 0.1 needs as many Newton
    steps as 1e-3 with half the CG iterations, and the svd curvature halves svd's CG work.
    Tried without gain: a higher or faster-growing penalty, a larger CG budget, starting PCG
    from the previous call's correction, and an exact Newton step (sparse Cholesky): the
    rounds are bound by the non-smooth active set, not by the linear solves. A round's inner
    loop ends after ``max_newton`` steps or once |grad L_A| fell below ``inner_rtol`` times
    its value at the round's first step (None: per coupling, ``INNER_RTOL``; 0 turns it off).
    """

    def __init__(self, model, method=_DEFAULT["method"], warp=tuple(_DEFAULT["warp"]),
                 weft=tuple(_DEFAULT["weft"]), bias=None, solver=_DEFAULT["solver"],
                 tol=_DEFAULT["tol"], max_iters=None, max_newton=None,
                 max_cg=None, cg_rtol=0.1, mu_scale=None, mu_grow=4.0, mu_max_scale=1e6,
                 mapping_delta=MAPPING_DELTA, mapping_iso=_DEFAULT["isotropy"],
                 jacobi_omega=1.0, active_margin=1e-2, inner_rtol=None,
                 adaptive_margin=False, stitches=None, coupling=_DEFAULT["coupling"],
                 linear_solver=_DEFAULT["linear_solver"], curvature=_DEFAULT["curvature"],
                 stop=_DEFAULT["stop"], kkt_velocity=_DEFAULT["kkt_velocity"],
                 newton_model=_DEFAULT["newton_model"], precondition=_DEFAULT["precondition"]):
        _check_choices(solver=solver, coupling=coupling, linear_solver=linear_solver,
                       curvature=curvature, tol=tol, stop=stop, newton_model=newton_model,
                       kkt_velocity=kkt_velocity, mapping_iso=mapping_iso,
                       precondition=precondition)
        if max_iters is None:
            max_iters = _rounds_default(solver)
        for name, val in (("max_iters", max_iters),
                          ("max_newton", 1 if max_newton is None else max_newton),
                          ("max_cg", 1 if max_cg is None else max_cg)):
            if int(val) < 1:
                raise StrainLimitError(f"{name} must be >= 1 (got {val})")
        if mu_scale is None:
            mu_scale = _default_mu_scale(coupling, newton_model)
        if not (mu_scale > 0 and mu_grow >= 1 and mu_max_scale >= mu_scale):
            raise StrainLimitError("penalty settings need mu_scale > 0, mu_grow >= 1 and "
                                   "mu_max_scale >= mu_scale")
        if not mapping_delta > 0:
            raise StrainLimitError(f"mapping_delta must be > 0 (got {mapping_delta}); "
                                   f"use {MAPPING_DELTA}")
        if not 0 < jacobi_omega <= 2:
            raise StrainLimitError(f"jacobi_omega must be in (0, 2] (got {jacobi_omega})")
        self.model = model
        self.solver = solver
        self.coupling = coupling
        self.linear_solver = linear_solver
        self.newton_model = newton_model
        self._full_mass = None     # M in the full block pattern (the paper's projection metric)
        self._chol = None          # SparseCholesky of this mesh's block pattern
        self._system = None        # the implicit step's matrix (coupling "implicit")
        self._pattern = None       # the block pattern both metrics share (_build_pattern)
        self._spare_patterns = []  # the last mesh's patterns, whose arrays a new one reuses
        self._system_ready = False
        self._pc = None            # Factor- or MultigridPreconditioner of the implicit metric
        self._last_pattern_solves = 0   # solves the last mesh's preconditioner saw
        self._spare_pc = None
        self._stubs = None         # placeholder arrays for the preconditioners not in use
        self.precondition = precondition
        self.precondition_contacts = False
        # The start candidate beside x_hat (al.choose_start): the substep's start moved on at
        # the last projection's velocity above ``settle_speed`` (True), or the start itself
        # (False, the rule before issue #32's landing fix; kept for old-against-new runs).
        self.start_extrapolate = True
        self.settle_speed = SETTLE_SPEED
        # Vertices near an obstacle that are not moving (below ``settle_speed``) start at, and
        # take their velocity from, where the substep truly began (True; al.start_candidate,
        # al.finish_solve): the obstacle pass stopped them without moving them back. False:
        # x_hat - h v and v + dx / h for every vertex, the rule before (kept for old-against-
        # new runs). Measured on drape at resolution 25: docs/speed/motion.md section 12.
        self.true_start_at_contacts = True
        self._v_last_valid = False    # v_last belongs to this mesh's vertices
        # (h, extrapolate, settle, step_start) of the last begin_solve
        self._start_args = (0.0, 0, 0.0, 0)
        self.multigrid_cg = None       # None: the method's MULTIGRID_CG
        self.factor_cg = None          # None: from the mesh size (FACTOR_CG_WORK)
        self.factor_max_faces = None   # None: FACTOR_MAX_FACES (a probe's override)
        self.tol = float(tol)
        self.stop = stop
        self.kkt_velocity = float(kkt_velocity)
        self.kkt_length = 0.0          # metres, this projection's stationarity tolerance
        self.max_iters = int(max_iters)
        self.max_newton = None if max_newton is None else int(max_newton)
        self.cg_rtol = cg_rtol
        self.max_cg = None if max_cg is None else int(max_cg)
        self.mu_scale, self.mu_grow, self.mu_max_scale = mu_scale, mu_grow, mu_max_scale
        self.mapping_delta = float(mapping_delta)
        self.mapping_iso = float(mapping_iso)
        # Coulomb friction at contacts inside the projection (coefficients from the collider).
        self.friction = True
        self.svd_delta = SVD_DELTA
        self.jacobi_omega = float(jacobi_omega)
        self.active_margin = float(active_margin)
        self.inner_rtol = INNER_RTOL.get(coupling, 0.0) if inner_rtol is None \
            else float(inner_rtol)
        if not 0 <= self.inner_rtol < 1:
            raise StrainLimitError(f"inner_rtol must be in [0, 1) (got {inner_rtol})")
        # The Cholesky path's Newton matrix with the constraints' exact (PSD) curvature instead
        # of the model: False, "full" or "split" (exact_curvature.py). An experiment,
        # host-side and slow.
        self.exact_curvature = False
        # The Newton matrix's constraint curvature in the kernels: "model" (constraints.py) or
        # "exact" (c_curvature.py).
        self.curvature = curvature
        self.adaptive_margin = bool(adaptive_margin)
        if not 0 <= active_margin < 1:
            raise StrainLimitError(f"active_margin must be in [0, 1) (got {active_margin})")
        self._stitches = np.zeros((0, 2), np.int32) if stitches is None else \
            np.asarray(stitches, np.int32).reshape(-1, 2)
        self.method = None
        self.warp = self.weft = self.bias = None
        self._ws = None
        self._mesh_key = None
        self._explicit_bias = bias is not None
        self.on_mesh_changed()
        self.set_bands(warp=warp, weft=weft, bias=bias)
        self.set_method(method)
        self.last_iterations, self.last_violation_max = 0, 0.0
        self.last_converged, self.last_ms = True, 0.0
        self.last_newton = self.last_cg = self.last_factorizations = self.last_trials = 0
        self.last_solves = 0          # linear solves (active-set: several per Newton step)
        self.last_fallback = False    # active-set: solved again with the margin model
        self.last_stationarity, self._kkt_h = 0.0, 1.0 / 30.0
        self.last_reverted, self.reverted_count = False, 0

    # ---- settings ------------------------------------------------------------------------
    def configure(self, st):
        """Adopt the ``strain`` settings section ``st`` (``Settings.strain``): the one function
        that derives the limiter's copies of the settings, its attributes and, through
        ``_upload_params``, the kernels' ``params``. The Simulator calls it after every change
        of its settings. Every value is checked before any is adopted, so a refused change
        leaves the limiter as it was. A changed method starts its multipliers cold; a changed
        coupling or Newton model re-derives the initial penalty and the inner stop
        (``MU_SCALE``, ``ACTIVE_SET_MU``, ``INNER_RTOL``)."""
        _check_method(st.method)
        _check_choices(solver=st.solver, coupling=st.coupling, linear_solver=st.linear_solver,
                       curvature=st.curvature, tol=st.tol, stop=st.stop,
                       newton_model=st.newton_model, kkt_velocity=st.kkt_velocity,
                       mapping_iso=st.isotropy, precondition=st.precondition)
        warp, weft = _check_band("warp", st.warp), _check_band("weft", st.weft)
        bias = _check_band("bias", st.bias) if st.bias else None
        if int(st.iters) < 1:
            raise StrainLimitError(f"max_iters must be >= 1 (got {st.iters})")
        if (st.coupling, st.newton_model) != (self.coupling, self.newton_model):
            self.mu_scale = _default_mu_scale(st.coupling, st.newton_model)
        if st.coupling != self.coupling:
            self.inner_rtol = INNER_RTOL[st.coupling]
            self._system_ready = False
        if st.method != self.method:
            ndarrays.zero(self._ws.lam)   # multipliers belong to the constraints of one method
        self.method, self.solver, self.tol = st.method, st.solver, float(st.tol)
        self.max_iters = int(st.iters)
        self.mapping_iso = float(st.isotropy)
        self.coupling, self.linear_solver = st.coupling, st.linear_solver
        self.curvature, self.newton_model = st.curvature, st.newton_model
        self.stop, self.kkt_velocity = st.stop, float(st.kkt_velocity)
        self.precondition = st.precondition
        self.warp, self.weft = warp, weft
        self._explicit_bias = bias is not None
        self.bias = bias if bias is not None else metrics.default_bias_band(warp, weft)
        self._upload_params()

    def set_method(self, name):
        _check_method(name)
        if name != self.method:
            # Multipliers belong to the constraints of one method: start the new one cold.
            ndarrays.zero(self._ws.lam)
        self.method = name
        self._upload_params()               # the Newton matrix's curvature follows the method

    def set_coupling(self, coupling):
        """Switch between the split projection and the implicit step's metric (live); the
        initial penalty and the inner loop's stop follow (``MU_SCALE``, ``INNER_RTOL``)."""
        if coupling not in COUPLINGS:
            raise StrainLimitError(f"unknown strain coupling '{coupling}': use one of "
                                   f"{', '.join(COUPLINGS)}")
        self.coupling = coupling
        self.mu_scale = _default_mu_scale(coupling, self.newton_model)
        self.inner_rtol = INNER_RTOL[coupling]
        self._upload_params()
        self._system_ready = False

    def set_newton_model(self, name):
        """Switch the AL's Newton model (live); the initial penalty follows
        (``ACTIVE_SET_MU``)."""
        if name not in NEWTON_MODELS:
            raise StrainLimitError(f"unknown strain newton_model '{name}': use one of "
                                   f"{', '.join(NEWTON_MODELS)}")
        self.newton_model = name
        self.mu_scale = _default_mu_scale(self.coupling, name)
        self._upload_params()

    def set_bands(self, warp=None, weft=None, bias=None):
        """Change the warp / weft / bias bands (strains). Without an explicit bias band (or
        with ``bias="auto"``) the bias follows the warp and weft bands
        (``metrics.default_bias_band``)."""
        if warp is not None:
            self.warp = _check_band("warp", warp)
        if weft is not None:
            self.weft = _check_band("weft", weft)
        if isinstance(bias, str):
            if bias != "auto":
                raise ValueError(f"bias band must be [min, max] or \"auto\" (got {bias!r})")
            self._explicit_bias = False
            bias = None
        if bias is not None:
            self.bias = _check_band("bias", bias)
            self._explicit_bias = True
        elif not self._explicit_bias:
            self.bias = metrics.default_bias_band(self.warp, self.weft)
        self._upload_params()

    def shear_band(self):
        """The bias band in ||w_u + w_v|| units (sqrt 2 at rest), as the constraints use it."""
        return tuple(float(np.sqrt(2.0) * (1.0 + b)) for b in self.bias)

    def set_linear_solver(self, name):
        """"pcg" or "cholesky" for the Newton steps, live (under the active-set model it also
        chooses kernels or host loop: the parameters follow)."""
        if name not in LINEAR_SOLVERS:
            raise StrainLimitError(f"unknown strain linear_solver '{name}': use one of "
                                   f"{', '.join(LINEAR_SOLVERS)}")
        self.linear_solver = name
        self._upload_params()

    def _kernel_pdas(self):
        """The active-set model in the kernels (PCG, ``al.pdas_resolves``), not on the host."""
        return self.newton_model == "active-set" and self.linear_solver == "pcg"

    def _upload_params(self, margin_fallback=False):
        """The kernels' ``params`` from the settings (the one place that writes them). With
        ``margin_fallback`` for the solve again with the margin model after the active-set
        model did not converge (``_solve_al_with_fallback``, ``direct.solve``): the margin
        model's matrix and step, the rest as the settings say."""
        if self._ws is None or self.warp is None or self.weft is None:
            return
        active_set = self.newton_model == "active-set" and not margin_fallback
        params = np.zeros(buffers.N_PARAMS)
        params[buffers.P_WARP:buffers.P_WARP + 2] = self.warp
        params[buffers.P_WEFT:buffers.P_WEFT + 2] = self.weft
        params[buffers.P_SHEAR:buffers.P_SHEAR + 2] = self.shear_band()
        # The active-set model's matrix is the Hessian: no constraint enters it early.
        params[buffers.P_MARGIN] = 0.0 if active_set else self.active_margin
        params[buffers.P_INNER_RTOL] = 0.0 if self._kernel_pdas() else self.inner_rtol
        params[buffers.P_KKT_TOL] = self.kkt_length
        params[buffers.P_PDAS] = 1.0 if self._kernel_pdas() and active_set else 0.0
        params[buffers.P_DELTA] = self.mapping_delta
        params[buffers.P_SVD_DELTA] = self.svd_delta
        params[buffers.P_ISO] = self.mapping_iso
        params[buffers.P_CURVATURE] = float(self._kernel_curvature())
        params[buffers.P_C_STEP] = C_STEP_F32 if backend.precision() == "f32" else C_STEP_F64
        # Contact violations are metres; divided by the typical edge they read like strains.
        m = self.model
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
        al.copy_vectors(m.n_verts, m.state.x, ws.x_trial)
        self._assemble(METHOD_IDS[self.method], ws.x_trial)
        return max(float(al.max_violation(N_CONSTRAINTS[self.method], m.n_faces, ws.rest_area,
                                          ws.g)), 0.0)

    def system_metric(self):
        """The BlockMatrix the implicit step's matrix goes into (coupling "implicit"): the
        caller fills it after each dynamics step (``ImplicitEuler.system_matrix``); the next
        projection with h > 0 then uses it as its metric. Its pattern is rebuilt after a mesh
        or seam change (and the projection falls back to the masses until it is filled)."""
        self._sync_mesh()
        m = self.model
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
        return {"lam": self._ws.lam.to_numpy()[:n].copy(),
                "area": np.asarray(self.model.rest_area[:n], np.float64).copy()}

    def solve_state(self):
        """What the next projection depends on besides the positions and velocities: the
        faces' multipliers and the last projection's velocities (where its start moves each
        vertex on to, ``al.begin_solve``). With ``set_solve_state``: one substep tried several
        ways from the same state (``Simulator.substep_state``)."""
        return self.face_state(), self._ws.v_last.to_numpy(), self._v_last_valid

    def set_solve_state(self, state):
        faces, v_last, valid = state
        self.set_face_state(faces)
        self._ws.v_last.from_numpy(v_last)
        self._v_last_valid = valid

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
        """The penalty's unit: the mean lumped vertex mass, or under coupling "implicit" the
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

    def project(self, h, contacts=False, warm=True):
        """Project model.state.x (holding x_hat on entry) onto the strain limits in place and
        add the correction to the velocities (v += dx / h; h <= 0 leaves v alone). With
        ``contacts`` the half-spaces in ``contact_planes`` are constraints of the same
        projection (else they are cleared first).

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
        reverting such solves instead left the cloth stuck outside its limits)."""
        t0 = time.perf_counter()
        if self.method == "none":
            self.last_iterations, self.last_violation_max = 0, 0.0
            self.last_converged, self.last_ms = True, 0.0
            return
        self._sync_mesh()
        self._set_kkt_length(h)
        ws, m = self._ws, self.model
        nv, nf = m.n_verts, m.n_faces
        mid, K = METHOD_IDS[self.method], N_CONSTRAINTS[self.method]
        # Friction holds contact vertices against sliding over the substep (from x - h v).
        self._start_args = (float(h), int(self.start_extrapolate and self._v_last_valid),
                            float(self.settle_speed),
                            int(self.true_start_at_contacts and m.state.step_start_valid))
        al.begin_solve(nv, float(h), int(contacts and h > 0 and self.friction),
                       int(not contacts), *self._start_args[1:], ws.step_pack(m.state),
                       ws.vector_pack(), ws.contact_pack(), ws.stats)
        self.last_reverted = False
        if self.solver == "al":
            saved = None
            if not warm:
                saved = self.multipliers()
                for a in (ws.lam, ws.lam_c, ws.lam_s, ws.lam_t):
                    ndarrays.zero(a)
            use_system = self.coupling == "implicit" and h > 0 and self._system_ready
            if self.linear_solver == "cholesky" or _host_loop_only() or \
                    (self.newton_model == "active-set" and not self._kernel_pdas()):
                rounds, newton, converged = self._solve_direct(mid, K, use_system)
                stats = ws.stats.to_numpy()
            else:
                # (_solve_al read the stats already: a read-back costs ~0.2 ms.)
                rounds, newton, converged, stats = self._solve_al_with_fallback(
                    mid, K, self._newton_metric(use_system), contacts)
            if saved is not None:
                for a, val in zip((ws.lam, ws.lam_c, ws.lam_s, ws.lam_t), saved):
                    a.from_numpy(val)
            if not converged and stats[ST_VIOL] > max(stats[ST_START_VIOL], self.tol):
                al.copy_vectors(nv, ws.x_start, ws.x)
                stats[ST_VIOL] = stats[ST_START_VIOL]
                self.last_reverted = True
                self.reverted_count += 1
        else:
            pbd.pbd_solve(mid, int(self.solver == "jacobi"), self.tol, self.max_iters,
                          self.jacobi_omega, ws.x, ws.mesh_pack(), ws.contact_pack(), ws.acc,
                          ws.cnt, ws.stats)
            # Measure the final positions (a sweep sees each face before moving it).
            self._assemble(mid, ws.x)
            stats = ws.stats.to_numpy()
            stats[ST_VIOL] = al.max_violation(K, nf, ws.rest_area, ws.g)
            rounds, newton, converged = int(stats[ST_ITERS]), 0, stats[ST_VIOL] < self.tol
        # Only an unconverged AL iterate is capped, and only where it moved a vertex further
        # than half a typical edge (a budget-limited solve is a legitimate answer; capping
        # every unconverged one raised the band error of 8-round svd from 3.6e-4 to 6.9e-2).
        kick = 0.5 * self.model.typical_edge() / h if (self.solver == "al" and not converged
                                                and h > 0) else -1.0
        al.finish_solve(nv, float(h), kick, *self._start_args[1:], ws.x, ws.step_pack(m.state),
                        ws.contact_pack())
        self._v_last_valid = h > 0
        self.last_iterations = int(rounds)
        self.last_violation_max = float(max(stats[ST_VIOL], 0.0))
        self.last_converged = bool(converged)
        self.last_newton, self.last_cg = int(newton), int(stats[ST_CG])
        self.last_trials = int(stats[ST_TRIALS]) if self.solver == "al" else 0
        # The stationarity reached, as a velocity (m/s): the Newton step at the answer over h
        # (0 when nothing needed solving; NaN under the "violation" stop, which does not
        # compute that step).
        self.last_stationarity = float(stats[ST_KKT]) / self._kkt_h \
            if self.solver == "al" and self.stop == "kkt" else \
            (0.0 if rounds == 0 else float("nan"))
        self.last_ms = 1e3 * (time.perf_counter() - t0)

    def _set_kkt_length(self, h):
        """This projection's stationarity tolerance in metres: ``kkt_velocity`` x h (a
        projection without a time step, h = 0, uses 1/30 s), or 0 under the old stop."""
        self._kkt_h = h if h > 0 else 1.0 / 30.0
        length = self.kkt_velocity * self._kkt_h if self.stop == "kkt" else 0.0
        if length != self.kkt_length:
            self.kkt_length = length
            self._upload_params()

    def _assemble(self, mid, pos):
        """The constraints of the method ``mid`` at ``pos`` into the work arrays (ws.g,
        ws.grad, ...)."""
        ws = self._ws
        al.assemble(mid, pos, ws.mesh_pack(), ws.constraint_pack(N_CONSTRAINTS[self.method]))

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
        """Newton steps per AL round: ``max_newton``, or when that is None FACTOR_NEWTON
        with the factor, MULTIGRID_NEWTON with the multigrid and MAX_NEWTON with block
        Jacobi."""
        if self.max_newton is not None:
            return self.max_newton
        if self._kernel_pdas():
            return PDAS_NEWTON
        if pc_mode == PC_MULTIGRID:
            return MULTIGRID_NEWTON
        return MAX_NEWTON if pc_mode == PC_JACOBI else FACTOR_NEWTON

    def pcg_budget(self, pc_mode):
        """PCG iterations per Newton step for this preconditioner: the factor's
        (``factor_cg``, else FACTOR_CG_WORK / faces clipped to [FACTOR_CG, FACTOR_CG_MAX]),
        the multigrid's (``multigrid_cg``, else the method's MULTIGRID_CG), or block Jacobi's
        ``cg_budget``."""
        if pc_mode == PC_FACTOR:
            return self.factor_cg if self.factor_cg is not None else int(np.clip(
                round(FACTOR_CG_WORK / max(self.model.n_faces, 1)), FACTOR_CG, FACTOR_CG_MAX))
        if pc_mode == PC_MULTIGRID:
            return self.multigrid_cg if self.multigrid_cg is not None else \
                MULTIGRID_CG.get(self.method, 4)
        return self.cg_budget()

    def cg_budget(self):
        """PCG iterations per Newton step: ``max_cg`` or, when that is None, the method's
        ``CG_BUDGET`` (coupling "implicit") or ``CG_BUDGET_PROJECTION``, per 1000 faces. CG
        iterations grow with the cloth's diameter in triangles (corrections travel across it),
        so above 1000 faces the budget grows like sqrt(n_faces / 1000)."""
        per_1000 = self.max_cg
        if per_1000 is None:
            per_1000 = CG_BUDGET.get(self.method, CG_BUDGET_PROJECTION) \
                if self.coupling == "implicit" else CG_BUDGET_PROJECTION
        return int(round(per_1000 * max(1.0, np.sqrt(self.model.n_faces / 1000.0))))

    def _kernel_curvature(self):
        """1 where the kernels use the exact curvature (c_curvature.py), 0 for the model.
        The host experiment (exact_curvature.py) replaces the model itself. For solve_al it
        is a compile-time switch, so the default kernel does not carry the exact curvature's
        code: cold, full optimisation, hanging res 9 with mapping built and ran its first
        frame in 122 s against 339 s with both in one kernel (2026-12-02, 2 cores, the other
        one busy). Choosing "exact" compiles its own variant once."""
        return int(self.curvature == "exact" and not self.exact_curvature
                   and self.method in EXACT_CURVATURE_FOR)

    def forget_last_velocity(self):
        """The next projection starts from the substep's start, not moved on at the last
        projection's velocities (``settle_speed``): after a correction that is not motion."""
        self._v_last_valid = False

    def multipliers(self):
        """The AL multipliers (faces, contacts, seams, friction) as numpy copies."""
        ws = self._ws
        return [a.to_numpy() for a in (ws.lam, ws.lam_c, ws.lam_s, ws.lam_t)]

    def restart_from(self, multipliers):
        """A projection solved again from its start: x back to x_start, the multipliers to
        ``multipliers`` (``multipliers()`` taken before), ``last_fallback`` set."""
        ws = self._ws
        self.last_fallback = True
        al.copy_vectors(self.model.n_verts, ws.x_start, ws.x)
        al.reset_start(self.model.n_verts, *self._start_args, ws.step_pack(self.model.state),
                       ws.vector_pack(), ws.contact_pack())
        for a, val in zip((ws.lam, ws.lam_c, ws.lam_s, ws.lam_t), multipliers):
            a.from_numpy(val)

    def _solve_al_with_fallback(self, mid, K, metric, contacts):
        """``_solve_al``; under the kernels' active-set model (``_kernel_pdas``) a projection
        not converged in ``direct.ACTIVE_SET_ROUNDS`` rounds is solved again from its start
        with the margin model (``last_fallback``), as the host loop does (direct.solve)."""
        self.last_fallback, self.last_solves = False, 0      # (host solves: direct.py)
        if not self._kernel_pdas():
            return self._solve_al(mid, K, metric, contacts)
        from .direct import ACTIVE_SET_ROUNDS
        multipliers_in = self.multipliers()
        budget = self.max_iters
        self.max_iters = min(ACTIVE_SET_ROUNDS, budget)
        try:
            out = self._solve_al(mid, K, metric, contacts)
        finally:
            self.max_iters = budget
        if out[2]:
            return out
        self.restart_from(multipliers_in)
        mu_scale = self.mu_scale
        self._upload_params(margin_fallback=True)
        self.mu_scale = _default_mu_scale(self.coupling, "margin")
        try:
            rounds, newton, converged, stats = self._solve_al(mid, K, metric, contacts)
        finally:
            self._upload_params()
            self.mu_scale = mu_scale
        return out[0] + rounds, out[1] + newton, converged, stats

    def _solve_al(self, mid, K, metric, contacts=False):
        """The AL loop (METHOD 4), one kernel launch (al.solve_al): rounds of inexact
        minimisation of L_A by projected Newton with a backtracking line search, then the
        multiplier step of eq. 27 and mu *= mu_grow. Returns (rounds, Newton steps,
        converged, the stats array)."""
        ws, m = self._ws, self.model
        mean_mass = self._mean_mass(metric)
        mu, mu_max = self.mu_scale * mean_mass, self.mu_max_scale * mean_mass
        # An inner loop stops once its steps are far below the tolerance (in metres).
        step_tol = 0.01 * self.tol * m.typical_edge()
        pc = None if contacts and not self.precondition_contacts else \
            self._pcg_preconditioner(metric)
        made_before = pc is not None and pc.before_solve(m.pinned[: m.n_verts])
        pc_mode = pc.mode if pc is not None and pc.usable(m.pinned[: m.n_verts]) else PC_JACOBI
        if self._stubs is None:
            self._stubs = {PC_FACTOR: FactorStub(), PC_MULTIGRID: MultigridStub()}
        fp = pc if pc_mode == PC_FACTOR else self._stubs[PC_FACTOR]
        mg = pc if pc_mode == PC_MULTIGRID else self._stubs[PC_MULTIGRID]
        budget = ws.budget
        budget[buffers.B_MU0], budget[buffers.B_MU_GROW] = mu, self.mu_grow
        budget[buffers.B_MU_MAX], budget[buffers.B_MAX_ROUNDS] = mu_max, self.max_iters
        budget[buffers.B_MAX_NEWTON] = self.newton_budget(pc_mode)
        budget[buffers.B_MAX_CG] = self.pcg_budget(pc_mode)
        budget[buffers.B_RTOL] = min(self.cg_rtol, PDAS_CG_RTOL) if self._kernel_pdas() \
            else self.cg_rtol
        budget[buffers.B_TOL], budget[buffers.B_STEP_TOL] = self.tol, step_tol
        budget[buffers.B_ADAPTIVE] = float(self.adaptive_margin)
        budget[buffers.B_FROM_PREV] = float(self.coupling == "implicit" and
                                            metric is self._system)
        budget[buffers.B_PC_MODE] = pc_mode
        al.solve_al(mid, self._kernel_curvature(), self._kernel_pdas(), ws.budget, ws.mesh_pack(),
                    ws.metric_pack(metric), ws.constraint_pack(K), ws.contact_pack(),
                    ws.vector_pack(), ws.precond_pack(fp, mg), ws.stats)
        stats = ws.stats.to_numpy()
        rounds, newton = int(stats[ST_ITERS]), int(stats[ST_NEWTON])
        self.last_factorizations = int(made_before)
        if pc is not None:
            self.last_factorizations += int(pc.after_solve(m.pinned))
        return rounds, newton, bool(stats[ST_CONVERGED] > 0), stats

    def _pcg_preconditioner(self, metric):
        """The preconditioner object of this metric's pattern when the PCG solve uses one
        (coupling "implicit" and a CPU backend: both run serially in the solve's kernel);
        else None. ``precondition``: "auto" takes the factor (factor_precond.py) up to
        FACTOR_MAX_FACES faces (``factor_max_faces``) and the multigrid (multigrid.py)
        above, "factor" / "multigrid" one of them at every size, "jacobi" neither. The
        factor needs CHOLMOD (else the multigrid is taken), the multigrid pyamg and more than
        MAX_COARSE unknowns. (Solves with contacts use block Jacobi: on drape the factor kept
        none of the sheet's kinetic energy through the landing and it draped in 0 of 7
        drops, against 0.4 % and 2 of 7 with block Jacobi; docs/speed/drape_depth.md.)"""
        if not (self.precondition != "jacobi" and metric is self._system and
                backend.arch() == "cpu"):
            return None
        kind = self.precondition
        if kind == "auto":
            limit = FACTOR_MAX_FACES if self.factor_max_faces is None else self.factor_max_faces
            kind = "factor" if self.model.n_faces <= limit else "multigrid"
        if kind == "factor" and not linalg.HAVE_CHOLMOD:
            kind = "multigrid"
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
        al.copy_vectors(self.model.n_verts, self.model.state.x, ws.x_trial)
        self._assemble(METHOD_IDS[self.method], ws.x_trial)
        g = ws.g.to_numpy()[:n, :K].astype(np.float64)
        return g / np.sqrt(self.model.rest_area[:n])[:, None]
