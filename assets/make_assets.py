"""Generate the T-shirt experiment's assets: ``python -m assets.make_assets [--resolution H]``.

Writes, next to this file:
  mannequin.json  the mannequin as spheres and capsules (what the collision code uses)
  mannequin.obj   a triangle mesh of those primitives, for drawing only
  tshirt.npz      the two-panel T-shirt (see ``assets.load_tshirt`` for the arrays)
  tshirt.obj      the same shirt with its material coordinates as texture coordinates (vt)
  dress_form.obj, tabard.obj  the garment example of scenes/examples/garment.toml (--garment
                  writes only these): a closed torso mesh and a two-panel tabard with UV islands

Everything is built from numbers in this file with numpy (trimesh only tessellates the
drawing mesh), so the output is deterministic.

Conventions: metres, y up, the mannequin stands on y = 0 facing +z, its left arm towards +x.

The shirt is a kimono-cut T-shirt: a front and a back panel, each one piece with its short
sleeves, sewn along the shoulder/over-arm line and the side/under-arm line. Panels are flat in
material space (uv, metres, u across, v up from the hem); the warp runs along v (the garment's
vertical) in every face. The back panel is cut as seen from behind, i.e. its material u runs
along world -x, so both panels have their right (outer) side up in material space.

Initial placement (x), in three steps:
  1. Wrap. Below a fold height the torso part of a panel lies on a stadium-shaped cylinder
     around the torso whose half-perimeter equals the panel width, so the side seams land on
     the body's sides (z = 0); above it the panel curls back over the shoulders on a
     quarter-ellipse sized so that the shoulder seam lands on top (z = 0). The sleeves are
     half-tubes around the arm axes with the under- and over-arm seams at z = 0. Near the
     armhole the two maps are blended.
  2. Relax. The blend stretches and squeezes the armhole region, so Jacobi sweeps restore the
     material edge lengths (with non-shrinking smoothing against crumples) while holding
     stitched pairs level across their seam, keeping the front at z > 0 and the back at z < 0
     and pushing vertices out of the mannequin.
  3. Clear. Vertices closer than ``CLEARANCE`` and edges closer than ``EDGE_CLEARANCE`` to the
     mannequin are pushed out along the distance gradient.
Stitched pairs start ``SEAM_GAP`` apart, mirror images through z = 0.
"""
import argparse
import json
import os

import numpy as np

from assets import ASSET_DIR, primitives_sdf

# ---------------------------------------------------------------------------------------------
# Mannequin: a 1.75 m adult in an A-pose.
# ---------------------------------------------------------------------------------------------
HEIGHT = 1.75
ARM_ANGLE = np.radians(42.0)      # arms below the horizontal
SHOULDER_JOINT = (0.19, 1.395)    # (|x|, y) of the upper-arm capsule's start
UPPER_ARM, FOREARM, HAND = 0.29, 0.25, 0.09   # segment lengths
# Torso: horizontal capsules along x, centred on x = 0, z = 0: (name, y, half-length, radius).
# Their x-z sections are stadiums (wider than deep); neighbours overlap so the sides are smooth.
TORSO = [
    ("pelvis", 0.86, 0.075, 0.095),
    ("hips", 0.93, 0.080, 0.100),
    ("belly", 1.01, 0.065, 0.097),
    ("waist", 1.09, 0.060, 0.095),
    ("lower_chest", 1.17, 0.070, 0.100),
    ("chest", 1.25, 0.075, 0.105),
    ("upper_chest", 1.33, 0.085, 0.100),
    ("shoulders", 1.41, 0.150, 0.060),
]


def _capsule(name, a, b, r):
    return {"kind": "capsule", "name": name, "a": [float(c) for c in a],
            "b": [float(c) for c in b], "radius": float(r)}


def mannequin_primitives():
    """The mannequin as a list of primitive dicts (see ``assets.load_mannequin``)."""
    prims = [{"kind": "sphere", "name": "head", "center": [0.0, HEIGHT - 0.105, 0.01],
              "radius": 0.105},
             _capsule("neck", (0, 1.42, 0), (0, 1.565, 0.01), 0.055)]
    for name, y, hl, r in TORSO:
        prims.append(_capsule(name, (-hl, y, 0), (hl, y, 0), r))
    for side, sx in (("left", 1.0), ("right", -1.0)):
        d = np.array([sx * np.cos(ARM_ANGLE), -np.sin(ARM_ANGLE), 0.0])
        shoulder = np.array([sx * SHOULDER_JOINT[0], SHOULDER_JOINT[1], 0.0])
        elbow = shoulder + UPPER_ARM * d
        wrist = elbow + FOREARM * d
        prims += [_capsule(f"{side}_upper_arm", shoulder, elbow, 0.046),
                  _capsule(f"{side}_forearm", elbow, wrist, 0.037),
                  _capsule(f"{side}_hand", wrist + 0.02 * d, wrist + HAND * d, 0.032)]
        hip, knee = (sx * 0.09, 0.86, 0.0), (sx * 0.10, 0.47, 0.01)
        ankle = (sx * 0.10, 0.09, -0.01)
        prims += [_capsule(f"{side}_thigh", hip, knee, 0.070),
                  _capsule(f"{side}_shin", knee, ankle, 0.048),
                  _capsule(f"{side}_foot", (sx * 0.10, 0.04, -0.04), (sx * 0.11, 0.04, 0.14),
                           0.040)]
    return prims


def mannequin_trimesh(prims):
    """A drawing mesh: one icosphere or capsule per primitive, concatenated (not a union)."""
    import trimesh
    parts = []
    for p in prims:
        if p["kind"] == "sphere":
            m = trimesh.creation.icosphere(subdivisions=3, radius=p["radius"])
            m.apply_translation(p["center"])
        else:
            a, b = np.array(p["a"]), np.array(p["b"])
            axis = b - a
            length = np.linalg.norm(axis)
            m = trimesh.creation.capsule(height=length, radius=p["radius"], count=[20, 10])
            # trimesh's capsule is centred on the origin along z.
            m.apply_transform(trimesh.geometry.align_vectors([0, 0, 1], axis / length))
            m.apply_translation(0.5 * (a + b))
        parts.append(m)
    return trimesh.util.concatenate(parts)


