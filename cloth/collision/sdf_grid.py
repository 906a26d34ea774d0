"""Signed-distance grid of a closed triangle mesh, built once in Taichi.

Why a grid and not a BVH of the triangles: the collider asks for the distance *and* its gradient
at every cloth vertex, several times per substep (continuous sampling of the substep's motion,
bisection, push-out iterations). A grid answers each in constant time with 8 (distance) or 48
(central-difference gradient) reads and no branching, which vectorises well on the CPU; a BVH
query costs a tree descent with a data-dependent stack per call, and the sign (inside/outside)
needs a winding number or ray test on top. The price is memory (n^3 floats: 64^3 is 2 MB) and a
resolution limit: features thinner than ~2 cells are smoothed and the lookup is only C0 across
cells, so the cloth thickness should be at least a fraction of a cell for the contact normal to
behave. Rigid motion of the obstacle does not need a rebuild: the grid lives in the obstacle's
local frame.

Construction (Taichi kernels, serial loops where they write shared cells):
1. narrow band: each triangle writes its exact distance into the nodes of its bounding box grown
   by ``band`` cells, keeping the closest triangle per node;
2. fast sweeping: eight ordered sweeps propagate the closest-triangle index to every node and
   recompute the exact distance to that triangle (so the distance far from the surface is the
   exact distance to a nearby-optimal triangle, typically exact);
3. sign: a ray along +z from below every grid column counts crossings with the triangles, using
   an orientation test with deterministic tie-breaking so a ray through a shared edge or vertex
   is counted once; nodes with an odd count below them are inside.
The sign needs a closed (watertight) mesh; an open mesh gives streaks along z.
"""
import time

import numpy as np
import taichi as ti
from taichi.lang.util import to_numpy_type

from .geom import closest_on_triangle


@ti.func
def _orient2(x1, y1, x2, y2):
    """Sign of the 2-D cross product with ties broken by coordinates, so that a point on a
    shared edge belongs to exactly one of the two triangles (consistent for all callers)."""
    area = y1 * x2 - x1 * y2
    s = 0
    if area > 0.0:
        s = 1
    elif area < 0.0:
        s = -1
    elif y2 > y1:
        s = 1
    elif y2 < y1:
        s = -1
    elif x1 > x2:
        s = 1
    elif x1 < x2:
        s = -1
    return s


@ti.func
def _tri(tris: ti.template(), t):
    a = ti.Vector([tris[t, 0, 0], tris[t, 0, 1], tris[t, 0, 2]])
    b = ti.Vector([tris[t, 1, 0], tris[t, 1, 1], tris[t, 1, 2]])
    c = ti.Vector([tris[t, 2, 0], tris[t, 2, 1], tris[t, 2, 2]])
    return a, b, c


@ti.func
def _tri_dist(tris: ti.template(), t, p):
    a, b, c = _tri(tris, t)
    q, _w = closest_on_triangle(p, a, b, c)
    return (p - q).norm()


# The build kernels take numpy arrays (ndarray arguments), so they compile once per process
# instead of once per obstacle as data-oriented methods on fields would.
@ti.kernel
def _narrow_band(tris: ti.types.ndarray(), phi: ti.types.ndarray(), closest: ti.types.ndarray(),
                 o: ti.types.vector(3, float), dx: float, band: ti.i32):
    nx, ny, nz = phi.shape[0], phi.shape[1], phi.shape[2]
    for i, j, k in ti.ndrange(nx, ny, nz):
        phi[i, j, k] = 1e30
        closest[i, j, k] = -1
    ti.loop_config(serialize=True)
    for t in range(tris.shape[0]):
        a, b, c = _tri(tris, t)
        lo = ti.min(a, ti.min(b, c))
        hi = ti.max(a, ti.max(b, c))
        i0 = ti.max(ti.cast(ti.floor((lo - o) / dx), ti.i32) - band, 0)
        i1 = ti.cast(ti.ceil((hi - o) / dx), ti.i32) + band
        i1 = ti.min(i1, ti.Vector([nx - 1, ny - 1, nz - 1]))
        for i in range(i0[0], i1[0] + 1):
            for j in range(i0[1], i1[1] + 1):
                for k in range(i0[2], i1[2] + 1):
                    p = o + dx * ti.Vector([i, j, k])
                    d = _tri_dist(tris, t, p)
                    if d < phi[i, j, k]:
                        phi[i, j, k] = d
                        closest[i, j, k] = t


