"""Collision detection and response: rigid obstacles and (optionally) cloth self-collision.

Obstacles are signed distance functions (SDF, metres, negative inside) in their own local frame;
a pose ``(c, R)`` maps local to world, ``x = R p + c``. A static obstacle has a fixed pose; a
scripted one gets its pose from ``path(t)`` (a Python callable of time), evaluated once per
substep on the host at the substep's start and end time and sent to the kernel as arguments.

The collider runs once per substep (METHOD.md section 1, step 5):

    col = Collider(model, [Plane(...), Sphere(...)], thickness=0.005, self_collision=False)
    col.resolve(h, t)          # t = time at the *start* of the substep, h = substep length

With strain limiting the Simulator runs it before the projection and hands the projection the
contacts as half-space constraints (``contact_planes``), then runs the obstacle pass once more
to remove what the planes' linearisation leaves (see ``Simulator._strain_limit``).

For each cloth vertex it needs where the vertex was at the substep's start; with implicit Euler
followed by a velocity-consistent strain projection (``v += dx / h``) that is exactly
``x_start = x - h v``, so the collider keeps no per-vertex history (remeshing may renumber the
vertices between substeps). Response per vertex and obstacle (Bridson, Fedkiw, Anderson 2002,
section 7 applied to a rigid body):
  * position: the vertex is moved out to ``sdf = thickness`` along the SDF gradient; when it was
    outside at the start and the relative motion crossed the surface (including straight through
    a thin or fast obstacle, found by sampling the segment in the obstacle's frame), it is put back
    on the side it came from, at the tangent plane of the first crossing, and then pushed out;
  * velocity: relative to the obstacle's velocity at that point (``v_lin + omega x r``), the
    inward normal component is removed and Coulomb friction acts on the tangential part:
    ``|dv_t| <= mu |dv_n|``; below that the vertex sticks (tangential relative velocity 0);
  * the tangential velocity change is also applied to the position (``x += h dv_t``), so a
    sticking vertex does not creep by ``h^2 g sin(theta)`` every substep.
Pinned vertices are never touched.

Units: SI. Fields use ``float`` (Taichi's default float).
"""
import time

import numpy as np
import taichi as ti
import trimesh

from . import backend
from .collision_geom import (sdf_box, sdf_capsule, sdf_plane, sdf_sphere, safe_normalize)
from .collision_mesh import SDFGrid

vec3 = ti.types.vector(3, float)
mat3 = ti.types.matrix(3, 3, float)


# The distance cloth keeps from obstacles (m) unless a scene says otherwise: a few
# millimetres, about a fabric's thickness (scenes' collision.thickness; tshirt uses 4 mm).
THICKNESS = 0.005


class CollisionError(ValueError):
    """Bad obstacle or collider settings; the message names the fix."""


def _rotation_between(a, b):
    """A rotation matrix taking unit vector a to unit vector b."""
    a = np.asarray(a, float) / np.linalg.norm(a)
    b = np.asarray(b, float) / np.linalg.norm(b)
    v = np.cross(a, b)
    c = float(np.dot(a, b))
    if c < -1 + 1e-12:                       # opposite: rotate pi about any perpendicular axis
        axis = np.cross(a, [1.0, 0.0, 0.0])
        if np.linalg.norm(axis) < 1e-6:
            axis = np.cross(a, [0.0, 1.0, 0.0])
        axis /= np.linalg.norm(axis)
        return 2.0 * np.outer(axis, axis) - np.eye(3)
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + c)


def rotation_about(axis, angle):
    """Rotation matrix for ``angle`` radians about ``axis`` (Rodrigues)."""
    k = np.asarray(axis, float)
    k = k / np.linalg.norm(k)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def _rotvec(R):
    """Axis * angle of a rotation matrix (log map), robust near 0 and pi."""
    c = np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(c)
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if angle < 1e-8:
        return 0.5 * w
    if np.pi - angle < 1e-6:
        # near pi: axis from the symmetric part
        M = (R + np.eye(3)) / 2.0
        axis = np.sqrt(np.clip(np.diag(M), 0, None))
        i = int(np.argmax(axis))
        axis = M[:, i] / np.sqrt(max(M[i, i], 1e-300))
        return axis / np.linalg.norm(axis) * angle
    return w * angle / (2.0 * np.sin(angle))


