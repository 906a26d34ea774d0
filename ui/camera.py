"""An orbit camera (target, distance, yaw, pitch) that drives a GGUI camera and turns screen
positions into world rays for picking. Plain numpy, so the app's state machine and the tests
use it without a window.

Screen coordinates are GGUI's ``window.get_cursor_pos()``: (x, y) in [0, 1], y up. The
projection matches GGUI's: ``fov`` is the vertical field of view in degrees.
"""
import numpy as np

UP = np.array([0.0, 1.0, 0.0])


class OrbitCamera:
    PITCH_LIMIT = np.radians(89.0)

    def __init__(self, position=(0.0, 1.5, 3.0), lookat=(0.0, 1.0, 0.0), fov=40.0):
        self.home = (np.array(position, float), np.array(lookat, float), float(fov))
        self.reset()

    # -- state --------------------------------------------------------------------------------
    def reset(self):
        position, lookat, self.fov = self.home
        self.target = lookat.copy()
        d = position - lookat
        self.distance = max(float(np.linalg.norm(d)), 1e-3)
        d = d / self.distance
        self.pitch = float(np.arcsin(np.clip(d[1], -1.0, 1.0)))
        self.yaw = float(np.arctan2(d[0], d[2]))

    @property
    def direction(self):
        """Unit vector from the target to the eye."""
        cp = np.cos(self.pitch)
        return np.array([cp * np.sin(self.yaw), np.sin(self.pitch), cp * np.cos(self.yaw)])

    @property
    def position(self):
        return self.target + self.distance * self.direction

    def basis(self):
        """(right, up, forward) unit vectors of the view; forward points into the scene."""
        forward = -self.direction
        right = np.cross(forward, UP)
        right /= max(np.linalg.norm(right), 1e-12)
        up = np.cross(right, forward)
        return right, up, forward

    # -- mouse gestures (deltas in screen units, i.e. fractions of the window) ---------------
    def orbit(self, dx, dy):
        self.yaw -= 3.0 * dx
        self.pitch = float(np.clip(self.pitch - 3.0 * dy, -self.PITCH_LIMIT, self.PITCH_LIMIT))

    def pan(self, dx, dy, aspect=1.0):
        right, up, _ = self.basis()
        h = 2.0 * self.distance * np.tan(np.radians(self.fov) / 2)   # view height at target
        self.target = self.target - right * dx * h * aspect - up * dy * h

    def zoom(self, factor):
        self.distance = float(np.clip(self.distance * factor, 0.05, 100.0))

    def fit(self, points, aspect, x_range=(0.0, 1.0), y_range=(0.0, 1.0)):
        """Keep the viewing direction; move and zoom so ``points`` fill the screen box
        ``x_range`` x ``y_range`` (fractions of the window, y up)."""
        pts = np.asarray(points, float)
        self.target = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
        for _ in range(6):
            s, _ = self.project(pts, aspect)
            ext = np.ptp(s, axis=0)
            need = max(ext[0] / (x_range[1] - x_range[0]), ext[1] / (y_range[1] - y_range[0]))
            self.zoom(need)
            s, _ = self.project(pts, aspect)
            mid = 0.5 * (s.min(axis=0) + s.max(axis=0))
            goal = np.array([np.mean(x_range), np.mean(y_range)])
            self.pan((goal - mid)[0], (goal - mid)[1], aspect)

    # -- GGUI and geometry ----------------------------------------------------------------------
    def apply(self, camera):
        camera.position(*self.position)
        camera.lookat(*self.target)
        camera.up(*UP)
        camera.fov(self.fov)

    def ray(self, sx, sy, aspect):
        """World ray (origin, unit direction) through screen point (sx, sy)."""
        right, up, forward = self.basis()
        t = np.tan(np.radians(self.fov) / 2)
        d = forward + (2 * sx - 1) * t * aspect * right + (2 * sy - 1) * t * up
        return self.position, d / np.linalg.norm(d)

    def project(self, points, aspect):
        """Screen coordinates (N, 2) (y up) and view depth (N,) of world points."""
        right, up, forward = self.basis()
        p = np.asarray(points, float) - self.position
        z = p @ forward
        t = np.tan(np.radians(self.fov) / 2)
        zs = np.where(np.abs(z) > 1e-9, z, 1e-9)
        sx = 0.5 + 0.5 * (p @ right) / (zs * t * aspect)
        sy = 0.5 + 0.5 * (p @ up) / (zs * t)
        return np.stack([sx, sy], axis=1), z
