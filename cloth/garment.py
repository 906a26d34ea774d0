"""Cloth meshes from OBJ files: texture coordinates (``vt``) are the material coordinates.

    g = load_garment("shirt.obj", uv_scale="auto", warp="u")
    g.mesh          MeshArrays (uv in metres, x = the file's positions, grain from ``warp``)
    g.stitches      (K, 2) pairs of vertices that were one vertex of the file (a UV seam)
    g.islands       (F,) island (panel) index of every face

A garment exported from a pattern tool has one UV island per panel, at an arbitrary scale, and
its panels share vertices along the seams (one ``v`` used with a different ``vt`` on each
side). Loom needs every panel flat in its own material space, so each (v, vt) pair of the file
becomes a vertex; the copies of one file vertex are sewn back together by stitch pairs, the
seams that ``tshirt`` simulates (``sim.stitch_stiffness`` springs and, with strain limiting,
equality constraints of the projection).

``uv_scale``: metres per vt unit (a number), or ``"auto"``: each island is scaled so that its
material area equals its area in the file's 3-D positions (the garment as modelled is taken to
be unstretched on average). ``warp``: ``"u"`` (default), ``"v"``, or an angle in degrees from
material u, counter-clockwise.

Every check that can fail does so here, before a Taichi kernel is compiled, with one line that
names the problem and the fix (``ConfigError``): a missing file, no ``vt``, NaN or infinite
numbers, face indices out of range, faces without a ``vt`` index, non-manifold edges, zero-area
or flipped material triangles, a mesh too large for the memory. Polygons with more than three
corners are split into triangle fans (``GarmentMesh.notes`` says how many).

The OBJ is read line by line here rather than with trimesh: trimesh splits the seams itself but
forgets which copies were one vertex (the stitches) and cannot say on which line a problem is.
"""
import os
from dataclasses import dataclass, field

import numpy as np

from .config import ConfigError
from .model import MeshArrays, grain_from_angle

# Peak memory per triangle of a run, measured (README: 2.0 GB peak RSS at 100k triangles).
BYTES_PER_FACE = 20_000
# Bytes of OBJ text per face, at least (a face line plus its share of v and vt lines).
MIN_OBJ_BYTES_PER_FACE = 24


@dataclass
class GarmentMesh:
    mesh: MeshArrays
    stitches: np.ndarray            # (K, 2) int32
    islands: np.ndarray             # (F,) int
    island_scale: np.ndarray        # (I,) metres per vt unit of each island
    source_vertex: np.ndarray       # (V,) index of the file vertex each vertex copies
    notes: list = field(default_factory=list)


