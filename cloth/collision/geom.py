"""Exact closest-point queries and the primitives' signed distances used by the collision code
(Taichi funcs; arrays come in as arguments, no fields).

Conventions: every function works in ``float`` (Taichi's default float); distances in metres.
The closest-point routines follow the Voronoi-region case analysis of a triangle and the
clamped two-parameter minimisation for two segments (as in Ericson, "Real-Time Collision
Detection", 2005, sections 5.1.5 and 5.1.9), written out here for Taichi.
"""
import taichi as ti


@ti.func
def closest_on_triangle(p, a, b, c):
    """Closest point to ``p`` on triangle (a, b, c).

    Returns (q, w) with q the closest point and w = (wa, wb, wc) its barycentric weights
    (non-negative, summing to 1). Degenerate triangles fall back to the vertex/edge cases."""
    ab = b - a
    ac = c - a
    ap = p - a
    d1 = ab.dot(ap)
    d2 = ac.dot(ap)
    w = ti.Vector([1.0, 0.0, 0.0])
    done = False
    if d1 <= 0.0 and d2 <= 0.0:                         # vertex a region
        done = True
    if not done:
        bp = p - b
        d3 = ab.dot(bp)
        d4 = ac.dot(bp)
        if d3 >= 0.0 and d4 <= d3:                      # vertex b region
            w = ti.Vector([0.0, 1.0, 0.0])
            done = True
        if not done:
            vc = d1 * d4 - d3 * d2
            if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:  # edge ab
                t = d1 / (d1 - d3)
                w = ti.Vector([1.0 - t, t, 0.0])
                done = True
            if not done:
                cp = p - c
                d5 = ab.dot(cp)
                d6 = ac.dot(cp)
                if d6 >= 0.0 and d5 <= d6:              # vertex c region
                    w = ti.Vector([0.0, 0.0, 1.0])
                    done = True
                if not done:
                    vb = d5 * d2 - d1 * d6
                    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:   # edge ac
                        t = d2 / (d2 - d6)
                        w = ti.Vector([1.0 - t, 0.0, t])
                        done = True
                    if not done:
                        va = d3 * d6 - d5 * d4
                        if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:  # edge bc
                            t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
                            w = ti.Vector([0.0, 1.0 - t, t])
                            done = True
                        if not done:                    # face interior
                            den = va + vb + vc
                            if ti.abs(den) > 0.0:
                                s = vb / den
                                u = vc / den
                                w = ti.Vector([1.0 - s - u, s, u])
    q = w[0] * a + w[1] * b + w[2] * c
    return q, w


@ti.func
def closest_segments(p1, q1, p2, q2):
    """Closest points of segments p1-q1 and p2-q2.

    Returns (s, t): the points are p1 + s (q1 - p1) and p2 + t (q2 - p2), s, t in [0, 1]."""
    d1 = q1 - p1
    d2 = q2 - p2
    r = p1 - p2
    a = d1.dot(d1)
    e = d2.dot(d2)
    f = d2.dot(r)
    s = 0.0
    t = 0.0
    tiny = 1e-30
    if a <= tiny and e <= tiny:
        s = 0.0
        t = 0.0
    elif a <= tiny:
        t = ti.math.clamp(f / e, 0.0, 1.0)
    else:
        c = d1.dot(r)
        if e <= tiny:
            s = ti.math.clamp(-c / a, 0.0, 1.0)
        else:
            b = d1.dot(d2)
            den = a * e - b * b
            if den > 1e-14 * a * e:
                s = ti.math.clamp((b * f - c * e) / den, 0.0, 1.0)
            else:
                s = 0.0                                  # parallel: any s works
            t = (b * s + f) / e
            if t < 0.0:
                t = 0.0
                s = ti.math.clamp(-c / a, 0.0, 1.0)
            elif t > 1.0:
                t = 1.0
                s = ti.math.clamp((b - c) / a, 0.0, 1.0)
    return s, t


# -- signed distances of primitives in their local frames -----------------------------------

@ti.func
def sdf_sphere(p, radius):
    return p.norm() - radius


@ti.func
def sdf_plane(p):
    """Half-space z <= 0 is solid; the surface is the plane z = 0."""
    return p[2]


@ti.func
def sdf_capsule(p, half_length, radius):
    """Segment from (0, 0, -half_length) to (0, 0, +half_length), inflated by ``radius``."""
    z = ti.math.clamp(p[2], -half_length, half_length)
    return (p - ti.Vector([0.0, 0.0, z])).norm() - radius


@ti.func
def sdf_box(p, half):
    """Axis-aligned box centred at the origin with half extents ``half`` (exact inside and out)."""
    q = ti.abs(p) - half
    outside = ti.max(q, 0.0).norm()
    inside = ti.min(ti.max(q[0], ti.max(q[1], q[2])), 0.0)
    return outside + inside


# A union of capsules (capsule_union.py): row k of ``prims`` is (a, b, radius), the segment a-b
# inflated by radius (a sphere has a == b). The union's distance is the minimum over the rows.
@ti.func
def _capsule_offset(prims: ti.template(), k, p):
    """p minus the nearest point of primitive k's segment."""
    a = ti.Vector([prims[k, 0], prims[k, 1], prims[k, 2]])
    b = ti.Vector([prims[k, 3], prims[k, 4], prims[k, 5]])
    ab = b - a
    t = 0.0
    L2 = ab.dot(ab)
    if L2 > 1e-20:
        t = ti.math.clamp((p - a).dot(ab) / L2, 0.0, 1.0)
    return p - (a + t * ab)


@ti.func
def sdf_capsule_union(prims: ti.template(), p):
    best = 1e30
    for k in range(prims.shape[0]):
        best = ti.min(best, _capsule_offset(prims, k, p).norm() - prims[k, 6])
    return best


@ti.func
def nearest_two_capsules(prims: ti.template(), p):
    """The two nearest primitives' distances and outward normals (exact, per capsule):
    (d1, n1, d2, n2), d1 <= d2; with one primitive d2 = 1e30."""
    d1, d2 = 1e30, 1e30
    n1 = ti.Vector([0.0, 0.0, 1.0])
    n2 = ti.Vector([0.0, 0.0, 1.0])
    for k in range(prims.shape[0]):
        off = _capsule_offset(prims, k, p)
        dist = off.norm()
        d = dist - prims[k, 6]
        nk = off / dist if dist > 1e-12 else ti.Vector([0.0, 0.0, 1.0])
        if d < d1:
            d2, n2 = d1, n1
            d1, n1 = d, nk
        elif d < d2:
            d2, n2 = d, nk
    return d1, n1, d2, n2


@ti.func
def safe_normalize(v, fallback):
    n = v.norm()
    out = fallback
    if n > 1e-300:
        out = v / n
    return out
