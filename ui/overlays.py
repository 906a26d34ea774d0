"""Drawing the teaching view with GGUI (``ui/teaching.py`` computes it): the principal-axes
strokes in the 3-D scene, and on the canvas, over the scene, the strain-space plot and the
binding map's key. The canvas has no text, so labels are drawn as rectangles from a bitmap
font (``teaching.text_runs``): they appear in the window and in captures (headless frames,
screenshots) alike.

The window and headless frames both come through ``TeachingLayer.draw_scene`` (before the
scene is rendered) and ``TeachingLayer.draw_canvas`` (after).
"""
import itertools
from dataclasses import dataclass

import numpy as np

from cloth import metrics

from . import teaching
from .colormap import binding_colors
from .ggui_buffers import (draw_circles_2d, draw_lines, draw_triangles_2d, redraw_circles_2d,
                           redraw_triangles_2d)

INK = np.array([0.16, 0.16, 0.20])
GRID = np.array([0.80, 0.81, 0.84])
PANEL_BG = np.array([1.0, 1.0, 1.0])
REGION_FILL = np.array([0.86, 0.95, 0.86])
REGION_EDGE = np.array([0.10, 0.50, 0.15])
REFERENCE = np.array([0.55, 0.55, 0.60])
THREAD = (0.50, 0.50, 0.55)
HIGHLIGHT = np.array([0.05, 0.85, 0.95])
HOVER = np.array([0.85, 0.10, 0.85])       # the triangle under the cursor (magenta)
MARK_WIDTH = 3.0                           # pixels: principal strokes, face outlines
FAINT = np.array([0.30, 0.30, 0.36])       # thread strains behind the mapped ones
OVERLAYS = ("axes", "plot")


_TEXT_TRIS = {}
_LAYERS = itertools.count()      # each layer its own vertex buffers (it redraws them later)


