"""The interactive app as a state machine, separate from the window: every panel control, key
and mouse gesture of ``ui/app.py`` is one method here, so tests drive it without a display.

One ``AppState`` holds one simulator, or three in the comparison view (the same scene with
the methods svd, warp-weft and mapping side by side). Controls that change settings apply to
every simulator; ``switch_method`` applies to the single view only. The state changes a
simulator only through its public controls (``Simulator.set_*``, ``hold_vertex``, ``reset``);
it keeps no copy of the settings: the controls read and write ``Simulator.settings``
(``AppState.settings``), and the simulators are rebuilt from it.

    state = AppState.from_scene("hanging")
    state.switch_method("mapping"); state.set_band("warp", hi=0.02)
    state.tick()                     # one frame unless paused
    v = state.pick_ray(origin, direction)[1]
    state.begin_drag(0, v); state.drag(point); state.tick(); state.end_drag()
"""
import copy
import traceback

import numpy as np

from cloth import metrics
from cloth.simulator import SimulationDiverged, Simulator
from cloth.strain.families import METHODS
from cloth.backend import LoopCapError

COMPARE_METHODS = METHODS                  # the three families, without "none"
BANDS = ("warp", "weft", "bias")
# What each method bounds, one line for the panel: the read-outs then show the violation of
# these constraints (the number the solver drives below strain.tol) and the warp, weft and
# bias strains as strains, which only warp-weft bounds directly.
LIMITS = {
    "svd": "bounds the principal stretches (the larger by the warp band, the smaller by the "
           "weft band), blind to the grain",
    "warp-weft": "bounds the stretch along the warp and weft threads and the bias shear",
    "mapping": "bounds the principal stretches mapped onto the grain: the warp may reach "
               "sqrt(2) x its band at 45 deg",
    "none": "limits nothing: the cloth stretches as its material lets it",
}
MATERIAL_KEYS = ("k_warp", "k_weft", "k_shear", "k_bend", "damp_mass", "damp_stiff")


def readout_lines(r, width=40):
    """The panel's lines for one simulator's ``AppState.readouts`` (at most ``width``
    characters, the read-out column's width): what the method bounds, the violation of its
    own constraints against the tolerance, the iterations, then the strains with their bands."""
    import textwrap
    lines = textwrap.wrap(f"{r['method']}: {r['limits']}", width, subsequent_indent="  ")
    if r["own_violation"] is not None:
        mx = r["own_violation"][0]
        lines.append(f"own limits {'held' if mx <= r['tol'] else 'NOT HELD'}: max {mx:.1e} "
                     f"(tol {r['tol']:.0e})")
    lines.append(f"SL rounds {r['sl_iterations']}  CG {r['cg_iterations']} it "
                 f"({r['cg_preconditioner']})")
    lines.append(f"{'strain %':8s}{'min':>6s}{'max':>7s}{'rms':>6s}  band")
    for name in BANDS:
        lo, hi = r["bands"][name]
        lines.append(f"{name:8s}{100 * r['strain_min'][name]:+6.2f}"
                     f"{100 * r['strain_max'][name]:+7.2f}{100 * r['strain_rms'][name]:6.2f}"
                     f"  {100 * lo:+.1f}..{100 * hi:+.1f}")
    return lines


def build_simulator(module, cfg):
    setup = module.build(cfg)
    return Simulator(setup, cfg)