# ---------------------------------------------------------------------------------------------
# T-shirt pattern (material space, metres): u across (0 = centre line), v up from the hem.
# ---------------------------------------------------------------------------------------------
HALF_WIDTH = 0.275          # panel half width (chest circumference 1.10 m)
HEM_Y = 0.80                # world height of the hem
ARMPIT_V = 0.40             # side seam length
SLEEVE_ANGLE = ARM_ANGLE    # sleeves cut at the arms' angle
UNDERARM_LEN = 0.11         # under-arm seam length of the sleeve
SLEEVE_OPEN = 0.20          # sleeve hem width per panel (half the opening's circumference)
SHOULDER_U = 0.23           # where the over-arm line meets the shoulder line
NECK_HALF = 0.085           # half width of the neck opening
NECK_RISE = 0.03            # the shoulder line rises this much from shoulder to neck
NECK_DEPTH = (0.09, 0.025)  # neckline depth below the neck points: front, back
SEAMS = ("side", "underarm", "overarm", "shoulder")

# Placement
FOLD_Y = 1.30               # above this the torso part curls over the shoulders
MIN_EASE = 0.02             # torso wrap at least this far from the body
CLEARANCE = 0.010           # final minimum vertex distance from the body
EDGE_CLEARANCE = 0.007      # final minimum distance of any point on an edge from the body
SEAM_GAP = 0.01             # stitched pairs start this far apart
THICKNESS = 0.005           # the cloth thickness the assets are checked against


def _sleeve_dirs():
    """Unit vectors in the pattern for the right-hand (u > 0) sleeve: along the arm, and
    perpendicular to it towards the over-arm side."""
    d = np.array([np.cos(SLEEVE_ANGLE), -np.sin(SLEEVE_ANGLE)])
    n = np.array([np.sin(SLEEVE_ANGLE), np.cos(SLEEVE_ANGLE)])
    return d, n


def key_points():
    """Corner points of the right half of the pattern (u >= 0)."""
    d, n = _sleeve_dirs()
    A = np.array([HALF_WIDTH, ARMPIT_V])           # armpit
    B = A + UNDERARM_LEN * d                       # sleeve hem, under-arm corner
    C = B + SLEEVE_OPEN * n                        # sleeve hem, over-arm corner
    S = C - (C[0] - SHOULDER_U) / d[0] * d         # shoulder point
    N = np.array([NECK_HALF, S[1] + NECK_RISE])    # neck point
    return {"A": A, "B": B, "C": C, "S": S, "N": N}


def _resample(points, h):
    """Points at equal arc-length steps of at most ``h`` along a polyline (ends included)."""
    points = np.asarray(points, float)
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    s = np.r_[0.0, np.cumsum(seg)]
    n = max(1, int(np.ceil(s[-1] / h - 1e-9)))
    t = np.linspace(0.0, s[-1], n + 1)
    return np.stack([np.interp(t, s, points[:, 0]), np.interp(t, s, points[:, 1])], axis=1)


def panel_outline(h, panel):
    """Boundary vertices of a panel, counter-clockwise, and the seam each lies on ('' if none).

    The right half's seam pieces are resampled once and mirrored for the left half, so the
    seams of both panels hold exactly mirrored vertices (u -> -u), which is how front and back
    vertices pair up."""
    k = key_points()
    right = {"side": _resample([[HALF_WIDTH, 0.0], k["A"]], h),
             "underarm": _resample([k["A"], k["B"]], h),
             "sleeve_hem": _resample([k["B"], k["C"]], h),
             "overarm": _resample([k["C"], k["S"]], h),
             "shoulder": _resample([k["S"], k["N"]], h)}
    depth = NECK_DEPTH[panel]
    ang = np.linspace(0.0, np.pi, 65)
    neck = np.stack([NECK_HALF * np.cos(ang), k["N"][1] - depth * np.sin(ang)], axis=1)
    neck = _resample(neck, h)
    hem = _resample([[-HALF_WIDTH, 0.0], [HALF_WIDTH, 0.0]], h)

    pts, spans = [], []

    def add(piece, tag):
        # Each piece's last point is the next piece's first, so it is not added twice; the
        # span remembers that the piece (and its seam) ends on that point.
        spans.append((tag, len(pts), len(piece)))
        pts.extend(piece[:-1])

    add(hem, "")
    for name in ("side", "underarm", "sleeve_hem", "overarm", "shoulder"):
        add(right[name], name)
    add(neck, "")
    mirror = np.array([-1.0, 1.0])
    for name in ("shoulder", "overarm", "sleeve_hem", "underarm", "side"):
        add(right[name][::-1] * mirror, name)
    pts = np.array(pts)
    tags = np.full(len(pts), "", dtype=object)
    for tag, start, count in spans:
        if tag in SEAMS:
            tags[(start + np.arange(count)) % len(pts)] = tag
    tags = tags.astype(str)
    return pts, tags


# ---------------------------------------------------------------------------------------------
# Triangulation: lattice points inside the outline + the outline's vertices, Delaunay
# (Bowyer-Watson), triangles outside the outline dropped, then Laplacian smoothing.
# ---------------------------------------------------------------------------------------------
def _inside_polygon(p, poly):
    """Even-odd test of points p (N,2) against a closed polygon (M,2)."""
    a, b = poly, np.roll(poly, -1, axis=0)
    px, py = p[:, None, 0], p[:, None, 1]
    crosses = (a[None, :, 1] > py) != (b[None, :, 1] > py)
    with np.errstate(divide="ignore", invalid="ignore"):
        xint = a[None, :, 0] + (py - a[None, :, 1]) * (b[None, :, 0] - a[None, :, 0]) / (
            b[None, :, 1] - a[None, :, 1])
    return np.count_nonzero(crosses & (px < xint), axis=1) % 2 == 1