class Canvas2D:
    """Batches canvas triangles (rectangles, strokes, text) and discs in window coordinates
    (0..1, y up), drawn in two calls."""

    def __init__(self, renderer):
        self.r = renderer
        w, h = renderer.window.get_window_shape()
        self.px = np.array([1.0 / w, 1.0 / h])
        self.tris, self.cols = [], []
        self.discs, self.disc_cols, self.disc_r = [], [], []

    def rect(self, x0, y0, x1, y1, color):
        p = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y0], [x1, y1], [x0, y1]])
        self.tris.append(p)
        self.cols.append(np.tile(color, (6, 1)))

    def rects(self, lo, hi, colors):
        """Many rectangles: corners lo, hi (n, 2), colours (n, 3)."""
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        if not len(lo):
            return
        a, c = lo, hi
        b, d = np.c_[hi[:, 0], lo[:, 1]], np.c_[lo[:, 0], hi[:, 1]]
        self.tris.append(np.stack([a, b, c, a, c, d], axis=1).reshape(-1, 2))
        self.cols.append(np.repeat(np.asarray(colors, float).reshape(-1, 3), 6, axis=0))

    def segment(self, p0, p1, color, width_px=1.0):
        """A stroke as a thin quad (canvas lines are not usable in Taichi 1.7.4's GGUI)."""
        p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
        d = (p1 - p0) / self.px
        n = np.array([-d[1], d[0]]) / max(np.linalg.norm(d), 1e-9) * 0.5 * width_px * self.px
        q = np.array([p0 - n, p1 - n, p1 + n, p0 - n, p1 + n, p0 + n])
        self.tris.append(q)
        self.cols.append(np.tile(color, (6, 1)))

    def outline(self, x0, y0, x1, y1, color, width_px=1.0):
        for a, b in (((x0, y0), (x1, y0)), ((x1, y0), (x1, y1)), ((x1, y1), (x0, y1)),
                     ((x0, y1), (x0, y0))):
            self.segment(a, b, color, width_px)

    def text(self, s, x, y, color=INK, size=12, anchor="left"):
        """Text with its top-left (or top-right, top-centre) corner at (x, y); its triangles
        are kept between frames (labels rarely change)."""
        key = (s, round(x, 6), round(y, 6), tuple(np.round(color, 3)), size, anchor,
               tuple(self.px))
        hit = _TEXT_TRIS.get(key)
        if hit is None:
            runs, (w, _) = teaching.text_runs(s, size)
            if anchor == "right":
                x -= w * self.px[0]
            elif anchor == "centre":
                x -= 0.5 * w * self.px[0]
            lo = np.c_[x + runs[:, 2] * self.px[0], y - runs[:, 1] * self.px[1]]
            hi = np.c_[x + runs[:, 3] * self.px[0], y - runs[:, 0] * self.px[1]]
            n0 = len(self.tris)
            self.rects(lo, hi, np.tile(color, (len(runs), 1)))
            hit = (self.tris[n0:], self.cols[n0:])
            if len(_TEXT_TRIS) > 4000:
                _TEXT_TRIS.clear()
            _TEXT_TRIS[key] = hit
            return
        self.tris += hit[0]
        self.cols += hit[1]

    def disc(self, xy, colors, radius_px, merge=False):
        """Discs of one radius (pixels). ``merge``: of discs with the same colour whose
        centres fall in the same half-pixel cell, only the last is kept (it covers the
        others but for a fraction of a pixel): dense clouds draw far fewer discs."""
        xy = np.asarray(xy, float).reshape(-1, 2)
        colors = np.asarray(colors, float).reshape(-1, 3)
        if merge and len(xy) > 1:
            keep = distinct_discs(xy, colors, self.px)
            xy, colors = xy[keep], colors[keep]
        self.discs.append(xy)
        self.disc_cols.append(colors)
        self.disc_r.append(radius_px)

    def geometry(self):
        """What ``flush`` draws: (triangle corners, their colours, disc centres, their
        colours, disc radii as fractions of the window's height); None for an empty part."""
        tris = (np.concatenate(self.tris), np.concatenate(self.cols)) if self.tris else None
        discs = None
        if self.discs:
            discs = (np.concatenate(self.discs), np.concatenate(self.disc_cols),
                     np.concatenate([np.full(len(d), rr * self.px[1])
                                     for d, rr in zip(self.discs, self.disc_r)]))
        return tris, discs

    def flush(self, key):
        draw_geometry(self.r, key, *self.geometry())


def distinct_discs(xy, colors, px, cell=0.5):
    """Indices (in drawing order) of the discs to draw: per half-pixel cell and colour the
    last one drawn."""
    q = np.floor(xy / (cell * px)).astype(np.int64) & 0xFFFF
    c = np.round(np.clip(colors, 0, 1) * 255).astype(np.int64)
    key = (q[:, 0] << 40) | (q[:, 1] << 24) | (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]
    _, first_rev = np.unique(key[::-1], return_index=True)
    return np.sort(len(key) - 1 - first_rev)


def draw_geometry(renderer, key, tris, discs):
    """Canvas triangles (one call), then discs (one call: GGUI's per-disc radius sits in the
    vertex's fourth slot), as ``Canvas2D.geometry`` gives them. Returns a function that draws
    the same again in a later frame without refilling the vertex buffers."""
    calls = []
    if tris is not None:
        vbo = draw_triangles_2d(renderer.canvas, renderer._buffers, key + ".tri", *tris)
        calls.append(lambda: redraw_triangles_2d(renderer.canvas, vbo))
    if discs is not None:
        dbo = draw_circles_2d(renderer.canvas, renderer._buffers, key + ".disc", *discs)
        rmax = float(np.max(discs[2]))
        calls.append(lambda: redraw_circles_2d(renderer.canvas, dbo, rmax))

    def again():
        for call in calls:
            call()
    return again


