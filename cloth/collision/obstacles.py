"""Obstacles: rigid bodies as signed distance functions (SDF, metres, negative inside) in
their own local frame; a pose ``(c, R)`` maps local to world, ``x = R p + c``. A static
obstacle has a fixed pose; a scripted one gets its pose from ``path(t)`` (a Python callable
of time), evaluated once per substep on the host and sent to the kernels as arguments.

The shape, too, reaches the kernels as arguments (``Obstacle.shape_args``: a kind id, a small
parameter vector and two arrays, see ``shape.py``), never as a compile-time specialisation: every
collision kernel compiles once per process, however many obstacles of whatever kinds and sizes
a process builds.
"""
import numpy as np
import taichi as ti

from .. import backend
from . import shape
from .sdf_grid import SDFGrid

vec3 = ti.types.vector(3, float)
mat3 = ti.types.matrix(3, 3, float)


# The distance cloth keeps from obstacles (m) unless a scene says otherwise: a few
# millimetres, about a fabric's thickness (scenes' collision.thickness; tshirt uses 4 mm).
THICKNESS = 0.005


class CollisionError(ValueError):
    """Bad obstacle or collider settings; the message names the fix."""


def rotation_between(a, b):
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

class Obstacle:
    """Base class: a rigid solid with a local signed distance, one of the kinds of
    ``shape.py`` (``kind_id``) with its parameters (``shape_params``) and, for a capsule union
    or a mesh, its primitives or grid (``host_prims``, ``host_phi``).

    position, rotation: the static pose (rotation a 3x3 world-from-local matrix).
    path: optional ``path(t) -> position`` or ``-> (position, rotation)``; overrides the
        static pose (rotation None keeps the static rotation).
    mu: Coulomb friction coefficient against the cloth.
    Shape parameters are read on the host at every launch, but a capsule union's primitives
    and a mesh's grid are copied to Taichi once: make a new obstacle to change those."""

    kind = "obstacle"
    kind_id = None               # shape.PLANE, shape.SPHERE, ...

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

    def shape_params(self):
        """The kind's parameters after the finite-difference step (layout: ``shape.py``)."""
        return ()

    def host_prims(self):
        """(n, 7) primitives (a, b, radius) of a capsule union; None for other kinds."""
        return None

    def host_phi(self):
        """The signed-distance grid of a mesh obstacle; None for other kinds."""
        return None

    # the shape as kernel arguments ----------------------------------------------------------
    def shape_args(self):
        """(kind, prm, prims, phi): this shape as the arguments of the collision kernels (see
        ``shape.py``). The arrays are copied to Taichi on first use (and again after a
        ``ti.reset``); kinds without primitives or a grid share the dummy arrays."""
        if self.kind_id is None:
            raise CollisionError(f"{type(self).__name__} has no shape kind: use Plane, Sphere, "
                                 "Capsule, Box, MeshObstacle or CapsuleUnion")
        rt = shape.current_runtime()
        dev = self.__dict__.get("_device")
        if dev is None or dev[0] is not rt:
            prims, phi = shape.dummy_arrays()
            host_prims, host_phi = self.host_prims(), self.host_phi()
            if host_prims is not None:
                prims = shape.upload(host_prims)
            if host_phi is not None:
                phi = shape.upload(host_phi)
            dev = self._device = (rt, prims, phi)
        return (self.kind_id, shape.make_params(self.fd_eps, self.shape_params()), dev[1],
                dev[2])

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
        return self._evaluate(points, t, True)

    def distance(self, points, t=0.0):
        """``sdf``'s phi alone (N,): without the gradient, which most kinds take by central
        differences (six more evaluations a point; the remesher's sizing reads the distance
        every frame: the T-shirt's body 3.5 ms a call with it at 2k points)."""
        return self._evaluate(points, t, False)[0]

    def _evaluate(self, points, t, with_grad):
        # In Taichi's default float (f32 kernels get f32 arrays), returned as float64.
        fp = shape.float_dtype()
        pts = np.ascontiguousarray(np.asarray(points, np.float64).reshape(-1, 3), dtype=fp)
        phi = np.zeros(len(pts), fp)
        grad = np.zeros((len(pts) if with_grad else 1, 3), fp)
        c, R = self.pose(t)
        _eval(*self.shape_args(), pts, phi, grad, int(with_grad), ti.Matrix(R), ti.Vector(c))
        return phi.astype(np.float64, copy=False), grad.astype(np.float64, copy=False)


