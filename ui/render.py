"""Drawing the cloth with GGUI: one code path for the window, the comparison view and headless
frames (an offscreen window, ``show_window=False``).

The cloth is drawn "exploded" (three render vertices per face) so a face can carry one colour
(a strain heat map per triangle). Normals are per vertex (smooth shading, the default) or per
face (flat). GGUI's two-sided lighting uses |n . l|, so both sides of the cloth are lit.

Colours and legends come from ``ui/colormap.py``.
"""
import numpy as np
import taichi as ti

from .camera import OrbitCamera
from .colormap import BACKGROUND, GROUND, OBSTACLE, PLAIN, WIRE, face_colors_legend
from .ggui_buffers import (VertexBuffers, draw_lines, draw_mesh, draw_particles,
                           draw_triangles_2d)


class RenderUnavailable(RuntimeError):
    """GGUI could not open a (possibly offscreen) window: no Vulkan device or no display."""


# The connection to the X server, once open, stays open for the process: an X server started
# for one run (Xvfb, xvfb-run) resets when its last client leaves, and a connection opened
# during the reset fails. Closed after the screen-size query, it made the display check just
# after it fail now and then under load (the laptop-screen window test: "cannot connect to the
# X display ':0'", once in a suite run, not alone).
_x_open = {}


def _x_display():
    """(libX11, display pointer, name) for $DISPLAY; None when there is no X display to ask
    (no DISPLAY, Wayland, no libX11); the pointer is None when the server does not answer.
    An open display stays open (``_x_open``)."""
    import ctypes
    import ctypes.util
    import os
    name = os.environ.get("DISPLAY")
    if name and _x_open.get("name") == name:
        return _x_open["found"]
    path = ctypes.util.find_library("X11")
    if not name or os.environ.get("WAYLAND_DISPLAY") or path is None:
        return None
    try:
        x11 = ctypes.CDLL(path)
    except OSError:
        return None
    x11.XOpenDisplay.restype = ctypes.c_void_p
    x11.XOpenDisplay.argtypes = [ctypes.c_char_p]
    x11.XDefaultScreen.argtypes = [ctypes.c_void_p]
    x11.XDisplayWidth.argtypes = x11.XDisplayHeight.argtypes = [ctypes.c_void_p, ctypes.c_int]
    found = x11, x11.XOpenDisplay(name.encode()) or None, name
    if found[1] is not None:
        _x_open.update(name=name, found=found)
    return found


def check_display():
    """Raise ``RenderUnavailable`` if $DISPLAY names an X server that does not answer. GLFW
    would print "cannot initialize GLFW" and end the process without a Python error."""
    found = _x_display()
    if found is None:
        return
    x11, dpy, name = found
    if dpy is None:
        raise RenderUnavailable(f"cannot connect to the X display '{name}' (is the X server "
                                "running and may this user connect? check DISPLAY and xhost); "
                                "without a screen use xvfb-run")


def screen_size():
    """(width, height) in pixels of the X display's default screen, or None (no X display,
    Wayland, no libX11)."""
    found = _x_display()
    if found is None or found[1] is None:
        return None
    x11, dpy, _ = found
    screen = x11.XDefaultScreen(dpy)
    return int(x11.XDisplayWidth(dpy, screen)), int(x11.XDisplayHeight(dpy, screen))


# The window's largest size, and the room left on the screen for a desktop's title bar and
# task bar: 1280 x 800 opens at 1280 x 740 on a 1280 x 800 screen, 1280 x 708 on 1366 x 768.
WINDOW_SIZE, SCREEN_MARGIN = (1280, 800), (0, 60)


def fit_window(requested=None):
    """The window's size: ``requested`` (--window-size) as given, else WINDOW_SIZE shrunk to
    fit the screen it opens on (with SCREEN_MARGIN to spare)."""
    if requested is not None:
        return tuple(int(v) for v in requested)
    screen = screen_size()
    if screen is None:
        return WINDOW_SIZE
    return tuple(max(480, min(w, s - m)) for w, s, m in zip(WINDOW_SIZE, screen, SCREEN_MARGIN))