def plot_frame(panel, box, px):
    """The plot frame (x0, y0, x1, y1) inside a panel's window box, leaving room for the
    labels (``px``: one pixel in window fractions)."""
    x0, y0, x1, y1 = box
    return (x0 + 42 * px[0], y0 + 18 * px[1], x1 - 10 * px[0],
            y1 - (48 + 14 * len(panel.extra)) * px[1])


def to_window(panel, frame, pts):
    """Strains -> window coordinates inside ``frame``."""
    fx0, fy0, fx1, fy1 = frame
    u = panel.to_unit(pts)
    return np.c_[fx0 + u[:, 0] * (fx1 - fx0), fy0 + u[:, 1] * (fy1 - fy0)]


def draw_panel(cv, panel, box, highlight=None, title=True):
    """One strain-space panel in the window box (x0, y0, x1, y1), y up."""
    x0, y0, x1, y1 = box
    px, py = cv.px
    frame = plot_frame(panel, box, cv.px)
    fx0, fy0, fx1, fy1 = frame
    cv.rect(x0, y0, x1, y1, PANEL_BG)

    def to_win(pts):
        return to_window(panel, frame, pts)

    if panel.region is not None:
        (a, b), (c, d) = panel.region
        (wa, wc), (wb, wd) = to_win([[a, c], [b, d]])
        cv.rect(wa, wc, wb, wd, REGION_FILL)
    for v, horizontal in ((0.0, True), (0.0, False)):      # the zero lines
        if horizontal and panel.ylim[0] < v < panel.ylim[1]:
            (_, wy), = to_win([[panel.xlim[0], v]])
            cv.segment((fx0, wy), (fx1, wy), GRID)
        if not horizontal and panel.xlim[0] < v < panel.xlim[1]:
            (wx, _), = to_win([[v, panel.ylim[0]]])
            cv.segment((wx, fy0), (wx, fy1), GRID)
    if panel.diagonal:
        lo = max(panel.xlim[0], panel.ylim[0])
        hi = min(panel.xlim[1], panel.ylim[1])
        if hi > lo:
            (p, q) = to_win([[lo, lo], [hi, hi]])
            cv.segment(p, q, GRID, 1.0)
    if panel.reference is not None:
        (a, b), (c, d) = panel.reference
        (wa, wc), (wb, wd) = to_win([[a, c], [b, d]])
        cv.outline(wa, wc, wb, wd, REFERENCE, 1.0)
    if panel.region is not None:
        cv.outline(wa, wc, wb, wd, REGION_EDGE, 2.0)
    cv.outline(fx0, fy0, fx1, fy1, INK, 1.0)
    if panel.faint is not None and len(panel.faint):
        cv.disc(to_win(panel.faint), np.tile(FAINT, (len(panel.faint), 1)), 1.3, merge=True)
    cv.disc(to_win(panel.points), panel.colors, 2.0, merge=True)
    if highlight is not None:
        draw_marks(cv, panel, frame, highlight)
    # Labels: title and note above, ranges at the frame's ends, axis names.
    if title:
        cv.text(panel.title, x0 + 4 * px, y1 - 3 * py, INK, 12)
        cv.text(panel.note, x0 + 4 * px, y1 - 17 * py, REFERENCE * 0.8, 10)
        for k, line in enumerate(panel.extra):
            cv.text(line, x0 + 4 * px, y1 - (31 + 14 * k) * py, INK, 10)
    f = lambda v: f"{100 * v:+.3g}%"  # noqa: E731
    cv.text(f(panel.xlim[0]), fx0, fy0 - 3 * py, INK, 10)
    cv.text(f(panel.xlim[1]), fx1, fy0 - 3 * py, INK, 10, anchor="right")
    cv.text(panel.xlabel + " ->", 0.5 * (fx0 + fx1), fy0 - 3 * py, INK, 10, anchor="centre")
    cv.text(f(panel.ylim[0]), fx0 - 2 * px, fy0 + 10 * py, INK, 10, anchor="right")
    cv.text(f(panel.ylim[1]), fx0 - 2 * px, fy1, INK, 10, anchor="right")
    cv.text("^ " + panel.ylabel, fx0, fy1 + 14 * py, INK, 10)