class AppState:
    def __init__(self, sim, cfg, module, compare=False):
        self.module = module
        self.scene_name = cfg.get("scene", getattr(module, "__name__", "scene").split(".")[-1])
        self.compare = compare
        self.color = cfg["output"]["color"]
        self.wireframe = False
        self.smooth = True
        self.paused = False
        self.message = ""           # last error or notice, shown in the panel
        self.failed = False         # the simulation diverged or a stage raised: reset first
        self._defer_tick = False    # skip one tick: the panel shows a compile notice first
        self.render_ms = 0.0
        self.fps = 0.0
        self.overlays = set()       # the teaching view's "axes" and "plot" (ui/overlays.py)
        self.selected = None        # (sim index, face) picked in the teaching view
        self.grab = None            # (sim index, vertex) while a vertex is held
        self.grab_target = None
        self._strain_cache = {}
        # The method the single view returns to from the comparison view (which runs all three).
        self.single_method = cfg["strain"]["method"]
        self._install(sim, cfg)

    @classmethod
    def from_scene(cls, name, overrides=(), compare=False):
        import scenes
        from scenes.common import resolve
        module = scenes.get(name)
        cfg = resolve(module.DEFAULTS, list(overrides))
        cfg["scene"] = name
        sim = None if compare else build_simulator(module, cfg)
        return cls(sim, cfg, module, compare=compare)

    # -- building -----------------------------------------------------------------------------
    def _install(self, sim, cfg):
        """Adopt ``sim`` (or build the three comparison simulators) for ``cfg``."""
        if self.compare:
            self.sims = []
            for m in COMPARE_METHODS:
                c = copy.deepcopy(cfg)
                c["strain"]["method"] = m
                self.sims.append(build_simulator(self.module, c))
        else:
            self.sims = [sim if sim is not None else build_simulator(self.module, cfg)]
        self.offsets = self._layout()
        self.grab = None
        self.selected = None
        self._strain_cache.clear()

    def _layout(self):
        """World offsets of the simulators: side by side along x in the comparison view."""
        if len(self.sims) == 1:
            return [np.zeros(3)]
        x = self.sims[0].model.positions()
        width = max(np.ptp(x[:, 0]), np.ptp(x[:, 2]), 0.2)
        gap = 1.35 * width
        k = len(self.sims)
        return [np.array([(i - (k - 1) / 2) * gap, 0.0, 0.0]) for i in range(k)]

    @property
    def sim(self):
        return self.sims[0]

    @property
    def labels(self):
        """Each simulator's method, as the views label them."""
        return [s.method for s in self.sims]

    @property
    def settings(self):
        """The settings in force (``Simulator.settings``: every simulator shares them, but for
        the method in the comparison view). The panel reads its controls from here."""
        return self.sim.settings

    def _settings_dict(self):
        """The nested dict the simulators are rebuilt from: the settings in force, with the
        single view's method."""
        cfg = self.settings.to_dict()
        cfg["strain"]["method"] = self.single_method if self.compare else self.sim.method
        return cfg

    def _each(self, fn):
        """Apply ``fn(sim)`` to every simulator; a ValueError becomes the panel message."""
        try:
            for s in self.sims:
                fn(s)
            return True
        except (ValueError, ImportError) as err:
            self.message = str(err)
            return False

    # -- time ---------------------------------------------------------------------------------
    def pause(self):
        self.paused = True

    def resume(self):
        if self.failed:
            return      # a diverged run must be reset first
        self.paused = False

    def toggle_pause(self):
        self.resume() if self.paused else self.pause()

    def tick(self):
        """One window frame: advance the simulation one frame unless paused (or, once, after
        a method switch that compiles: that frame shows the notice first)."""
        if self._defer_tick:
            self._defer_tick = False
            return
        if not self.paused:
            self._advance()
            if self.message.startswith("compiling"):
                self.message = ""

    def step(self):
        """Advance exactly one frame (the single-step button); pauses."""
        self.paused = True
        if not self.failed:
            self._advance()

    def _advance(self):
        for i, s in enumerate(self.sims):
            try:
                s.step_frame()
            except SimulationDiverged as err:
                self.paused = self.failed = True
                self.message = f"diverged ({self.labels[i]}): {err}. Press reset."
                return False
            except LoopCapError as err:   # the driver, not the cloth: its whole message names
                self.paused = self.failed = True       # the fix, so it is shown whole
                self.message = f"{err}."
                return False
            except Exception as err:   # a stage failed: keep the window, show why, pause
                traceback.print_exc()
                self.paused = self.failed = True
                first = str(err).strip().splitlines()
                self.message = (f"stage error ({self.labels[i]}): {type(err).__name__}"
                                f" {first[0][:160] if first else ''} (traceback on stderr). "
                                "Press reset.")
                return False
            if self.grab is not None and self.grab[0] == i:
                self.grab = (i, s.held_vertex)      # renumbered by a remesh
        self._strain_cache.clear()
        return True

    def reset(self):
        """Restart the scene with the current settings (method, bands, sliders kept). The
        simulators reload the scene's initial mesh into their arrays; if that fails they are
        rebuilt."""
        self.end_drag()
        self.message, self.failed = "", False
        try:
            for s in self.sims:
                s.reset()
        except Exception:       # anything unexpected: the slow, sure way
            traceback.print_exc()
            self._install(None, self._settings_dict())
        self._strain_cache.clear()

    def switch_scene(self, name):
        """Load another scene with its defaults (the colour mode is kept)."""
        import scenes
        from scenes.common import resolve
        try:
            module = scenes.get(name)
            cfg = resolve(module.DEFAULTS, [])
        except (KeyError, ValueError) as err:
            self.message = str(err).strip("'\"")
            return False
        cfg["scene"] = name
        self.module, self.scene_name = module, name
        self.single_method = cfg["strain"]["method"]
        self.message, self.failed = "", False
        self._install(None, cfg)
        return True

    @property
    def fabric(self):
        """The measured fabric the material and bands came from (``set_fabric``), or None."""
        from cloth import fabrics
        preset = self.settings.material.preset
        return preset if preset in fabrics.names() else None

    def set_fabric(self, name):
        """Restart the scene in fabric ``name``: its material and its derived bands
        (cloth/fabrics.py); the method, the damping and the other settings are kept. The
        cloth is rebuilt, since its mass and its bending ratio are read when it is built."""
        from cloth import fabrics
        from cloth.config import ConfigError
        try:
            cfg = fabrics.apply_fabric(self._settings_dict(), name)
            cfg["scene"] = self.scene_name
            self._install(None, cfg)
        except (ConfigError, ValueError) as err:
            self.message = str(err)
            return False
        self.message, self.failed = f"fabric {name}: material and bands from its data", False
        return True

    def set_compare(self, on):
        """Switch between the single view and the comparison view (svd, warp-weft and mapping
        side by side) of the current scene with the current settings; both restart at frame 0.
        Returns False (and says why in ``message``) when the simulators cannot be built."""
        on = bool(on)
        if on == self.compare:
            return True
        cfg = self._settings_dict()
        if on:
            self.single_method = cfg["strain"]["method"]
        self.compare, self.message, self.failed = on, "", False
        try:
            self._install(None, cfg)
        except ValueError as err:
            self.compare = not on
            self.message = str(err)
            return False
        return True

    # -- strain limiting ----------------------------------------------------------------------
    def switch_method(self, name):
        """Switch the strain-limiting method live (next substep). Single view only."""
        if self.compare:
            self.message = "the comparison view runs all three methods"
            return False
        ok = self._each(lambda s: s.set_method(name))      # an unknown name: the message
        if ok:
            line = self.sim.compile_pending()
            if line is not None:
                # Shown for one window frame before the step that compiles (the window does
                # not respond while Taichi compiles).
                self.message = line.replace("loom: ", "") + "; the window waits until it is done"
                self._defer_tick = True
        return ok

    @property
    def method(self):
        return "compare" if self.compare else self.sim.method

    def bands(self):
        """Current (warp, weft, bias) bands; bias from the automatic rule when auto."""
        return self.sim.bands()

    def set_band(self, which, lo=None, hi=None):
        """Move one edge (or both) of the warp, weft or bias band; min stays <= 0 <= max.
        Changing bias turns off its automatic value."""
        if which not in BANDS:
            raise ValueError(f"band must be one of {BANDS}")
        old = self.bands()[which]
        lo = old[0] if lo is None else min(float(lo), 0.0)
        hi = old[1] if hi is None else max(float(hi), 0.0)
        lo = max(lo, -0.9)
        ok = self._each(lambda s: s.set_bands(**{which: (lo, hi)}))
        self._strain_cache.clear()
        return ok

    @property
    def auto_bias(self):
        """Whether the bias band follows the warp and weft bands (settings strain.bias = [])."""
        return not self.settings.strain.bias

    def set_auto_bias(self, on=True):
        """The bias band follows the warp and weft bands again, or (off) stays where it is
        now, as an explicit band."""
        bias = "auto" if on else self.bands()["bias"]
        return self._each(lambda s: s.set_bands(bias=bias))

    def set_rounds(self, n):
        return self._each(lambda s: s.set_rounds(max(1, int(n))))

    @property
    def exact_solve(self):
        return self.settings.strain.solve == "exact"

    def set_exact_solve(self, on):
        """Each projection solved to its minimiser (strain.solve "exact") or stopped once the
        limits hold ("fast", the default): 2x to several hundred times slower."""
        return self._each(lambda s: s.set_strain_solve("exact" if on else "fast"))

    # -- time step and material ---------------------------------------------------------------
    def set_substeps(self, n):
        return self._each(lambda s: s.set_substeps(max(1, int(n))))

    def set_material(self, key, value):
        """Change a stiffness or damping live (the dynamics reads the material every step)."""
        if key not in MATERIAL_KEYS:
            raise ValueError(f"material key must be one of {MATERIAL_KEYS}")
        changes = {key: float(value)}
        mat = self.settings.material
        if key == "k_bend" and mat.k_bend > 0:
            # An orthotropic plate (a fabric's k_bend_warp / k_bend_weft) keeps its ratio: the
            # slider scales both directions (a live change of the ratio is refused).
            for k in ("k_bend_warp", "k_bend_weft"):
                if getattr(mat, k) > 0:
                    changes[k] = getattr(mat, k) * changes["k_bend"] / mat.k_bend
        return self._each(lambda s: s.set_material(**changes))

    # -- optional stages ----------------------------------------------------------------------
    @property
    def has_remesh(self):
        return "remesh" in self.settings

    @property
    def remesh_on(self):
        return self.settings.remesh.enabled

    def set_remesh(self, on):
        if not self.has_remesh:
            self.message = "this scene has no remeshing settings"
            return False
        return self._each(lambda s: s.set_remesh(on))

    @property
    def has_self_collision(self):
        return any(s.can_self_collide for s in self.sims)

    @property
    def self_collision_on(self):
        return self.sim.self_collision_on

    def set_self_collision(self, on):
        if not self.has_self_collision:
            self.message = "this scene has no self-collision"
            return False
        return self._each(lambda s: s.set_self_collision(on))

    # -- teaching view ------------------------------------------------------------------------
    def toggle_overlay(self, name):
        """Switch the principal-axes strokes ("axes") or the strain-space plot ("plot")."""
        from .overlays import OVERLAYS
        if name not in OVERLAYS:
            raise ValueError(f"overlay must be one of {OVERLAYS}")
        self.overlays.symmetric_difference_update({name})

    def select(self, hit):
        """Select a triangle ``(sim index, face)`` to highlight in both views; None clears."""
        if hit is not None:
            i, f = int(hit[0]), int(hit[1])
            if not (0 <= i < len(self.sims) and 0 <= f < self.sims[i].model.n_faces):
                raise ValueError(f"no face {f} in simulator {i}")
            hit = (i, f)
        self.selected = hit

    # -- picking and dragging -----------------------------------------------------------------
    def world_positions(self, i):
        return self.sims[i].model.positions() + self.offsets[i]

    def pick_ray(self, origin, direction, max_dist=None):
        """The cloth vertex nearest to a world ray (drawn positions, comparison offsets
        included): (sim index, vertex) or None if none lies within ``max_dist`` of the ray
        (default: 3 % of the cloth size). Among close vertices the nearest to the eye wins."""
        o = np.asarray(origin, float)
        d = np.asarray(direction, float)
        d = d / np.linalg.norm(d)
        best = None
        for i in range(len(self.sims)):
            x = self.world_positions(i)
            rel = x - o
            t = rel @ d
            perp = np.linalg.norm(rel - t[:, None] * d, axis=1)
            lim = max_dist if max_dist is not None else 0.03 * max(np.ptp(x, axis=0).max(), 0.1)
            ok = (perp < lim) & (t > 0)
            if not ok.any():
                continue
            cand = np.flatnonzero(ok)
            # Front-most: within a small depth window of the nearest hit, take the closest to
            # the ray.
            tmin = t[cand].min()
            front = cand[t[cand] < tmin + lim]
            v = int(front[np.argmin(perp[front])])
            if best is None or t[v] < best[2]:
                best = (i, v, t[v])
        return None if best is None else best[:2]

    def begin_drag(self, i, v):
        """Hold vertex ``v`` of simulator ``i``: it becomes a pin that follows ``drag``."""
        if self.grab is not None:
            self.end_drag()
        self.grab = (i, int(v))
        self.grab_target = self.world_positions(i)[v]
        self.sims[i].hold_vertex(v, self.grab_target - self.offsets[i])

    def drag(self, point):
        """Move the held vertex's target to ``point`` (world, as drawn)."""
        if self.grab is None:
            return
        i, v = self.grab
        self.grab_target = np.asarray(point, float)
        self.sims[i].hold_vertex(v, self.grab_target - self.offsets[i])

    def end_drag(self):
        """Release: the vertex gets back its own pin state and target."""
        if self.grab is None:
            return
        self.sims[self.grab[0]].release_vertex()
        self.grab = None
        self.grab_target = None

    def drag_plane_point(self, origin, direction):
        """Where a ray meets the plane through the held point facing the ray (for mouse
        drags); None if nothing is held."""
        if self.grab is None:
            return None
        o, d = np.asarray(origin, float), np.asarray(direction, float)
        p = self.grab_target
        n = d / np.linalg.norm(d)
        t = (p - o) @ n
        return o + t * n / max(n @ n, 1e-12)

    # -- read-outs ----------------------------------------------------------------------------
    def strains(self, i=0):
        """Face strains of simulator ``i`` (cached until the next frame or band change)."""
        key = (i, self.sims[i].frame)
        if key not in self._strain_cache:
            self._strain_cache[key] = self.sims[i].face_strains()
        return self._strain_cache[key]

    def own_violation(self, i=0):
        """Per-face violation of simulator ``i``'s own constraints (None without a method;
        cached like ``strains``)."""
        key = ("own", i, self.sims[i].frame, self.sims[i].method)
        if key not in self._strain_cache:
            self._strain_cache[key] = self.sims[i].own_violation()
        return self._strain_cache[key]

    def readouts(self, i=0):
        """Numbers for the panel: frame, time, faces, stage and render times, iterations (and
        the dynamics' CG preconditioner), the violation of the method's own constraints (max
        and area-weighted RMS, strain; None without a method) with what the method bounds, and
        the warp, weft and bias strains (min, max, area-weighted RMS)."""
        s = self.sims[i]
        st = self.strains(i)
        area = s.model.rest_area
        b = self.bands()
        out = {"frame": s.frame, "time": s.time, "faces": s.model.n_faces,
               "vertices": s.model.n_verts, "method": s.method,
               "stage_ms": {st_.name: st_.ms for st_ in s.stages if st_.enabled},
               "sim_ms": s.frame_ms,
               "render_ms": self.render_ms, "fps": self.fps,
               "sl_iterations": s.strain.last_iterations if s.strain is not None
               and s.stage("strain_limit").enabled else 0,
               "cg_iterations": s.dynamics.last_cg_iters,
               "cg_preconditioner": s.dynamics.last_preconditioner}
        own = self.own_violation(i)
        out["own_violation"] = None if own is None else metrics.summarize(own, area)
        out["tol"] = s.settings.strain.tol
        out["limits"] = LIMITS[s.method]
        out["bands"] = b
        out["strain_max"] = {n: float(np.max(st[n])) for n in BANDS}
        out["strain_min"] = {n: float(np.min(st[n])) for n in BANDS}
        out["strain_rms"] = {n: metrics.weighted_rms(st[n], area) for n in BANDS}
        return out
