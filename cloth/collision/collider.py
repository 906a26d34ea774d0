"""Collision detection and response: rigid obstacles and (optionally) cloth self-collision.

Obstacles are signed distance functions (SDF, metres, negative inside) in their own local frame;
a pose ``(c, R)`` maps local to world, ``x = R p + c``. A static obstacle has a fixed pose; a
scripted one gets its pose from ``path(t)`` (a Python callable of time), evaluated once per
substep on the host at the substep's start and end time and sent to the kernel as arguments.

The collider runs once per substep (docs/method.md §1, step 5):

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

The kernels are module-level functions of ndarray arguments: the model's arrays, the
collider's small result arrays and the obstacle's shape (kind, parameters, primitives, grid; see
``shape.py``). None captures a field or is specialised to an obstacle, so each compiles once
per process however many Colliders, obstacles and models a process builds. The obstacle pass
takes the obstacle's motion over the substep and its scalars in one float array (``_motion``,
``M_*`` indices; it took 21 arguments).

Units: SI. Arrays use ``float`` (Taichi's default float).
"""
import time

import numpy as np
import taichi as ti

# The contact half-spaces' layout is the strain projection's (its work arrays hold them).
from ..ndarrays import A, PackCache, T
from ..strain.buffers import CONTACT_SLOTS, NO_CONTACT
from . import shape
from .obstacles import THICKNESS, CollisionError, Obstacle, mat3, vec3



# Indices into the obstacle pass's ``motion`` array (``Collider._motion``): the substep h, the
# thickness, the obstacle's friction coefficient, the continuous test's sample spacing (<= 0:
# none), and the obstacle's pose at the start (R0, c0) and end (R1, c1) of the substep and its
# linear and angular velocity; R row by row. Why an array: these were 10 of the kernel's 21
# arguments, six of them matrices and vectors built as Taichi objects at every launch; a CPU
# kernel reads a numpy array in place.
M_H, M_TH, M_MU, M_STEP, M_R0, M_C0, M_R1, M_C1, M_VLIN, M_OMEGA = \
    0, 1, 2, 3, 4, 13, 16, 25, 28, 31
N_MOTION = 34
# The cloth's vertex arrays the contact-plane and resting passes read, with the active vertex
# count (those kernels took 14 and 13 arguments). The pose stays a mat3 / vec3 argument: read
# from the motion array instead (before the loop, or in it with full optimisation), tshirt's
# capsule planes came out different in the last bit, which the strain projection's active-set
# model then amplified into visible differences (measured).
ClothPack = ti.types.argpack(x=A, v=A, pinned=A, n_verts=ti.i32)