def draw_marks(cv, panel, frame, face, hover=False):
    """Ring the points of ``face`` in a panel drawn in ``frame``: the selection (large), or
    the triangle under the cursor (``hover``: small)."""
    sel = np.nonzero(np.asarray(panel.faces) == face)[0]
    if len(sel):
        w = to_window(panel, frame, panel.points[sel])
        outer, inner = (4.5, 3.0) if hover else (6.0, 4.0)
        cv.disc(w, np.tile(INK, (len(sel), 1)), outer)
        cv.disc(w, np.tile(HOVER if hover else HIGHLIGHT, (len(sel), 1)), inner)


def draw_key(cv, title, entries, box):
    """The binding map's key: a swatch and a label per entry, from the box's top-left (the
    box shrinks to its entries)."""
    x0, y0, x1, y1 = box
    px, py = cv.px
    y0 = max(y0, y1 - (26 + 15 * len(entries)) * py)
    cv.rect(x0, y0, x1, y1, PANEL_BG)
    cv.outline(x0, y0, x1, y1, GRID)
    cv.text(title, x0 + 5 * px, y1 - 4 * py, INK, 11)
    for k, (label, rgb, count) in enumerate(entries):
        top = y1 - (20 + 15 * k) * py
        cv.rect(x0 + 6 * px, top - 10 * py, x0 + 18 * px, top, rgb)
        cv.text(label if count is None else f"{label} ({count})", x0 + 23 * px, top, INK, 10)


@dataclass
class Layout:
    """Where the teaching view goes in a window (fractions, y up): per simulator a box for
    its plot panels, the binding key's box, the colour bar (x, y, w, h) and the screen box
    the cloth is fitted into while the plot is shown."""
    plot: list
    key: tuple
    bar: tuple = (0.70, 0.075, 0.27, 0.025)
    view_x: tuple = (0.0, 1.0)
    view_y: tuple = (0.0, 1.0)


def frame_layout(overlays):
    """Headless frames: with the plot, the cloth in the left half and the two panels in the
    right half's lower part, the key above them; else the key at the top right. The key
    stays below the frame's caption strip (``render.caption``: at most 0.045 of the height)."""
    if "plot" in overlays:
        return Layout(plot=[(0.515, 0.01, 0.995, 0.62)], key=(0.60, 0.66, 0.93, 0.95),
                      bar=(0.04, 0.06, 0.40, 0.022), view_x=(0.04, 0.48), view_y=(0.10, 0.92))
    return Layout(plot=[], key=(0.71, 0.70, 0.995, 0.95))