def available_memory():
    """Bytes of memory available now (Linux: MemAvailable), or None when unknown."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def check_size(n_faces, max_faces, what, memory=None):
    """Refuse a mesh of ``n_faces`` above ``max_faces`` or beyond the memory available."""
    if max_faces and n_faces > max_faces:
        raise ConfigError(f"{what} has {n_faces} triangles, more than cloth.max_faces = "
                          f"{max_faces}: decimate the mesh, or raise cloth.max_faces if the "
                          "machine has the memory (about 20 kB per triangle)")
    memory = available_memory() if memory is None else memory
    if memory is not None and n_faces * BYTES_PER_FACE > memory:
        raise ConfigError(f"{what} has {n_faces} triangles, which needs about "
                          f"{n_faces * BYTES_PER_FACE / 1e9:.1f} GB but only "
                          f"{memory / 1e9:.1f} GB of memory is available: decimate the mesh")


def _index(token, count, lineno, path, kind):
    i = int(token)
    j = i - 1 if i > 0 else count + i     # OBJ: 1-based, negative = relative to the end
    if i == 0 or j < 0:
        raise ConfigError(f"{path}:{lineno}: face refers to {kind} {i}, which does not exist "
                          f"({count} {kind}s so far): fix the face indices (1-based)")
    return j


def read_obj(path, max_faces=None, memory=None):
    """(v (N,3), vt (T,2), corners: list of [(vi, ti), ...] per face, face line numbers).
    Raises ConfigError with the file and line of the first problem."""
    if not os.path.isfile(path):
        raise ConfigError(f"mesh file '{path}' not found: give an existing OBJ file (paths in a "
                          "scene file are relative to the scene file)")
    size = os.path.getsize(path)
    if max_faces or memory is not None or available_memory() is not None:
        # The file cannot hold more faces than this; refuse hopeless files before reading.
        bound = size // MIN_OBJ_BYTES_PER_FACE
        mem = available_memory() if memory is None else memory
        if mem is not None and bound * BYTES_PER_FACE > 4 * mem:
            raise ConfigError(f"mesh file '{path}' is {size / 1e9:.1f} GB, too large for the "
                              f"{mem / 1e9:.1f} GB of memory available: decimate the mesh")
    v, vt, faces, lines = [], [], [], []
    with open(path, "r", errors="replace") as fh:
        for lineno, line in enumerate(fh, 1):
            parts = line.split()
            if not parts or parts[0].startswith("#"):
                continue
            key = parts[0]
            try:
                if key == "v":
                    v.append([float(t) for t in parts[1:4]])
                    if len(v[-1]) != 3:
                        raise ValueError
                elif key == "vt":
                    vt.append([float(t) for t in parts[1:3]])
                    if len(vt[-1]) != 2:
                        raise ValueError
                elif key == "f":
                    corners = []
                    for tok in parts[1:]:
                        s = tok.split("/")
                        vi = _index(s[0], len(v), lineno, path, "vertex")
                        if len(s) < 2 or s[1] == "":
                            raise ConfigError(
                                f"{path}:{lineno}: face corner '{tok}' has no texture "
                                "coordinate index: every corner needs v/vt (the vt are the "
                                "material coordinates); export the OBJ with UVs")
                        ti = _index(s[1], len(vt), lineno, path, "texture coordinate")
                        corners.append((vi, ti))
                    if len(corners) < 3:
                        raise ConfigError(f"{path}:{lineno}: a face needs at least 3 corners "
                                          f"(got {len(corners)})")
                    faces.append(corners)
                    lines.append(lineno)
            except ConfigError:
                raise
            except ValueError:
                raise ConfigError(f"{path}:{lineno}: cannot read '{line.strip()[:60]}': "
                                  f"'{key}' needs {3 if key == 'v' else 2} numbers") from None
    if not faces:
        raise ConfigError(f"mesh file '{path}' has no faces: give an OBJ with triangles "
                          "('f' lines)")
    if not vt:
        raise ConfigError(f"mesh file '{path}' has no texture coordinates (vt): the cloth's "
                          "material coordinates come from them; export the OBJ with UVs")
    v, vt = np.array(v, np.float64), np.array(vt, np.float64)
    for arr, kind, key in ((v, "vertex", "v"), (vt, "texture coordinate", "vt")):
        bad = ~np.all(np.isfinite(arr), axis=1)
        if bad.any():
            raise ConfigError(f"mesh file '{path}': {int(bad.sum())} {kind} line(s) ('{key}') "
                              f"hold NaN or infinite numbers (first: {key} "
                              f"{int(np.argmax(bad)) + 1}): fix the export")
    # Forward references are legal in OBJ syntax only if the element exists by the end.
    for corners, lineno in zip(faces, lines):
        for vi, ti in corners:
            if vi >= len(v) or ti >= len(vt):
                raise ConfigError(f"{path}:{lineno}: face refers to a missing "
                                  f"{'vertex' if vi >= len(v) else 'texture coordinate'}: "
                                  "fix the face indices (1-based)")
    return v, vt, faces, lines


def triangulate(faces, lines):
    """Fan triangulation of polygons: (tris (F,3,2) of (vi, ti), line of each triangle,
    number of polygons split)."""
    tris, tlines, split = [], [], 0
    for corners, lineno in zip(faces, lines):
        if len(corners) > 3:
            split += 1
        for k in range(1, len(corners) - 1):
            tris.append((corners[0], corners[k], corners[k + 1]))
            tlines.append(lineno)
    return np.array(tris, np.int64), np.array(tlines), split


def _islands(faces, n_verts):
    """Connected components of faces across shared edges (UV islands): (F,) labels 0..I-1."""
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    face_of = np.tile(np.arange(len(faces)), 3)
    key = np.sort(edges, axis=1)
    order = np.lexsort((key[:, 1], key[:, 0]))
    k = key[order]
    same = np.all(k[1:] == k[:-1], axis=1)
    pairs = np.stack([face_of[order][:-1][same], face_of[order][1:][same]], axis=1)
    labels = np.arange(len(faces))
    a, b = pairs[:, 0], pairs[:, 1]
    while True:           # min-label propagation with pointer jumping
        old = labels.copy()
        m = np.minimum(labels[a], labels[b])
        np.minimum.at(labels, a, m)
        np.minimum.at(labels, b, m)
        labels = labels[labels]
        if np.array_equal(labels, old):
            break
    return np.unique(labels, return_inverse=True)[1].reshape(-1)


def _edge_use(faces):
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]),
                    axis=1)
    uniq, inverse, counts = np.unique(edges, axis=0, return_inverse=True, return_counts=True)
    return uniq, inverse.reshape(-1), counts


def _fan_split_vertex(faces, n_verts):
    """A vertex whose triangles form more than one fan (they meet only at the vertex, sharing
    no edge around it): (vertex, a face of its second fan, the number of fans), or None. The
    faces around a vertex are joined where two of them share an edge through it."""
    corner = np.arange(3 * len(faces))                 # corner 3 f + k: faces[f, k]
    parent = corner.copy()

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    where = {}
    for f, tri in enumerate(faces):
        for k in range(3):
            a, b = int(tri[k]), int(tri[(k + 1) % 3])
            key = (min(a, b), max(a, b))
            ends = {a: 3 * f + k, b: 3 * f + (k + 1) % 3}
            other = where.setdefault(key, ends)
            if other is not ends:                        # the edge's second face: join
                for v in key:
                    parent[root(ends[v])] = root(other[v])
    roots = np.array([root(i) for i in corner])
    verts = faces.reshape(-1)
    order = np.lexsort((roots, verts))
    v_s, r_s = verts[order], roots[order]
    new_fan = np.r_[True, (v_s[1:] != v_s[:-1]) | (r_s[1:] != r_s[:-1])]
    fans = np.bincount(v_s[new_fan], minlength=n_verts)
    if fans.max(initial=0) <= 1:
        return None
    vert = int(np.argmax(fans))
    second = order[new_fan & (v_s == vert)][1]
    return vert, int(second // 3), int(fans[vert])


def build_garment(v, vt, tris, tri_lines, path, uv_scale=1.0, warp="u"):
    """Split along UV seams, scale, orient and check. See the module docstring."""
    # One vertex per (file vertex, texture coordinate) pair used by a corner.
    pairs = tris.reshape(-1, 2)
    uniq, inv = np.unique(pairs, axis=0, return_inverse=True)
    faces = inv.reshape(-1, 3).astype(np.int64)
    src_v, src_t = uniq[:, 0], uniq[:, 1]
    x, uv = v[src_v], vt[src_t].copy()
    notes = []

    # Non-manifold edges: more than two triangles on one edge (in material space).
    edges, inverse, counts = _edge_use(faces)
    if counts.max() > 2:
        e = int(np.argmax(counts))
        f = int(np.flatnonzero(inverse == e)[0] % len(faces))
        raise ConfigError(f"{path}:{tri_lines[f]}: non-manifold edge: {counts[e]} faces share "
                          f"one edge ({int((counts > 2).sum())} such edges): the cloth must be "
                          "a surface; remove the extra faces or split the panels")
    bowtie = _fan_split_vertex(faces, len(uv))
    if bowtie is not None:
        vert, f, fans = bowtie
        raise ConfigError(f"{path}:{tri_lines[f]}: vertex {int(src_v[vert]) + 1} joins {fans} "
                          "separate fans of triangles that share no edge there (a bowtie): "
                          "the cloth must be a surface; give each fan its own vertex, or join "
                          "the fans with triangles")
    islands = _islands(faces, len(uv))
    n_isl = int(islands.max()) + 1

    # Orientation in material space: counter-clockwise, consistently within each island. An
    # island cut mirrored (all clockwise) is turned over; a mixed one is refused.
    a, b, c = uv[faces[:, 0]], uv[faces[:, 1]], uv[faces[:, 2]]
    area2 = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    span = np.ptp(uv, axis=0).max()
    tiny = 1e-10 * max(span, 1e-300) ** 2
    zero = np.abs(area2) <= tiny
    if zero.any():
        f = int(np.argmax(zero))
        raise ConfigError(f"{path}:{tri_lines[f]}: {int(zero.sum())} triangle(s) have zero area "
                          "in material space (their vt are collinear or repeated): fix the UV "
                          "layout of those faces")
    flipped_islands = 0
    for i in range(n_isl):
        sel = islands == i
        neg = area2[sel] < 0
        if neg.all():
            faces[sel] = faces[sel][:, ::-1]
            flipped_islands += 1
        elif neg.any():
            minority = neg if neg.sum() <= (~neg).sum() else ~neg
            f = int(np.flatnonzero(sel)[np.argmax(minority)])
            raise ConfigError(f"{path}:{tri_lines[f]}: {int(minority.sum())} triangle(s) of UV "
                              f"island {i} are flipped in material space (their vt wind the "
                              "other way from their neighbours', a fold in the UV layout): "
                              "unfold the UVs so the island lies flat without overlaps")
    if flipped_islands:
        notes.append(f"{flipped_islands} UV island(s) were laid out mirrored; their faces were "
                     "turned over")

    # Scale: metres per vt unit, global or per island.
    scale = np.ones(n_isl)
    if isinstance(uv_scale, str):
        if uv_scale != "auto":
            raise ConfigError(f"cloth.uv_scale takes a number (metres per vt unit) or \"auto\" "
                              f"(got '{uv_scale}')")
        area3 = 0.5 * np.linalg.norm(np.cross(x[faces[:, 1]] - x[faces[:, 0]],
                                              x[faces[:, 2]] - x[faces[:, 0]]), axis=1)
        areau = 0.5 * np.abs(area2)
        for i in range(n_isl):
            sel = islands == i
            if not area3[sel].sum() > 0:
                raise ConfigError(f"{path}: UV island {i} has zero area in 3-D, so "
                                  "uv_scale = \"auto\" cannot size it: give cloth.uv_scale "
                                  "as a number")
            scale[i] = np.sqrt(area3[sel].sum() / areau[sel].sum())
    else:
        if not (np.isfinite(uv_scale) and uv_scale > 0):
            raise ConfigError(f"cloth.uv_scale must be > 0 or \"auto\" (got {uv_scale})")
        scale[:] = float(uv_scale)
    vert_island = np.zeros(len(uv), np.int64)
    vert_island[faces.ravel()] = np.repeat(islands, 3)
    uv *= scale[vert_island][:, None]

    # Grain: the warp direction in material space.
    if isinstance(warp, str):
        if warp not in ("u", "v"):
            raise ConfigError(f"cloth.warp takes \"u\", \"v\" or an angle in degrees from "
                              f"material u (got '{warp}')")
        angle = 0.0 if warp == "u" else 90.0
    else:
        angle = float(warp)
    grain = grain_from_angle(np.radians(angle), len(faces))
    if angle % 90.0 == 0.0:
        grain = np.round(grain)          # exact axes for u, v and their opposites

    # Seams: the copies of one file vertex are sewn together (star from the first copy).
    order = np.argsort(src_v, kind="stable")
    sv = src_v[order]
    starts = np.r_[0, np.flatnonzero(np.diff(sv)) + 1]
    first = np.repeat(order[starts], np.diff(np.r_[starts, len(sv)]))
    stitches = np.stack([first, order], axis=1)
    stitches = stitches[stitches[:, 0] != stitches[:, 1]].astype(np.int32)
    mesh = MeshArrays(uv=uv, x=x, faces=faces.astype(np.int32), grain=grain)
    return GarmentMesh(mesh=mesh, stitches=stitches, islands=islands, island_scale=scale,
                       source_vertex=src_v, notes=notes)


def load_garment(path, uv_scale=1.0, warp="u", max_faces=200_000, memory=None):
    """Read, triangulate, split along UV seams, scale and check an OBJ cloth mesh."""
    v, vt, faces, lines = read_obj(path, max_faces, memory)
    tris, tri_lines, split = triangulate(faces, lines)
    check_size(len(tris), max_faces, f"mesh file '{path}'", memory)
    g = build_garment(v, vt, tris, tri_lines, path, uv_scale, warp)
    if split:
        g.notes.insert(0, f"{split} polygon(s) with more than three corners were split into "
                          "triangles")
    return g


def write_garment_obj(path, x, uv, faces, groups=None, header="", digits=9):
    """An OBJ with v and vt numbered independently (v shared along seams, vt per panel), as
    pattern tools write them. ``faces`` (F, 3, 2) of (v index, vt index), 0-based; coordinates
    with ``digits`` significant digits (17 round-trips a float64 exactly)."""
    tmp = path + ".tmp"
    with open(tmp, "w") as fh:
        for line in header.splitlines():
            fh.write(f"# {line}\n")
        g = f"%.{int(digits)}g"
        np.savetxt(fh, np.asarray(x), fmt=f"v {g} {g} {g}")
        np.savetxt(fh, np.asarray(uv), fmt=f"vt {g} {g}")
        f = np.asarray(faces, np.int64) + 1
        if groups is None:
            groups = [(None, np.ones(len(f), bool))]
        for name, sel in groups:
            if name:
                fh.write(f"g {name}\n")
            np.savetxt(fh, f[sel].reshape(-1, 6), fmt="f %d/%d %d/%d %d/%d")
    os.replace(tmp, path)
