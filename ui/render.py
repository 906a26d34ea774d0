"""Drawing the cloth with GGUI: one code path for the window and for headless frames
(an offscreen window, ``show_window=False``).

The cloth is drawn "exploded" (three render vertices per face) so a face can carry one colour
(a strain heat map per triangle) and a flat normal; two-sided lighting shows both sides.
"""
import numpy as np
import taichi as ti

from cloth import metrics

COLOR_MODES = ("shading", "warp-strain", "weft-strain", "bias-strain", "principal-strain",
               "violation", "size")
CLOTH_FRONT = np.array([0.80, 0.45, 0.30])
GROUND = np.array([0.55, 0.57, 0.60])


class RenderUnavailable(RuntimeError):
    """GGUI could not open a (possibly offscreen) window: no Vulkan device or no display."""


def open_window(title, size, show_window):
    try:
        return ti.ui.Window(title, size, vsync=show_window, show_window=show_window)
    except Exception as err:  # GGUI raises plain RuntimeError with a Vulkan message
        raise RenderUnavailable(
            f"cannot open a GGUI window ({str(err).splitlines()[0][:120]}). "
            "Install a Vulkan driver (on Debian: apt-get install mesa-vulkan-drivers libvulkan1; "
            "for a window without a screen also xvfb and run under xvfb-run), "
            "or run with --no-images") from None


def diverging(values, scale):
    """Blue (negative) - white (0) - red (positive) colours for ``values / scale`` in [-1, 1]."""
    t = np.clip(np.asarray(values) / max(scale, 1e-12), -1.0, 1.0)[:, None]
    white = np.array([0.95, 0.95, 0.95])
    red, blue = np.array([0.80, 0.10, 0.10]), np.array([0.15, 0.30, 0.85])
    return np.where(t >= 0, white + t * (red - white), white - t * (blue - white))


def face_colors(mode, x, uv, faces, grain, strain_cfg=None, rest_area=None):
    """Per-face RGB for a colour mode; heat maps come from ``cloth.metrics`` (one definition).
    Returns (colors (F, 3), legend text)."""
    if mode == "shading":
        return np.tile(CLOTH_FRONT, (len(faces), 1)), ""
    st = metrics.face_strains(x, uv, faces, grain)
    strain_cfg = strain_cfg or {}
    band = {"warp-strain": strain_cfg.get("warp"), "weft-strain": strain_cfg.get("weft")}
    if mode in ("warp-strain", "weft-strain", "bias-strain", "principal-strain"):
        key = {"warp-strain": "warp", "weft-strain": "weft", "bias-strain": "bias",
               "principal-strain": "principal_max"}[mode]
        b = band.get(mode) or [-0.05, 0.05]
        scale = 2.0 * max(abs(b[0]), abs(b[1]), 1e-3)
        return diverging(st[key], scale), f"{key} strain, full colour at +/-{scale:.3g}"
    if mode == "violation":
        warp, weft = strain_cfg.get("warp", [-1, 1]), strain_cfg.get("weft", [-1, 1])
        viol = np.maximum(metrics.band_violation(st["warp"], warp),
                          metrics.band_violation(st["weft"], weft))
        return diverging(viol, 0.01), "band violation, full red at 0.01"
    if mode == "size":
        area = metrics.material_areas(uv, faces) if rest_area is None else rest_area
        s = np.sqrt(area)
        t = (s - s.min()) / max(s.max() - s.min(), 1e-12)
        return diverging(2 * t - 1, 1.0), "triangle size, blue small, red large"
    raise ValueError(f"unknown colour mode '{mode}': use one of {', '.join(COLOR_MODES)}")