def open_window(title, size, show_window, vsync=None):
    if show_window:
        check_display()
    try:
        # At the screen's corner: GGUI's default (100, 100) pushed a screen-sized window's
        # right and bottom edges off the screen.
        return ti.ui.Window(title, tuple(int(s) for s in size),
                            vsync=show_window if vsync is None else vsync,
                            show_window=show_window, pos=(0, 0))
    except Exception as err:  # GGUI raises plain RuntimeError with a Vulkan or GLFW message
        reason = str(err).splitlines()[0][:120] if str(err) else type(err).__name__
        if show_window:
            raise RenderUnavailable(
                f"cannot open a window ({reason}). Install a Vulkan driver (on Debian: apt-get "
                "install mesa-vulkan-drivers libvulkan1)") from None
        raise RenderUnavailable(
            f"cannot open an offscreen Vulkan surface ({reason}). "
            "Install a Vulkan driver (on Debian: apt-get install mesa-vulkan-drivers libvulkan1), "
            "or run with --no-images") from None


# -- colours ---------------------------------------------------------------------------------
def vertex_normals(x, faces):
    """Area-weighted unit vertex normals (V, 3)."""
    n = np.cross(x[faces[:, 1]] - x[faces[:, 0]], x[faces[:, 2]] - x[faces[:, 0]])
    out = np.zeros_like(x)
    for c in range(3):
        idx = faces[:, c]
        for k in range(3):
            out[:, k] += np.bincount(idx, weights=n[:, k], minlength=len(x))
    return out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-20)


def _logging_level():
    for name in ("trace", "debug", "info", "warn", "error", "critical"):
        if ti._logging.is_logging_effective(name):
            return name
    return "info"