def _distance_to_polygon(p, poly):
    a, b = poly, np.roll(poly, -1, axis=0)
    ab = b - a
    t = np.einsum("nmk,mk->nm", p[:, None] - a[None], ab) / np.einsum("mk,mk->m", ab, ab)
    c = a[None] + np.clip(t, 0, 1)[..., None] * ab[None]
    return np.linalg.norm(p[:, None] - c, axis=2).min(axis=1)


def _circumcircles(p, tris):
    a, b, c = p[tris[:, 0]], p[tris[:, 1]], p[tris[:, 2]]
    bx, by = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    cx, cy = c[:, 0] - a[:, 0], c[:, 1] - a[:, 1]
    d = 2.0 * (bx * cy - by * cx)
    b2, c2 = bx * bx + by * by, cx * cx + cy * cy
    ux = (cy * b2 - by * c2) / d
    uy = (bx * c2 - cx * b2) / d
    return a + np.stack([ux, uy], axis=1), ux * ux + uy * uy


def delaunay(points):
    """Delaunay triangulation (Bowyer-Watson) of 2-D points; faces counter-clockwise."""
    n = len(points)
    lo, hi = points.min(axis=0), points.max(axis=0)
    mid, span = 0.5 * (lo + hi), float(np.max(hi - lo))
    big = np.array([[-1.0, -1.0], [1.0, -1.0], [0.0, 1.0]]) * 50.0 * span + mid
    p = np.vstack([points, big])
    cap = 2 * n + 16
    tris = np.zeros((cap, 3), np.int64)
    cc = np.zeros((cap, 2))
    r2 = np.zeros(cap)
    alive = np.zeros(cap, bool)
    tris[0] = (n, n + 1, n + 2)
    cc[:1], r2[:1] = _circumcircles(p, tris[:1])
    alive[0] = True
    m = 1
    for i in range(n):
        q = p[i]
        d2 = np.sum((cc[:m] - q) ** 2, axis=1)
        bad = np.flatnonzero(alive[:m] & (d2 < r2[:m] * (1.0 - 1e-12)))
        directed = set()
        for t in tris[bad]:
            directed.update(((t[0], t[1]), (t[1], t[2]), (t[2], t[0])))
        rim = [e for e in directed if (e[1], e[0]) not in directed]
        rim.sort()
        alive[bad] = False
        new = np.array([(a, b, i) for a, b in rim], np.int64)
        if m + len(new) > cap:                            # compact, then grow if needed
            keep = np.flatnonzero(alive[:m])
            k = len(keep)
            cap = max(cap, 2 * (k + len(new)))
            tris = np.r_[tris[keep], np.zeros((cap - k, 3), np.int64)]
            cc = np.r_[cc[keep], np.zeros((cap - k, 2))]
            r2 = np.r_[r2[keep], np.zeros(cap - k)]
            alive = np.r_[np.ones(k, bool), np.zeros(cap - k, bool)]
            m = k
        tris[m:m + len(new)] = new
        cc[m:m + len(new)], r2[m:m + len(new)] = _circumcircles(p, new)
        alive[m:m + len(new)] = True
        m += len(new)
    out = tris[:m][alive[:m]]
    out = out[np.all(out < n, axis=1)]
    return out


def _keep_inside(points, tris, outline):
    centroid = points[tris].mean(axis=1)
    return tris[_inside_polygon(centroid, outline)]


def triangulate_outline(outline, h, smooth_iters=4):
    """Triangulate the polygon ``outline`` (its vertices are kept, in order, as the first
    vertices) with interior vertices about ``h`` apart. Returns (uv, faces), faces CCW."""
    lo, hi = outline.min(axis=0), outline.max(axis=0)
    dv = h * np.sqrt(3.0) / 2.0
    rows = []
    for j in range(int(np.ceil((hi[1] - lo[1]) / dv)) + 1):
        shift = 0.5 * h * (j % 2)
        i0, i1 = int(np.floor(lo[0] / h)) - 1, int(np.ceil(hi[0] / h)) + 1
        us = np.arange(i0, i1 + 1) * h + shift
        rows.append(np.stack([us, np.full_like(us, lo[1] + j * dv)], axis=1))
    lattice = np.concatenate(rows)
    lattice = lattice[_inside_polygon(lattice, outline)]
    lattice = lattice[_distance_to_polygon(lattice, outline) > 0.6 * h]
    points = np.vstack([outline, lattice])
    nb = len(outline)
    faces = _keep_inside(points, delaunay(points), outline)
    for _ in range(smooth_iters):
        # Each interior vertex moves to the mean of its neighbours (the outline stays put).
        edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
        acc = np.zeros_like(points)
        cnt = np.zeros(len(points))
        np.add.at(acc, edges[:, 0], points[edges[:, 1]])
        np.add.at(cnt, edges[:, 0], 1.0)
        target = acc / np.maximum(cnt, 1)[:, None]
        moved = points.copy()
        moved[nb:] = target[nb:]
        ok = _inside_polygon(moved[nb:], outline) & (
            _distance_to_polygon(moved[nb:], outline) > 0.4 * h)
        points[nb:][ok] = moved[nb:][ok]
        faces = _keep_inside(points, delaunay(points), outline)
    _check_outline_edges(faces, nb)
    return points, faces.astype(np.int32)


def _check_outline_edges(faces, nb):
    have = set(map(tuple, np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]],
                                          faces[:, [2, 0]]]).tolist()))
    missing = [i for i in range(nb) if (i, (i + 1) % nb) not in have]
    if missing:
        raise RuntimeError(f"triangulation lost {len(missing)} outline edge(s), first at "
                           f"outline vertex {missing[0]}: use a smaller resolution")


def min_angles(uv, faces):
    """Smallest interior angle (degrees) of every triangle."""
    p = uv[faces]
    out = []
    for k in range(3):
        e1 = p[:, (k + 1) % 3] - p[:, k]
        e2 = p[:, (k + 2) % 3] - p[:, k]
        c = np.einsum("ij,ij->i", e1, e2) / (np.linalg.norm(e1, axis=1) *
                                             np.linalg.norm(e2, axis=1))
        out.append(np.degrees(np.arccos(np.clip(c, -1, 1))))
    return np.min(out, axis=0)