# -- obstacles ---------------------------------------------------------------------------------

@ti.data_oriented
class Obstacle:
    """Base class: a rigid solid with a local signed distance ``sdf_local(p)`` (a ti.func).

    position, rotation: the static pose (rotation a 3x3 world-from-local matrix).
    path: optional ``path(t) -> position`` or ``-> (position, rotation)``; overrides the
        static pose (rotation None keeps the static rotation).
    mu: Coulomb friction coefficient against the cloth.
    Shape parameters are compile-time constants of the kernels: do not change them after the
    first substep (make a new obstacle instead)."""

    kind = "obstacle"

    def __init__(self, mu=0.3, position=(0.0, 0.0, 0.0), rotation=None, path=None):
        if mu < 0:
            raise CollisionError(f"friction coefficient mu must be >= 0 (got {mu})")
        self.mu = float(mu)
        self.position = np.asarray(position, dtype=np.float64).reshape(3)
        self.rotation = np.eye(3) if rotation is None else np.asarray(rotation, np.float64)
        if self.rotation.shape != (3, 3):
            raise CollisionError("rotation must be a 3x3 matrix (world from local)")
        if path is not None and not callable(path):
            raise CollisionError("path must be a callable t -> position or (position, rotation)")
        self.path = path
        # Finite-difference step of the gradient: relative to the obstacle's size, larger in f32.
        rel = 1e-6 if backend.precision() != "f32" else 1e-3
        self.fd_eps = rel * max(self.size(), 1e-3)

    # shape interface, overridden ------------------------------------------------------------
    def size(self):
        """A length scale of the shape (m), for finite-difference steps."""
        return 1.0

    def ccd_step(self, thickness):
        """Spacing (m) at which the continuous test samples a vertex's motion relative to the
        obstacle. A segment between two samples that are both outside the thickened surface may
        still cut a chord through it; the spacing is chosen so such a chord cannot reach the
        solid itself (it stays within the thickness shell) and cannot jump over the solid."""
        return np.inf

    def local_mesh(self):
        """(vertices, faces) of the surface in the local frame, for drawing and export."""
        raise NotImplementedError

    @ti.func
    def sdf_local(self, p):
        return 0.0

    @ti.func
    def grad_local(self, p):
        """Unit gradient of the SDF by central differences (exact SDFs have |grad| = 1 almost
        everywhere; on a medial surface this picks a consistent average)."""
        e = self.fd_eps
        g = ti.Vector([
            self.sdf_local(p + ti.Vector([e, 0.0, 0.0])) - self.sdf_local(p - ti.Vector([e, 0.0, 0.0])),
            self.sdf_local(p + ti.Vector([0.0, e, 0.0])) - self.sdf_local(p - ti.Vector([0.0, e, 0.0])),
            self.sdf_local(p + ti.Vector([0.0, 0.0, e])) - self.sdf_local(p - ti.Vector([0.0, 0.0, e])),
        ])
        return safe_normalize(g, ti.Vector([0.0, 0.0, 1.0]))

    @ti.func
    def nearest_two(self, p):
        """The two nearest parts of the shape as (sdf1, normal1, sdf2, normal2), for contact
        planes; a single solid has one part (sdf2 = 1e30). Unions override it: near a
        concave corner the second part's plane keeps the cloth out of it."""
        return self.sdf_local(p), self.grad_local(p), 1e30, ti.Vector([0.0, 0.0, 1.0])

    # pose --------------------------------------------------------------------------------------
    @property
    def moving(self):
        """True when a scripted path drives the obstacle."""
        return self.path is not None

    def pose(self, t):
        """(c, R) at time t: world position of the local origin and world-from-local rotation."""
        if self.path is None:
            return self.position, self.rotation
        out = self.path(t)
        if isinstance(out, tuple) and len(out) == 2:
            c, R = out
        else:
            c, R = out, None
        c = np.asarray(c, np.float64).reshape(3)
        R = self.rotation if R is None else np.asarray(R, np.float64).reshape(3, 3)
        return c, R

    def velocity(self, t, h):
        """(linear, angular) velocity over [t, t + h] from the scripted path."""
        if self.path is None or h <= 0:
            return np.zeros(3), np.zeros(3)
        c0, R0 = self.pose(t)
        c1, R1 = self.pose(t + h)
        return (c1 - c0) / h, _rotvec(R1 @ R0.T) / h

    def mesh_at(self, t=0.0):
        """Surface triangle mesh in world coordinates at time t: (vertices (N,3), faces (M,3))."""
        v, f = self.local_mesh()
        c, R = self.pose(t)
        return np.asarray(v, np.float64) @ R.T + c, np.asarray(f, np.int32)

    # host evaluation (tests, tools) --------------------------------------------------------
    def sdf(self, points, t=0.0):
        """Signed distance at world points (N,3) at time t, via the same Taichi code the
        collider uses. Returns (phi (N,), grad (N,3))."""
        pts = np.ascontiguousarray(np.asarray(points, np.float64).reshape(-1, 3))
        phi = np.zeros(len(pts))
        grad = np.zeros((len(pts), 3))
        c, R = self.pose(t)
        self._eval(pts, phi, grad, ti.Matrix(R), ti.Vector(c))
        return phi, grad

    @ti.kernel
    def _eval(self, pts: ti.types.ndarray(), phi: ti.types.ndarray(), grad: ti.types.ndarray(),
              R: mat3, c: vec3):
        for i in range(pts.shape[0]):
            x = ti.Vector([pts[i, 0], pts[i, 1], pts[i, 2]])
            p = R.transpose() @ (x - c)
            phi[i] = self.sdf_local(p)
            g = R @ self.grad_local(p)
            for d in ti.static(range(3)):
                grad[i, d] = g[d]


