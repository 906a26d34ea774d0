"""Drawing the teaching view with GGUI (``ui/teaching.py`` computes it): the principal-axes
strokes in the 3-D scene, and on the canvas, over the scene, the strain-space plot and the
binding map's key. The canvas has no text, so labels are drawn as rectangles from a bitmap
font (``teaching.text_runs``): they appear in the window and in captures (headless frames,
screenshots) alike.

The window and headless frames both come through ``TeachingLayer.draw_scene`` (before the
scene is rendered) and ``TeachingLayer.draw_canvas`` (after).
"""
from dataclasses import dataclass

import numpy as np

from cloth import metrics

from . import teaching
from .colormap import binding_colors
from .ggui_buffers import draw_circles_2d, draw_lines, draw_triangles_2d

INK = np.array([0.16, 0.16, 0.20])
GRID = np.array([0.80, 0.81, 0.84])
PANEL_BG = np.array([1.0, 1.0, 1.0])
REGION_FILL = np.array([0.86, 0.95, 0.86])
REGION_EDGE = np.array([0.10, 0.50, 0.15])
REFERENCE = np.array([0.55, 0.55, 0.60])
THREAD = (0.50, 0.50, 0.55)
HIGHLIGHT = np.array([0.05, 0.85, 0.95])
FAINT = np.array([0.30, 0.30, 0.36])       # thread strains behind the mapped ones
OVERLAYS = ("axes", "plot")


_TEXT_TRIS = {}


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
            lo = np.c_[x + runs[:, 1] * self.px[0], y - (runs[:, 0] + 1) * self.px[1]]
            hi = np.c_[x + runs[:, 2] * self.px[0], y - runs[:, 0] * self.px[1]]
            n0 = len(self.tris)
            self.rects(lo, hi, np.tile(color, (len(runs), 1)))
            hit = (self.tris[n0:], self.cols[n0:])
            if len(_TEXT_TRIS) > 4000:
                _TEXT_TRIS.clear()
            _TEXT_TRIS[key] = hit
            return
        self.tris += hit[0]
        self.cols += hit[1]

    def disc(self, xy, colors, radius_px):
        self.discs.append(np.asarray(xy, float).reshape(-1, 2))
        self.disc_cols.append(np.asarray(colors, float).reshape(-1, 3))
        self.disc_r.append(radius_px)

    def flush(self, key):
        r = self.r
        if self.tris:
            draw_triangles_2d(r.canvas, r._buffers, key + ".tri", np.concatenate(self.tris),
                              np.concatenate(self.cols))
        if self.discs:
            # One call: GGUI's per-disc radius sits in the vertex's fourth slot.
            xy = np.concatenate(self.discs)
            rad = np.concatenate([np.full(len(d), rr * self.px[1])
                                  for d, rr in zip(self.discs, self.disc_r)])
            draw_circles_2d(r.canvas, r._buffers, key + ".disc", xy,
                            np.concatenate(self.disc_cols), rad)


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
        cv.disc(to_win(panel.faint), np.tile(FAINT, (len(panel.faint), 1)), 1.3)
    cv.disc(to_win(panel.points), panel.colors, 2.0)
    if highlight is not None:
        sel = np.nonzero(np.asarray(panel.faces) == highlight)[0]
        if len(sel):
            cv.disc(to_win(panel.points[sel]), np.tile(INK, (len(sel), 1)), 6.0)
            cv.disc(to_win(panel.points[sel]), np.tile(HIGHLIGHT, (len(sel), 1)), 4.0)
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
        cv.text(f"{label} ({count})", x0 + 23 * px, top, INK, 10)


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
    right half's lower part, the key above them; else the key at the top right."""
    if "plot" in overlays:
        return Layout(plot=[(0.515, 0.01, 0.995, 0.62)], key=(0.60, 0.66, 0.93, 0.985),
                      bar=(0.04, 0.06, 0.40, 0.022), view_x=(0.04, 0.48), view_y=(0.10, 0.92))
    return Layout(plot=[], key=(0.71, 0.70, 0.995, 0.99))