# ---------------------------------------------------------------------------------------------
# Placement around the mannequin.
# ---------------------------------------------------------------------------------------------
def _torso_section(y):
    """Half-length and radius of the torso's stadium cross-section at heights y."""
    ys = np.array([t[1] for t in TORSO])
    return (np.interp(y, ys, [t[2] for t in TORSO]), np.interp(y, ys, [t[3] for t in TORSO]))


def _wrap_section(y):
    """The stadium the torso part of a panel wraps onto at heights y: (half-length, radius),
    sized so that its half-perimeter is the panel width (at least MIN_EASE off the body)."""
    hl, r = _torso_section(np.minimum(y, FOLD_Y))
    radius = np.maximum((HALF_WIDTH - hl) / (np.pi / 2), r + MIN_EASE)
    return hl, radius


def _on_stadium(s, hl, radius):
    """(x, z) of the point at arc length s (>= 0) from the front centre of a stadium's front
    half, with s scaled so that s = HALF_WIDTH lands on the side (z = 0); beyond that the
    point continues straight outwards in x."""
    quarter = hl + 0.5 * np.pi * radius
    t = np.minimum(s, HALF_WIDTH) * quarter / HALF_WIDTH
    phi = np.clip((t - hl) / radius, 0.0, np.pi / 2)
    x = np.where(t <= hl, t, hl + radius * np.sin(phi)) + np.maximum(s - HALF_WIDTH, 0.0)
    z = np.where(t <= hl, radius, radius * np.cos(phi))
    return x, z


def _quarter_ellipse_length(a, b):
    """Ramanujan's approximation of a quarter of an ellipse's perimeter."""
    return 0.25 * np.pi * (3 * (a + b) - np.sqrt((3 * a + b) * (a + 3 * b)))


def _shoulder_top_v(u):
    """Material height v of the shoulder seam above column |u| (held constant across the neck
    opening and outside the shoulder point)."""
    k = key_points()
    uc = np.clip(u, k["N"][0], k["S"][0])
    return np.interp(uc, [k["N"][0], k["S"][0]], [k["N"][1], k["S"][1]])


def _body_map(u, v):
    """World (x, y, z >= 0) of material points (|u|, v) of the front panel's torso part."""
    y = HEM_Y + v
    hl, radius = _wrap_section(y)
    x, z = _on_stadium(u, hl, radius)
    # Over the shoulders: from (z_f, FOLD_Y) up to the seam at (0, FOLD_Y + H) on a quarter
    # ellipse whose length is the material left above the fold, so the seam lands at z = 0.
    v_fold = FOLD_Y - HEM_Y
    above = v > v_fold
    m = _shoulder_top_v(u) - v_fold
    zf = z                                    # depth at the fold
    lo, hi = np.zeros_like(u), np.full_like(u, 1.0)
    for _ in range(50):                       # bisection for the ellipse height H
        mid = 0.5 * (lo + hi)
        longer = _quarter_ellipse_length(zf, mid) > m
        hi = np.where(longer, mid, hi)
        lo = np.where(longer, lo, mid)
    height = 0.5 * (lo + hi)
    psi = 0.5 * np.pi * np.clip((v - v_fold) / m, 0.0, 1.0)
    y = np.where(above, FOLD_Y + height * np.sin(psi), y)
    z = np.where(above, zf * np.cos(psi), z)
    return np.stack([x, y, z], axis=1)


def _arm_frame():
    """Right-hand (+x) arm: shoulder joint J, unit axis D (down the arm), unit N (up, normal to
    the arm in the x-y plane)."""
    J = np.array([SHOULDER_JOINT[0], SHOULDER_JOINT[1], 0.0])
    D = np.array([np.cos(ARM_ANGLE), -np.sin(ARM_ANGLE), 0.0])
    N = np.array([np.sin(ARM_ANGLE), np.cos(ARM_ANGLE), 0.0])
    return J, D, N


def _sleeve_map(u, v):
    """World points of material points (|u|, v) on a half-tube around the arm: the under-arm
    line at the bottom of the tube, the over-arm line on top, the front half at z >= 0."""
    k = key_points()
    d, n = _sleeve_dirs()
    rel = np.stack([u, v], axis=1) - k["A"]
    s, t = rel @ d, rel @ n                   # along the arm, across it (0 .. SLEEVE_OPEN)
    J, D, N = _arm_frame()
    armpit = _body_map(k["A"][:1], k["A"][1:])[0]
    s0 = (armpit - J) @ D                     # the armpit's place along the arm
    radius = SLEEVE_OPEN / np.pi
    phi = np.pi * np.clip(t / SLEEVE_OPEN, 0.0, 1.0)
    return (J + (s + s0)[:, None] * D - (radius * np.cos(phi))[:, None] * N
            + (radius * np.sin(phi))[:, None] * np.array([0.0, 0.0, 1.0]))


def _past_armhole(u, v):
    """Signed distance (m) of material points (|u|, v) past the armhole line A-S, positive on
    the sleeve side."""
    k = key_points()
    along = (k["S"] - k["A"]) / np.linalg.norm(k["S"] - k["A"])
    out = np.array([along[1], -along[0]])          # normal pointing towards the sleeve
    return (np.stack([u, v], axis=1) - k["A"]) @ out


def _sleeve_weight(u, v, ramp=(-0.02, 0.06)):
    """0 on the torso, 1 on the sleeve: a smoothstep across the armhole line."""
    t = np.clip((_past_armhole(u, v) - ramp[0]) / (ramp[1] - ramp[0]), 0.0, 1.0)
    return t * t * (3 - 2 * t)


def push_out(x, prims, clearance=CLEARANCE, iters=20):
    """Move points closer than ``clearance`` to the mannequin out along the distance gradient."""
    x = x.copy()
    for _ in range(iters):
        sdf, grad = primitives_sdf(x, prims, return_grad=True)
        low = sdf < clearance
        if not np.any(low):
            break
        x[low] += (clearance - sdf[low] + 1e-6)[:, None] * grad[low]
    return x


