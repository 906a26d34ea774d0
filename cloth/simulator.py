"""The frame loop: a flat list of named stages, each switchable and timed (ARCSim style).

    every substep:  pins -> dynamics -> self_collision -> collision -> strain_limit
                    -> collision_final -> contact_reproject
    every frame:    remesh -> remesh_reproject -> metrics -> snapshot

A scene enables only the stages it needs (``_enable_stages``). Every piece of work a frame does
is one of them, timed on its own, so the stages' times add up to the frame's (``frame_ms``;
metrics.csv has a column per stage). With obstacles and strain limiting both on, the contacts
are constraints of the strain projection (half-spaces found by the collision stage), so the
projection cannot push cloth into a body and contact cannot undo the limits; the
``collision_final`` stage then runs the obstacle pass once more to remove what the half-spaces'
linearisation leaves on curved bodies (tested in tests/test_all_scenes.py), and where
it had to push further than the strain tolerance ``contact_reproject`` projects again. After an
applied remesh ``remesh_reproject`` projects where the new mesh broke the limits. Seams
(stitch pairs) are equality constraints of the same projection.

The Simulator reads its settings from one ``cloth.settings.Settings`` (``self.settings``) and owns
every live control: ``set_method``, ``set_bands``, ``set_rounds``, ``set_substeps``,
``set_material``, ``set_remesh``, ``set_self_collision``, ``hold_vertex`` / ``release_vertex`` and
``reset``. Each changes ``settings`` and nothing else; ``_follow`` then derives every copy kept
elsewhere (the strain limiter's attributes and kernel parameters, the model's material, the
stages switched on) from the new settings, in one place. A change takes effect at the next
substep, and a window, a script and a test change a run the same way.

"""
import dataclasses
import sys
import time
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

# Every stage's module (``sim.linear_solver = "direct"`` swaps in dynamics_sparse.py, imported
# where it is built: it loads scipy).
from . import compile_notice, ndarrays
from . import metrics                                  # stage "metrics"
from . import remesh                                   # stage "remesh"
from .collision import THICKNESS, Collider  # stages "self_collision", "collision", "collision_final"
from .dynamics import DynamicsSettings, ImplicitEuler  # stage "dynamics"
from .model import CapacityExceeded, ClothModel, Material, MeshArrays
from .config import ConfigError
from .settings import Settings
from .strain.solver import StrainLimiter              # stage "strain_limit" (cloth/strain/)

# m/s: a remesh carries the projection's last velocity of a vertex at least this fast (a
# landing), and forgets the slower ones (``Simulator._remesh``).
CARRY_SPEED = 1.0

# m: how far settings sim.nudge moves the start (``nudged_start``).
NUDGE_SIZE = 1e-9


# Projection and obstacle pass alternate at most this often in a substep: the garment on its
# dress form needed 4-5 in its landing frames, and stopped at 3 those frames ended at 3.7-4.7
# times strain.tol.
CONTACT_REPROJECT_ROUNDS = 8


class SimulationDiverged(RuntimeError):
    """The state became non-finite; ``frame`` and ``stage`` say where."""

    def __init__(self, frame, stage):
        super().__init__(f"the simulation became non-finite at frame {frame} in stage "
                         f"'{stage}': reduce the time step (raise sim.substeps) or soften the "
                         "material")
        self.frame, self.stage = frame, stage


@dataclass
class SceneSetup:
    """What a scene builder hands the simulator."""
    mesh: MeshArrays
    material: Material
    # Pinned vertices' targets as a function of time and their material coordinates:
    # f(t, uv (P, 2), rest (P, 3)) -> (P, 3). None for pins that never move.
    pin_motion: Optional[Callable] = None
    obstacles: list = field(default_factory=list)
    stitches: Optional[np.ndarray] = None
    self_collision: bool = False
    camera: dict = field(default_factory=dict)
    check_final: Optional[Callable] = None   # f(sim) -> (ok: bool, message: str)


def nudged_start(setup, seed, size=NUDGE_SIZE):
    """A copy of ``setup`` whose free vertices start moved by ``size`` m at random (normal,
    per coordinate; ``seed``): settings ``sim.nudge``. 1 nm lies far below what any picture or
    measure reads, and far above round-off (f64 at 1 m: 1e-16 m), so a chaotic scene's runs from
    nudged starts differ as runs on two CPUs do, where the last bits differ."""
    noise = np.random.default_rng(seed).normal(0.0, size, setup.mesh.x.shape)
    noise[np.asarray(setup.mesh.pinned, bool)] = 0.0
    return dataclasses.replace(setup, mesh=dataclasses.replace(setup.mesh,
                                                               x=setup.mesh.x + noise))


@dataclass
class Stage:
    name: str
    run: Callable
    enabled: bool = True
    per_substep: bool = True
    ms: float = 0.0            # time spent in the current frame
    moves: bool = True         # changes the state (then checked for NaN after it runs)