class TeachingLayer:
    """The overlays of one window (or offscreen renderer): which are on, the selected face,
    the face under the cursor, per simulator the cached glyph sites (they change only with
    the mesh), and the canvas drawing of the last plot.

    The plot and the key are rebuilt only when what they show changed (the simulators'
    frames, methods, bands, the layout, the window's size); a window sets
    ``refresh_every = k`` to rebuild a running plot at most every k-th frame (the frames
    between redraw the kept vertex buffers: the plot lags the cloth by up to k - 1 frames).
    The selection and hover marks are drawn every frame on top."""

    def __init__(self, overlays=(), plot_rect=None, refresh_every=1):
        self.on = set(overlays)
        unknown = self.on - set(OVERLAYS)
        if unknown:
            raise ValueError(f"unknown overlay '{sorted(unknown)[0]}': use "
                             f"{', '.join(OVERLAYS)}")
        self.plot_rect = plot_rect            # (x0, y0, x1, y1) window fractions, y up
        self.selected = None                  # (simulator index, face)
        self.hover = None                     # (simulator index, face) under the cursor
        self.refresh_every = refresh_every
        self.fixed_axes = False               # the plot's axes only grow, per method (the tour)
        self._held = {}                       # method -> the plot's ranges so far
        self._sites = {}
        self._canvas = None                   # the last plot's keys, age and redraw call
        self._buffer_key = f"teach{next(_LAYERS)}"
        self.last_panels = {}                 # simulator index -> (panels, boxes)
        self._px = np.array([1e-3, 1e-3])      # one pixel in window fractions (last draw)

    def toggle(self, name):
        self.on.symmetric_difference_update({name})

    def _mesh_cache(self, i, sim):
        m = sim.model
        key = (i, id(m.faces), m.n_faces)
        if key not in self._sites:
            self._sites = {k: v for k, v in self._sites.items() if k[0] != i}
            sites, size = teaching.glyph_sites(m.uv, m.faces)
            self._sites[key] = (sites, size, metrics.material_Dm_inv(m.uv, m.faces))
        return self._sites[key]

    def draw_scene(self, renderer, sims, offsets):
        """The principal-axes strokes (3-D, before the scene is rendered), lifted off the
        side of the cloth that faces the camera, and the outlines of the selected and the
        hovered face. Every scene draw call costs GGUI about a millisecond a frame on
        software Vulkan whatever it holds, so the outlines go into the strokes' call."""
        eye = np.asarray(renderer.orbit.position, float)
        outlines = self._outlines(sims, offsets, eye)
        if "axes" in self.on:
            for i, sim in enumerate(sims):
                self._draw_axes(renderer, sim, i, offsets[i], eye,
                                outlines if i == len(sims) - 1 else None)
        elif outlines is not None:
            draw_lines(renderer.scene, renderer._buffers, "marks", outlines[0], (0, 0, 0),
                       width=MARK_WIDTH, colors=outlines[1])

    def _outlines(self, sims, offsets, eye):
        """The selected and the hovered face's edges as segments (points, colours), or None;
        moved 2 % of the way to the camera (the same place on screen, in front of the
        cloth)."""
        hover = self.hover if self.hover != self.selected else None
        pts, cols = [], []
        for mark, color in ((self.selected, HIGHLIGHT), (hover, HOVER)):
            if mark is None or mark[0] >= len(sims) or mark[1] >= sims[mark[0]].model.n_faces:
                continue                              # (remeshed since)
            i, m = mark[0], sims[mark[0]].model
            tri = m.positions()[m.faces[mark[1]]] + offsets[i]
            tri += 0.02 * (eye - tri)
            pts.append(np.concatenate([tri, tri[[1, 2, 0]]], axis=1).reshape(-1, 3))
            cols.append(np.tile(color, (6, 1)))
        return (np.concatenate(pts), np.concatenate(cols)) if pts else None

    def _draw_axes(self, renderer, sim, i, offset, eye, outlines=None):
        m = sim.model
        sites, size, Dm_inv = self._mesh_cache(i, sim)
        x = m.positions() + offset
        g = teaching.axis_glyphs(x, m.faces, Dm_inv, m.grain, sites, size, sim.bands())
        t = x[m.faces[sites]]
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        # The side seen from the camera (the cloth hides the other): half the strokes of
        # drawing both sides. Two draw calls for all: the threads with the ground grid, the
        # principal strokes with the outlines.
        n *= np.where(np.einsum("ij,ij->i", n, eye - g["centroids"]) < 0, -1.0, 1.0)[:, None]
        off = (0.06 * size * n)[:, None, None, :]
        thr = (g["grain"].reshape(-1, 2, 2, 3) + off).reshape(-1, 3)
        renderer.add_thin_lines(thr, THREAD)          # in the ground grid's draw call
        pr = (g["principal"].reshape(-1, 2, 2, 3) + 1.5 * off).reshape(-1, 3)
        col = np.repeat(g["principal_colors"], 2, axis=0)
        if outlines is not None:
            pr, col = np.concatenate([pr, outlines[0]]), np.concatenate([col, outlines[1]])
        draw_lines(renderer.scene, renderer._buffers, f"axes{i}.pr", pr, (0, 0, 0),
                   width=MARK_WIDTH, colors=col)

    def _keys(self, renderer, sims, labels, color, layout, want_plot):
        """What the canvas shows besides the simulators' states, and their states."""
        px = tuple(1.0 / np.asarray(renderer.window.get_window_shape(), float))
        per_sim = []
        for s in sims:
            iso = s.strain.isotropy if s.strain is not None else 0.0
            on = s.strain is not None and s.stage("strain_limit").enabled
            per_sim.append((id(s), id(s.model), s.model.n_faces, s.method,
                            repr(sorted(s.bands().items())), iso, on))
        shown = (id(renderer), px, bool(want_plot), color, tuple(labels), tuple(per_sim),
                 None if layout is None else (tuple(layout.plot), layout.key))
        return shown, tuple((s.frame, s.time) for s in sims)

    def draw_canvas(self, renderer, sims, labels, binds, boxes=None, key_box=None,
                    key_entries=None, key_title=""):
        """The strain-space plot (one pair of panels per simulator, in ``boxes``: per
        simulator a (x0, y0, x1, y1) window box for its two panels) and the binding key,
        after the scene is rendered (on top of it). Returns a function that draws the same
        again."""
        cv = Canvas2D(renderer)
        self._px = cv.px
        self.last_panels = {}
        if "plot" in self.on and boxes is not None:
            for i, sim in enumerate(sims):
                m = sim.model
                _, _, Dm_inv = self._mesh_cache(i, sim)
                iso = sim.strain.isotropy if sim.strain is not None else 0.0
                panels, _ = teaching.strain_plot(sim.method, m.positions(), m.faces, Dm_inv,
                                                 m.grain, sim.bands(), iso, binds[i],
                                                 held=self._held.setdefault(sim.method, {})
                                                 if self.fixed_axes else None)
                x0, y0, x1, y1 = boxes[i]
                if len(sims) == 1:      # side by side
                    mid = 0.5 * (x0 + x1)
                    sub = [(x0, y0, mid - 0.003, y1), (mid + 0.003, y0, x1, y1)]
                else:                   # stacked under each cloth
                    mid = 0.5 * (y0 + y1)
                    sub = [(x0, mid + 0.004, x1, y1), (x0, y0, x1, mid - 0.004)]
                for p, b in zip(panels, sub):
                    if len(sims) > 1:
                        p.title = f"{labels[i]}: {p.title}"
                    draw_panel(cv, p, b)
                self.last_panels[i] = (panels, sub)
        if key_entries is not None and key_box is not None:
            draw_key(cv, key_title, key_entries, key_box)
        return draw_geometry(renderer, self._buffer_key, *cv.geometry())

    def draw_frame(self, renderer, sims, labels, color, layout):
        """Everything on the canvas for one frame: the plot (if on) and, in the binding
        colour mode, its key (rebuilt when they changed, see the class), then the selection
        and hover marks."""
        want_plot = "plot" in self.on and layout is not None and layout.plot
        shown, states = self._keys(renderer, sims, labels, color, layout, want_plot)
        c = self._canvas
        if c is not None and c["shown"] == shown and (c["states"] == states or
                                                      c["age"] + 1 < self.refresh_every):
            if c["states"] != states:
                c["age"] += 1
            c["again"]()
        else:
            again = self._build(renderer, sims, labels, color, layout, want_plot)
            self._canvas = {"shown": shown, "states": states, "age": 0, "again": again}
        self._draw_plot_marks(renderer)

    def _build(self, renderer, sims, labels, color, layout, want_plot):
        binds = [teaching.binding(s) if (want_plot or color == "binding") else None
                 for s in sims]
        entries, title = None, ""
        if color == "binding" and layout is not None:
            entries = []
            for s, lab, b in zip(sims, labels, binds):
                _, key = binding_colors(s.method, b, s.model.n_faces)
                pre = f"{lab}: " if len(sims) > 1 else ""
                entries += [(pre + name, rgb, n) for name, rgb, n in key
                            if len(sims) == 1 or not name.startswith("free")]
            title = ("binding constraint (largest multiplier)" if len(sims) == 1 else
                     "binding constraint per method (grey: free)")
        elif layout is not None and len(sims) == 1 and ("axes" in self.on or want_plot):
            entries, title = self.marks_key(sims[0], binds[0], want_plot), "key"
        return self.draw_canvas(renderer, sims, labels, binds,
                                layout.plot if want_plot else None,
                                layout.key if layout is not None else None, entries, title)

    def marks_key(self, sim, bind, plot):
        """The key of the principal axes' strokes and of the plot's dots and box (the binding
        map has its own key): (label, colour, count or None)."""
        from .teaching import GLYPH_COMPRESSION, GLYPH_STRETCH
        entries = []
        if "axes" in self.on:
            entries += [("stretch axis", GLYPH_STRETCH[-1][1], None),
                        ("compression axis", GLYPH_COMPRESSION[-1][1], None),
                        ("warp and weft threads", np.asarray(THREAD), None)]
        if plot:
            _, key = binding_colors(sim.method, bind, sim.model.n_faces)
            entries += [("dot: " + name, rgb, n) for name, rgb, n in key]
            if sim.method == "mapping":
                entries.append(("dark dot: thread strains", FAINT, None))
            if sim.method in ("svd", "warp-weft", "mapping"):
                entries.append(("box: feasible region", REGION_EDGE, None))
            if sim.method in ("svd", "none"):
                entries.append(("outline: bands, not bounded", REFERENCE, None))
        return entries

    def _draw_plot_marks(self, renderer):
        """The selected and the hovered face's points in the plot, ringed."""
        cv = Canvas2D(renderer)
        hover = self.hover if self.hover != self.selected else None
        for mark, is_hover in ((hover, True), (self.selected, False)):
            if mark is None or mark[0] not in self.last_panels:
                continue
            panels, boxes = self.last_panels[mark[0]]
            for p, b in zip(panels, boxes):
                draw_marks(cv, p, plot_frame(p, b, self._px), mark[1], is_hover)
        if cv.discs:
            cv.flush(self._buffer_key + ".marks")

    # -- picking ------------------------------------------------------------------------------
    def pick_plot(self, pos, radius_px=8):
        """The face whose plotted point is nearest the cursor (window fractions, y up) within
        ``radius_px`` pixels: (simulator index, face) or None."""
        best = None
        for i, (panels, boxes) in self.last_panels.items():
            for p, (x0, y0, x1, y1) in zip(panels, boxes):
                if not (x0 <= pos[0] <= x1 and y0 <= pos[1] <= y1):
                    continue
                w = to_window(p, plot_frame(p, (x0, y0, x1, y1), self._px), p.points)
                d = np.linalg.norm((w - np.asarray(pos)) / self._px, axis=1)
                k = int(np.argmin(d))
                if d[k] <= radius_px and (best is None or d[k] < best[0]):
                    best = (d[k], i, int(p.faces[k]))
        return None if best is None else (best[1], best[2])

    def in_plot(self, pos):
        return any(x0 <= pos[0] <= x1 and y0 <= pos[1] <= y1
                   for _, boxes in self.last_panels.values() for (x0, y0, x1, y1) in boxes)


def pick_face(x, faces, origin, direction):
    """The face a world ray hits first (Moller-Trumbore over all faces), or None."""
    x = np.asarray(x, float)
    a, b, c = x[faces[:, 0]], x[faces[:, 1]], x[faces[:, 2]]
    e1, e2 = b - a, c - a
    d = np.asarray(direction, float)
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-14
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = np.asarray(origin, float) - a
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    v = (q @ d) * inv
    t = np.einsum("ij,ij->i", e2, q) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    if not hit.any():
        return None
    t = np.where(hit, t, np.inf)
    return int(np.argmin(t))
