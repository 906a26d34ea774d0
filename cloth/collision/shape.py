"""Obstacle shapes as run-time data, so that every collision kernel compiles once per process.

A shape reaches a kernel as four arguments (``Obstacle.shape_args()``):

    kind    i32: PLANE, SPHERE, CAPSULE, BOX, MESH or UNION
    prm     vector of N_PARAMS floats: prm[P_FD_EPS], the finite-difference step of the
            gradient, then the kind's parameters (layout below)
    prims   ndarray (n, 7) of float: a capsule union's primitives, rows (a, b, radius)
    phi     ndarray (nx, ny, nz) of float: a mesh obstacle's signed-distance grid

A kind that does not use ``prims`` or ``phi`` passes small dummy arrays (``dummy_arrays``): the
kernels are generic over every kind, so their signature must not change with it. ``sdf_local``,
``grad_local`` and ``nearest_two`` branch on ``kind`` at run time (the same branch for every
vertex of a launch). Why not one specialisation per obstacle (``ti.template()`` obstacles with
their sizes as compile-time constants, as before): every new obstacle and every new Simulator
then recompiled the collider's kernels, ~3 s per tshirt Simulator even with fast compile.

Parameter layout after prm[P_FD_EPS]:
    SPHERE   radius
    CAPSULE  half length, radius (segment along local z)
    BOX      half extents (3)
    MESH     grid origin (3), cell size dx
    PLANE, UNION: none
"""
import numpy as np
import taichi as ti
from taichi.lang import impl
from taichi.lang.util import to_numpy_type

from .geom import (nearest_two_capsules, safe_normalize, sdf_box, sdf_capsule,
                   sdf_capsule_union, sdf_plane, sdf_sphere)
from .sdf_grid import lookup

PLANE, SPHERE, CAPSULE, BOX, MESH, UNION = range(6)
N_KINDS = 6
N_PARAMS = 8
P_FD_EPS = 0
P_SHAPE = 1                      # first shape parameter
PRIM_COLS = 7                    # a (3), b (3), radius
params_t = ti.types.vector(N_PARAMS, float)


def make_params(fd_eps, values=()):
    """The ``prm`` kernel argument (a ``params_t``): the finite-difference step, then the
    shape's values. A plain tuple: Taichi converts it at the launch (building a ti.Vector
    here as well cost another ~30 us per launch)."""
    values = [float(v) for v in values]
    if len(values) > N_PARAMS - P_SHAPE:
        raise ValueError(f"a shape has at most {N_PARAMS - P_SHAPE} parameters")
    return tuple([float(fd_eps)] + values + [0.0] * (N_PARAMS - P_SHAPE - len(values)))


_dummies = {"runtime": None, "arrays": None}


def current_runtime():
    """Taichi's runtime object; a new one after ``ti.reset`` (arrays of the old one are gone)."""
    return impl.get_runtime()


def dummy_arrays():
    """(prims, phi) placeholders for shapes without primitives or a grid, one pair per Taichi
    runtime."""
    rt = current_runtime()
    if _dummies["runtime"] is not rt:
        _dummies["arrays"] = (ti.ndarray(float, (1, PRIM_COLS)), ti.ndarray(float, (2, 2, 2)))
        _dummies["runtime"] = rt
    return _dummies["arrays"]


def float_dtype():
    """The numpy type of Taichi's default float (what ``float`` means in the kernels)."""
    return to_numpy_type(impl.get_runtime().default_fp)


def upload(values):
    """A float ndarray holding ``values`` (a numpy array of any shape)."""
    values = np.asarray(values)
    arr = ti.ndarray(float, values.shape)
    arr.from_numpy(np.ascontiguousarray(values, dtype=float_dtype()))
    return arr


# -- the shape funcs, dispatching on kind at run time -----------------------------------------
# Each public func branches once on ``kind`` over the kinds unrolled at compile time
# (``ti.static``), and the branch of a kind holds that kind's code only: a finite-difference
# gradient loops over its six samples inside its kind's branch. Measured (box, sdf and gradient
# at 4e5 points, CPU f64, fast compile): 21 ms with the branch on kind inside each sample,
# 11 ms like this, 8.4 ms with the six samples unrolled as well (which doubled the collider's
# compile time on an empty offline cache, 2.8 s -> 6.6 s); a box kernel of its own took 7.3 ms.

@ti.func
def _sdf_of(k: ti.template(), prm, prims: ti.template(), phi: ti.template(), p):
    """The signed distance of kind ``k`` (a compile-time constant)."""
    d = 0.0
    if ti.static(k == PLANE):
        d = sdf_plane(p)
    elif ti.static(k == SPHERE):
        d = sdf_sphere(p, prm[P_SHAPE])
    elif ti.static(k == CAPSULE):
        d = sdf_capsule(p, prm[P_SHAPE], prm[P_SHAPE + 1])
    elif ti.static(k == BOX):
        d = sdf_box(p, ti.Vector([prm[P_SHAPE], prm[P_SHAPE + 1], prm[P_SHAPE + 2]]))
    elif ti.static(k == MESH):
        o = ti.Vector([prm[P_SHAPE], prm[P_SHAPE + 1], prm[P_SHAPE + 2]])
        d = lookup(phi, o, prm[P_SHAPE + 3], p)
    else:
        d = sdf_capsule_union(prims, p)
    return d


@ti.func
def sdf_local(kind, prm, prims: ti.template(), phi: ti.template(), p):
    """Signed distance at local point p (m, negative inside)."""
    d = 0.0
    for k in ti.static(range(N_KINDS)):
        if kind == k:
            d = _sdf_of(k, prm, prims, phi, p)
    return d


@ti.func
def grad_local(kind, prm, prims: ti.template(), phi: ti.template(), p):
    """Unit outward gradient of the SDF at local point p: the plane's normal and the sphere's
    radial direction exactly; for the other kinds central differences with step
    prm[P_FD_EPS] (exact SDFs have |grad| = 1 almost everywhere; on a medial surface this
    picks a consistent average)."""
    up = ti.Vector([0.0, 0.0, 1.0])
    g = up
    for k in ti.static(range(N_KINDS)):
        if kind == k:
            if ti.static(k == PLANE):
                g = up
            elif ti.static(k == SPHERE):
                g = safe_normalize(p, up)
            else:
                e = prm[P_FD_EPS]
                diff = ti.Vector([0.0, 0.0, 0.0])
                for m in range(6):
                    axis = m // 2
                    s = 1.0 - 2.0 * (m % 2)
                    unit = ti.cast(ti.Vector([axis == 0, axis == 1, axis == 2]), float)
                    diff += (s * _sdf_of(k, prm, prims, phi, p + (s * e) * unit)) * unit
                g = safe_normalize(diff, up)
    return g


@ti.func
def nearest_two(kind, prm, prims: ti.template(), phi: ti.template(), p):
    """The two nearest parts of the shape as (sdf1, normal1, sdf2, normal2), for contact
    planes; a single solid has one part (sdf2 = 1e30). A capsule union gives its two nearest
    primitives: near a concave corner the second part's plane keeps the cloth out of it."""
    d1 = 0.0
    n1 = ti.Vector([0.0, 0.0, 1.0])
    d2 = 1e30
    n2 = ti.Vector([0.0, 0.0, 1.0])
    if kind == UNION:
        d1, n1, d2, n2 = nearest_two_capsules(prims, p)
    else:
        d1 = sdf_local(kind, prm, prims, phi, p)
        n1 = grad_local(kind, prm, prims, phi, p)
    return d1, n1, d2, n2