# -- the renderer ----------------------------------------------------------------------------
class ClothRenderer:
    """Draws cloth meshes, obstacle meshes, a ground grid and a colour bar into a GGUI window.
    ``orbit`` (an ``OrbitCamera``) holds the view; ``reset_camera`` returns to the scene's."""

    def __init__(self, window, camera_cfg=None, ground_y=0.0, ground_half=3.0):
        self.window = window
        self.canvas = window.get_canvas()
        self.scene = window.get_scene()
        self.camera = ti.ui.Camera()
        self._buffers = VertexBuffers()   # alive until the next frame (see ggui_buffers)
        self.ground_y, self.ground_half = ground_y, ground_half
        self.set_camera_cfg(camera_cfg)
        self._add_ground()
        self._thin = []
        self._legend = None

    def set_camera_cfg(self, camera_cfg):
        c = dict(camera_cfg or {})
        self.camera_cfg = c
        self.orbit = OrbitCamera(c.get("position", [0.0, 1.5, 3.0]),
                                 c.get("lookat", [0.0, 1.0, 0.0]), c.get("fov", 40.0))
        self.orbit.apply(self.camera)

    def reset_camera(self):
        self.orbit.reset()
        self.orbit.apply(self.camera)

    @property
    def aspect(self):
        w, h = self.window.get_window_shape()
        return w / max(h, 1)

    def _add_ground(self, n=13):
        half = self.ground_half
        s = np.linspace(-half, half, n)
        lines = []
        for t in s:
            lines += [[t, self.ground_y, -half], [t, self.ground_y, half],
                      [-half, self.ground_y, t], [half, self.ground_y, t]]
        self.ground = np.array(lines, np.float32)

    def add_mesh(self, key, x, faces, face_rgb, wireframe=False, smooth=False, offset=None):
        """Draw one triangle mesh with per-face colours; ``smooth`` interpolates vertex
        normals, ``wireframe`` overlays the edges, ``offset`` translates it."""
        x = np.asarray(x, np.float64)
        faces = np.asarray(faces)
        if offset is not None:
            x = x + np.asarray(offset, float)
        corners = x[faces].reshape(-1, 3)
        if smooth:
            vn = vertex_normals(x, faces)
            normals = vn[faces].reshape(-1, 3)
        else:
            n = np.cross(x[faces[:, 1]] - x[faces[:, 0]], x[faces[:, 2]] - x[faces[:, 0]])
            n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-20)
            normals = np.repeat(n, 3, axis=0)
        colors = np.repeat(np.asarray(face_rgb, float), 3, axis=0)
        draw_mesh(self.scene, self._buffers, key, corners, normals, colors)
        if wireframe:
            self.add_wireframe(key + ".wire", x, faces, vn if smooth else vertex_normals(x, faces))

    def add_wireframe(self, key, x, faces, normals):
        """Mesh edges as lines, lifted a little off both sides so the surface does not hide
        them."""
        e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
        e = np.unique(np.sort(e, axis=1), axis=0)
        size = np.ptp(x, axis=0).max() if len(x) else 1.0
        lift = 2e-3 * size * normals
        pts = np.concatenate([x + lift, x - lift])
        idx = np.concatenate([e, e + len(x)])
        draw_lines(self.scene, self._buffers, key, pts, WIRE, indices=idx)

    def add_points(self, key, pts, radius, color):
        pts = np.asarray(pts, float).reshape(-1, 3)
        draw_particles(self.scene, self._buffers, key, pts, radius, color)

    def begin(self):
        self.orbit.apply(self.camera)
        self.scene.set_camera(self.camera)
        self.scene.ambient_light((0.35, 0.35, 0.38))
        self.scene.point_light(pos=(2.0, 4.0, 3.0), color=(0.9, 0.9, 0.9))
        self.scene.point_light(pos=(-3.0, 3.0, -2.0), color=(0.35, 0.35, 0.4))
        self._thin = []          # width-1 lines drawn with the ground (add_thin_lines)

    def add_thin_lines(self, points, color):
        """Segments (consecutive point pairs, world) one pixel wide in ``color`` (one, or one
        per point), drawn in the ground grid's draw call: each scene draw call costs GGUI
        about a millisecond a frame on software Vulkan, whatever it holds."""
        points = np.asarray(points, np.float32).reshape(-1, 3)
        colors = np.broadcast_to(np.asarray(color, np.float32), (len(points), 3))
        self._thin.append((points, colors))

    def finish(self, legend=None, bar_rect=(0.70, 0.075, 0.27, 0.025)):
        """Render the scene into the canvas (call before every capture) and draw the colour
        bar of ``legend`` (rect x, y, w, h in window fractions, y up)."""
        pts = [self.ground] + [p for p, _ in self._thin]
        cols = [np.broadcast_to(np.asarray(GROUND, np.float32), self.ground.shape)]
        cols += [c for _, c in self._thin]
        draw_lines(self.scene, self._buffers, "ground", np.concatenate(pts), GROUND,
                   colors=np.concatenate(cols))
        self._thin = []
        self.canvas.set_background_color(BACKGROUND)
        self._legend = (legend, bar_rect) if legend is not None else None
        if legend is not None:
            self.draw_colorbar(legend, bar_rect)
        self.canvas.scene(self.scene)

    def draw_colorbar(self, legend, rect):
        x0, y0, w, h = rect
        n = 64
        vals = np.linspace(legend.lo, legend.hi, n + 1)
        mids = 0.5 * (vals[1:] + vals[:-1])
        rgb = legend.colors(mids)
        xs = x0 + w * np.arange(n + 1) / n
        tris, cols = [], []
        for i in range(n):
            a, b = xs[i], xs[i + 1]
            tris += [[a, y0], [b, y0], [b, y0 + h], [a, y0], [b, y0 + h], [a, y0 + h]]
            cols += [rgb[i]] * 6
        for m in legend.marks:   # tick marks at band edges (and zero)
            t = (m - legend.lo) / (legend.hi - legend.lo)
            if 0 <= t <= 1:
                xm = x0 + w * t
                tw = 0.0015
                tris += [[xm - tw, y0 - 0.3 * h], [xm + tw, y0 - 0.3 * h], [xm + tw, y0 + 1.3 * h],
                         [xm - tw, y0 - 0.3 * h], [xm + tw, y0 + 1.3 * h], [xm - tw, y0 + 1.3 * h]]
                cols += [np.array(WIRE)] * 6
        draw_triangles_2d(self.canvas, self._buffers, "colorbar", np.array(tris),
                          np.array(cols))

    def image(self, annotate=True):
        """The last drawn frame as (H, W, 3) uint8, top row first; with a heat map the colour
        bar gets its numbers (GGUI draws no text into the frame)."""
        level = _logging_level()
        ti.set_logging_level(ti.WARN)     # GGUI logs every image dump at info level
        try:
            buf = self.window.get_image_buffer_as_numpy()
        finally:
            ti.set_logging_level(level)
        img = np.flipud(np.asarray(buf).transpose(1, 0, 2))[:, :, :3]
        img = (np.clip(img, 0.0, 1.0) * 255 + 0.5).astype(np.uint8)
        if annotate and self._legend is not None:
            img = label_colorbar(img, *self._legend)
        return img