class Simulator:
    def __init__(self, setup: SceneSetup, settings):
        """``settings``: a ``Settings``, or the resolved nested dict of a scene (checked here;
        a bad value raises ``ConfigError`` naming the key)."""
        self.settings = Settings.of(settings)
        sim = self.settings.sim
        self.setup = setup = nudged_start(setup, int(sim.nudge)) if sim.nudge else setup
        self.frame, self.time = 0, 0.0
        self.grow_count = 0
        self._sl_stationarity = 0.0
        self._remesh_deferred = 0      # remeshes deferred in a row (RemeshParams.defer_ops)
        self._remeshed_once = False    # a remesh was applied since the scene's mesh was loaded
        self._carried_motion = None    # (v_last, valid) carried by the last remesh
        self.model = ClothModel(setup.mesh, setup.material,
                                capacity_factor=self._capacity_factor(setup.mesh,
                                                                      self.settings.remesh),
                                bending=sim.bending)
        self._pin_rest = setup.mesh.pin_target.copy()
        self._held = None          # (vertex, was pinned, its own target, uv) while held
        self.dynamics_settings = DynamicsSettings(
            gravity=tuple(sim.gravity), stitch_stiffness=float(sim.stitch_stiffness),
            cg_tol=float(sim.cg_tol), cg_max_iters=int(sim.cg_iters))
        self.dynamics = self._make_dynamics(setup.stitches)
        self.strain = None
        self.collider = None
        self.remesher = None
        self._untried = {"dynamics", "self_collision", "collision"}
        self._contact_push = 0.0       # m: the last obstacle pass's largest push
        self._remeshed = False         # the frame's remesh was applied
        self.remeshes_applied = 0      # remeshes applied so far (others deferred or empty)
        self._row = None               # (frame, the metrics row the "metrics" stage measured)
        self.frame_ms = 0.0            # the last frame's wall time, every stage included
        # The frame, flat: every piece of work a frame does is one of these, timed on its own
        # (Stage.ms; the stages add up to ``frame_ms``). ``_enable_stages`` switches on just
        # the stages a scene and its settings use.
        self.stages = [
            Stage("pins", self._move_pins),
            Stage("dynamics", self._dynamics_step),
            Stage("self_collision", self._self_collide),
            Stage("collision", self._collide),
            Stage("strain_limit", self._strain_limit),
            Stage("collision_final", self._collide_final),
            Stage("contact_reproject", self._contact_reproject),
            Stage("remesh", self._remesh, per_substep=False),
            Stage("remesh_reproject", self._remesh_reproject, per_substep=False),
            Stage("limits_watch", self._watch_limits, per_substep=False, moves=False),
            Stage("metrics", self._measure, per_substep=False, enabled=False, moves=False),
            Stage("snapshot", self._snapshot, per_substep=False, moves=False),
        ]
        self._metrics_stage = False    # ``set_metrics_stage``
        self._watched = None           # the limits watch's per-face values, for the metrics
        if setup.obstacles or setup.self_collision:
            self._make_collider()
        self._follow(self.settings)
        self._relax_initial_state()
        self.last_good = self.model.mesh_arrays()
        self.remesh_stats = {}
        self._reset_limit_watch()

    @property
    def substeps(self):
        return int(self.settings.sim.substeps)

    @property
    def h(self):
        """The time step (s): 1 / (fps x substeps)."""
        return 1.0 / (float(self.settings.sim.fps) * self.substeps)

    def reset(self):
        """Back to the scene's initial state at time 0 with the current settings (method,
        bands, material, substeps kept). Nothing compiles; everything a run carries over (the
        CG warm start, the AL multipliers) is reset, so a reset run repeats a fresh one."""
        self._held = None
        self.model.load(self.setup.mesh)
        self._pin_rest = self.setup.mesh.pin_target.copy()
        self.dynamics.stitches_np = self._initial_stitches()
        self._mesh_changed()
        self.frame, self.time = 0, 0.0
        self._remesh_deferred = 0
        self._remeshed, self._row, self.frame_ms = False, None, 0.0
        self._remeshed_once = False
        for s in self.stages:
            s.ms = 0.0
        self._relax_initial_state()
        self.last_good = self.model.mesh_arrays()
        self.remesh_stats = {}
        self._reset_limit_watch()

    def _initial_stitches(self):
        st = self.setup.stitches
        return np.zeros((0, 2), np.int32) if st is None else np.asarray(st, np.int32).reshape(-1, 2)

    def _mesh_changed(self):
        """The model's arrays were refilled (reset, remesh): every solver forgets what it kept
        per vertex or face and re-reads the mesh. The one place that tells them all."""
        self.dynamics.on_mesh_changed()
        if self.strain is not None:
            self.strain.set_stitches(self.dynamics.stitches_np)
            self.strain.on_mesh_changed()
        if self.collider is not None:
            self.collider.on_mesh_changed()

    @staticmethod
    def _capacity_factor(mesh, remesh_settings, cap_faces=200_000):
        """Spare room in the model's arrays. With remeshing, room for the finest mesh the
        sizing allows (2.5 x the count of equilateral triangles of edge size_min that tile
        it), so a refining cloth rarely outgrows its arrays (growing rebuilds the solvers)."""
        if not remesh_settings.enabled:
            return 1.2
        area = metrics.material_areas(mesh.uv, mesh.faces).sum()
        finest = 2.5 * area / (0.433 * remesh_settings.size_min ** 2)
        return max(2.0, min(finest, cap_faces) / len(mesh.faces))

    def _relax_initial_state(self):
        """Project a scene's starting shape onto the strain limits without touching the
        velocities (h = 0): a start outside the limits (a garment wrapped around a body) would
        otherwise be corrected in the first substep with a velocity jump of dx / h."""
        if self.strain is not None and self.stage("strain_limit").enabled:
            self._project_limits(0.0, self.time)

    # -- stages -------------------------------------------------------------------------------
    def _make_dynamics(self, stitches):
        """Backward Euler with the linear solver the config asks for: ``cg`` (matrix-free
        PCG, the default: fastest for soft cloth and up to ~10k triangles) or ``direct``
        (assembled sparse Cholesky: exact, cheaper for stiff cloth from ~10k triangles)."""
        kind = self.settings.sim.linear_solver
        if kind == "cg":
            return ImplicitEuler(self.model, self.dynamics_settings, stitches=stitches)
        if kind == "direct":
            from .dynamics_sparse import SparseImplicitEuler
            return SparseImplicitEuler(self.model, self.dynamics_settings, stitches=stitches,
                                       linear_solver="llt")
        raise ValueError(f"unknown sim.linear_solver '{kind}': use cg or direct")

    def stage(self, name):
        for s in self.stages:
            if s.name == name:
                return s
        raise KeyError(name)

    def _make_strain_limiter(self, settings):
        """The strain limiter of ``settings.strain`` (``StrainLimiter.configure``)."""
        self.strain = StrainLimiter(self.model, settings.strain,
                                    stitches=self.dynamics.stitches_np)

    def _dynamics_step(self):
        """The implicit step. Its matrix then becomes the strain projection's metric
        (cloth/system_matrix.py). Its CG is preconditioned by the factor or the multigrid of
        that matrix that the strain solve keeps (``StrainLimiter.implicit_preconditioner``),
        else (no strain limits, the first substeps on a mesh) by block Jacobi."""
        limits = self.strain is not None and self.stage("strain_limit").enabled
        self.dynamics.set_preconditioner(self.strain.implicit_preconditioner() if limits
                                         else None)
        self.dynamics.step(self.h)
        if limits:
            self.dynamics.system_matrix(self.h, self.strain.system_metric())

    def _strain_limit(self):
        self._project_limits(self.h, self.time + self.h)
        self._sl_stationarity = self.strain.last_stationarity

    def _project_limits(self, h, t, warm=True, friction=True):
        """Strain projection with the obstacles' contacts at time t as constraints (with
        their friction unless ``friction`` is False)."""
        with_contacts = self.collider is not None and bool(self.collider.obstacles)
        if with_contacts:
            # Reach: half an edge, about the most a projection moves a vertex in one substep
            # (measured on drape at 10 cm edges: with a 5 mm reach the final obstacle pass had
            # to push by 8.6 mm, undoing the limits by 1.5e-2; with 5 cm it pushed nothing).
            self.collider.contact_planes(t, self.strain.contact_planes,
                                         reach=0.5 * self.model.typical_edge(),
                                         mu_out=self.strain.contact_friction)
        with compile_notice.first_use(*self.compile_work("strain_limit")):
            self.strain.project(h, contacts=with_contacts, warm=warm, friction=friction)

    def _make_collider(self):
        c = self.settings.section("collision")
        self.collider = Collider(self.model, self.setup.obstacles,
                                 thickness=c.thickness if c is not None else THICKNESS,
                                 self_collision=self.setup.self_collision)

    def _self_collide(self):
        self.collider.resolve_self(self.h, self.time)

    def _collide(self):
        """The obstacle pass (with its continuous test)."""
        self.collider.resolve_contacts(self.h, self.time)

    def _collide_final(self):
        """The obstacle pass after the projection (no continuous test: ``resolve_obstacles``);
        how far it pushed decides whether ``contact_reproject`` has work."""
        self._contact_push = self.collider.resolve_obstacles(self.h, self.time)

    def _contact_reproject(self):
        """Where the final obstacle pass had to move a vertex by more than the strain
        tolerance (a vertex beyond the planes' reach pulled into a body, a concave corner of
        it): project again with the contacts as they are now and run the obstacle pass again,
        up to CONTACT_REPROJECT_ROUNDS times while it still pushes that far."""
        tol_m = self.strain.tol * self.model.typical_edge()
        for _ in range(CONTACT_REPROJECT_ROUNDS):
            if self._contact_push <= tol_m:
                return
            self._project_limits(self.h, self.time + self.h, warm=False)
            self._contact_push = self.collider.resolve_obstacles(self.h, self.time)

    def _make_remesher(self, settings):
        rcfg = dataclasses.asdict(settings.remesh)
        params = remesh.RemeshParams(**{k: v for k, v in rcfg.items() if k != "enabled"})
        params.validate()
        self.remesher = (remesh, params)

    def _remesh(self):
        remesh, params = self.remesher
        mesh = self.model.mesh_arrays()
        obstacle_distance = self._obstacle_distance if self.setup.obstacles else None
        # Pins and seam vertices are frozen: never removed or moved, seams never split.
        frozen = mesh.pinned.copy()
        stitches = self.dynamics.stitches_np
        if len(stitches):
            frozen[stitches.ravel()] = True
        t0, c0 = time.perf_counter(), time.process_time()
        edges = self.model.edge_topology()
        Mv = remesh.mesh_sizing(mesh, params, obstacle_distance, edges)
        if self._defer_unmade(mesh, Mv, frozen, edges, params):
            self.remesh_stats.update(ms=1e3 * (time.perf_counter() - t0),
                                     ms_cpu=1e3 * (time.process_time() - c0))
            return
        # What the solver carries to the new mesh, read only for a remesh that is made.
        face_data = self.strain.face_state() if self.strain is not None and \
            params.warm_multipliers else None
        motion = self.strain.last_velocity() if self.strain is not None else None
        new, new_face_data, stats = remesh.remesh(mesh, params, obstacle_distance=obstacle_distance,
                                                  face_data=face_data, frozen_verts=frozen,
                                                  sizing=Mv, edges=edges)
        self.remesh_stats = stats
        stats["applied"] = stats["grown"] = False
        self._remeshed = False
        if not self._apply_remesh(stats, params):
            return
        stats["applied"] = self._remeshed = self._remeshed_once = True
        self.remeshes_applied += 1
        if len(stitches):
            self.dynamics.stitches_np = stats["vertex_map"][stitches].astype(np.int32)
        # The dynamics' last velocity change, carried to the new vertices like v: its CG
        # starts from it (warm start), as it does between substeps on an unchanged mesh.
        # Measured on hanging at 900 faces: 140 CG iterations per step from zero after every
        # remesh, ~80 warm (41 on the regular grid of the same size).
        dv = remesh.transfer_vertex_data(self.dynamics.warm_start(), stats)
        try:
            self.model.load(new, vertex_map=stats["vertex_map"])
        except CapacityExceeded:
            self._rebuild_for(new)
            stats["grown"] = True
        self._mesh_changed()
        self.dynamics.set_warm_start(dv)
        if self.strain is not None and new_face_data:   # only with remesh.warm_multipliers
            self.strain.set_face_state(new_face_data)
        # The cloth's motion carried to the new vertices, handed to the solver after the
        # re-projection that follows (``_remesh_reproject``).
        self._carried_motion = None
        if motion is not None:
            v_last = remesh.transfer_vertex_data(motion[0], stats)
            # Only fast motion is carried (``CARRY_SPEED``: a landing's). Slower vertices start
            # the next projection where they were, which damps them: a remesh sets off small
            # motion (a flip or a collapse on a curved sheet changes its shape), and carried
            # at every speed, or from 0.4 m/s, that motion was kept going: a hanging sheet
            # remeshed every frame never settled (warp-weft V5H1 at resolution 31, Table 1
            # remeshed: kinetic energy 2e-3 to 1e-2 J over 150 frames at 3.1k faces, where
            # it rests at 2e-7 J and 2.1k faces with this rule).
            v_last[np.linalg.norm(v_last, axis=1) < CARRY_SPEED] = 0.0
            self._carried_motion = (v_last, motion[1])
        if self._held is not None:
            self._find_held_again()

    def _remesh_reproject(self):
        """After an applied remesh: flips and collapses change some triangles' deformation
        (splits do not: a split vertex sits at its edge's midpoint in both spaces), so the
        limits may no longer hold on the new mesh: project again where they do not, so that
        they hold at the end of every frame. With obstacles always (contacts are constraints
        of that projection, and a new vertex on a chord may lie inside a curved body), but
        without friction: friction holds a contact vertex near where its substep began, and
        a remesh's correction is not a substep's motion. With friction the limits' pull
        raised the contact multipliers and the friction bound with them (the capstan of
        ``StrainLimiter.project``): on drape --remesh two of six runs had a re-projection
        locked for 2.1 and 11.8 s, none without (docs/remesh/drape.md)."""
        if not self._remeshed:
            return
        self._remeshed = False
        with_contacts = self.collider is not None and bool(self.collider.obstacles)
        if with_contacts or self.strain.own_violation_max() > self.strain.tol:
            # It starts where the cloth is (the remesh left no last velocity): it corrects
            # positions already at the end of the substep, so the carried motion is handed
            # over only after it.
            self._project_limits(self.h, self.time, friction=False)
            self.remesh_stats["reprojected"] = True
        # The next projection moves on at the motion carried from before the remesh, not at
        # the re-projection's correction, which is the remesh's, not the cloth's motion
        # (carried on, the correction kept the remeshed mapping sheet moving: refined to 426
        # faces where it settles at 188, and three of 300 frames stalled for 100 rounds;
        # tests/test_strain_scenes.py).
        if self._carried_motion is not None:
            self.strain.set_last_velocity(*self._carried_motion)
        else:
            self.strain.forget_last_velocity()

    def _defer_unmade(self, mesh, Mv, frozen, edges, params):
        """Defer this frame's remesh without making it when it would start from few
        operations (``remesh.pending_operations``: the edges to split and to flip, at most
        ``params.defer_ops`` per face) and fewer than ``params.defer_frames`` frames in a row
        were deferred. Making a remesh costs as much as half a frame of a small cloth (the
        mesh copied into Python lists, the candidate passes, the export: 8 of 11 ms at 900
        faces), and most frames of a settling cloth defer theirs anyway (``_apply_remesh``),
        so the count decides before the remesh is made. Collapses are not counted: coarsening
        waits at most ``defer_frames`` frames, then the remesh is made and applied as before.
        Refinement the cloth needs now (many edges too long) is never deferred, nor the first
        remesh of the scene's own mesh (made for no sizing: hanging's first remesh collapses
        1699 edges of 4050 faces, which the count does not see)."""
        if not (params.defer_ops > 0 and self._remesh_deferred < params.defer_frames
                and self._remeshed_once):
            return False
        n = remesh.pending_operations(mesh, Mv, frozen, edges)
        if n > params.defer_ops * len(mesh.faces):
            return False
        self._remesh_deferred += 1
        nf, nv = len(mesh.faces), len(mesh.uv)
        self.remesh_stats = dict(splits=0, flips=0, collapses=0, pending=n, faces_in=nf,
                                 faces_out=nf, verts_in=nv, verts_out=nv, applied=False,
                                 grown=False, deferred=True, made=False)
        return True

    def _apply_remesh(self, stats, params):
        """Whether to apply this remesh: not when it changed nothing, nor when its operations
        are few (``params.defer_ops`` per face) and fewer than ``params.defer_frames`` frames
        in a row were deferred (RemeshParams: deferring keeps the mesh and what is built on
        it)."""
        ops = stats["splits"] + stats["flips"] + stats["collapses"]
        if ops == 0:
            self._remesh_deferred = 0
            return False
        if ops <= params.defer_ops * stats["faces_in"] and \
                self._remesh_deferred < params.defer_frames:
            self._remesh_deferred += 1
            stats["deferred"] = True
            return False
        self._remesh_deferred = 0
        return True

    def _obstacle_distance(self, points):
        """Signed distance of world points to the nearest obstacle now (for remeshing)."""
        return np.min([o.distance(points, self.time) for o in self.setup.obstacles], axis=0)

    def _rebuild_for(self, mesh):
        """The remeshed cloth outgrew the arrays: build a model with twice the room and new
        solver objects around it (nothing compiles: every kernel takes arrays as arguments)."""
        self.grow_count += 1
        print(f"loom: remeshing grew the cloth to {len(mesh.faces)} faces; reallocating arrays "
              f"with room for {2 * len(mesh.faces)} (grown {self.grow_count}x)", file=sys.stderr)
        self.model = ClothModel(mesh, self.setup.material, capacity_factor=2.0,
                                bending=self.model.bending)
        self.dynamics = self._make_dynamics(self.dynamics.stitches_np)
        if self.strain is not None:
            self._make_strain_limiter(self.settings)
        if self.collider is not None:
            self._make_collider()
            self._follow(self.settings)

    # -- live controls: each takes effect at the next substep and keeps ``settings`` in step --
    def _change(self, section, **changes):
        """Check ``changes`` against the schema (ConfigError names the key), derive every copy
        from the new settings (``_follow``) and adopt them. A change the solvers refuse leaves
        ``settings`` as it was."""
        new = self.settings.replace(section, **changes)
        self._follow(new)
        self.settings = new
        return getattr(new, section)

    def _follow(self, settings):
        """The one function that derives everything kept outside ``settings`` from it: the
        strain limiter's attributes and kernel parameters (``StrainLimiter.configure``), the
        model's material, the remesher, the collider's self-collision and which stages run
        (``_enable_stages``). Cheap: called on every live change."""
        if self.model.bending == "isotropic" and \
                settings.material_model().bend_alpha() != self.model.bend_alpha:
            # The orthotropy is in the bending matrix, built with the cloth (bending.py:
            # orthotropic_coordinates); scaling both rigidities together is live.
            raise ConfigError("material.k_bend_warp / k_bend_weft: their ratio is read when the "
                              "cloth is built; restart the scene with the new values (scaling "
                              "both by one factor, or k_bend, is live)")
        st = settings.strain
        if self.strain is not None:
            self.strain.configure(st)
        elif st.method != "none":
            self._make_strain_limiter(settings)
        # The material the scene built the model with (``SceneSetup.material``) is the
        # settings' at the start; from then on the changed keys are copied.
        for f in dataclasses.fields(self.model.material):
            value = getattr(settings.material, f.name)
            if value != getattr(self.settings.material, f.name):
                setattr(self.model.material, f.name, float(value))
        if settings.remesh.enabled and self.remesher is None:
            self._make_remesher(settings)
        on = getattr(settings.section("collision"), "self_collision", None)
        if self.collider is not None and self.can_self_collide and on is not None and \
                bool(on) != self.collider.self_collision:
            self.collider.set_self_collision(bool(on))
        self._enable_stages(settings)

    def _enable_stages(self, settings):
        """Switch on just the stages this scene and these settings use."""
        limit = self.strain is not None and settings.strain.method != "none"
        obstacles = bool(self.setup.obstacles)
        remesh = bool(settings.remesh.enabled)
        on = {"pins": self.setup.pin_motion is not None, "dynamics": True,
              "self_collision": self.self_collision_on, "collision": obstacles,
              "strain_limit": limit, "collision_final": limit and obstacles,
              "contact_reproject": limit and obstacles, "remesh": remesh,
              "remesh_reproject": remesh and limit, "limits_watch": limit,
              "metrics": self._metrics_stage,
              "snapshot": True}
        for s in self.stages:
            s.enabled = on[s.name]

    def set_metrics_stage(self, on):
        """Measure ``metrics_row`` inside every frame, as its stage "metrics" (a run that
        writes metrics.csv: its cost is then part of the frame time)."""
        self._metrics_stage = bool(on)
        self.stage("metrics").enabled = self._metrics_stage

    def set_method(self, name):
        """Switch strain limiting (``svd``, ``warp-weft``, ``mapping`` or ``none``; the schema
        refuses other names)."""
        self._change("strain", method=name)

    def set_bands(self, warp=None, weft=None, bias=None):
        """Change the strain bands ([min, max], strain). ``bias="auto"`` makes the bias band
        follow the warp and weft bands again (``metrics.default_bias_band``)."""
        changes = {k: list(v) for k, v in (("warp", warp), ("weft", weft)) if v is not None}
        if isinstance(bias, str) and bias != "auto":
            raise ValueError(f"bias band must be [min, max] or \"auto\" (got {bias!r})")
        if bias is not None:
            changes["bias"] = [] if isinstance(bias, str) else list(bias)
        self._change("strain", **changes)

    def bands(self):
        """The (warp, weft, bias) bands in force, the automatic bias band worked out."""
        st = self.settings.strain
        warp, weft = tuple(st.warp), tuple(st.weft)
        bias = tuple(st.bias) if st.bias else metrics.default_bias_band(warp, weft)
        return {"warp": warp, "weft": weft, "bias": bias}

    def set_rounds(self, n):
        """The AL round budget per projection."""
        self._change("strain", rounds=int(n))

    def set_strain_solve(self, solve):
        """How hard each projection is solved, live: "fast" (stops once the limits hold) or
        "exact" (to the projection's minimiser; slower)."""
        self._change("strain", solve=solve)      # the schema refuses other names

    def set_substeps(self, n):
        """Time steps per frame (h = 1 / (fps x substeps))."""
        self._change("sim", substeps=int(n))

    def set_material(self, **values):
        """Change stiffnesses or damping (``k_warp=...``); the dynamics reads the material
        every step. Stretch moduli must stay positive."""
        for key in ("k_warp", "k_weft"):
            if key in values and not float(values[key]) > 0:
                raise ValueError(f"material.{key} must be > 0 N/m (got {values[key]})")
        self._change("material", **{k: float(v) for k, v in values.items()})

    def set_remesh(self, on):
        """Switch the per-frame remeshing stage (its settings: ``settings.remesh``)."""
        self._change("remesh", enabled=bool(on))

    @property
    def can_self_collide(self):
        return self.setup.self_collision

    def set_self_collision(self, on):
        """Switch cloth-cloth repulsion (scenes built with self-collision only)."""
        if self.collider is None or not self.can_self_collide:
            raise ValueError("this scene was built without self-collision")
        self._change("collision", self_collision=bool(on))

    @property
    def self_collision_on(self):
        return self.collider is not None and self.collider.self_solver is not None

    def hold_vertex(self, v, target):
        """Hold vertex ``v`` at ``target`` (m), as a pin, until ``release_vertex``; call again
        to move it. Holding another vertex releases the first. The hold follows its material
        point through remeshing (``held_vertex``)."""
        if self._held is not None and self._held[0] != v:
            self.release_vertex()
        m = self.model
        if self._held is None:
            self._held = (int(v), bool(m.pinned[v]), np.array(m.vert_pin_target[v], float),
                          m.uv[v].copy(), None)
        self._held = self._held[:4] + (np.asarray(target, float).copy(),)
        m.set_vertex_pin(v, True, target)

    @property
    def held_vertex(self):
        return None if self._held is None else self._held[0]

    def release_vertex(self):
        """Give the held vertex back its own pin state and target."""
        if self._held is None:
            return
        v, was, old = self._held[:3]
        if v < self.model.n_verts:
            self.model.set_vertex_pin(v, was, old)
        self._held = None

    def _find_held_again(self):
        """After a remesh the vertex numbers change: hold the same material point again."""
        _, _, _, uv, target = self._held
        m = self.model
        v = int(np.argmin(np.linalg.norm(m.uv - uv, axis=1)))
        self._held = (v, bool(m.pinned[v]), np.array(m.vert_pin_target[v], float), uv, target)
        m.set_vertex_pin(v, True, target)

    @property
    def method(self):
        return self.settings.strain.method

    # -- one substep tried several ways (benchmarks, tests) ------------------------------------
    def substep_state(self):
        """Positions, velocities and the strain solver's state: what the next substep starts
        from (``set_substep_state`` puts it back)."""
        return (self.model.positions(), self.model.velocities(),
                None if self.strain is None else self.strain.solve_state())

    def set_substep_state(self, state):
        x, v, solve = state
        self.model.set_positions(x)
        self.model.set_velocities(v)
        if solve is not None:
            self.strain.set_solve_state(solve)

    def run_substep_through(self, name):
        """Run the next substep's stages up to and including the stage ``name``, without
        moving the clock (the substep can be put back and run again another way). Returns
        the positions just before that stage ran (for the strain projection: its start)."""
        for s in self.stages:
            if s.enabled and s.per_substep:
                if s.name == name:
                    before = self.model.positions()
                    self._run_stage(s)
                    return before
                self._run_stage(s)
        raise ValueError(f"no enabled per-substep stage '{name}' (stages: "
                         f"{', '.join(s.name for s in self.stages)})")

    # -- the frame loop -----------------------------------------------------------------------
    def _move_pins(self):
        self._update_pins(self.time + self.h)

    def _reset_limit_watch(self):
        # Each frame's largest own violation at its end, as (time, value); the frames that
        # ended above strain.tol: how many, and the first (frame, violation, AL rounds used,
        # round budget).
        self.own_violation_log = []
        self.limit_misses, self.first_limit_miss = 0, None

    def _watch_limits(self):
        """Stage "limits_watch": the largest own violation at the end of the frame, against
        strain.tol; the final checks judge the run's largest (``own_violation_log``), not
        only the last frame's."""
        if self._metrics_stage:
            # The per-face values, handed to this frame's metrics stage, which runs next and
            # would assemble the same constraints again (2.5 ms at 16k faces).
            self._watched = self.own_violation()
            value = float(self._watched.max()) if self._watched.size else 0.0
        else:
            value = self.strain.own_violation_max()
        frame = self.frame + 1
        self.own_violation_log.append((self.time, value))
        if value > self.settings.strain.tol:
            self.limit_misses += 1
            if self.first_limit_miss is None:
                self.first_limit_miss = (frame, value, self.strain.last_iterations,
                                         int(self.settings.strain.rounds))

    def _snapshot(self):
        """Keep the frame's mesh and state (``last_good``: what a diverged run had last)."""
        self.last_good = self.model.mesh_arrays()

    def _update_pins(self, t):
        """Move the scene's scripted pins to their targets at time t (a held vertex stays
        where it is held)."""
        if self.setup.pin_motion is None:
            return
        pinned = self.model.pinned.copy()
        if self._held is not None:
            pinned[self._held[0]] = False
        if not np.any(pinned):
            return
        targets = ndarrays.get_rows(self.model.vert_pin_target, self.model.n_verts)
        targets[pinned] = self.setup.pin_motion(t, self.model.uv[pinned], self._pin_rest_of(pinned))
        self.model.set_pin_targets(targets)

    def _pin_rest_of(self, pinned=None):
        """Rest positions of the ``pinned`` vertices (default: all pinned ones; the scene's
        initial targets), looked up by material point so they survive remeshing."""
        pinned = self.model.pinned if pinned is None else pinned
        uv0 = self.setup.mesh.uv[self.setup.mesh.pinned]
        rest0 = self._pin_rest[self.setup.mesh.pinned]
        uv = self.model.uv[pinned]
        d = np.linalg.norm(uv[:, None, :] - uv0[None, :, :], axis=2)
        return rest0[np.argmin(d, axis=1)]

    def step_frame(self):
        """Advance one frame (``substeps`` time steps and the per-frame stages). Every stage
        is timed on its own; ``frame_ms`` is the whole frame's wall time, which they add up
        to."""
        t0 = time.perf_counter()
        for s in self.stages:
            s.ms = 0.0
        self._watched = None
        for _ in range(self.substeps):
            for s in self.stages:
                if s.enabled and s.per_substep:
                    self._run_stage(s)
            self.time += self.h
        for s in self.stages:
            if s.enabled and not s.per_substep:
                self._run_stage(s)
        self.frame += 1
        self.frame_ms = 1000.0 * (time.perf_counter() - t0)

    def compile_work(self, stage):
        """(what, key, estimate in s) of the kernels a stage compiles at its first call: the
        key names the kernel variant (cloth/compile_notice.py, which keeps the estimates).
        The strain solver is one kernel for the three methods, one per ``strain.solve``: a
        switch of method compiles nothing, a switch to the exact solve compiles its own."""
        if stage == "strain_limit":
            solve = self.settings.strain.solve
            return (f"the {solve} strain solver", f"strain solver:{solve}",
                    compile_notice.strain_estimate(solve, self.strain.uses_host_loop()))
        if stage == "dynamics":
            return ("the dynamics step", f"dynamics:{self.settings.sim.linear_solver}",
                    compile_notice.DYNAMICS_COMPILE_S)
        if stage in ("collision", "self_collision"):
            return ("the collision pass", "collision", compile_notice.COLLISION_COMPILE_S)
        return None

    def compile_pending(self):
        """The notice line when the next frame's strain solve will compile its kernels (its
        first use on this machine: limiting switched on from "none", or the exact solve), else
        None: the window shows it before the step that compiles."""
        if self.strain is None or not self.stage("strain_limit").enabled:
            return None
        return compile_notice.notice(*self.compile_work("strain_limit"))

    def _run_stage(self, s):
        t0 = time.perf_counter()
        if s.name in self._untried:       # its first run: it may compile (strain: per call)
            self._untried.discard(s.name)
            with compile_notice.first_use(*self.compile_work(s.name)):
                s.run()
        else:
            s.run()
        # (all_finite waits for the stage's kernels; a stage that only reads syncs itself)
        finite = self.model.all_finite(self.model.n_verts) if s.moves else True
        s.ms += 1000.0 * (time.perf_counter() - t0)
        if not finite:
            raise SimulationDiverged(self.frame + 1, s.name)

    # -- metrics ------------------------------------------------------------------------------
    def face_strains(self):
        m = self.model
        return metrics.face_strains(m.positions(), m.uv, m.faces, m.grain, m.material_Dm_inv)

    def own_violation(self):
        """Per face, how far the current method's own constraints are violated (strain, 0 when
        they hold): the number strain limiting drives below ``strain.tol``. None when no
        method limits the strain."""
        if self.strain is None or not self.stage("strain_limit").enabled:
            return None
        if self._watched is not None:          # this frame's limits watch measured them
            watched, self._watched = self._watched, None
            return watched
        own = self.strain.constraint_values()
        if not own.size:
            return np.zeros(self.model.n_faces)
        return np.max(np.maximum(own, 0.0), axis=1)

    def metrics_row(self):
        """One row of metrics.csv for the current frame (column names fixed; see README):
        ``ms_total`` is the frame's wall time and ``ms_<stage>`` each stage's share of it
        (every stage, 0 when off). With the "metrics" stage on the rest was measured inside
        the frame, else it is measured now."""
        if self._row is not None and self._row[0] == self.frame:
            values = self._row[1]
        else:
            values = self._metrics_values()
        m = self.model
        row = {"frame": self.frame, "time": round(self.time, 9), "vertices": m.n_verts,
               "faces": m.n_faces, "ms_total": self.frame_ms}
        for s in self.stages:
            row[f"ms_{s.name}"] = s.ms
        row.update(values)
        return row

    def _measure(self):
        """Stage "metrics": the frame's row of metrics.csv, measured inside the frame."""
        self._row = (self.frame + 1, self._metrics_values())

    def _metrics_values(self):
        """metrics_row's columns after the timings."""
        m = self.model
        x, v = m.positions(), m.velocities()
        st = metrics.face_strains(x, m.uv, m.faces, m.grain, m.material_Dm_inv)
        area = m.rest_area
        row = {}
        row["kinetic_energy"] = metrics.kinetic_energy(v, m.mass)
        # Kinetic + elastic + gravitational (J): what metrics.energy_drift reads.
        row["total_energy"] = (row["kinetic_energy"] + self.dynamics.energy()
                               + metrics.gravitational_energy(x, m.mass,
                                                              self.settings.sim.gravity))
        for name in ("warp", "weft"):
            row[f"{name}_strain_max"], row[f"{name}_strain_rms"] = metrics.summarize(st[name], area)
        row["nan"] = int(not (np.all(np.isfinite(x)) and np.all(np.isfinite(v))))
        row["method"] = self.method
        on = self.strain is not None and self.stage("strain_limit").enabled
        row["sl_iterations"] = self.strain.last_iterations if on else 0
        # The stationarity the frame's last strain-limiting step reached (m/s: its Newton step
        # at the answer over h; under the exact solve, below 1 cm/s when it converged).
        row["sl_stationarity"] = self._sl_stationarity if on else 0.0
        own_v = self.own_violation()
        row["own_violation_max"], row["own_violation_rms"] = metrics.summarize(
            np.zeros(m.n_faces) if own_v is None else own_v, area)
        row["bias_strain_max"], row["bias_strain_rms"] = metrics.summarize(st["bias"], area)
        row["cg_iterations"] = self.dynamics.last_cg_iters
        row["cg_preconditioner"] = self.dynamics.last_preconditioner
        return row