def place_panel(uv, panel, prims):
    """Initial world positions of a panel's vertices (panel 0 front, 1 back)."""
    # The back is cut as seen from behind: its material u runs along world -x.
    xside = uv[:, 0] if panel == 0 else -uv[:, 0]
    u, v = np.abs(xside), uv[:, 1]
    w = _sleeve_weight(u, v)[:, None]
    p = (1 - w) * _body_map(u, v) + w * _sleeve_map(u, v)
    p[:, 0] *= np.where(xside < 0, -1.0, 1.0)
    p[:, 2] += 0.5 * SEAM_GAP
    if panel == 1:
        p[:, 2] *= -1.0
    return push_out(p, prims)


def relax(x, uv, faces, panel_of_vertex, stitches, prims, iters=300, smoothing=0.3):
    """Even out the stretch of the wrapped panels with Jacobi sweeps that
      - restore every edge's material length,
      - smooth out crumples at the scale of the mesh (Taubin's lambda|mu smoothing, which
        unlike plain Laplacian smoothing does not shrink the surface),
      - keep the front at z >= SEAM_GAP/2 and the back at z <= -SEAM_GAP/2,
      - put each stitched pair level across the seam (same x, y; z = +-SEAM_GAP/2),
      - push vertices out of the mannequin."""
    x = x.copy()
    edges = np.unique(np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]],
                                              faces[:, [2, 0]]]), axis=1), axis=0)
    i, j = edges[:, 0], edges[:, 1]
    nv = len(x)
    rest = np.linalg.norm(uv[j] - uv[i], axis=1)
    degree = np.bincount(edges.ravel(), minlength=nv).astype(float)

    def gather(values_i, values_j):           # sum per vertex of per-edge vectors
        return np.stack([np.bincount(i, values_i[:, k], nv) + np.bincount(j, values_j[:, k], nv)
                         for k in range(3)], axis=1)

    side = np.where(panel_of_vertex == 0, 1.0, -1.0)
    half_gap = 0.5 * SEAM_GAP
    f, b = stitches[:, 0], stitches[:, 1]
    for _ in range(iters):
        d = x[j] - x[i]
        length = np.linalg.norm(d, axis=1)
        corr = (0.5 * (length - rest) / np.maximum(length, 1e-12))[:, None] * d
        x += gather(corr, -corr) / degree[:, None]
        for step in (smoothing, -1.04 * smoothing):
            x += step * (gather(x[j], x[i]) / degree[:, None] - x)
        x[:, 2] = side * np.maximum(side * x[:, 2], half_gap)
        mid = 0.5 * (x[f, :2] + x[b, :2])
        x[f, :2], x[b, :2] = mid, mid
        x[f, 2], x[b, 2] = half_gap, -half_gap
        x = push_out(x, prims, iters=1)
    return push_out_edges(push_out(x, prims), edges, prims)


def push_out_edges(x, edges, prims, clearance=EDGE_CLEARANCE, iters=20):
    """Move the end points of edges that pass closer than ``clearance`` to the mannequin
    (checked at a quarter, half and three quarters of their length) out together."""
    x = x.copy()
    i, j = edges[:, 0], edges[:, 1]
    for _ in range(iters):
        moved = False
        for t in (0.25, 0.5, 0.75):
            sdf, grad = primitives_sdf((1 - t) * x[i] + t * x[j], prims, return_grad=True)
            low = np.flatnonzero(sdf < clearance)
            if len(low):
                step = (clearance - sdf[low] + 1e-6)[:, None] * grad[low]
                x[i[low]] += step
                x[j[low]] += step
                moved = True
        if not moved:
            break
    return x


# ---------------------------------------------------------------------------------------------
# Putting it together.
# ---------------------------------------------------------------------------------------------
WARP_VERTICAL = np.array([[0.0, -1.0], [1.0, 0.0]])   # columns: warp (0, 1), weft (-1, 0)


def build_tshirt(resolution=0.03, prims=None, relax_iters=300):
    """The T-shirt arrays (see ``assets.load_tshirt``) with material edges about
    ``resolution`` metres long."""
    if prims is None:
        prims = mannequin_primitives()
    uvs, faces, xs, vert_panel, seam_tags = [], [], [], [], []
    start = 0
    for panel in (0, 1):
        outline, tags = panel_outline(resolution, panel)
        uv, f = triangulate_outline(outline, resolution)
        uvs.append(uv)
        faces.append(f + start)
        xs.append(place_panel(uv, panel, prims))
        vert_panel.append(np.full(len(uv), panel))
        seam_tags.append(np.r_[tags, np.full(len(uv) - len(tags), "")])
        start += len(uv)
    uv, faces, x = np.vstack(uvs), np.vstack(faces), np.vstack(xs)
    vert_panel, tags = np.concatenate(vert_panel), np.concatenate(seam_tags)

    # Stitches: a front seam vertex (u, v) meets the back seam vertex at (-u, v).
    front = np.flatnonzero((vert_panel == 0) & (tags != ""))
    back = np.flatnonzero((vert_panel == 1) & (tags != ""))
    key = {(round(-uv[k, 0], 9), round(uv[k, 1], 9)): k for k in back}
    partner = np.array([key[(round(uv[k, 0], 9), round(uv[k, 1], 9))] for k in front])
    stitches = np.stack([front, partner], axis=1).astype(np.int32)
    stitch_seam = np.array([SEAMS.index(t) for t in tags[front]], dtype=np.int32)

    x = relax(x, uv, faces, vert_panel, stitches, prims, iters=relax_iters)
    face_panel = vert_panel[faces[:, 0]].astype(np.int32)
    region = _face_region(uv, faces)
    return {"uv": uv, "x": x, "faces": faces.astype(np.int32),
            "grain": np.tile(WARP_VERTICAL, (len(faces), 1, 1)),
            "panel": face_panel, "region": region, "vert_panel": vert_panel.astype(np.int32),
            "stitches": stitches, "stitch_seam": stitch_seam,
            "seam_names": np.array(SEAMS), "resolution": np.float64(resolution),
            "thickness": np.float64(THICKNESS)}