def _font(h):
    """Pillow's default font at a size that reads in an image ``h`` pixels high."""
    from PIL import ImageFont
    size = max(9, min(14, h // 40))
    try:
        return ImageFont.load_default(size=size), size
    except TypeError:           # Pillow < 10.1: one bitmap size
        return ImageFont.load_default(), 11


INK = (40, 40, 46)


def label_colorbar(img, legend, rect):
    """Write the legend's title and band above its colour bar and the numbers under it, each
    band edge under its tick (Pillow)."""
    from PIL import Image, ImageDraw
    h, w = img.shape[:2]
    font, size = _font(h)
    pil = Image.fromarray(img)
    d = ImageDraw.Draw(pil)
    x0, y0, bw, bh = rect
    left = x0 * w
    top, bottom = (1 - y0 - bh) * h, (1 - y0) * h
    edges = [m for m in legend.marks if m != 0.0]
    above = top - 0.3 * (bottom - top) - 2
    lines = [legend.title] + (["band " + " .. ".join(legend.fmt(m) for m in edges)] if edges
                              else [])
    for line in reversed(lines):      # kept inside the frame when the bar is near its edge
        x = min(left, w - d.textlength(line, font=font) - 4)
        d.text((x, above), line, fill=INK, font=font, anchor="ls")
        above -= size + 3
    below = bottom + 0.3 * (bottom - top) + 2
    for start, label in legend.place_ticks(bw * w, lambda t: d.textlength(t, font=font), 4):
        d.text((left + start, below), label, fill=INK, font=font, anchor="lt")
    return np.asarray(pil)


def caption(img, text):
    """One line of text on a light strip along the frame's top edge (Pillow)."""
    from PIL import Image, ImageDraw
    h, w = img.shape[:2]
    font, size = _font(h)
    pil = Image.fromarray(img)
    d = ImageDraw.Draw(pil)
    d.rectangle((0, 0, w, size + 8), fill=(250, 250, 252))
    d.text((6, 4), text, fill=INK, font=font, anchor="lt")
    return np.asarray(pil)


def frame_caption(sim, scene):
    """What a headless frame shows, for its caption: the scene, frame, time, the method and
    the bands in force (%)."""
    def band(lo, hi):
        return f"{100 * lo:+.3g}..{100 * hi:+.3g} %"
    text = f"{scene}   frame {sim.frame}   t = {sim.time:.2f} s   {sim.method}"
    if sim.method != "none":
        text += "   " + "   ".join(f"{k} {band(*v)}" for k, v in sim.bands().items())
    return text


def draw_cloth(renderer, sim, key="cloth", color="shading", wireframe=False, smooth=True,
               offset=None, strains=None, plain=False):
    """Draw one simulator's cloth and obstacles (after ``renderer.begin()``); returns the
    colour mode's ``Legend`` (None for shading and the binding map). ``plain``: under
    shading, a light grey cloth (the principal-axes strokes read better on it)."""
    m = sim.model
    x = m.positions()
    if color == "binding":
        from .teaching import binding
        strains = {"binding": (sim.method, binding(sim))}
    elif strains is None and color not in ("shading", "size"):
        strains = sim.face_strains()
    if color == "violation":
        strains = dict(strains, own=sim.own_violation(), own_tol=sim.settings.strain.tol)
    rgb, legend = face_colors_legend(color, x, m.uv, m.faces, m.grain, sim.bands(), m.rest_area,
                                     strains=strains)
    if plain and color == "shading":
        rgb = np.tile(PLAIN, (len(m.faces), 1))
    renderer.add_mesh(key, x, m.faces, rgb, wireframe=wireframe, smooth=smooth, offset=offset)
    for k, o in enumerate(sim.setup.obstacles):
        v, f = o.mesh_at(sim.time)
        f = np.asarray(f)
        renderer.add_mesh(f"{key}.obstacle{k}", v, f, np.tile(OBSTACLE, (len(f), 1)),
                          smooth=False, offset=offset)
    return legend


def draw_simulation(renderer, sim, color="shading", wireframe=False, extra_cloths=(),
                    smooth=True, legend=True, teach=None, layout=None):
    """Draw a simulator's cloth (and obstacles) in one colour mode, ready for capture. The
    window app and headless frames both come through here (or ``draw_cloth``). ``teach``: a
    ``ui.overlays.TeachingLayer`` (principal axes, strain-space plot, binding key) placed by
    ``layout`` (``ui.overlays.Layout``)."""
    renderer.begin()
    plain = teach is not None and "axes" in teach.on
    lg = draw_cloth(renderer, sim, "cloth", color, wireframe=wireframe, smooth=smooth,
                    plain=plain)
    for k, (x, faces, rgb) in enumerate(extra_cloths):
        renderer.add_mesh(f"extra{k}", x, faces, rgb, smooth=smooth)
    if teach is not None:
        teach.draw_scene(renderer, [sim], [np.zeros(3)])
    renderer.finish(lg if legend else None, *(() if layout is None else (layout.bar,)))
    if teach is not None:
        teach.draw_frame(renderer, [sim], [sim.method], color, layout)
    return lg