@ti.kernel
def _eval(kind: ti.i32, prm: shape.params_t, prims: ti.types.ndarray(), grid: ti.types.ndarray(),
          pts: ti.types.ndarray(), phi: ti.types.ndarray(), grad: ti.types.ndarray(),
          with_grad: ti.i32, R: mat3, c: vec3):
    for i in range(pts.shape[0]):
        x = ti.Vector([pts[i, 0], pts[i, 1], pts[i, 2]])
        p = R.transpose() @ (x - c)
        phi[i] = shape.sdf_local(kind, prm, prims, grid, p)
        if with_grad:
            g = R @ shape.grad_local(kind, prm, prims, grid, p)
            for d in ti.static(range(3)):
                grad[i, d] = g[d]


class Plane(Obstacle):
    """The half-space behind a plane through ``point`` with outward unit ``normal``.
    Drawn as a square of side ``draw_size`` (m)."""

    kind = "plane"
    kind_id = shape.PLANE

    def __init__(self, point=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0), mu=0.3, path=None,
                 draw_size=4.0):
        n = np.asarray(normal, np.float64)
        if not np.linalg.norm(n) > 0:
            raise CollisionError("plane normal must be non-zero")
        self.draw_size = float(draw_size)
        super().__init__(mu=mu, position=point, rotation=rotation_between([0, 0, 1], n),
                         path=path)

    def size(self):
        return 1.0

    def local_mesh(self):
        s = self.draw_size / 2
        v = np.array([[-s, -s, 0], [s, -s, 0], [s, s, 0], [-s, s, 0]], float)
        return v, np.array([[0, 1, 2], [0, 2, 3]])


class Sphere(Obstacle):
    kind = "sphere"
    kind_id = shape.SPHERE

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
        import trimesh      # here: 0.7 s to import, and only meshes need it
        m = trimesh.creation.icosphere(subdivisions=3, radius=self.radius)
        return m.vertices, m.faces

    def shape_params(self):
        return (self.radius,)


class Capsule(Obstacle):
    """A segment of length ``length`` along the local z axis, inflated by ``radius``;
    ``rotation`` (or the path) orients it."""

    kind = "capsule"
    kind_id = shape.CAPSULE

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
        import trimesh      # here: 0.7 s to import, and only meshes need it
        m = trimesh.creation.capsule(height=self.length, radius=self.radius, count=[24, 24])
        return m.vertices, m.faces

    def shape_params(self):
        return (0.5 * self.length, self.radius)


class Box(Obstacle):
    """An oriented box with full side lengths ``extents`` (m)."""

    kind = "box"
    kind_id = shape.BOX

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
        import trimesh      # here: 0.7 s to import, and only meshes need it
        m = trimesh.creation.box(extents=[2 * h for h in self.half])
        return m.vertices, m.faces

    def shape_params(self):
        return self.half


class MeshObstacle(Obstacle):
    """A closed triangle mesh (OBJ/PLY/STL/GLB via trimesh, or given arrays) turned once into a
    signed-distance grid (see ``sdf_grid``). ``resolution`` is the number of cells along
    the longest side. ``scale`` and ``offset`` are applied to the file's vertices first."""

    kind = "mesh"
    kind_id = shape.MESH

    def __init__(self, source, resolution=64, mu=0.3, position=(0.0, 0.0, 0.0), rotation=None,
                 path=None, scale=1.0, offset=(0.0, 0.0, 0.0)):
        import trimesh      # here: 0.7 s to import, and only meshes need it
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

    def shape_params(self):
        return self.grid.origin + (self.grid.dx,)

    def host_phi(self):
        return self.grid.phi