def _face_region(uv, faces):
    """1 for faces past the armhole line (sleeves), else 0."""
    c = uv[faces].mean(axis=1)
    return (_past_armhole(np.abs(c[:, 0]), c[:, 1]) > 0).astype(np.int32)


def write_obj(path, vertices, faces, uv=None, groups=None, header=""):
    """A Wavefront OBJ; with ``uv`` every vertex has a texture coordinate of the same index.
    ``groups``: list of (name, face mask)."""
    with open(path, "w") as out:
        for line in header.splitlines():
            out.write(f"# {line}\n")
        for p in vertices:
            out.write(f"v {p[0]:.6f} {p[1]:.6f} {p[2]:.6f}\n")
        if uv is not None:
            for t in uv:
                out.write(f"vt {t[0]:.6f} {t[1]:.6f}\n")
        for name, mask in groups or [("", np.ones(len(faces), bool))]:
            if name:
                out.write(f"g {name}\n")
            for f in np.asarray(faces)[mask] + 1:
                if uv is None:
                    out.write(f"f {f[0]} {f[1]} {f[2]}\n")
                else:
                    out.write(f"f {f[0]}/{f[0]} {f[1]}/{f[1]} {f[2]}/{f[2]}\n")


def save_assets(out_dir=ASSET_DIR, resolution=0.03):
    prims = mannequin_primitives()
    with open(os.path.join(out_dir, "mannequin.json"), "w") as f:
        f.write("[\n" + ",\n".join(json.dumps(p) for p in prims) + "\n]\n")
    mesh = mannequin_trimesh(prims)
    write_obj(os.path.join(out_dir, "mannequin.obj"), mesh.vertices, mesh.faces,
              header="Loom mannequin (drawing mesh; collide with mannequin.json)\n"
                     "made by python -m assets.make_assets")
    shirt = build_tshirt(resolution, prims)
    np.savez(os.path.join(out_dir, "tshirt.npz"), **shirt)
    write_obj(os.path.join(out_dir, "tshirt.obj"), shirt["x"], shirt["faces"], uv=shirt["uv"],
              groups=[("front", shirt["panel"] == 0), ("back", shirt["panel"] == 1)],
              header="Loom T-shirt: v = initial positions, vt = material coordinates (m)\n"
                     f"made by python -m assets.make_assets --resolution {resolution}")
    return prims, shirt


def _rasterise(tris, colours, forward, up, extent, size):
    """A tiny z-buffer renderer (orthographic): triangles (T,3,3) with colours (T,3) seen
    along ``forward``; ``extent`` = (left, right, bottom, top) in view coordinates."""
    forward = forward / np.linalg.norm(forward)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    left, rgt, bottom, top = extent
    w = size
    h = int(round(size * (top - bottom) / (rgt - left)))
    sx = (tris @ right - left) / (rgt - left) * w
    sy = (top - tris @ up) / (top - bottom) * h
    depth = tris @ forward
    normal = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    shade = 0.3 + 0.7 * np.abs(normal @ forward)
    image = np.ones((h, w, 3))
    zbuf = np.full((h, w), np.inf)
    for t in range(len(tris)):
        x0, x1 = int(max(np.floor(sx[t].min()), 0)), int(min(np.ceil(sx[t].max()), w - 1))
        y0, y1 = int(max(np.floor(sy[t].min()), 0)), int(min(np.ceil(sy[t].max()), h - 1))
        if x0 > x1 or y0 > y1:
            continue
        px, py = np.meshgrid(np.arange(x0, x1 + 1) + 0.5, np.arange(y0, y1 + 1) + 0.5)
        (ax, bx, cx), (ay, by, cy) = sx[t], sy[t]
        det = (bx - ax) * (cy - ay) - (cx - ax) * (by - ay)
        if abs(det) < 1e-12:
            continue
        l1 = ((px - ax) * (cy - ay) - (cx - ax) * (py - ay)) / det
        l2 = ((bx - ax) * (py - ay) - (px - ax) * (by - ay)) / det
        l0 = 1 - l1 - l2
        inside = (l0 >= 0) & (l1 >= 0) & (l2 >= 0)
        z = l0 * depth[t, 0] + l1 * depth[t, 1] + l2 * depth[t, 2]
        block = zbuf[y0:y1 + 1, x0:x1 + 1]
        win = inside & (z < block)
        block[win] = z[win]
        image[y0:y1 + 1, x0:x1 + 1][win] = colours[t] * shade[t]
    return image


