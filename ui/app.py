"""The interactive GGUI app: the 3-D view, the control panel, mouse and keys. All decisions
live in ``ui.state.AppState``; this module only turns window input into its method calls and
draws (through ``ui.render``, the same code as headless frames).

Mouse (outside the panel):
    right drag          orbit around the target        shift + right drag / middle drag: pan
    ctrl + right drag   zoom (up: closer)               ctrl or shift + left drag: grab cloth
    left click          select a triangle (on the cloth or its point in the strain-space
                        plot): highlighted in both; a click on nothing clears it
    hover               with the teaching view on, the triangle under the cursor is
                        outlined (magenta) in both views
Keys:
    space pause/run   n single step   r reset simulation   v reset view   z / x zoom in / out
    w wireframe   s smooth/flat   c next colour mode   m next method   p screenshot
    o record on/off   1..8 colour modes   a principal axes   g strain-space plot   esc quit

Environment: LOOM_APP_FRAMES=N quits after N window frames and prints frame-time statistics
(used for measurements and smoke tests); LOOM_APP_NO_VSYNC=1 disables vsync.

"""
import os
import sys
import textwrap
import time

import numpy as np
import taichi as ti

from cloth.strain.families import STRAIN_METHODS

from .colormap import COLOR_MODES
from .layout import (CHAR, CHROME, GAP, PAD, TEXT_ROW, WIDGET_ROW, Accordion, measure,
                     panel_height, wrap_width)
from .overlays import Layout, TeachingLayer, pick_face
from .render import ClothRenderer, draw_cloth, fit_window, open_window
from .state import AppState, readout_lines

COLUMN = 0.26          # the control column (left) and the view column (right): window fraction
BAR_HEIGHT = 0.022     # the colour bar's height (window fraction), above its legend
# The teaching view (x0, y0, x1, y1 bottom-up): the strain-space plot under the cloth, the
# binding key in the right column below the read-outs; the cloth moves up while the plot shows.
PLOT = (0.265, 0.005, 0.735, 0.41)
KEY = (0.745, 0.01, 0.995, 0.31)
VIEW_WITH_PLOT = ((0.30, 0.70), (0.44, 0.97))
# A running strain-space plot is rebuilt every PLOT_EVERY-th window frame (the frames between
# redraw it as it was; docs/teaching.md, Cost); the hovered face is looked up again as often
# while the cloth moves under a still cursor, and at once when the cursor moves.
PLOT_EVERY = 3
SHORT = {"pins": "pins", "dynamics": "dyn", "self_collision": "self", "collision": "coll",
         "strain_limit": "limit", "collision_final": "coll2", "contact_reproject": "reproj",
         "remesh": "remesh", "remesh_reproject": "reproj2", "metrics": "metrics",
         "snapshot": "snap"}
COLOR_LABELS = {"shading": "shading", "warp-strain": "warp strain", "weft-strain": "weft strain",
                "bias-strain": "bias strain", "principal-strain": "max principal strain",
                "violation": "own-limit violation", "size": "triangle size",
                "binding": "binding constraint"}


def moved(new, old):
    """Did the user move a slider? GGUI's sliders hand back float32, so an untouched one
    differs from the double it was given in the last digits."""
    return abs(new - old) > 1e-5 * max(1.0, abs(old))


def sized(title, rect, size_px):
    """A sub-window's name for its place and size: GGUI sets a sub-window's place and size
    only when it first appears (ImGui's 'once'), so a panel that must grow or shrink is a new
    ImGui window, told apart by the text after '##' (not shown)."""
    W, H = size_px
    x, y, w, h = (int(round(v * s)) for v, s in zip(rect, (W, H, W, H)))
    return f"{title}##{x}.{y}.{w}.{h}"


class Recorder:
    """Frames of the 3-D view to PNG files, and to video.mp4 (imageio) when stopped."""

    def __init__(self, folder, fps):
        self.folder, self.fps, self.count = folder, fps, 0
        os.makedirs(folder, exist_ok=True)

    def add(self, img):
        import imageio.v2 as imageio
        imageio.imwrite(os.path.join(self.folder, f"frame_{self.count:04d}.png"), img)
        self.count += 1

    def close(self):
        if self.count == 0:
            return None
        import imageio.v2 as imageio
        path = os.path.join(self.folder, "video.mp4")
        with imageio.get_writer(path, fps=self.fps, macro_block_size=8, quality=7) as w:
            for k in range(self.count):
                w.append_data(imageio.imread(os.path.join(self.folder, f"frame_{k:04d}.png")))
        return path


