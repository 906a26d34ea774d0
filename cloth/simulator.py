"""The frame loop: a flat list of named stages, each switchable and timed (ARCSim style).

    every substep:  pins -> dynamics -> collision -> strain_limit -> collision_final
    every frame:    remesh -> metrics

A scene enables only the stages it needs. With obstacles and strain limiting both on, the
contacts are constraints of the strain projection (half-spaces found by the collision stage), so
the projection cannot push cloth into a body and contact cannot undo the limits; the
``collision_final`` stage then runs the obstacle pass once more to remove what the half-spaces'
linearisation leaves on curved bodies (issue #5; tested in tests/test_all_scenes.py). Seams
(stitch pairs) are equality constraints of the same projection.

``Simulator.set_method`` and ``set_bands`` switch strain limiting live: they take effect at the
next substep.
"""
import sys
import time
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np
import taichi as ti

from . import metrics
from .dynamics import DynamicsSettings, ImplicitEuler
from .model import CapacityExceeded, ClothModel, Material, MeshArrays
from .strain.constraints import METHODS

STRAIN_METHODS = METHODS + ("none",)


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


@dataclass
class Stage:
    name: str
    run: Callable
    enabled: bool = True
    per_substep: bool = True
    ms: float = 0.0            # time spent in the current frame