@ti.data_oriented
class Plane(Obstacle):
    """The half-space behind a plane through ``point`` with outward unit ``normal``.
    Drawn as a square of side ``draw_size`` (m)."""

    kind = "plane"

    def __init__(self, point=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0), mu=0.3, path=None,
                 draw_size=4.0):
        n = np.asarray(normal, np.float64)
        if not np.linalg.norm(n) > 0:
            raise CollisionError("plane normal must be non-zero")
        self.draw_size = float(draw_size)
        super().__init__(mu=mu, position=point, rotation=_rotation_between([0, 0, 1], n),
                         path=path)

    def size(self):
        return 1.0

    def local_mesh(self):
        s = self.draw_size / 2
        v = np.array([[-s, -s, 0], [s, -s, 0], [s, s, 0], [-s, s, 0]], float)
        return v, np.array([[0, 1, 2], [0, 2, 3]])

    @ti.func
    def sdf_local(self, p):
        return sdf_plane(p)

    @ti.func
    def grad_local(self, p):
        return ti.Vector([0.0, 0.0, 1.0])


@ti.data_oriented
class Sphere(Obstacle):
    kind = "sphere"

    def __init__(self, center=(0.0, 0.0, 0.0), radius=0.25, mu=0.3, path=None):
        if not radius > 0:
            raise CollisionError(f"sphere radius must be > 0 (got {radius})")
        self.radius = float(radius)
        super().__init__(mu=mu, position=center, path=path)

    def size(self):
        return self.radius

    def ccd_step(self, thickness):
        # A chord of length c through a ball of radius R + th dips c^2 / (8 (R + th)) below
        # its surface: keep that under the thickness.
        return min(self.radius, np.sqrt(8.0 * self.radius * thickness))

    def local_mesh(self):
        m = trimesh.creation.icosphere(subdivisions=3, radius=self.radius)
        return m.vertices, m.faces

    @ti.func
    def sdf_local(self, p):
        return sdf_sphere(p, self.radius)

    @ti.func
    def grad_local(self, p):
        return safe_normalize(p, ti.Vector([0.0, 0.0, 1.0]))


