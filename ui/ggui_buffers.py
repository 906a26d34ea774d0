"""Vertex buffers for GGUI that live until the frame is drawn.

Why this exists: Taichi 1.7.4's ``SceneV2.mesh / lines / particles`` and ``Canvas.triangles``
copy the geometry into a *temporary* numpy array and hand GGUI its address
(``FieldSource.HostMappedPtr``). GGUI reads that memory only when the frame is rendered
(``window.show()`` or an image capture), after the array has been freed. Whether the freed
memory still holds the vertices depends on the allocator, so meshes vanished from captures at
random: CI's failing reference image, and the dress form that disappeared from frames
(reproduced: the same draw twice in one process, the cloth present in the first capture and
gone from the second).

Here the buffers are numpy arrays owned by a ``VertexBuffers`` object, reused frame to frame
and alive until the next frame is built; they are filled in numpy (no Taichi kernel per
draw) and passed to GGUI's core calls with the same arguments the Python wrappers pass.

Meshes are drawn as one instance with an identity transform (``draw_mesh``). GGUI's mesh
vertex shader (Taichi 1.7.4, shaders/Mesh_vk.vert) always reads an instance transform and
blends it with the identity, ``I * (1 - has) + T * has``; a plain ``scene.mesh`` call has no
transforms (has = 0) and never writes their buffer, so T is whatever the driver's new
allocation held, and NaN * 0 is NaN: every vertex NaN, the mesh gone while lines draw. With
lavapipe that memory comes from the process's heap, so whether the cloth showed depended on
what the process had run before (the window tests failed in a full suite run after other
tests, never alone; reproduced by writing NaN transforms once: every later plain mesh draw
of that renderable vanished).
"""
import numpy as np
from taichi.ui.utils import get_field_info

# GGUI's vertex layout (taichi/ui/staging_buffer.py): position 3, normal 3, texcoord 2, rgba 4.
STRIDE = 12
POS, NORMAL, COLOR = slice(0, 3), slice(3, 6), slice(8, 12)
RADIUS = 3          # particles keep a per-vertex radius in the normal's first slot


class VertexBuffers:
    """Named host buffers, grown when needed and never freed while a frame may read them."""

    def __init__(self):
        self._arrays = {}

    def array(self, key, n, width=STRIDE, dtype=np.float32):
        """A zeroed (n, width) array for ``key``; the storage is reused between frames."""
        buf = self._arrays.get(key)
        if buf is None or buf.shape[0] < n or buf.shape[1:] != (width,) or buf.dtype != dtype:
            buf = np.zeros((max(n, 16) * 3 // 2, width), dtype)
            self._arrays[key] = buf
        view = buf[:n]
        view.fill(0)
        return view

    def vertices(self, key, positions, normals=None, colors=None):
        """Fill ``key``'s vertex buffer (rows = vertices) and return it."""
        positions = np.asarray(positions, np.float32)
        n, dim = positions.shape
        vbo = self.array(key, n)
        vbo[:, :dim] = positions
        if normals is not None:
            vbo[:, NORMAL] = normals
        if colors is not None:
            colors = np.asarray(colors, np.float32)
            vbo[:, 8:8 + colors.shape[1]] = colors
            if colors.shape[1] == 3:
                vbo[:, 11] = 1.0
        return vbo

    def indices(self, key, idx):
        idx = np.asarray(idx, np.int32).reshape(-1)
        buf = self.array(key, len(idx), width=1, dtype=np.int32)
        buf[:, 0] = idx
        return buf.reshape(-1)


def _color(c):
    return tuple(float(v) for v in c)


# One instance transform, the identity (4x4 f32; GGUI transposes it, which keeps it).
IDENTITY = np.eye(4, dtype=np.float32)[None]


def draw_mesh(scene, buffers, key, corners, normals, colors, two_sided=True):
    """Triangles listed corner by corner (3 rows per face), with per-vertex normals and
    colours; one instance with the identity transform, written every draw (see above)."""
    vbo = buffers.vertices(key, corners, normals, colors)
    n = len(vbo)
    scene.scene.mesh_instance(get_field_info(vbo), True, get_field_info(None), (0.5, 0.5, 0.5),
                              two_sided, get_field_info(IDENTITY), 1, 0, n, 0, n, 0, False)


def draw_lines(scene, buffers, key, points, color, width=1.0, indices=None, colors=None):
    """Line segments: consecutive point pairs, or pairs of ``indices``; one ``color``, or
    per-point ``colors`` (N, 3)."""
    vbo = buffers.vertices(key, points, colors=colors)
    n = len(vbo) - len(vbo) % 2
    if indices is None:
        info, count = get_field_info(None), n
    else:
        ind = buffers.indices(key + ".indices", indices)
        info, count = get_field_info(ind), len(ind)
    scene.scene.lines(get_field_info(vbo), info, colors is not None, _color(color), float(width),
                      count, 0, n, 0)


def draw_particles(scene, buffers, key, centers, radius, color):
    vbo = buffers.vertices(key, centers)
    scene.scene.particles(get_field_info(vbo), False, False, _color(color), float(radius),
                          len(vbo), 0)


def draw_circles_2d(canvas, buffers, key, xy, colors, radius):
    """Canvas discs at ``xy`` (window coordinates 0..1, y up), one colour each; ``radius``
    (one, or one per disc) as a fraction of the window's height."""
    vbo = buffers.vertices(key, xy, colors=colors)
    per_disc = np.ndim(radius) > 0
    if per_disc:
        vbo[:, RADIUS] = radius       # GGUI reads a disc's radius from the fourth slot
    redraw_circles_2d(canvas, vbo, float(np.max(radius)) if per_disc else float(radius),
                      per_disc)
    return vbo


def redraw_circles_2d(canvas, vbo, radius, per_disc=True):
    """Draw discs from a vertex buffer ``draw_circles_2d`` filled (in an earlier frame: the
    buffer is kept until its key is drawn again)."""
    canvas.canvas.circles(get_field_info(vbo), True, per_disc, (0.5, 0.5, 0.5), float(radius))


def draw_triangles_2d(canvas, buffers, key, xy, colors):
    """Canvas triangles in window coordinates (0..1, y up), three rows per triangle; returns
    the vertex buffer (``redraw_triangles_2d`` draws it again)."""
    vbo = buffers.vertices(key, xy, colors=colors)
    redraw_triangles_2d(canvas, vbo)
    return vbo


def redraw_triangles_2d(canvas, vbo):
    canvas.canvas.triangles(get_field_info(vbo), get_field_info(None), True, (0.5, 0.5, 0.5))