@ti.data_oriented
class Simulator:
    def __init__(self, setup: SceneSetup, cfg: dict):
        self.cfg = cfg
        self.setup = setup
        sim = cfg["sim"]
        if not sim["fps"] > 0 or not sim["substeps"] >= 1:
            raise ValueError(f"the time step must be positive: sim.fps ({sim['fps']}) must be "
                             f"> 0 and sim.substeps ({sim['substeps']}) >= 1")
        self.h = 1.0 / (sim["fps"] * sim["substeps"])
        self.substeps = int(sim["substeps"])
        self.frame, self.time = 0, 0.0
        self.grow_count = 0
        self.model = ClothModel(setup.mesh, setup.material,
                                capacity_factor=self._capacity_factor(setup.mesh, cfg))
        self._pin_rest = setup.mesh.pin_target.copy()
        self.dynamics_settings = DynamicsSettings(
            gravity=tuple(sim["gravity"]), stitch_stiffness=float(sim.get("stitch_stiffness", 0.0)),
            cg_tol=float(sim.get("cg_tol", 1e-4)), cg_max_iters=int(sim.get("cg_iters", 500)))
        self.dynamics = self._make_dynamics(setup.stitches)
        self.strain = None
        self.collider = None
        self.remesher = None
        self.stages = [
            Stage("dynamics", self._dynamics_step),
            Stage("collision", self._collide, enabled=bool(setup.obstacles) or setup.self_collision),
            Stage("strain_limit", self._strain_limit, enabled=False),
            Stage("collision_final", self._collide_final, enabled=False),
            Stage("remesh", self._remesh, enabled=False, per_substep=False),
        ]
        strain = cfg.get("strain")
        if strain is not None and strain["method"] != "none":
            self._make_strain_limiter(strain)
        if self.stage("collision").enabled:
            self._make_collider()
        if cfg.get("remesh", {}).get("enabled", False):
            self._make_remesher(cfg["remesh"])
        self._relax_initial_state()
        self.last_good = self.model.mesh_arrays()
        self.remesh_stats = {}

    def can_restart(self, setup: SceneSetup, cfg: dict):
        """Whether ``restart`` may reuse this Simulator for ``setup``: the same mesh topology,
        no stitches, self-collision, moving obstacles or remeshing (their solvers hold state
        that ``restart`` does not reset; obstacles must be equal, which the caller knows)."""
        m = self.model
        return (len(setup.mesh.uv) == m.n_verts and len(setup.mesh.faces) == m.n_faces
                and np.array_equal(setup.mesh.faces, m.faces) and setup.stitches is None
                and self.setup.stitches is None and not setup.self_collision
                and all(o.path is None for o in setup.obstacles)
                and not cfg.get("remesh", {}).get("enabled", False) and self.remesher is None)

    def restart(self, setup: SceneSetup, cfg: dict):
        """Start again from ``setup``'s initial state with the settings of ``cfg`` without
        compiling anything: state, pins, material, time step, dynamics and strain-limiting
        settings, clock. Everything a run carries over (the CG warm start, the AL multipliers)
        is reset, so a restarted run repeats a run on a fresh Simulator bit for bit
        (tests/test_benchmarks.py). The obstacles stay those this Simulator was built with.
        Raises ValueError where ``can_restart`` is False."""
        if not self.can_restart(setup, cfg):
            raise ValueError("restart needs the same mesh and no stitches, self-collision, "
                             "moving obstacles or remeshing: build a new Simulator")
        s_cfg, st_cfg = cfg["sim"], cfg.get("strain", {"method": "none"})
        self.cfg, self.setup = cfg, setup
        self.model.material = setup.material          # load() recomputes the masses from it
        self.model.load(setup.mesh)
        self._pin_rest = setup.mesh.pin_target.copy()
        ds = self.dynamics.settings                   # the object the dynamics reads each step
        ds.gravity = tuple(s_cfg["gravity"])
        ds.cg_tol, ds.cg_max_iters = float(s_cfg["cg_tol"]), int(s_cfg["cg_iters"])
        self.dynamics.on_mesh_changed()               # forgets the CG warm start
        self.substeps = int(s_cfg["substeps"])
        self.h = 1.0 / (s_cfg["fps"] * self.substeps)
        self.frame, self.time = 0, 0.0
        if st_cfg["method"] != "none":
            self.set_method(st_cfg["method"])         # builds the limiter if there was none
            lim = self.strain
            lim.solver, lim.tol, lim.max_iters = st_cfg["solver"], float(st_cfg["tol"]), \
                int(st_cfg["iters"])
            lim.mapping_iso = float(st_cfg.get("isotropy", lim.mapping_iso))
            lim._explicit_bias = bool(st_cfg["bias"])
            lim.set_coupling(st_cfg.get("coupling", "projection"))
            lim.linear_solver = st_cfg.get("linear_solver", "pcg")
            lim.set_bands(warp=st_cfg["warp"], weft=st_cfg["weft"],
                          bias=st_cfg["bias"] if st_cfg["bias"] else None)
            lim.on_mesh_changed()                     # multipliers back to zero
        elif self.strain is not None:
            self.set_method("none")
        self._relax_initial_state()
        self.last_good = self.model.mesh_arrays()
        self.remesh_stats = {}
        return self

    @staticmethod
    def _capacity_factor(mesh, cfg, cap_faces=200_000):
        """Spare room in the fields. With remeshing, room for the finest mesh the sizing
        allows (2.5 x the count of equilateral triangles of edge size_min that tile it), so a
        refining cloth rarely outgrows its fields (growing means recompiling the kernels)."""
        rcfg = cfg.get("remesh", {})
        if not rcfg.get("enabled", False):
            return 1.2
        from .metrics import material_areas
        area = material_areas(mesh.uv, mesh.faces).sum()
        finest = 2.5 * area / (0.433 * rcfg["size_min"] ** 2)
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
        kind = self.cfg["sim"].get("linear_solver", "cg")
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

    def _make_strain_limiter(self, strain):
        # imported here: scenes may not limit strain
        from .strain.constraints import MAPPING_ISO
        from .strain.solver import StrainLimiter
        self.strain = StrainLimiter(
            self.model, method=strain["method"], warp=tuple(strain["warp"]),
            weft=tuple(strain["weft"]), bias=tuple(strain["bias"]) if strain["bias"] else None,
            solver=strain["solver"], tol=strain["tol"], max_iters=strain["iters"],
            mapping_iso=strain.get("isotropy", MAPPING_ISO), stitches=self.dynamics.stitches_np,
            coupling=strain.get("coupling", "projection"),
            linear_solver=strain.get("linear_solver", "pcg"))
        self._enable_strain_limit(strain["method"] != "none")

    def _enable_strain_limit(self, on):
        self.stage("strain_limit").enabled = on
        self.stage("collision_final").enabled = on and bool(self.setup.obstacles)

    def _dynamics_step(self):
        """The implicit step. Under coupling "implicit" its matrix then becomes the strain
        projection's metric (cloth/system_matrix.py)."""
        self.dynamics.step(self.h)
        if self.strain is not None and self.strain.coupling == "implicit" and \
                self.stage("strain_limit").enabled:
            self.dynamics.system_matrix(self.h, self.strain.system_metric())

    def _strain_limit(self):
        self._project_limits(self.h, self.time + self.h)

    def _project_limits(self, h, t, warm=True):
        """Strain projection with the obstacles' contacts at time t as constraints."""
        with_contacts = self.collider is not None and bool(self.collider.obstacles)
        if with_contacts:
            # Reach: half an edge, about the most a projection moves a vertex in one substep
            # (measured on drape at 10 cm edges: with a 5 mm reach the final obstacle pass had
            # to push by 8.6 mm, undoing the limits by 1.5e-2; with 5 cm it pushed nothing).
            self.collider.contact_planes(t, self.strain.contact_planes,
                                         reach=0.5 * self._contact_scale(),
                                         mu_out=self.strain.contact_friction)
        self.strain.project(h, contacts=with_contacts, warm=warm)

    def _make_collider(self):
        from .collision import Collider
        c = self.cfg.get("collision", {})
        self.collider = Collider(self.model, self.setup.obstacles,
                                 thickness=c.get("thickness", 0.005),
                                 self_collision=self.setup.self_collision)

    def _collide(self):
        self.collider.resolve(self.h, self.time)

    def _collide_final(self, max_rounds=3):
        """The obstacle pass after the projection. Where it still has to move a vertex by more
        than the strain tolerance (a vertex beyond the planes' reach pulled into a body, a
        concave corner of it), project again with the contacts as they are now, and repeat."""
        tol_m = self.strain.tol * self._contact_scale()
        for _ in range(max_rounds):
            if self.collider.resolve_obstacles(self.h, self.time) <= tol_m:
                return
            self._project_limits(self.h, self.time + self.h, warm=False)
        self.collider.resolve_obstacles(self.h, self.time)

    def _contact_scale(self):
        """The typical edge length (m): sqrt of the mean rest area."""
        m = self.model
        return float(np.sqrt(np.mean(m.rest_area[:m.n_faces])))

    def _make_remesher(self, rcfg):
        from . import remesh
        params = remesh.RemeshParams(**{k: v for k, v in rcfg.items() if k != "enabled"})
        params.validate()
        self.remesher = (remesh, params)
        self.stage("remesh").enabled = True

    def _remesh(self):
        remesh, params = self.remesher
        mesh = self.model.mesh_arrays()
        obstacle_distance = self._obstacle_distance if self.setup.obstacles else None
        face_data = self.strain.face_state() if self.strain is not None and \
            params.warm_multipliers else None
        # Pins and seam vertices are frozen: never removed or moved, seams never split.
        frozen = mesh.pinned.copy()
        stitches = self.dynamics.stitches_np
        if len(stitches):
            frozen[stitches.ravel()] = True
        new, new_face_data, stats = remesh.remesh(mesh, params, obstacle_distance=obstacle_distance,
                                                  face_data=face_data, frozen_verts=frozen)
        if len(stitches):
            self.dynamics.stitches_np = stats["vertex_map"][stitches].astype(np.int32)
        try:
            self.model.load(new)
            stats["grown"] = False
        except CapacityExceeded:
            self._rebuild_for(new)
            stats["grown"] = True
        self.remesh_stats = stats
        self.dynamics.on_mesh_changed()
        if self.strain is not None:
            self.strain.set_stitches(self.dynamics.stitches_np)
            self.strain.on_mesh_changed()
            if new_face_data:           # only with remesh.warm_multipliers (off: slower)
                self.strain.set_face_state(new_face_data)
        if self.collider is not None:
            self.collider.on_mesh_changed()
        # Flips and collapses change some triangles' deformation; project once more so the
        # limits hold on the new mesh at the end of every frame (nearly free when they do).
        if self.strain is not None and self.stage("strain_limit").enabled:
            self._project_limits(self.h, self.time)

    def _obstacle_distance(self, points):
        """Signed distance of world points to the nearest obstacle now (for remeshing)."""
        return np.min([o.sdf(points, self.time)[0] for o in self.setup.obstacles], axis=0)

    def _rebuild_for(self, mesh):
        """The remeshed cloth outgrew the fields: build a model with twice the room and new
        solver objects around it (their kernels compile anew against the new fields)."""
        self.grow_count += 1
        print(f"loom: remeshing grew the cloth to {len(mesh.faces)} faces; reallocating fields "
              f"with room for {2 * len(mesh.faces)} (grown {self.grow_count}x)", file=sys.stderr)
        self.model = ClothModel(mesh, self.setup.material, capacity_factor=2.0)
        self.dynamics = self._make_dynamics(self.dynamics.stitches_np)
        if self.strain is not None:
            self._make_strain_limiter(self.cfg["strain"])
        if self.collider is not None:
            self._make_collider()

    # -- live switches ------------------------------------------------------------------------
    def set_method(self, name):
        """Switch strain limiting (``svd``, ``warp-weft``, ``mapping`` or ``none``); it takes
        effect at the next substep."""
        if name not in STRAIN_METHODS:
            raise ValueError(f"unknown strain-limiting method '{name}': use one of "
                             f"{', '.join(STRAIN_METHODS)}")
        if self.strain is None and name != "none":
            self._make_strain_limiter(dict(self.cfg["strain"], method=name))
        elif self.strain is not None:
            self.strain.set_method(name)
        self.cfg["strain"]["method"] = name
        self._enable_strain_limit(name != "none")

    def set_bands(self, warp=None, weft=None, bias=None):
        if self.strain is None:
            self._make_strain_limiter(self.cfg["strain"])
        self.strain.set_bands(warp=warp, weft=weft, bias=bias)
        for key, val in (("warp", warp), ("weft", weft), ("bias", bias)):
            if val is not None:
                self.cfg["strain"][key] = list(val)

    @property
    def method(self):
        return self.cfg["strain"]["method"] if self.stage("strain_limit").enabled else "none"

    # -- the frame loop -----------------------------------------------------------------------
    def _update_pins(self, t):
        if self.setup.pin_motion is None:
            return
        pinned = self.model.pinned
        if not np.any(pinned):
            return
        targets = self.model.vert_pin_target.to_numpy()[: self.model.n_verts].astype(np.float64)
        targets[pinned] = self.setup.pin_motion(t, self.model.uv[pinned], self._pin_rest_of())
        self.model.set_pin_targets(targets)

    def _pin_rest_of(self):
        """Rest positions of the pinned vertices (the scene's initial targets), looked up by
        material point so they survive remeshing."""
        uv0 = self.setup.mesh.uv[self.setup.mesh.pinned]
        rest0 = self._pin_rest[self.setup.mesh.pinned]
        uv = self.model.uv[self.model.pinned]
        d = np.linalg.norm(uv[:, None, :] - uv0[None, :, :], axis=2)
        return rest0[np.argmin(d, axis=1)]

    def step_frame(self):
        """Advance one frame (``substeps`` time steps and the per-frame stages)."""
        for s in self.stages:
            s.ms = 0.0
        for _ in range(self.substeps):
            self._update_pins(self.time + self.h)
            for s in self.stages:
                if s.enabled and s.per_substep:
                    self._run_stage(s)
            self.time += self.h
        for s in self.stages:
            if s.enabled and not s.per_substep:
                self._run_stage(s)
        self.frame += 1
        self.last_good = self.model.mesh_arrays()

    def _run_stage(self, s):
        t0 = time.perf_counter()
        s.run()
        ti.sync()
        s.ms += 1000.0 * (time.perf_counter() - t0)
        if not self.model.all_finite(self.model.n_verts):
            raise SimulationDiverged(self.frame + 1, s.name)

    # -- metrics ------------------------------------------------------------------------------
    def face_strains(self):
        m = self.model
        return metrics.face_strains(m.positions(), m.uv, m.faces, m.grain)

    def metrics_row(self):
        """One row of metrics.csv for the current frame (column names fixed; see README)."""
        m = self.model
        x, v = m.positions(), m.velocities()
        st = metrics.face_strains(x, m.uv, m.faces, m.grain)
        area = m.rest_area
        cfg_s = self.cfg.get("strain", {})
        row = {"frame": self.frame, "time": round(self.time, 9), "vertices": m.n_verts,
               "faces": m.n_faces,
               "ms_total": sum(s.ms for s in self.stages)}
        for s in self.stages:
            row[f"ms_{s.name}"] = s.ms
        row["kinetic_energy"] = metrics.kinetic_energy(v, m.mass)
        # Kinetic + elastic + gravitational (J): what metrics.energy_drift reads.
        row["total_energy"] = (row["kinetic_energy"] + self.dynamics.energy()
                               + metrics.gravitational_energy(x, m.mass,
                                                              self.cfg["sim"]["gravity"]))
        for name in ("warp", "weft"):
            row[f"{name}_strain_max"], row[f"{name}_strain_rms"] = metrics.summarize(st[name], area)
        row["nan"] = int(not (np.all(np.isfinite(x)) and np.all(np.isfinite(v))))
        row["method"] = self.method
        row["sl_iterations"] = self.strain.last_iterations if self.strain is not None and \
            self.stage("strain_limit").enabled else 0
        own = self.strain.constraint_values() if self.strain is not None and \
            self.stage("strain_limit").enabled else np.zeros((m.n_faces, 1))
        own_v = np.max(np.maximum(own, 0.0), axis=1) if own.size else np.zeros(m.n_faces)
        row["own_violation_max"], row["own_violation_rms"] = metrics.summarize(own_v, area)
        row["bias_strain_max"] = float(np.max(np.abs(st["bias"])))
        warp_band = tuple(cfg_s.get("warp", (-np.inf, np.inf)))
        weft_band = tuple(cfg_s.get("weft", (-np.inf, np.inf)))
        row["warp_violation_max"] = float(np.max(metrics.band_violation(st["warp"], warp_band)))
        row["weft_violation_max"] = float(np.max(metrics.band_violation(st["weft"], weft_band)))
        row["cg_iterations"] = self.dynamics.last_cg_iters
        return row