class App:
    def __init__(self, state: AppState, size=None, out_dir="out"):
        # Always a shown window: GGUI's panel crashes in an offscreen window (tests drive the
        # app under Xvfb, see tests/test_app.py).
        self.state = state
        vsync = not os.environ.get("LOOM_APP_NO_VSYNC")
        self.window = open_window("Loom", fit_window(size), show_window=True, vsync=vsync)
        self.renderer = ClothRenderer(self.window, state.sim.setup.camera)
        self.gui = self.window.get_gui()
        self.out_dir = out_dir
        self.recorder = None
        self.mouse = None          # (mode, last cursor) while a camera drag is on
        self.frame_times = []      # ms per window frame
        self.render_times = []     # ms of drawing, panel and show per window frame
        self.parts = []            # (draw, panel, show) ms per window frame
        self.sim_times = []        # ms of simulation per window frame
        self.frames_shown = 0
        self._last = time.perf_counter()
        self.teach = TeachingLayer(state.overlays, refresh_every=PLOT_EVERY)
        self._hover_at = None      # (cursor, simulator frames) the hover was found for
        # The columns' sections (ui/layout.py); closed ones show their header only.
        self.left = Accordion(["run", "strain", "dynamics", "fabric"])
        self.right = Accordion(["colour", "readouts"])
        self._legend_lines = 1
        self.place()
        self.reset_view()

    # -- view ---------------------------------------------------------------------------------
    def layout(self):
        """Where the plot panels (one pair per simulator, side by side under the cloths) and
        the binding key go."""
        n = len(self.state.sims)
        x0, y0, x1, y1 = PLOT
        w = (x1 - x0) / n
        boxes = [(x0 + k * w + 0.002, y0, x0 + (k + 1) * w - 0.002, y1) for k in range(n)]
        return Layout(plot=boxes, key=KEY, bar=self.bar)

    def toggle_overlay(self, name):
        self.state.toggle_overlay(name)
        self.teach.on = set(self.state.overlays)
        if name == "plot":
            self.reset_view()

    def reset_view(self):
        r = self.renderer
        r.set_camera_cfg(self.state.sim.setup.camera)
        if "plot" in self.state.overlays:
            # The cloth(s) above the plot, between the panels.
            pts = np.concatenate([self.state.world_positions(i)
                                  for i in range(len(self.state.sims))])
            r.orbit.fit(pts, r.aspect, *VIEW_WITH_PLOT)
            r.orbit.home = (r.orbit.position.copy(), r.orbit.target.copy(), r.orbit.fov)
        elif len(self.state.sims) > 1:
            # Fit the three cloths between the panels, looking from the scene's direction.
            pts = np.concatenate([self.state.world_positions(i)
                                  for i in range(len(self.state.sims))])
            r.orbit.fit(pts, r.aspect, x_range=(COLUMN + 0.01, 1 - COLUMN - 0.01),
                        y_range=(0.2, 0.8))
            r.orbit.home = (r.orbit.position.copy(), r.orbit.target.copy(), r.orbit.fov)
        r.orbit.apply(r.camera)

    def in_panel(self, pos):
        """Is the cursor over a panel (or the colour bar) rather than the 3-D view?"""
        x, yd = pos[0], 1 - pos[1]
        bx, by, bw, bh = self.bar
        return any(rx <= x <= rx + rw and ry <= yd <= ry + rh for rx, ry, rw, rh in self.rects) \
            or (bx <= x <= bx + bw and by - bh <= pos[1] <= by + 2 * bh)

    # -- input --------------------------------------------------------------------------------
    def handle_events(self):
        w, st = self.window, self.state
        pos = w.get_cursor_pos()
        for e in w.get_events(ti.ui.PRESS):
            key = e.key
            if key in (ti.ui.LMB, ti.ui.RMB, ti.ui.MMB):
                if key == ti.ui.LMB and self.teach.in_plot(pos):
                    self.select_at(pos)
                    continue
                if self.in_panel(pos):
                    continue
                mod_ctrl, mod_shift = w.is_pressed(ti.ui.CTRL), w.is_pressed(ti.ui.SHIFT)
                if key == ti.ui.LMB and not (mod_ctrl or mod_shift):
                    self.select_at(pos)
                elif key == ti.ui.LMB and (mod_ctrl or mod_shift):
                    o, d = self.renderer.orbit.ray(*pos, self.renderer.aspect)
                    hit = st.pick_ray(o, d)
                    if hit is not None:
                        st.begin_drag(*hit)
                        self.mouse = ("grab", pos)
                elif key == ti.ui.RMB:
                    mode = "zoom" if mod_ctrl else "pan" if mod_shift else "orbit"
                    self.mouse = (mode, pos)
                elif key == ti.ui.MMB:
                    self.mouse = ("pan", pos)
            elif key == ti.ui.ESCAPE:
                w.running = False
            elif key == " ":
                st.toggle_pause()
            elif key == "n":
                st.step()
            elif key == "r":
                self.reset_sim()
            elif key == "v":
                self.renderer.reset_camera()
            elif key == "a":
                self.toggle_overlay("axes")
            elif key == "g":
                self.toggle_overlay("plot")
            elif key == "z":
                self.renderer.orbit.zoom(0.85)
            elif key == "x":
                self.renderer.orbit.zoom(1 / 0.85)
            elif key == "w":
                st.wireframe = not st.wireframe
            elif key == "s":
                st.smooth = not st.smooth
            elif key == "c":
                st.color = COLOR_MODES[(COLOR_MODES.index(st.color) + 1) % len(COLOR_MODES)]
            elif key == "m" and not st.compare:
                st.switch_method(STRAIN_METHODS[(STRAIN_METHODS.index(st.sim.method) + 1)
                                                % len(STRAIN_METHODS)])
            elif key == "p":
                self.screenshot()
            elif key == "o":
                self.toggle_record()
            elif isinstance(key, str) and key in "12345678" and len(key) == 1:
                st.color = COLOR_MODES[int(key) - 1]
        for e in w.get_events(ti.ui.RELEASE):
            if e.key in (ti.ui.LMB, ti.ui.RMB, ti.ui.MMB) and self.mouse is not None:
                if self.mouse[0] == "grab" and e.key == ti.ui.LMB:
                    st.end_drag()
                    self.mouse = None
                elif self.mouse[0] != "grab" and e.key != ti.ui.LMB:
                    self.mouse = None
        if self.mouse is not None:
            mode, last = self.mouse
            dx, dy = pos[0] - last[0], pos[1] - last[1]
            orbit = self.renderer.orbit
            if mode == "orbit":
                orbit.orbit(dx, dy)
            elif mode == "pan":
                orbit.pan(dx, dy, self.renderer.aspect)
            elif mode == "zoom":
                orbit.zoom(float(np.exp(-2.0 * dy)))
            elif mode == "grab":
                o, d = orbit.ray(*pos, self.renderer.aspect)
                p = st.drag_plane_point(o, d)
                if p is not None:
                    st.drag(p)
            self.mouse = (mode, pos)
        self.hover_at(pos)

    def reset_sim(self):
        self.state.reset()

    def select_at(self, pos):
        """Select the triangle under the cursor: its point in the strain-space plot, else the
        cloth face the view ray hits first; nothing there clears the selection."""
        self.state.select(self.face_at(pos))
        self.teach.selected = self.state.selected

    def hover_at(self, pos):
        """Highlight the triangle under the cursor while the teaching view is on (an overlay
        or the binding map) and no drag is under way; looked up when the cursor moved, or
        every ``PLOT_EVERY`` frames while the cloth moves under it."""
        st = self.state
        if not (st.overlays or st.color == "binding") or self.mouse is not None or \
                not (0 <= pos[0] <= 1 and 0 <= pos[1] <= 1) or \
                (self.in_panel(pos) and not self.teach.in_plot(pos)):
            self.teach.hover, self._hover_at = None, None
            return
        frames = tuple(s.frame for s in st.sims)
        last = self._hover_at
        if last is not None and last[0] == tuple(pos) and (
                last[1] == frames or self.frames_shown - last[2] < PLOT_EVERY):
            return
        self._hover_at = (tuple(pos), frames, self.frames_shown)
        self.teach.hover = self.face_at(pos)

    def face_at(self, pos):
        """(simulator index, face) under the cursor or None: the face whose point in the
        strain-space plot is nearest, else the cloth face the view ray hits first."""
        hit = self.teach.pick_plot(pos)
        if hit is None and not self.teach.in_plot(pos):
            o, d = self.renderer.orbit.ray(*pos, self.renderer.aspect)
            best = None
            for i in range(len(self.state.sims)):
                x = self.state.world_positions(i)
                f = pick_face(x, self.state.sims[i].model.faces, o, d)
                if f is not None:
                    depth = np.linalg.norm(x[self.state.sims[i].model.faces[f]].mean(0) - o)
                    if best is None or depth < best[0]:
                        best = (depth, i, f)
            hit = None if best is None else best[1:]
        return hit

    # -- panel --------------------------------------------------------------------------------
    # -- panels -------------------------------------------------------------------------------
    def place(self):
        """Pixel sizes of this frame's columns: the control column on the left, the view
        column (colour modes and read-outs) on the right above the colour bar and its legend
        (or above the binding key); see ui/layout.py."""
        W, H = self.window.get_window_shape()
        self.size_px = (W, H)
        col = int(COLUMN * W)
        self.wrap = wrap_width(col)
        legend_h = panel_height((self._legend_lines + 1) * TEXT_ROW) \
            if self.state.color not in ("shading", "binding") else 0
        bar_h = int(BAR_HEIGHT * H)
        key_h = int(KEY[3] * H) if self.state.color == "binding" else 0
        bottom = legend_h + (2 * bar_h + GAP if legend_h else 0) + key_h
        self.right_room = H - bottom - GAP
        x0 = (W - col + PAD) / W
        self.bar = (x0, (legend_h + 0.5 * bar_h) / H, (col - 2 * PAD) / W, bar_h / H)
        self.legend_rect = ((W - col) / W, (H - legend_h) / H, col / W, legend_h / H)
        self.rects = []

    def _column(self, title, x_px, sections, accordion, room):
        """One sub-window of sections (name, header label, draw(gui)) at ``x_px``, as tall
        as its open sections (closing sections until it fits ``room`` px)."""
        g, (W, H) = self.gui, self.size_px
        heights = {name: measure(draw) for name, _, draw in sections}
        content = accordion.fit(heights, WIDGET_ROW * len(sections), room - CHROME + 4)
        rect = (x_px / W, 0.0, int(COLUMN * W) / W, min(panel_height(content), room) / H)
        self.rects.append(rect)
        with g.sub_window(sized(title, rect, self.size_px), *rect):
            for name, label, draw in sections:
                is_open = accordion.is_open(name)
                if g.button(f"[{'-' if is_open else '+'}] {label}"):
                    accordion.toggle(name)
                elif is_open:
                    draw(g)

    def panel(self):
        W, H = self.size_px
        self._column("Loom", 0, [("run", "scene and run", self._run_section),
                                 ("strain", "strain limiting", self._strain_section),
                                 ("dynamics", "dynamics", self._dynamics_section),
                                 ("fabric", "fabric", self._fabric_section)],
                     self.left, H)
        self._column("view", W - int(COLUMN * W),
                     [("colour", "colour and overlays", self._colour_section),
                      ("readouts", "read-outs", self.readouts)], self.right, self.right_room)

    def _text(self, g, text, color=None):
        """Text wrapped to the column (GGUI clips a long line)."""
        for line in textwrap.wrap(text, self.wrap, subsequent_indent="  ") or [""]:
            if color is None:
                g.text(line)
            else:
                g.text(line, color=color)

    def _run_section(self, g):
        st = self.state
        self._text(g, f"scene: {st.scene_name}" + ("   (comparison)" if st.compare else ""))
        import scenes
        for name in scenes.SCENES:
            if name != st.scene_name and g.button(f"load {name}"):
                if st.switch_scene(name):
                    self.reset_view()
        if g.button("run" if st.paused else "pause"):
            st.toggle_pause()
        if g.button("step one frame"):
            st.step()
        if g.button("reset simulation"):
            self.reset_sim()
        if g.button("reset view"):
            self.renderer.reset_camera()
        if g.button("stop recording" if self.recorder else "record"):
            self.toggle_record()
        if g.button("screenshot"):
            self.screenshot()
        if st.message:
            self._text(g, st.message[:300], color=(0.8, 0.1, 0.1))

    def _strain_section(self, g):
        st = self.state
        if st.compare:
            g.text("svd | warp-weft | mapping")
        if g.button("back to one method" if st.compare else "compare the three methods"):
            if st.set_compare(not st.compare):
                self.reset_view()
        if not st.compare:
            current = st.method
            for m in STRAIN_METHODS:
                if g.checkbox(m, m == current) and m != current:
                    st.switch_method(m)
        b = st.bands()
        for name in ("warp", "weft", "bias"):
            lo, hi = b[name]
            nlo = g.slider_float(f"{name} min %", 100 * lo, -20.0, 0.0) / 100
            nhi = g.slider_float(f"{name} max %", 100 * hi, 0.0, 20.0) / 100
            if moved(nlo, lo) or moved(nhi, hi):
                st.set_band(name, nlo, nhi)
        auto = g.checkbox("automatic bias band", st.auto_bias)
        if auto != st.auto_bias:
            st.set_auto_bias(auto)
        rounds = g.slider_int("SL rounds", int(st.settings.strain.rounds), 1, 200)
        if rounds != st.settings.strain.rounds:
            st.set_rounds(rounds)
        exact = g.checkbox("exact solve (slow)", st.exact_solve)
        if exact != st.exact_solve:
            st.set_exact_solve(exact)

    def _dynamics_section(self, g):
        st = self.state
        sub = g.slider_int("substeps", int(st.settings.sim.substeps), 1, 20)
        if sub != st.settings.sim.substeps:
            st.set_substeps(sub)
        mat = st.settings.material
        for key, lo, hi in (("k_warp", -1.0, 4.0), ("k_weft", -1.0, 4.0),
                            ("k_shear", -2.0, 3.0), ("k_bend", -8.0, -3.0)):
            old = np.log10(max(getattr(mat, key), 1e-12))
            new = g.slider_float(f"log10 {key}", old, lo, hi)
            if moved(new, old):
                st.set_material(key, 10 ** new)
        for key, hi in (("damp_mass", 2.0), ("damp_stiff", 0.02)):
            new = g.slider_float(key, float(getattr(mat, key)), 0.0, hi)
            if moved(new, getattr(mat, key)):
                st.set_material(key, new)
        if st.has_remesh:
            on = g.checkbox("remeshing", st.remesh_on)
            if on != st.remesh_on:
                st.set_remesh(on)
        if st.has_self_collision:
            on = g.checkbox("self-collision", st.self_collision_on)
            if on != st.self_collision_on:
                st.set_self_collision(on)

    def _fabric_section(self, g):
        """Measured fabrics (fabrics/*.toml): a click restarts the scene in that fabric, its
        material and bands derived from the data (docs/fabrics.md)."""
        from cloth import fabrics
        st = self.state
        self._text(g, f"now: {st.fabric or st.settings.material.preset + ' (preset)'}")
        for name in fabrics.names():
            if name != st.fabric and g.button(f"use {name}"):
                if st.set_fabric(name):
                    self.reset_view()

    def _colour_section(self, g):
        st = self.state
        g.text("colour (keys 1-8, c: next)")
        for m in COLOR_MODES:
            if g.checkbox(COLOR_LABELS[m], st.color == m):
                st.color = m
        for name, label in (("axes", "principal axes (a)"), ("plot", "strain-space plot (g)")):
            if g.checkbox(label, name in st.overlays) != (name in st.overlays):
                self.toggle_overlay(name)
        st.wireframe = g.checkbox("wireframe (w)", st.wireframe)
        st.smooth = g.checkbox("smooth shading (s)", st.smooth)

    def readouts(self, g):
        st = self.state
        for i in range(len(st.sims)):
            r = st.readouts(i)
            if i == 0:
                self._text(g, f"frame {r['frame']}  t = {r['time']:.2f} s  "
                              f"{r['faces']} faces")
                sim_ms = sum(st.readouts(k)['sim_ms'] for k in range(len(st.sims)))
                self._text(g, f"{self.fps():.1f} fps  render {st.render_ms:.1f} ms  "
                              f"sim {sim_ms:.1f} ms")
            if st.compare:
                continue      # per-method numbers sit under each cloth
            stages = "  ".join(f"{SHORT.get(k, k)} {v:.1f}" for k, v in r["stage_ms"].items())
            self._text(g, f"ms: {stages}")
            for line in readout_lines(r, self.wrap):
                g.text(line)

    def legend(self, lg):
        """The colour bar's title and band under the bar, and the tick labels each under its
        tick (the font is monospaced: a label is centred on its tick's character column)."""
        if lg is None:
            return
        g, (W, _) = self.gui, self.size_px
        self.rects.append(self.legend_rect)
        with g.sub_window(sized("legend", self.legend_rect, self.size_px), *self.legend_rect):
            edges = [m for m in lg.marks if m != 0.0]
            band = ("  band " + " .. ".join(lg.fmt(m) for m in edges)) if edges else ""
            head = lg.title + band + (f"  ({lg.note})" if lg.note else "")
            self._legend_lines = len(textwrap.wrap(head, self.wrap)) or 1
            self._text(g, head)
            # The bar spans the sub-window's text area exactly (``place``).
            g.text(lg.tick_line(int(self.bar[2] * W) // CHAR))

    def labels(self):
        """Method names above the three cloths of the comparison view."""
        st, orbit = self.state, self.renderer.orbit
        for i, label in enumerate(st.labels):
            x = st.world_positions(i)
            top = np.array([0.5 * (x[:, 0].min() + x[:, 0].max()), x[:, 1].max() + 0.08,
                            0.5 * (x[:, 2].min() + x[:, 2].max())])
            (sx, sy), = orbit.project(top[None], self.renderer.aspect)[0]
            r = st.readouts(i)
            w, h = 0.155, 0.16
            if 0 <= sx <= 1 and 0 <= sy <= 1:
                with self.gui.sub_window(label, float(np.clip(sx - w / 2, COLUMN, 1 - COLUMN - w)),
                                         float(np.clip(1 - sy - h, 0, 1 - h)), w, h):
                    sl = r["stage_ms"].get("strain_limit", 0.0)
                    self.gui.text(f"SL {r['sl_iterations']} it, {sl:.1f} ms")
                    if r["own_violation"] is not None:
                        self.gui.text(f"own violation {r['own_violation'][0]:.1e}")
                    for name in ("warp", "weft", "bias"):
                        self.gui.text(f"{name} strain max {100 * r['strain_max'][name]:+.2f}%")

    # -- drawing ------------------------------------------------------------------------------
    def draw(self):
        st, r = self.state, self.renderer
        r.begin()
        legend = None
        for i, s in enumerate(st.sims):
            strains = st.strains(i) if st.color not in ("shading", "size", "binding") else None
            lg = draw_cloth(r, s, f"cloth{i}", st.color, wireframe=st.wireframe,
                            smooth=st.smooth, offset=st.offsets[i], strains=strains,
                            plain="axes" in st.overlays)
            legend = legend or lg
        self.teach.selected = st.selected
        self.teach.draw_scene(r, st.sims, st.offsets)
        if st.grab is not None:
            i, v = st.grab[:2]
            x = st.world_positions(i)[v]
            size = np.ptp(st.world_positions(i), axis=0).max()
            r.add_points("grab", np.stack([x, st.grab_target]), 0.02 * size, (0.1, 0.75, 0.25))
        r.finish(legend, self.bar)
        self.teach.draw_frame(r, st.sims, st.labels, st.color, self.layout())
        return legend

    def screenshot(self, path=None):
        import imageio.v2 as imageio
        folder = os.path.join(self.out_dir, "screenshots")
        os.makedirs(folder, exist_ok=True)
        stamp = time.strftime("%Y%m%d_%H%M%S")
        path = path or os.path.join(
            folder, f"{self.state.scene_name}_{stamp}_f{self.state.sim.frame:04d}.png")
        self.draw()
        imageio.imwrite(path, self.renderer.image())
        self.state.message = f"screenshot: {path}"
        return path

    def toggle_record(self):
        st = self.state
        if self.recorder is None:
            folder = os.path.join(self.out_dir, "recordings",
                                  f"{st.scene_name}_{time.strftime('%Y%m%d_%H%M%S')}")
            self.recorder = Recorder(folder, st.settings.sim.fps)
            st.message = f"recording to {folder}/"
        else:
            path = self.recorder.close()
            st.message = f"recorded {self.recorder.count} frames" + (f": {path}" if path else "")
            self.recorder = None

    def fps(self):
        recent = self.frame_times[-30:]
        return 1000.0 / (sum(recent) / len(recent)) if recent else 0.0

    # -- the loop -----------------------------------------------------------------------------
    def frame(self):
        st = self.state
        self.handle_events()
        stepped_before = st.sim.frame
        ts = time.perf_counter()
        if self.frames_shown == 1 and st.message.startswith("compiling"):
            st.message = ""
        if self.frames_shown > 0:
            # The first window frame shows the initial state before the first step compiles
            # the kernels (tens of seconds for three simulators in the comparison view).
            st.tick()
        elif not st.message:
            st.message = "compiling the simulation kernels: the first step can take a while"
        self.frames_shown += 1
        t0 = time.perf_counter()
        self.sim_times.append(1e3 * (t0 - ts))
        self.place()
        legend = self.draw()
        if self.recorder is not None and st.sim.frame != stepped_before:
            self.recorder.add(self.renderer.image())
        t1 = time.perf_counter()
        self.panel()
        self.legend(legend)
        if st.compare:
            self.labels()
        t2 = time.perf_counter()
        self.window.show()
        now = time.perf_counter()
        st.render_ms = 1e3 * (now - t0)
        self.render_times.append(st.render_ms)
        self.parts.append((1e3 * (t1 - t0), 1e3 * (t2 - t1), 1e3 * (now - t2)))
        self.frame_times.append(1e3 * (now - self._last))
        st.fps = self.fps()
        self._last = now

    def run(self, max_frames=None):
        n = 0
        while self.window.running and (max_frames is None or n < max_frames):
            self.frame()
            n += 1
        if self.recorder is not None:
            self.toggle_record()
        return 0

    def stats(self, skip=10):
        """Mean window frame time, render time and simulation time (ms) after ``skip``
        warm-up frames."""
        ft = np.array(self.frame_times[skip:]) if len(self.frame_times) > skip else \
            np.array(self.frame_times)
        rt = np.array(self.render_times[skip:]) if len(self.render_times) > skip else \
            np.array(self.render_times)
        parts = np.array(self.parts[skip:] if len(self.parts) > skip else self.parts)
        return {"frames": len(ft), "frame_ms": float(ft.mean()) if ft.size else 0.0,
                "draw_ms": float(parts[:, 0].mean()) if parts.size else 0.0,
                "panel_ms": float(parts[:, 1].mean()) if parts.size else 0.0,
                "show_ms": float(parts[:, 2].mean()) if parts.size else 0.0,
                "render_ms": float(rt.mean()) if rt.size else 0.0,
                "fps": 1000.0 / float(ft.mean()) if ft.size else 0.0}


def final_checks(state):
    """The scene's final check of each simulator as the window closes, printed like a
    headless run's; True if every one held (a window run then exits 0, else 5, as headless
    runs do: a script driving the window, e.g. with LOOM_APP_FRAMES, can see a failure)."""
    held = True
    for label, sim in zip(state.labels, state.sims):
        if sim.setup.check_final is None or state.failed:
            continue
        ok, message = sim.setup.check_final(sim)
        held = held and ok
        print(f"final check ({label}): {'ok' if ok else 'FAILED'} ({message})")
    return held


def _run(state, make=None, size=None):
    max_frames = os.environ.get("LOOM_APP_FRAMES")
    app = App(state, size) if make is None else make(state)
    code = app.run(int(max_frames) if max_frames else None)
    if code == 0 and not final_checks(state):
        code = 5        # main.EXIT_CHECK_FAILED
    if max_frames:
        s = app.stats()
        share = 100 * s["render_ms"] / max(s["frame_ms"], 1e-9)
        print(f"loom: {s['frames']} window frames, {s['fps']:.1f} fps, "
              f"frame {s['frame_ms']:.1f} ms, render {s['render_ms']:.1f} ms ({share:.0f} %: "
              f"draw {s['draw_ms']:.1f}, panel {s['panel_ms']:.1f}, show {s['show_ms']:.1f}), "
              f"simulation {np.mean(app.sim_times[10:] or [0]):.1f} ms, "
              f"{state.sim.model.n_faces} faces", file=sys.stderr)
    return code


def _with_overlays(state, overlays):
    for name in overlays:
        state.toggle_overlay(name)
    return state


def run_app(sim, cfg, module, overlays=(), size=None):
    """The interactive window for one simulator (``overlays``: the teaching view's "axes",
    "plot" on from the start; ``size``: the window's (width, height), else it fits the
    screen). Raises ``RenderUnavailable`` (with a message that names the fix) when no window
    can be opened. Returns the exit code."""
    return _run(_with_overlays(AppState(sim, cfg, module), overlays), size=size)


def run_compare(cfg, module, overlays=(), size=None):
    """The comparison view: the same scene with svd, warp-weft and mapping side by side in
    one window, labelled, sharing every control."""
    return _run(_with_overlays(AppState(None, cfg, module, compare=True), overlays),
                size=size)


class TourApp(App):
    """The guided demo in the window (``ui/tour.py``): per method the sheet settles, then
    the tour pauses on each of its views with a caption until "next step" (key ``t``).
    Under ``LOOM_APP_FRAMES`` each pause lasts ``AUTO_HOLD`` window frames."""
    AUTO_HOLD = 15
    CAPTION = (PLOT[0], 0.86, PLOT[2], 1.0)

    def __init__(self, state, settle, **kw):
        from . import tour
        self.tour = tour
        self.plan = [p for stage in tour.STAGES for p in
                     [("settle", stage)] + [("pause", step) for step in tour.stage_steps(stage)]]
        self.settle, self.phase, self.held = settle, -1, 0
        self.caption, self.facts = "", None
        super().__init__(state, **kw)
        self.teach.fixed_axes = True          # each method's plot on axes that hold still
        self.advance()

    def advance(self):
        st = self.state
        self.phase = min(self.phase + 1, len(self.plan) - 1)
        kind, what = self.plan[self.phase]
        self.held = 0
        if kind == "settle":
            self.tour.start_stage(st, what)
            st.resume()
            st.color, st.overlays = "binding", {"plot"}
            label = f"{what[0]}, fabric {what[1]}" if what[1] else what[0]
            self.caption = (f"{label}: the sheet settles from the start; each triangle is a "
                            "point in strain space, coloured by the constraint that binds it.")
        else:
            st.pause()
            if self.facts is None or self.facts[0] != st.sim.frame:
                self.facts = (st.sim.frame, self.tour.facts(st.sim))
            self.tour._apply(st, what)
            n = sum(1 for k, _ in self.plan[:self.phase + 1] if k == "pause")
            self.caption = f"[{n}/{len(self.tour.STEPS)}] " + self.tour.caption(what,
                                                                             self.facts[1])
        self.teach.on = set(st.overlays)
        self.reset_view()

    def reset_view(self):
        super().reset_view()
        r = self.renderer
        pts = np.concatenate([self.state.world_positions(i) for i in range(len(self.state.sims))])
        r.orbit.fit(pts, r.aspect, VIEW_WITH_PLOT[0], (0.44, 0.84))

    def handle_events(self):
        if self.window.is_pressed("t") and not getattr(self, "_t_down", False):
            self.advance()
        self._t_down = self.window.is_pressed("t")
        super().handle_events()

    def frame(self):
        kind, _ = self.plan[self.phase]
        if kind == "settle" and self.state.sim.frame >= self.settle:
            self.advance()
        elif kind == "pause" and os.environ.get("LOOM_APP_FRAMES"):
            self.held += 1
            if self.held >= self.AUTO_HOLD:
                self.advance()
        super().frame()

    def draw(self):
        legend = super().draw()
        self.tour.draw_caption(self.renderer, self.caption, self.CAPTION)
        return legend

    def panel(self):
        super().panel()
        with self.gui.sub_window("tour", PLOT[0], 0.145, 0.16, 0.06):
            if self.gui.button("next step (t)"):
                self.advance()


def run_tour_window(state, settle):
    """The guided demo in a window (``python main.py --tour``)."""
    return _run(state, lambda st: TourApp(st, settle))