def preview(path, prims, shirt, size=420):
    """Draw the mannequin and the shirt from four sides, plus the flat pattern (PNG)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    body = mannequin_trimesh(prims)
    tris = np.concatenate([body.vertices[body.faces], shirt["x"][shirt["faces"]]])
    colours = np.concatenate([
        np.tile([0.78, 0.74, 0.70], (len(body.faces), 1)),
        np.where(shirt["panel"][:, None] == 0, [[0.25, 0.5, 0.85]], [[0.9, 0.45, 0.2]])])
    y_up = np.array([0.0, 1.0, 0.0])
    views = [("front (full body)", [0, 0, -1]), ("front", [0, 0, -1]),
             ("left side (from +x)", [-1, 0, 0]), ("back", [0, 0, 1]),
             ("from above, front-left", [-0.4, -0.8, -0.5])]
    fig, axes = plt.subplots(2, 3, figsize=(15, 10))
    for k, (ax, (title, forward)) in enumerate(zip(axes.ravel(), views)):
        forward = np.array(forward, float) / np.linalg.norm(forward)
        right = np.cross(forward, y_up)
        right /= np.linalg.norm(right)
        up = np.cross(right, forward)
        pts = body.vertices if k == 0 else shirt["x"]
        lo_r, hi_r = (pts @ right).min() - 0.05, (pts @ right).max() + 0.05
        lo_u, hi_u = (pts @ up).min() - 0.05, (pts @ up).max() + 0.05
        half = 0.5 * max(hi_r - lo_r, hi_u - lo_u)
        cr, cu = 0.5 * (lo_r + hi_r), 0.5 * (lo_u + hi_u)
        extent = (cr - half, cr + half, cu - half, cu + half)
        ax.imshow(_rasterise(tris, colours, forward, y_up, extent, size))
        ax.set_title(title)
        ax.set_axis_off()
    ax = axes.ravel()[-1]
    for panel, dx in ((0, 0.0), (1, 1.1)):
        mask = shirt["panel"] == panel
        ax.triplot(shirt["uv"][:, 0] + dx, shirt["uv"][:, 1], shirt["faces"][mask], lw=0.3,
                   color=("C0", "C1")[panel])
    st = shirt["stitches"]
    ax.plot(shirt["uv"][st[:, 0], 0], shirt["uv"][st[:, 0], 1], "k.", ms=3)
    ax.plot(shirt["uv"][st[:, 1], 0] + 1.1, shirt["uv"][st[:, 1], 1], "k.", ms=3)
    ax.set_aspect("equal")
    ax.set_title("pattern (m): front | back (seen from behind)\nblack dots: stitched vertices")
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


# ---------------------------------------------------------------------------------------------
# Garment example: a dress form as one closed triangle mesh, and a two-panel tabard (front and
# back panel sewn along the shoulders) exported the way pattern tools write garments: one UV
# island per panel at a non-metric scale (a 0..1 texture atlas), the panels turned in the atlas
# so that the garment's vertical (the warp) runs along u, and one shared vertex ("v") per seam
# point with a texture coordinate ("vt") per panel.
# ---------------------------------------------------------------------------------------------
FORM_BOTTOM, FORM_TOP = 0.74, 1.44   # the dress form's torso spans these heights
TABARD_LENGTH = 0.50                 # m, shoulder seam to hem (material, per panel)
TABARD_WIDTH = 0.36                  # m, panel width
TABARD_STEP = 0.025                  # m, target edge length
TABARD_CLEARANCE = 0.008             # m, start distance from the form
ATLAS_METRES = 1.6                   # metres per texture unit in the OBJ (non-metric UVs)


def _stadium_ring(hl, r, n):
    """n points around a stadium (half-length hl along x, radius r) in the x-z plane at equal
    arc-length steps, starting at the front centre (0, r) and going towards +x."""
    P = 4 * hl + 2 * np.pi * r
    pts = np.zeros((n, 2))
    for i, t in enumerate(np.arange(n) * P / n):
        if t < hl:                                  # front straight, from the centre to +x
            pts[i] = (t, r)
        elif t < hl + np.pi * r:                    # right half-circle
            phi = (t - hl) / r
            pts[i] = (hl + r * np.sin(phi), r * np.cos(phi))
        elif t < 3 * hl + np.pi * r:                # back straight
            pts[i] = (hl - (t - hl - np.pi * r), -r)
        elif t < 3 * hl + 2 * np.pi * r:            # left half-circle
            phi = (t - 3 * hl - np.pi * r) / r
            pts[i] = (-hl - r * np.sin(phi), -r * np.cos(phi))
        else:                                       # front straight back to the centre
            pts[i] = (-hl + (t - 3 * hl - 2 * np.pi * r), r)
    return pts


def _form_rings(dy=0.01, cap=4):
    """(half-length, radius, height) of the dress form's sections from bottom to top: the
    mannequin's torso sections, rounded off at both ends by ``cap`` shrinking rings."""
    ys = np.arange(FORM_BOTTOM, FORM_TOP + 1e-9, dy)
    hl, r = _torso_section(ys)
    out = []
    for k in range(cap, 0, -1):
        a = 0.5 * np.pi * k / (cap + 1)
        out.append((hl[0], r[0] * np.cos(a), ys[0] - 0.5 * r[0] * np.sin(a)))
    out += list(zip(hl, r, ys))
    for k in range(1, cap + 1):
        a = 0.5 * np.pi * k / (cap + 1)
        out.append((hl[-1], r[-1] * np.cos(a), ys[-1] + 0.5 * r[-1] * np.sin(a)))
    return out


def dress_form(n_ring=64):
    """A closed torso (one surface, no overlaps) lofted through the mannequin's torso
    sections. Returns (vertices, faces) with outward normals."""
    rings = _form_rings()
    verts = np.concatenate([np.c_[q[:, 0], np.full(n_ring, y), q[:, 1]]
                            for q, y in ((_stadium_ring(h, r, n_ring), y) for h, r, y in rings)])
    n_r = len(rings)
    faces = []
    for j in range(n_r - 1):
        for i in range(n_ring):
            a, b = j * n_ring + i, j * n_ring + (i + 1) % n_ring
            faces += [(a, a + n_ring, b), (b, a + n_ring, b + n_ring)]
    bottom, top = len(verts), len(verts) + 1
    verts = np.vstack([verts, [[0.0, rings[0][2] - 0.002, 0.0], [0.0, rings[-1][2] + 0.002, 0.0]]])
    last = (n_r - 1) * n_ring
    for i in range(n_ring):
        faces.append((bottom, i, (i + 1) % n_ring))
        faces.append((top, last + (i + 1) % n_ring, last + i))
    faces = np.array(faces, np.int64)
    p = verts[faces]
    if np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() < 0:
        faces = faces[:, ::-1]                       # outward normals: positive volume
    return verts, faces


def _tabard_profile(step):
    """The panel's path in the y-z plane (z >= 0, the front): the form's outline at x = 0
    from the top centre down the front, offset outwards by TABARD_CLEARANCE, resampled every
    ``step`` m of arc length over TABARD_LENGTH. A panel is this path swept along x, a
    developable surface, so it starts unstretched. Returns (rows, 2) of (y, z)."""
    rings = _form_rings()
    outline = [(rings[-1][2] + 0.002, 0.0)] + [(y, r) for _, r, y in rings[::-1]]
    outline = np.array(outline)                       # (y, z) from the top, going down
    d = np.gradient(outline, axis=0)
    n = np.stack([d[:, 1], -d[:, 0]], axis=1)         # right of the downward path: +z side
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n[0] = (1.0, 0.0)                                 # straight up at the top centre
    path = outline + TABARD_CLEARANCE * n
    path = _resample(path, 0.002)
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    s = np.r_[0.0, np.cumsum(seg)]
    rows = int(np.ceil(TABARD_LENGTH / step))
    t = np.linspace(0.0, TABARD_LENGTH, rows + 1)
    return np.stack([np.interp(t, s, path[:, 0]), np.interp(t, s, path[:, 1])], axis=1), t