class TeachingLayer:
    """The overlays of one window (or offscreen renderer): which are on, the selected face,
    and per simulator the cached glyph sites (they change only with the mesh)."""

    def __init__(self, overlays=(), plot_rect=None):
        self.on = set(overlays)
        unknown = self.on - set(OVERLAYS)
        if unknown:
            raise ValueError(f"unknown overlay '{sorted(unknown)[0]}': use "
                             f"{', '.join(OVERLAYS)}")
        self.plot_rect = plot_rect            # (x0, y0, x1, y1) window fractions, y up
        self.selected = None                  # (simulator index, face)
        self._sites = {}
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
        """The principal-axes strokes (3-D, before the scene is rendered)."""
        if "axes" not in self.on:
            return
        for i, sim in enumerate(sims):
            m = sim.model
            sites, size, Dm_inv = self._mesh_cache(i, sim)
            x = m.positions() + offsets[i]
            g = teaching.axis_glyphs(x, m.faces, Dm_inv, m.grain, sites, size, sim.bands())
            t = x[m.faces[sites]]
            n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
            n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
            # Lifted off both sides (seen from either), each kind in one draw call.
            off = (0.06 * size * n)[:, None, None, :]
            thr = g["grain"].reshape(-1, 2, 2, 3)
            thr = np.concatenate([thr + off, thr - off]).reshape(-1, 3)
            draw_lines(renderer.scene, renderer._buffers, f"axes{i}.grain", thr, THREAD,
                       width=1.0)
            pr = g["principal"].reshape(-1, 2, 2, 3)
            pr = np.concatenate([pr + 1.5 * off, pr - 1.5 * off]).reshape(-1, 3)
            col = np.repeat(g["principal_colors"], 2, axis=0)
            draw_lines(renderer.scene, renderer._buffers, f"axes{i}.pr", pr, (0, 0, 0),
                       width=3.0, colors=np.concatenate([col, col]))
            if self.selected is not None and self.selected[0] == i:
                self._draw_selected(renderer, sim, x, i)

    def _draw_selected(self, renderer, sim, x, i):
        if self.selected[1] >= sim.model.n_faces:       # remeshed since
            return
        f = sim.model.faces[self.selected[1]]
        tri = x[f]
        pts = np.concatenate([tri, tri[[1, 2, 0]]], axis=1).reshape(-1, 3)
        draw_lines(renderer.scene, renderer._buffers, f"sel{i}", pts, HIGHLIGHT, width=4.0)

    def draw_selection(self, renderer, sims, offsets):
        """The selected face's outline in the 3-D view (also without the axes overlay)."""
        if self.selected is None or "axes" in self.on:
            return
        i, _ = self.selected
        if i < len(sims):
            self._draw_selected(renderer, sims[i], sims[i].model.positions() + offsets[i], i)

    def draw_canvas(self, renderer, sims, labels, binds, boxes=None, key_box=None,
                    key_entries=None, key_title=""):
        """The strain-space plot (one pair of panels per simulator, in ``boxes``: per
        simulator a (x0, y0, x1, y1) window box for its two panels) and the binding key,
        after the scene is rendered (on top of it)."""
        cv = Canvas2D(renderer)
        self._px = cv.px
        self.last_panels = {}
        if "plot" in self.on and boxes is not None:
            for i, sim in enumerate(sims):
                m = sim.model
                _, _, Dm_inv = self._mesh_cache(i, sim)
                iso = sim.strain.mapping_iso if sim.strain is not None else 0.0
                panels, _ = teaching.strain_plot(sim.method, m.positions(), m.faces, Dm_inv,
                                                 m.grain, sim.bands(), iso, binds[i])
                x0, y0, x1, y1 = boxes[i]
                if len(sims) == 1:      # side by side
                    mid = 0.5 * (x0 + x1)
                    sub = [(x0, y0, mid - 0.003, y1), (mid + 0.003, y0, x1, y1)]
                else:                   # stacked under each cloth
                    mid = 0.5 * (y0 + y1)
                    sub = [(x0, mid + 0.004, x1, y1), (x0, y0, x1, mid - 0.004)]
                hl = self.selected[1] if self.selected and self.selected[0] == i else None
                for p, b in zip(panels, sub):
                    if len(sims) > 1:
                        p.title = f"{labels[i]}: {p.title}"
                    draw_panel(cv, p, b, hl)
                self.last_panels[i] = (panels, sub)
        if key_entries is not None and key_box is not None:
            draw_key(cv, key_title, key_entries, key_box)
        cv.flush("teach")

    def draw_frame(self, renderer, sims, labels, color, layout):
        """Everything on the canvas for one frame: the plot (if on) and, in the binding
        colour mode, its key."""
        want_plot = "plot" in self.on and layout is not None and layout.plot
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
        self.draw_canvas(renderer, sims, labels, binds, layout.plot if want_plot else None,
                         layout.key if layout is not None else None, entries, title)

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