class Collider:
    """Resolves cloth-obstacle contact (and self-contact when asked) once per substep.

    model: ClothModel (reads ``state.x``, ``state.v``, ``vert_pinned``, ``vert_mass``,
        ``face_verts``, ``edge_verts`` and the active counts at call time).
    obstacles: list of Obstacle.
    thickness: cloth-obstacle separation kept (m), > 0.
    self_collision: also keep the cloth ``self_thickness`` (default ``thickness``) away from
        itself (vertex-triangle and edge-edge repulsion, see ``self_collision``).
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
        self._counter = ti.ndarray(ti.i32, 1)     # contacts of the last obstacle pass
        self._maxval = ti.ndarray(float, 1)       # max_penetration's reduction
        self._moved = ti.ndarray(float, 1)        # largest push of the last obstacle pass (m)
        self._packs = PackCache()
        rt = ti.lang.impl.get_runtime()
        self._motion = np.zeros(N_MOTION, np.float64 if rt.default_fp == ti.f64 else np.float32)
        self._mu_tmp = None
        self.self_solver = None
        if self.self_collision:
            from .self_collision import SelfCollision
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
        """Resolve contacts at the end of the substep [t, t + h]: ``resolve_self`` then
        ``resolve_contacts`` (the Simulator runs them as two stages)."""
        if not h > 0:
            raise CollisionError(f"substep h must be > 0 (got {h})")
        self.resolve_self(h, t)
        self.resolve_contacts(h, t)
        self.last_ms = self.last_ms_self + self.last_ms_obstacles

    def resolve_self(self, h, t):
        """Cloth-cloth repulsion over the substep [t, t + h] (nothing when switched off)."""
        t_start = time.perf_counter()
        if self.self_solver is not None:
            # Flag the vertices touching an obstacle first (read-only pass): the self-collision
            # impulses treat them as heavy, so a layer landing on a layer that rests on the
            # ground is stopped by the upper layer's impulse instead of pushing the lower one
            # into the ground (which the final obstacle pass would undo, closing the gap).
            flags = self.self_solver.prepare_contacts()
            self._mark_pass(h, t, flags)
            self.self_solver.resolve(h)
            self.last_self_pairs = self.self_solver.last_pairs
        ti.sync()
        self.last_ms_self = 1e3 * (time.perf_counter() - t_start)

    def resolve_contacts(self, h, t):
        """The obstacle pass with its continuous test over the substep [t, t + h]."""
        t_start = time.perf_counter()
        self._counter[0] = 0
        self._obstacle_pass(h, t)
        self.last_contacts = int(self._counter[0]) if self.obstacles else 0
        self._last_t = t + h
        self.last_ms_obstacles = 1e3 * (time.perf_counter() - t_start)

    def resolve_obstacles(self, h, t):
        """The obstacle pass of ``resolve`` alone, keeping its statistics (the Simulator's
        ``collision_final`` stage after the projection), without the continuous test: the
        crossings were caught before the projection, and after it ``x - h v`` is no longer
        where the vertex started (the first pass moved x without the matching v), so a
        continuous test from there finds false crossings (measured on tshirt: vertices thrown
        to the far side of an arm, 27 cm). Returns how far it moved the vertex it moved most
        (m)."""
        self._moved[0] = 0.0
        if self.obstacles:
            self._obstacle_pass(h, t, ccd=False)
        return float(self._moved[0])

    def _obstacle_pass(self, h, t, ccd=True):
        st = self.model.state
        n = self.model.n_verts
        for o in self.obstacles:
            c0, R0 = o.pose(t)
            c1, R1 = o.pose(t + h)
            vlin, omega = o.velocity(t, h)
            step = min(o.ccd_step(self.thickness), 1e30) if ccd else -1.0
            mo = self._motion
            mo[M_H], mo[M_TH], mo[M_MU], mo[M_STEP] = h, self.thickness, o.mu, step
            mo[M_R0:M_C0], mo[M_C0:M_R1] = np.ravel(R0), c0
            mo[M_R1:M_C1], mo[M_C1:M_VLIN] = np.ravel(R1), c1
            mo[M_VLIN:M_OMEGA], mo[M_OMEGA:] = vlin, omega
            _resolve_obstacle(*o.shape_args(), st.x, st.v, self.model.vert_pinned, n,
                              self.ccd_samples, mo, self._counter, self._moved)

    def _cloth_pack(self):
        """The model's positions, velocities and pins with its vertex count now (a remesh
        changes it: PackCache then makes a new pack)."""
        m = self.model
        return self._packs.get("cloth", ClothPack, x=m.state.x, v=m.state.v,
                               pinned=m.vert_pinned, n_verts=int(m.n_verts))

    def _mark_pass(self, h, t, flags):
        """The read-only pass before self-collision: set ``flags[i]`` where vertex i started
        the substep on an obstacle (nothing else is written)."""
        cloth = self._cloth_pack()
        for o in self.obstacles:
            c0, R0 = o.pose(t)
            _mark_resting(*o.shape_args(), cloth, h, self.thickness, ti.Matrix(R0),
                          ti.Vector(c0), flags)

    # -- contacts as constraints of the strain projection -----------------------------------
    def contact_planes(self, t, out, reach=None, mu_out=None):
        """Write each free vertex's contact half-space at time t into ``out`` (a Taichi ndarray
        of vec4 per vertex, ``StrainLimiter.contact_planes``): for the vertex's nearest
        obstacle within ``reach`` (m, at least ``thickness``) of the thickened surface, the
        tangent plane of that surface as (n, d) with n.x >= d on the free side; elsewhere
        (0, 0, 0, NO_CONTACT), which no position violates. ``out`` has two slots per vertex: the
        two nearest planes over the obstacles and their parts (``shape.nearest_two``), so
        a vertex in a concave corner of a body (arm against torso) keeps out of both parts
        instead of being pushed from one into the other by the fix-up passes.

        The strain projection then keeps contact vertices outside while it limits the
        strains, instead of the collider pushing them out afterwards and undoing the limits.
        ``reach`` also catches vertices the projection would pull into the obstacle. On a
        curved obstacle the plane is its linearisation: a vertex sliding along it by s sinks
        by about s^2 / (2 radius), which the obstacle pass after the projection removes
        (``test_obstacle_contacts_keep_the_strain_limits`` in tests/test_all_scenes.py)."""
        reach = self.thickness if reach is None else max(float(reach), self.thickness)
        n = self.model.n_verts
        if mu_out is None:
            mu_out = self._mu_scratch(n)
        _clear_planes(n, out, mu_out)
        cloth = self._cloth_pack()
        for o in self.obstacles:
            c, R = o.pose(t)
            _planes(*o.shape_args(), cloth, self.thickness, reach, float(o.mu), ti.Matrix(R),
                    ti.Vector(c), out, mu_out)

    def _mu_scratch(self, n):
        if self._mu_tmp is None or self._mu_tmp.shape[0] < n:
            self._mu_tmp = ti.ndarray(float, max(n, 1))
        return self._mu_tmp

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
            self._maxval[0] = -1e30
            _max_pen(*o.shape_args(), self.model.state.x, n, self.thickness, ti.Matrix(R),
                     ti.Vector(c), self._maxval)
            worst = max(worst, float(self._maxval[0]))
        return worst

    def max_depth(self, t=None):
        """Largest depth below the obstacle surface itself (-sdf), clipped at 0."""
        return max(0.0, self.max_penetration(t) - self.thickness)

    def obstacle_meshes(self, t=None):
        """[(vertices, faces)] of every obstacle at time t, for drawing and export."""
        t = self._last_t if t is None else t
        return [o.mesh_at(t) for o in self.obstacles]


# -- kernels -------------------------------------------------------------------------------------
# Each takes an obstacle as (kind, prm, prims, grid) (``Obstacle.shape_args``, see shape.py) and
# the model's arrays as ndarrays: compiled once per process.

@ti.func
def _vec3_at(a: T, k):
    return ti.Vector([a[k], a[k + 1], a[k + 2]])


@ti.func
def _mat3_at(a: T, k):
    return ti.Matrix([[a[k], a[k + 1], a[k + 2]], [a[k + 3], a[k + 4], a[k + 5]],
                      [a[k + 6], a[k + 7], a[k + 8]]])


@ti.kernel
def _resolve_obstacle(kind: ti.i32, prm: shape.params_t, prims: A, grid: A, x: A, v: A,
                      pinned: A, n: ti.i32, ccd_samples: ti.i32, motion: A, counter: A,
                      moved: A):
    """One obstacle's response (the module docstring); ``counter[0]`` counts the contacts,
    ``moved[0]`` keeps the largest move of a vertex. ``step`` <= 0: no continuous test."""
    h, th, mu, step = motion[M_H], motion[M_TH], motion[M_MU], motion[M_STEP]
    R0, c0 = _mat3_at(motion, M_R0), _vec3_at(motion, M_C0)
    R1, c1 = _mat3_at(motion, M_R1), _vec3_at(motion, M_C1)
    vlin, omega = _vec3_at(motion, M_VLIN), _vec3_at(motion, M_OMEGA)
    for i in range(n):
        if pinned[i] == 0:
            x1 = x[i]
            vi = v[i]
            x0 = x1 - h * vi
            p0 = R0.transpose() @ (x0 - c0)
            p1 = R1.transpose() @ (x1 - c1)
            phi0 = shape.sdf_local(kind, prm, prims, grid, p0) - th
            phi1 = shape.sdf_local(kind, prm, prims, grid, p1) - th
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
                K = ti.min(ti.max(ti.cast(ti.ceil(L / step), ti.i32), 1), ccd_samples)
                s_lo = 0.0
                s_hi = -1.0
                for k in range(1, K + 1):
                    if s_hi < 0.0:
                        s = k / K
                        ph = phi1
                        if k < K:
                            ph = shape.sdf_local(kind, prm, prims, grid, p0 + s * seg) - th
                        if ph < 0.0:
                            s_hi = s
                        else:
                            s_lo = s
                if s_hi >= 0.0:
                    for _ in range(20):
                        sm = 0.5 * (s_lo + s_hi)
                        if shape.sdf_local(kind, prm, prims, grid, p0 + sm * seg) - th < 0.0:
                            s_hi = sm
                        else:
                            s_lo = sm
                    s_hit = s_lo
                    pe = p0 + s_lo * seg               # on the outer side of the crossing
                    ne = shape.grad_local(kind, prm, prims, grid, pe)
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
                ph = shape.sdf_local(kind, prm, prims, grid, pn) - th
                if ph < 0.0:
                    pn = pn - ph * shape.grad_local(kind, prm, prims, grid, pn)
                    contact = True
                    pushed = True
            if contact:
                # The contact normal: where the surface was first met for a caught crossing
                # (the vertex now sits on that tangent plane), else where it was pushed to.
                if pushed or not entry:
                    nloc = shape.grad_local(kind, prm, prims, grid, pn)
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
                    # Only in the pass before the projection: after it x - h v is not where
                    # the vertex started (the projection's friction already held it), and
                    # the step moved a sticking vertex back by a whole h v_t each pass (a
                    # sheet landing on a 20-degree plane, mu 0.8: 10-16 mm a pass, the
                    # limits broken by 0.3 at the frame's end).
                    before_projection = step > 0.0    # the pass with the continuous test
                    if before_projection:
                        xn += (1.0 - s_hit) * h * (vt_new - vt)
                    # On a curved surface that tangential step can dip below the shell.
                    pt = R1.transpose() @ (xn - c1)
                    for _ in range(2):
                        ph = shape.sdf_local(kind, prm, prims, grid, pt) - th
                        if ph < 0.0:
                            pt = pt - ph * shape.grad_local(kind, prm, prims, grid, pt)
                    xn = R1 @ pt + c1
                ti.atomic_max(moved[0], (xn - x1).norm())
                x[i] = xn
                ti.atomic_add(counter[0], 1)


@ti.kernel
def _mark_resting(kind: ti.i32, prm: shape.params_t, prims: A, grid: A, cloth: ClothPack,
                  h: float, th: float, R0: mat3, c0: vec3, flags: A):
    for i in range(cloth.n_verts):
        if cloth.pinned[i] == 0:
            # Resting on the obstacle at the start of the substep. (Not "inside at the end": a
            # layer falling onto a resting layer is predicted inside the ground too, and must
            # not count as supported.)
            p0 = R0.transpose() @ ((cloth.x[i] - h * cloth.v[i]) - c0)
            phi0 = shape.sdf_local(kind, prm, prims, grid, p0) - th
            if phi0 < 0.1 * th:
                flags[i] = 1


@ti.kernel
def _clear_planes(n: ti.i32, out: A, mu_out: A):
    for i in range(n):
        mu_out[i] = 0.0
        for j in ti.static(range(CONTACT_SLOTS)):
            out[i, j] = ti.Vector([0.0, 0.0, 0.0, NO_CONTACT])


@ti.kernel
def _planes(kind: ti.i32, prm: shape.params_t, prims: A, grid: A, cloth: ClothPack, th: float,
            reach: float, mu: float, R: mat3, c: vec3, out: A, mu_out: A):
    for i in range(cloth.n_verts):
        if cloth.pinned[i] == 0:
            xi = cloth.x[i]
            p = R.transpose() @ (xi - c)
            d1, n1, d2, n2 = shape.nearest_two(kind, prm, prims, grid, p)
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


@ti.kernel
def _max_pen(kind: ti.i32, prm: shape.params_t, prims: A, grid: A, x: A, n: ti.i32, th: float,
             R: mat3, c: vec3, maxval: A):
    for i in range(n):
        p = R.transpose() @ (x[i] - c)
        ti.atomic_max(maxval[0], th - shape.sdf_local(kind, prm, prims, grid, p))