def tabard():
    """The two-panel tabard over the dress form. Returns dict: x (N, 3) with the shoulder-seam
    vertices shared, vt (T, 2) atlas coordinates, faces (F, 3, 2) (v, vt) index pairs and
    panel (F,) 0 front, 1 back."""
    prof, v = _tabard_profile(TABARD_STEP)
    cols = int(np.ceil(TABARD_WIDTH / TABARD_STEP))
    u = np.linspace(-0.5 * TABARD_WIDTH, 0.5 * TABARD_WIDTH, cols + 1)
    R, C = len(v), len(u)
    # Panel material coordinates: u across, v down from the shoulder seam.
    U, V = np.meshgrid(u, v)
    x_front = np.stack([U, np.repeat(prof[:, :1], C, axis=1), np.repeat(prof[:, 1:], C, axis=1)],
                       axis=2)
    # The back panel is cut as seen from behind (its u runs along world -x), mirrored in z.
    x_back = np.stack([-U, x_front[..., 1], -x_front[..., 2]], axis=2)
    vid_front = np.arange(R * C).reshape(R, C)
    vid_back = vid_front + R * C
    vid_back[0] = vid_front[0, ::-1]                  # the shoulder seam: one vertex per point
    x = np.concatenate([x_front.reshape(-1, 3), x_back.reshape(-1, 3)])

    def atlas(panel):
        # Turned so the garment's vertical runs along the texture's u (warp = u), in a 0..1
        # atlas at 1 / ATLAS_METRES, the back island beside the front one.
        t = np.stack([V, U], axis=-1) / ATLAS_METRES
        return t + np.array([0.05, 0.25 + 0.5 * panel])
    vt = np.concatenate([atlas(0).reshape(-1, 2), atlas(1).reshape(-1, 2)])
    tid = np.arange(R * C).reshape(R, C)
    faces, panel = [], []
    for p, vid in enumerate((vid_front, vid_back)):
        for j in range(R - 1):
            for i in range(C - 1):
                a, b, c, d = (j, i), (j, i + 1), (j + 1, i + 1), (j + 1, i)
                tris = [(a, c, b), (a, d, c)] if (i + j) % 2 == 0 else [(a, d, b), (b, d, c)]
                for tri in tris:       # counter-clockwise in the atlas (texture u = v down)
                    faces.append([(vid[q], tid[q] + p * R * C) for q in tri])
                    panel.append(p)
    faces = np.array(faces)
    used = np.unique(faces[:, :, 0])
    remap = np.full(len(x), -1)
    remap[used] = np.arange(len(used))
    faces[:, :, 0] = remap[faces[:, :, 0]]
    return {"x": x[used], "vt": vt, "faces": faces, "panel": np.array(panel)}


def write_garment(path, x, vt, faces, panel, header):
    with open(path, "w") as out:
        for line in header.splitlines():
            out.write(f"# {line}\n")
        for p in x:
            out.write(f"v {p[0]:.6f} {p[1]:.6f} {p[2]:.6f}\n")
        for t in vt:
            out.write(f"vt {t[0]:.6f} {t[1]:.6f}\n")
        for k, name in enumerate(("front", "back")):
            out.write(f"g {name}\n")
            for f in faces[panel == k] + 1:
                out.write("f " + " ".join(f"{a}/{b}" for a, b in f) + "\n")


def save_garment(out_dir=ASSET_DIR):
    """Write dress_form.obj (a closed torso) and tabard.obj (two panels, welded seam)."""
    v, f = dress_form()
    write_obj(os.path.join(out_dir, "dress_form.obj"), v, f,
              header="Loom dress form: a closed torso mesh (an obstacle of kind 'mesh')\n"
                     "made by python -m assets.make_assets --garment")
    g = tabard()
    write_garment(os.path.join(out_dir, "tabard.obj"), g["x"], g["vt"], g["faces"], g["panel"],
                  "Loom tabard: front and back panel sewn along the shoulders, as a pattern "
                  "tool exports them:\nv shared along the seam, vt one UV island per panel in a "
                  f"0..1 atlas ({ATLAS_METRES} m per unit),\nthe garment's vertical along vt u\n"
                  "made by python -m assets.make_assets --garment")
    return (v, f), g


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--resolution", type=float, default=0.03,
                    help="target material edge length of the shirt, m (default 0.03)")
    ap.add_argument("--out", default=ASSET_DIR, help="output folder (default: assets/)")
    ap.add_argument("--preview", metavar="PNG", help="also draw the assets to this file")
    ap.add_argument("--garment", action="store_true",
                    help="write only the garment example (dress_form.obj, tabard.obj)")
    args = ap.parse_args(argv)
    if args.garment:
        (v, f), g = save_garment(args.out)
        print(f"dress form: {len(v)} vertices, {len(f)} faces; tabard: {len(g['x'])} vertices, "
              f"{len(g['vt'])} texture coordinates, {len(g['faces'])} faces")
        return
    prims, shirt = save_assets(args.out, args.resolution)
    if args.preview:
        preview(args.preview, prims, shirt)
    sdf = primitives_sdf(shirt["x"], prims)
    gap = np.linalg.norm(shirt["x"][shirt["stitches"][:, 0]] - shirt["x"][shirt["stitches"][:, 1]],
                         axis=1)
    print(f"mannequin: {len(prims)} primitives; shirt: {len(shirt['uv'])} vertices, "
          f"{len(shirt['faces'])} faces, {len(shirt['stitches'])} stitches; "
          f"min clearance {sdf.min() * 1000:.1f} mm; stitch gap max {gap.max() * 1000:.1f} mm; "
          f"min material angle {min_angles(shirt['uv'], shirt['faces']).min():.1f} deg")


if __name__ == "__main__":
    main()