class ClothRenderer:
    """Draws cloth meshes, obstacle meshes and a ground grid into a GGUI scene."""

    def __init__(self, window, camera_cfg=None, ground_y=0.0):
        self.window = window
        self.canvas = window.get_canvas()
        self.scene = window.get_scene()
        self.camera = ti.ui.Camera()
        self.camera_cfg = dict(camera_cfg or {})
        self.reset_camera()
        self._buffers = {}
        self.ground_y = ground_y
        self._make_ground()

    def reset_camera(self):
        c = self.camera_cfg
        self.camera.position(*c.get("position", [0.0, 1.5, 3.0]))
        self.camera.lookat(*c.get("lookat", [0.0, 1.0, 0.0]))
        self.camera.up(0.0, 1.0, 0.0)
        self.camera.fov(c.get("fov", 40.0))

    def _make_ground(self, half=3.0, n=13):
        s = np.linspace(-half, half, n)
        lines = []
        for t in s:
            lines += [[t, self.ground_y, -half], [t, self.ground_y, half],
                      [-half, self.ground_y, t], [half, self.ground_y, t]]
        self.ground = ti.Vector.field(3, ti.f32, len(lines))
        self.ground.from_numpy(np.array(lines, np.float32))

    def _buffer(self, key, n):
        """Render fields (f32) per key, reallocated only when they must grow."""
        buf = self._buffers.get(key)
        if buf is None or buf[0].shape[0] < n:
            cap = max(n, 16) * 3 // 2
            buf = (ti.Vector.field(3, ti.f32, cap), ti.Vector.field(3, ti.f32, cap),
                   ti.Vector.field(3, ti.f32, cap))
            self._buffers[key] = buf
        return buf

    def add_mesh(self, key, x, faces, face_rgb, wireframe=False):
        """Upload one triangle mesh with per-face colours (flat normals) and draw it."""
        x = np.asarray(x, np.float64)
        corners = x[faces].reshape(-1, 3)
        n = np.cross(x[faces[:, 1]] - x[faces[:, 0]], x[faces[:, 2]] - x[faces[:, 0]])
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-20)
        cnt = len(corners)
        pos, nrm, col = self._buffer(key, cnt)
        cap = pos.shape[0]
        pad = lambda a: np.concatenate([a, np.zeros((cap - len(a), 3))]).astype(np.float32)  # noqa
        pos.from_numpy(pad(corners))
        nrm.from_numpy(pad(np.repeat(n, 3, axis=0)))
        col.from_numpy(pad(np.repeat(np.asarray(face_rgb), 3, axis=0)))
        self.scene.mesh(pos, normals=nrm, per_vertex_color=col, two_sided=True,
                        vertex_count=cnt, show_wireframe=wireframe)

    def begin(self):
        self.scene.set_camera(self.camera)
        self.scene.ambient_light((0.35, 0.35, 0.38))
        self.scene.point_light(pos=(2.0, 4.0, 3.0), color=(0.9, 0.9, 0.9))
        self.scene.point_light(pos=(-3.0, 3.0, -2.0), color=(0.35, 0.35, 0.4))
        self.scene.lines(self.ground, width=1.0, color=tuple(GROUND))

    def finish(self):
        self.canvas.set_background_color((0.96, 0.96, 0.97))
        self.canvas.scene(self.scene)

    def image(self):
        """The last drawn frame as (H, W, 3) uint8, top row first."""
        buf = self.window.get_image_buffer_as_numpy()
        img = np.flipud(np.asarray(buf).transpose(1, 0, 2))[:, :, :3]
        return (np.clip(img, 0.0, 1.0) * 255 + 0.5).astype(np.uint8)


def draw_simulation(renderer, sim, color="shading", wireframe=False, extra_cloths=()):
    """Draw a simulator's cloth (and obstacles) in one colour mode, ready for capture."""
    renderer.begin()
    m = sim.model
    x = m.positions()
    rgb, _ = face_colors(color, x, m.uv, m.faces, m.grain, sim.cfg.get("strain"), m.rest_area)
    renderer.add_mesh("cloth", x, m.faces, rgb, wireframe=wireframe)
    for k, o in enumerate(sim.setup.obstacles):
        v, f = o.mesh_at(sim.time)
        renderer.add_mesh(f"obstacle{k}", v, np.asarray(f), np.tile([0.62, 0.66, 0.72], (len(f), 1)))
    renderer.finish()