@ti.data_oriented
class Capsule(Obstacle):
    """A segment of length ``length`` along the local z axis, inflated by ``radius``;
    ``rotation`` (or the path) orients it."""

    kind = "capsule"

    def __init__(self, center=(0.0, 0.0, 0.0), length=0.5, radius=0.1, rotation=None, mu=0.3,
                 path=None):
        if not (radius > 0 and length >= 0):
            raise CollisionError("capsule needs radius > 0 and length >= 0")
        self.radius, self.length = float(radius), float(length)
        super().__init__(mu=mu, position=center, rotation=rotation, path=path)

    def size(self):
        return self.radius

    def ccd_step(self, thickness):
        # A chord of length c through a ball of radius R + th dips c^2 / (8 (R + th)) below
        # its surface: keep that under the thickness.
        return min(self.radius, np.sqrt(8.0 * self.radius * thickness))

    def local_mesh(self):
        m = trimesh.creation.capsule(height=self.length, radius=self.radius, count=[24, 24])
        return m.vertices, m.faces

    @ti.func
    def sdf_local(self, p):
        return sdf_capsule(p, 0.5 * self.length, self.radius)


@ti.data_oriented
class Box(Obstacle):
    """An oriented box with full side lengths ``extents`` (m)."""

    kind = "box"

    def __init__(self, center=(0.0, 0.0, 0.0), extents=(0.5, 0.5, 0.5), rotation=None, mu=0.3,
                 path=None):
        e = np.asarray(extents, np.float64).reshape(3)
        if not np.all(e > 0):
            raise CollisionError(f"box extents must be > 0 (got {extents})")
        self.half = tuple(float(x) for x in e / 2)
        super().__init__(mu=mu, position=center, rotation=rotation, path=path)

    def size(self):
        return min(self.half)

    def ccd_step(self, thickness):
        # Cutting across a right-angled edge or corner, a chord of length c reaches c / 2 deep.
        return min(min(self.half), 2.0 * thickness)

    def local_mesh(self):
        m = trimesh.creation.box(extents=[2 * h for h in self.half])
        return m.vertices, m.faces

    @ti.func
    def sdf_local(self, p):
        return sdf_box(p, ti.Vector([self.half[0], self.half[1], self.half[2]]))


@ti.data_oriented
class MeshObstacle(Obstacle):
    """A closed triangle mesh (OBJ/PLY/STL/GLB via trimesh, or given arrays) turned once into a
    signed-distance grid (see ``collision_mesh``). ``resolution`` is the number of cells along
    the longest side. ``scale`` and ``offset`` are applied to the file's vertices first."""

    kind = "mesh"

    def __init__(self, source, resolution=64, mu=0.3, position=(0.0, 0.0, 0.0), rotation=None,
                 path=None, scale=1.0, offset=(0.0, 0.0, 0.0)):
        if isinstance(source, trimesh.Trimesh):
            mesh = source
        elif isinstance(source, (tuple, list)) and len(source) == 2:
            mesh = trimesh.Trimesh(vertices=source[0], faces=source[1], process=True)
        else:
            mesh = trimesh.load(source, force="mesh")
            if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
                raise CollisionError(f"could not read a triangle mesh from {source!r}; "
                                     "use an OBJ, PLY, STL or GLB file with faces")
        self.vertices = np.asarray(mesh.vertices, np.float64) * scale + np.asarray(offset, float)
        self.faces = np.asarray(mesh.faces, np.int64)
        self.watertight = bool(mesh.is_watertight)
        self.grid = SDFGrid(self.vertices, self.faces, resolution=resolution)
        self.build_seconds = self.grid.build_seconds
        self._size = float(np.ptp(self.vertices, axis=0).max())
        super().__init__(mu=mu, position=position, rotation=rotation, path=path)
        # Gradient from central differences of the interpolated grid, one cell apart.
        self.fd_eps = 0.5 * self.grid.dx

    def size(self):
        return self._size

    def ccd_step(self, thickness):
        return min(self.grid.dx, 2.0 * thickness)

    def local_mesh(self):
        return self.vertices, self.faces

    @ti.func
    def sdf_local(self, p):
        return self.grid.lookup(p)