@ti.func
def _try(tris: ti.template(), phi: ti.template(), closest: ti.template(), i, j, k, ni, nj, nk,
         p):
    t = closest[ni, nj, nk]
    if t >= 0 and t != closest[i, j, k]:
        d = _tri_dist(tris, t, p)
        if d < phi[i, j, k]:
            phi[i, j, k] = d
            closest[i, j, k] = t


@ti.kernel
def _sweep(tris: ti.types.ndarray(), phi: ti.types.ndarray(), closest: ti.types.ndarray(),
           o: ti.types.vector(3, float), dx: float, di: ti.i32, dj: ti.i32, dk: ti.i32):
    nx, ny, nz = phi.shape[0], phi.shape[1], phi.shape[2]
    ti.loop_config(serialize=True)
    for ii in range(nx):
        i = ii if di > 0 else nx - 1 - ii
        for jj in range(ny):
            j = jj if dj > 0 else ny - 1 - jj
            for kk in range(nz):
                k = kk if dk > 0 else nz - 1 - kk
                p = o + dx * ti.Vector([i, j, k])
                if 0 <= i - di < nx:
                    _try(tris, phi, closest, i, j, k, i - di, j, k, p)
                if 0 <= j - dj < ny:
                    _try(tris, phi, closest, i, j, k, i, j - dj, k, p)
                if 0 <= k - dk < nz:
                    _try(tris, phi, closest, i, j, k, i, j, k - dk, p)


@ti.kernel
def _count_crossings(tris: ti.types.ndarray(), crossings: ti.types.ndarray(),
                     o: ti.types.vector(3, float), dx: float):
    nx, ny, nz = crossings.shape[0], crossings.shape[1], crossings.shape[2]
    for i, j, k in ti.ndrange(nx, ny, nz):
        crossings[i, j, k] = 0
    ti.loop_config(serialize=True)
    for t in range(tris.shape[0]):
        a, b, c = _tri(tris, t)
        lo = ti.min(a, ti.min(b, c))
        hi = ti.max(a, ti.max(b, c))
        i0 = ti.max(ti.cast(ti.ceil((lo[0] - o[0]) / dx), ti.i32), 0)
        j0 = ti.max(ti.cast(ti.ceil((lo[1] - o[1]) / dx), ti.i32), 0)
        i1 = ti.min(ti.cast(ti.floor((hi[0] - o[0]) / dx), ti.i32), nx - 1)
        j1 = ti.min(ti.cast(ti.floor((hi[1] - o[1]) / dx), ti.i32), ny - 1)
        for i in range(i0, i1 + 1):
            for j in range(j0, j1 + 1):
                px = o[0] + i * dx
                py = o[1] + j * dx
                ax, ay = a[0] - px, a[1] - py
                bx, by = b[0] - px, b[1] - py
                cx, cy = c[0] - px, c[1] - py
                sa = _orient2(bx, by, cx, cy)
                sb = _orient2(cx, cy, ax, ay)
                sc = _orient2(ax, ay, bx, by)
                if sa != 0 and sa == sb and sb == sc:
                    wa = by * cx - bx * cy
                    wb = cy * ax - cx * ay
                    wc = ay * bx - ax * by
                    den = wa + wb + wc
                    if den != 0.0:
                        z = (wa * a[2] + wb * b[2] + wc * c[2]) / den
                        kz = ti.max(ti.cast(ti.ceil((z - o[2]) / dx), ti.i32), 0)
                        if kz < nz:
                            crossings[i, j, kz] += 1


@ti.kernel
def _apply_sign(phi: ti.types.ndarray(), crossings: ti.types.ndarray()):
    for i, j in ti.ndrange(phi.shape[0], phi.shape[1]):
        count = 0
        for k in range(phi.shape[2]):
            count += crossings[i, j, k]
            if count % 2 == 1:
                phi[i, j, k] = -phi[i, j, k]