# -- the collider ------------------------------------------------------------------------------

@ti.data_oriented
class Collider:
    """Resolves cloth-obstacle contact (and self-contact when asked) once per substep.

    model: ClothModel (reads ``state.x``, ``state.v``, ``vert_pinned``, ``vert_mass``,
        ``face_verts``, ``edge_verts`` and the active counts at call time).
    obstacles: list of Obstacle.
    thickness: cloth-obstacle separation kept (m), > 0.
    self_collision: also keep the cloth ``self_thickness`` (default ``thickness``) away from
        itself (vertex-triangle and edge-edge repulsion, see ``collision_self``).
    ccd_samples: most samples along a vertex's relative motion when looking for a crossing.

    After ``resolve``: ``last_ms`` (wall time, ms, with ``last_ms_obstacles`` and
    ``last_ms_self``), ``last_contacts`` (vertex-obstacle contacts), ``last_self_pairs``."""

    def __init__(self, model, obstacles=(), thickness=THICKNESS, self_collision=False,
                 self_thickness=None, self_iterations=6, ccd_samples=32):
        if not thickness > 0:
            raise CollisionError(f"collision thickness must be > 0 m (got {thickness}); "
                                 "a few millimetres suits cloth")
        for o in obstacles:
            if not isinstance(o, Obstacle):
                raise CollisionError(f"{o!r} is not an Obstacle (Plane, Sphere, Capsule, Box, "
                                     "MeshObstacle)")
        self.model = model
        self.obstacles = list(obstacles)
        self.thickness = float(thickness)
        self.ccd_samples = int(ccd_samples)
        self.self_collision = bool(self_collision)
        self.last_ms = self.last_ms_obstacles = self.last_ms_self = 0.0
        self.last_contacts = 0
        self.last_self_pairs = 0
        self._last_t = 0.0
        self._counter = ti.field(ti.i32, ())
        self._maxval = ti.field(float, ())
        self._moved = ti.field(float, ())      # largest push of the last obstacle pass (m)
        self.self_solver = None
        if self.self_collision:
            from .collision_self import SelfCollision
            self.self_solver = SelfCollision(
                model, thickness=self.thickness if self_thickness is None else self_thickness,
                iterations=self_iterations)
        self._self_built = self.self_solver    # kept while switched off (building compiles)

    def set_self_collision(self, on):
        """Switch cloth-cloth repulsion on or off live. Only a collider built with
        ``self_collision=True`` can switch it on (its spatial hash is built once)."""
        if on and self._self_built is None:
            raise CollisionError("this scene was built without self-collision: set "
                                 "self_collision in the scene to switch it on")
        self.self_solver = self._self_built if on else None
        self.self_collision = bool(on)

    def on_mesh_changed(self):
        """Call after the model was refilled (remeshing): nothing per vertex is kept between
        substeps, so this only re-checks the self-collision buffers against the capacities."""
        if self._self_built is not None:
            self._self_built.on_mesh_changed()

    def add(self, obstacle):
        if not isinstance(obstacle, Obstacle):
            raise CollisionError(f"{obstacle!r} is not an Obstacle")
        self.obstacles.append(obstacle)

    def resolve(self, h, t):
        """Resolve contacts at the end of the substep [t, t + h]."""
        if not h > 0:
            raise CollisionError(f"substep h must be > 0 (got {h})")
        t_start = time.perf_counter()
        if self.self_solver is not None:
            # Flag the vertices touching an obstacle first (read-only pass): the self-collision
            # impulses treat them as heavy, so a layer landing on a layer that rests on the
            # ground is stopped by the upper layer's impulse instead of pushing the lower one
            # into the ground (which the final obstacle pass would undo, closing the gap).
            g = self.self_solver.prepare_contacts()
            self._obstacle_pass(h, t, g, True)
            self.self_solver.resolve(h)
            self.last_self_pairs = self.self_solver.last_pairs
        ti.sync()
        t_mid = time.perf_counter()
        self._counter[None] = 0
        self._obstacle_pass(h, t, self._counter, False)
        self.last_contacts = int(self._counter[None]) if self.obstacles else 0
        t_end = time.perf_counter()
        self._last_t = t + h
        self.last_ms_self = 1e3 * (t_mid - t_start)
        self.last_ms_obstacles = 1e3 * (t_end - t_mid)
        self.last_ms = 1e3 * (t_end - t_start)

    def resolve_obstacles(self, h, t):
        """The obstacle pass of ``resolve`` alone, keeping its statistics (the Simulator's
        ``collision_final`` stage after the projection), without the continuous test: the
        crossings were caught before the projection, and after it ``x - h v`` is no longer
        where the vertex started (the first pass moved x without the matching v), so a
        continuous test from there finds false crossings (measured on tshirt: vertices thrown
        to the far side of an arm, 27 cm). Returns how far it moved the vertex it moved most
        (m)."""
        self._moved[None] = 0.0
        if self.obstacles:
            self._obstacle_pass(h, t, self._counter, False, ccd=False)
        return float(self._moved[None])

    def _obstacle_pass(self, h, t, out, mark, ccd=True):
        st = self.model.state
        n = self.model.n_verts
        for o in self.obstacles:
            c0, R0 = o.pose(t)
            c1, R1 = o.pose(t + h)
            vlin, omega = o.velocity(t, h)
            step = min(o.ccd_step(self.thickness), 1e30) if ccd else -1.0
            self._resolve_obstacle(o, st.x, st.v, self.model.vert_pinned, out, mark, n, h,
                                   self.thickness, o.mu, ti.Matrix(R0), ti.Vector(c0),
                                   ti.Matrix(R1), ti.Vector(c1), ti.Vector(vlin),
                                   ti.Vector(omega), step)

    @ti.kernel
    def _resolve_obstacle(self, o: ti.template(), x: ti.template(), v: ti.template(),
                          pinned: ti.template(), out: ti.template(), mark: ti.template(),
                          n: ti.i32, h: float, th: float, mu: float,
                          R0: mat3, c0: vec3, R1: mat3, c1: vec3, vlin: vec3, omega: vec3,
                          step: float):
        # out: the contact counter (mark False) or, for the read-only pass before
        # self-collision (mark True), a per-vertex flag set where the vertex started the
        # substep on the obstacle (nothing else is written then).
        for i in range(n):
            if pinned[i] == 0:
                x1 = x[i]
                vi = v[i]
                x0 = x1 - h * vi
                p0 = R0.transpose() @ (x0 - c0)
                p1 = R1.transpose() @ (x1 - c1)
                phi0 = o.sdf_local(p0) - th
                phi1 = o.sdf_local(p1) - th
                pn = p1
                contact = False
                s_hit = 0.0        # fraction of the substep before the contact began
                nloc = ti.Vector([0.0, 0.0, 1.0])
                entry = False
                if phi0 >= 0.0 and step > 0.0:      # step <= 0: no continuous test
                    # Continuous test: walk the relative motion in the obstacle's frame and find
                    # the first time the thickened surface is crossed.
                    seg = p1 - p0
                    L = seg.norm()
                    K = ti.min(ti.max(ti.cast(ti.ceil(L / step), ti.i32), 1), self.ccd_samples)
                    s_lo = 0.0
                    s_hi = -1.0
                    for k in range(1, K + 1):
                        if s_hi < 0.0:
                            s = k / K
                            ph = phi1
                            if k < K:
                                ph = o.sdf_local(p0 + s * seg) - th
                            if ph < 0.0:
                                s_hi = s
                            else:
                                s_lo = s
                    if s_hi >= 0.0:
                        for _ in range(20):
                            sm = 0.5 * (s_lo + s_hi)
                            if o.sdf_local(p0 + sm * seg) - th < 0.0:
                                s_hi = sm
                            else:
                                s_lo = sm
                        s_hit = s_lo
                        pe = p0 + s_lo * seg               # on the outer side of the crossing
                        ne = o.grad_local(pe)
                        # Back to the entry side: onto the tangent plane of the first crossing.
                        depth = (pe - p1).dot(ne)
                        if depth > 0.0:
                            pn = p1 + depth * ne
                        contact = True
                        entry = True
                        nloc = ne
                # Push out along the gradient (a few Newton steps on phi = thickness).
                pushed = False
                for _ in range(4):
                    ph = o.sdf_local(pn) - th
                    if ph < 0.0:
                        pn = pn - ph * o.grad_local(pn)
                        contact = True
                        pushed = True
                if contact and ti.static(not mark):
                    # The contact normal: where the surface was first met for a caught crossing
                    # (the vertex now sits on that tangent plane), else where it was pushed to.
                    if pushed or not entry:
                        nloc = o.grad_local(pn)
                    nrm = R1 @ nloc
                    xn = R1 @ pn + c1
                    vo = vlin + omega.cross(xn - c1)
                    vrel = vi - vo
                    vn = vrel.dot(nrm)
                    if vn < 0.0:
                        vt = vrel - vn * nrm
                        vt_len = vt.norm()
                        dvn = -vn
                        vt_new = ti.Vector([0.0, 0.0, 0.0])
                        if vt_len > mu * dvn:
                            vt_new = vt * (1.0 - mu * dvn / vt_len)
                        v[i] = vo + vt_new
                        # Keep x consistent with v (x = x_start + h v) along the tangent over
                        # the part of the substep in contact, so a sticking vertex stays put.
                        xn += (1.0 - s_hit) * h * (vt_new - vt)
                        # On a curved surface that tangential step can dip below the shell.
                        pt = R1.transpose() @ (xn - c1)
                        for _ in range(2):
                            ph = o.sdf_local(pt) - th
                            if ph < 0.0:
                                pt = pt - ph * o.grad_local(pt)
                        xn = R1 @ pt + c1
                    ti.atomic_max(self._moved[None], (xn - x1).norm())
                    x[i] = xn
                    if ti.static(not mark):
                        ti.atomic_add(out[None], 1)
                if ti.static(mark):
                    # Resting on the obstacle at the start of the substep. (Not "inside at the
                    # end": a layer falling onto a resting layer is predicted inside the ground
                    # too, and must not count as supported.)
                    if phi0 < 0.1 * th:
                        out[i] = 1

    # -- contacts as constraints of the strain projection -----------------------------------
    def contact_planes(self, t, out, reach=None, mu_out=None):
        """Write each free vertex's contact half-space at time t into ``out`` (a Taichi ndarray
        of vec4 per vertex, ``StrainLimiter.contact_planes``): for the vertex's nearest
        obstacle within ``reach`` (m, at least ``thickness``) of the thickened surface, the
        tangent plane of that surface as (n, d) with n.x >= d on the free side; elsewhere
        (0, 0, 0, -1e30), which no position violates. ``out`` has two slots per vertex: the
        two nearest planes over the obstacles and their parts (``Obstacle.nearest_two``), so
        a vertex in a concave corner of a body (arm against torso) keeps out of both parts
        instead of being pushed from one into the other by the fix-up passes.

        The strain projection then keeps contact vertices outside while it limits the
        strains, instead of the collider pushing them out afterwards and undoing the limits
        (issue #5). ``reach`` also catches vertices the projection would pull into the
        obstacle. On a curved obstacle the plane is its linearisation: a vertex sliding along
        it by s sinks by about s^2 / (2 radius), which the obstacle pass after the projection
        removes (``test_obstacle_contacts_keep_the_strain_limits`` in tests/test_all_scenes.py)."""
        reach = self.thickness if reach is None else max(float(reach), self.thickness)
        n = self.model.n_verts
        if mu_out is None:
            mu_out = self._mu_scratch(n)
        self._clear_planes(n, out, mu_out)
        for o in self.obstacles:
            c, R = o.pose(t)
            self._planes(o, self.model.state.x, self.model.vert_pinned, n, self.thickness,
                         reach, float(o.mu), ti.Matrix(R), ti.Vector(c), out, mu_out)

    def _mu_scratch(self, n):
        if getattr(self, "_mu_tmp", None) is None or self._mu_tmp.shape[0] < n:
            self._mu_tmp = ti.ndarray(float, max(n, 1))
        return self._mu_tmp

    @ti.kernel
    def _clear_planes(self, n: ti.i32, out: ti.types.ndarray(), mu_out: ti.types.ndarray()):
        for i in range(n):
            mu_out[i] = 0.0
            for j in ti.static(range(2)):
                out[i, j] = ti.Vector([0.0, 0.0, 0.0, -1e30])

    @ti.kernel
    def _planes(self, o: ti.template(), x: ti.template(), pinned: ti.template(), n: ti.i32,
                th: float, reach: float, mu: float, R: mat3, c: vec3,
                out: ti.types.ndarray(), mu_out: ti.types.ndarray()):
        for i in range(n):
            if pinned[i] == 0:
                xi = x[i]
                p = R.transpose() @ (xi - c)
                d1, n1, d2, n2 = o.nearest_two(p)
                for k in ti.static(range(2)):
                    gap = (d1 if k == 0 else d2) - th
                    if gap < reach:
                        nw = R @ (n1 if k == 0 else n2)
                        plane = ti.Vector([nw[0], nw[1], nw[2], nw.dot(xi) - gap])
                        # Keep the two nearest planes, nearest first (unset: gap 1e30).
                        p0, p1 = out[i, 0], out[i, 1]
                        gap0 = p0[0] * xi[0] + p0[1] * xi[1] + p0[2] * xi[2] - p0[3]
                        gap1 = p1[0] * xi[0] + p1[1] * xi[1] + p1[2] * xi[2] - p1[3]
                        if gap < gap0:
                            out[i, 1] = p0
                            out[i, 0] = plane
                            mu_out[i] = mu          # friction of the nearest contact
                        elif gap < gap1:
                            out[i, 1] = plane

    # -- diagnostics -------------------------------------------------------------------------
    def max_penetration(self, t=None):
        """Largest (thickness - sdf) over active vertices and obstacles at time t (default: the
        end of the last resolved substep), clipped at 0: how far a vertex sits inside the
        thickened obstacle. 0 means every vertex is at least ``thickness`` away."""
        t = self._last_t if t is None else t
        n = self.model.n_verts
        worst = 0.0
        for o in self.obstacles:
            c, R = o.pose(t)
            self._maxval[None] = -1e30
            self._max_pen(o, self.model.state.x, n, self.thickness, ti.Matrix(R), ti.Vector(c))
            worst = max(worst, float(self._maxval[None]))
        return worst

    def max_depth(self, t=None):
        """Largest depth below the obstacle surface itself (-sdf), clipped at 0."""
        return max(0.0, self.max_penetration(t) - self.thickness)

    @ti.kernel
    def _max_pen(self, o: ti.template(), x: ti.template(), n: ti.i32, th: float, R: mat3,
                 c: vec3):
        for i in range(n):
            p = R.transpose() @ (x[i] - c)
            ti.atomic_max(self._maxval[None], th - o.sdf_local(p))

    def obstacle_meshes(self, t=None):
        """[(vertices, faces)] of every obstacle at time t, for drawing and export."""
        t = self._last_t if t is None else t
        return [o.mesh_at(t) for o in self.obstacles]