@ti.func
def lookup(phi: ti.template(), o, dx, p):
    """The grid ``phi`` (an array argument, node (i, j, k) at ``o + (i, j, k) dx``) at local
    point p: trilinear interpolation; outside the grid, the distance to the grid box is added to
    the value at the nearest box point (the grid is padded so that point is outside)."""
    nx, ny, nz = phi.shape[0], phi.shape[1], phi.shape[2]
    top = o + dx * ti.Vector([nx - 1, ny - 1, nz - 1])
    pc = ti.min(ti.max(p, o), top)
    extra = (p - pc).norm()
    g = (pc - o) / dx
    i0 = ti.min(ti.max(ti.cast(ti.floor(g), ti.i32), 0), ti.Vector([nx - 2, ny - 2, nz - 2]))
    f = g - ti.cast(i0, float)
    i, j, k = i0[0], i0[1], i0[2]
    c00 = phi[i, j, k] * (1 - f[0]) + phi[i + 1, j, k] * f[0]
    c10 = phi[i, j + 1, k] * (1 - f[0]) + phi[i + 1, j + 1, k] * f[0]
    c01 = phi[i, j, k + 1] * (1 - f[0]) + phi[i + 1, j, k + 1] * f[0]
    c11 = phi[i, j + 1, k + 1] * (1 - f[0]) + phi[i + 1, j + 1, k + 1] * f[0]
    c0 = c00 * (1 - f[1]) + c10 * f[1]
    c1 = c01 * (1 - f[1]) + c11 * f[1]
    return c0 * (1 - f[2]) + c1 * f[2] + extra


class SDFGrid:
    """Signed distances on a regular grid: ``phi[i, j, k]`` (a numpy array in Taichi's default
    float) at ``origin + (i, j, k) * dx``. The collider reads it through ``lookup`` from an
    ndarray the obstacle uploads (``MeshObstacle``), so no kernel is specialised to a grid.
    ``build_seconds``: wall time of the construction (the first grid in a process also pays
    for compiling the build kernels, ~1 s)."""

    def __init__(self, vertices, faces, resolution=64, pad_cells=3, band=1, sweeps=2):
        vertices = np.asarray(vertices, dtype=np.float64)
        faces = np.asarray(faces, dtype=np.int64)
        if len(faces) == 0:
            raise ValueError("mesh obstacle has no faces")
        lo, hi = vertices.min(0), vertices.max(0)
        ext = hi - lo
        if not np.all(np.isfinite(ext)) or ext.max() <= 0:
            raise ValueError("mesh obstacle has a degenerate bounding box")
        resolution = int(resolution)
        if resolution < 8:
            raise ValueError(f"SDF grid resolution must be >= 8 (got {resolution})")
        self.dx = float(ext.max() / max(resolution - 2 * pad_cells - 1, 1))
        self.origin = tuple(float(c) for c in lo - pad_cells * self.dx)
        self.shape = tuple(int(np.ceil(e / self.dx)) + 2 * pad_cells + 1 for e in ext)
        self.n_tris = len(faces)
        fp = to_numpy_type(ti.lang.impl.get_runtime().default_fp)
        t0 = time.perf_counter()
        tris = np.ascontiguousarray(vertices[faces], dtype=fp)       # (T, 3, 3)
        phi = np.zeros(self.shape, dtype=fp)
        closest = np.zeros(self.shape, dtype=np.int32)
        crossings = np.zeros(self.shape, dtype=np.int32)
        o = ti.Vector(self.origin)
        _narrow_band(tris, phi, closest, o, self.dx, int(band))
        for _ in range(int(sweeps)):
            for d in [(1, 1, 1), (-1, 1, 1), (1, -1, 1), (-1, -1, 1),
                      (1, 1, -1), (-1, 1, -1), (1, -1, -1), (-1, -1, -1)]:
                _sweep(tris, phi, closest, o, self.dx, d[0], d[1], d[2])
        _count_crossings(tris, crossings, o, self.dx)
        _apply_sign(phi, crossings)
        ti.sync()
        self.phi = phi
        self.build_seconds = time.perf_counter() - t0

    def phi_numpy(self):
        return self.phi.copy()
