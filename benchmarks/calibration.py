"""Material calibration: does the simulated cloth have the lab's bending rigidity and tensile
moduli, at any resolution and with any triangulation?

    python -m benchmarks.calibration --out docs/calibration   # ~8-15 min on 2 shared cores
    python -m benchmarks.calibration --quick --out /tmp/cal   # h = 1 and 2 cm only

Writes ``calibration.md`` (tables of B_eff / B and k_eff / k), ``calibration.json``,
``calibration.png`` and ``ledge.png``. Every case (a cantilever pair, a ledge at every width,
a strip) is a run of a sweep (``benchmarks.sweep``: a local cluster, one worker process per
core, or ``--scheduler tcp://HOST:PORT``; cached in --out/calibration_runs/, --fresh runs
them again); a worker keeps one ``Rig`` for all its runs. Three static experiments, each
against a reference computed here (nothing hard-coded): the back-to-back cantilevers and the
hanging strip below, and the lab's own cantilever on a ledge at widths 2-16 cm (``ledge``).

Cantilever (flexural rigidity B = ``material.k_bend``, N m). Two cantilevers back to back: a
strip 2 L long (L = 20 cm, 8 cm wide) is held only along its middle line of vertices and both
halves droop under their own weight q = rho g (N/m^2). The static shape is found by minimising
elastic + gravitational energy with the simulator's own forces and Jacobian
(``SparseImplicitEuler`` steps from rest, accepted only when the energy drops). The reference
is the inextensible elastica ``B theta' = M``: with s the arc length from the clamp and theta
the slope below horizontal, ``B theta'' = -q (L - s) cos theta``, ``theta(0) = 0``,
``theta'(L) = 0``, solved by shooting on ``theta'(0)``; its shape depends only on
``G = q L^3 / B``. The measured chord angle (root to tip) is read back through the elastica as
``G_eff`` and ``B_eff = q L^3 / G_eff``. G = 1: small deflection (chord 7.1 deg); G = 8: large
(41.5 deg, the ASTM D1388 cantilever's angle, where the overhang is twice the bending length).

Directions: the strip along the mesh's warp lines (``make_sheet`` of the strip), along its
weft lines (the sheet turned 90 deg), or on the bias (a sheet meshed along its grain, turned
by +45 deg, ``bias``, or -45 deg, ``bias-``, and the strip cut from it: no grid lines run
across the strip; the regular pattern's diagonals run across it in ``bias``, along it in
``bias-``). Bending is isotropic, so the
grain itself matters only through the mesh.

Hanging strip (tensile modulus k, N/m). A 1 m x 4 cm strip hangs from its top row. The
tension per unit width at depth z is rho g (L - z); k_eff / k is read from the top row of
faces through the membrane law (Green strain, so exact at any strain), the linear reading
rho g (L - h / 2) / strain alongside.
"""
import argparse
import os
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import numpy as np

G_ACC = 9.81


def _bend_constant():
    from cloth.model import BEND_CONSTANT
    return BEND_CONSTANT


# ---- references -------------------------------------------------------------------------------
def _shoot(G, a, n):
    """RK4 of theta'' = -G (1 - s) cos theta from theta(0) = 0, theta'(0) = a over s in
    [0, 1] with n steps, for arrays G and a (broadcast); returns theta and theta' at s = 1
    and, with ``path``, theta at the n + 1 nodes."""
    ds = 1.0 / n
    t = np.zeros(np.broadcast(G, a).shape)
    o = np.broadcast_to(a, t.shape).astype(float)
    path = [t]
    for i in range(n):
        s = i * ds
        k1t, k1o = o, -G * (1.0 - s) * np.cos(t)
        k2t, k2o = o + ds / 2 * k1o, -G * (1.0 - s - ds / 2) * np.cos(t + ds / 2 * k1t)
        k3t, k3o = o + ds / 2 * k2o, -G * (1.0 - s - ds / 2) * np.cos(t + ds / 2 * k2t)
        k4t, k4o = o + ds * k3o, -G * (1.0 - s - ds) * np.cos(t + ds * k3t)
        t = t + ds / 6 * (k1t + 2 * k2t + 2 * k3t + k4t)
        o = o + ds / 6 * (k1o + 2 * k2o + 2 * k3o + k4o)
        path.append(t)
    return np.array(path), o


def elastica(G, n=400, rounds=14, k=16):
    """Inextensible cantilever under its own weight, nondimensional (s in [0, 1], lengths in
    units of L): theta'' = -G (1 - s) cos theta, theta(0) = 0, theta'(1) = 0, G = q L^3 / B
    (differentiate B theta' = M, M(s) = q int_s^L (x(t) - x(s)) dt). Shooting on a = theta'(0)
    for every G of an array at once: theta'(1) < 0 at a = 0 and >= 0 at a = G / 2 (the clamp
    moment of the undeflected beam, the largest the load can exert); each round evaluates k
    points of the bracket and keeps the first sign change (the physical branch, the smallest
    clamp moment). Returns (s, theta (n + 1, m), x, y) with y downward."""
    G = np.atleast_1d(np.asarray(G, float))[:, None]
    lo, hi = np.zeros_like(G), G / 2.0
    frac = np.linspace(0.0, 1.0, k + 1)[None, :]
    rows = np.arange(len(G))
    for _ in range(rounds):
        a = lo + (hi - lo) * frac
        _, om = _shoot(G, a, n)
        first = np.argmax(om >= 0.0, axis=1)       # om[:, -1] >= 0 by the bracket
        first = np.maximum(first, 1)
        lo, hi = a[rows, first - 1][:, None], a[rows, first][:, None]
    th, _ = _shoot(G, 0.5 * (lo + hi), n)
    th = th[:, :, 0]
    s = np.linspace(0.0, 1.0, n + 1)
    ds = 1.0 / n
    zero = np.zeros((1, th.shape[1]))
    x = np.r_[zero, np.cumsum(0.5 * (np.cos(th[1:]) + np.cos(th[:-1])) * ds, axis=0)]
    y = np.r_[zero, np.cumsum(0.5 * (np.sin(th[1:]) + np.sin(th[:-1])) * ds, axis=0)]
    return s, th, x, y


def chord_angle(G):
    """Angle (rad) below horizontal of the chord from the clamp to the tip of the elastica
    (array in, array out; a scalar gives a float)."""
    _, _, x, y = elastica(G)
    out = np.arctan2(y[-1], x[-1])
    return float(out[0]) if np.ndim(G) == 0 else out


_TABLE = {}


def G_from_chord(angle):
    """Invert ``chord_angle`` (increasing in G) by interpolation in log G on a table of
    400 elastica over G = 1e-2 ... 40 (chord 0.07 ... 71 deg; computed once, ~2 s). Linear
    interpolation there is good to 1e-4 in G (checked against a direct solve in the tests)."""
    if "G" not in _TABLE:
        G = np.geomspace(1e-2, 40.0, 400)
        _TABLE["G"], _TABLE["chord"] = G, chord_angle(G)
        assert np.all(np.diff(_TABLE["chord"]) > 0)
    G, ch = _TABLE["G"], _TABLE["chord"]
    if not ch[0] <= angle <= ch[-1]:
        raise ValueError(f"chord angle {np.degrees(angle):.3g} deg outside the table")
    return float(np.exp(np.interp(angle, ch, np.log(G))))


# ---- simulations ------------------------------------------------------------------------------
CANT_L, CANT_WIDTH = 0.20, 0.08     # m: overhang of each half, strip width
STRIP_L, STRIP_WIDTH = 1.0, 0.04                    # m: the hanging strip
DIRECTIONS = ("warp", "weft", "bias", "bias-")


def _rotate(uv, angle):
    c, s = np.cos(angle), np.sin(angle)
    return uv @ np.array([[c, s], [-s, c]])


def _compact(uv, faces):
    used = np.unique(faces)
    remap = -np.ones(len(uv), int)
    remap[used] = np.arange(len(used))
    return uv[used].copy(), remap[faces].astype(np.int32)


def cantilever_mesh(L, width, h, pattern="regular", direction="warp", seed=0):
    """The back-to-back cantilevers' strip [0, 2 L] x [0, width]: the half [0, L] meshed by
    ``strip_mesh`` and its mirror image across u = L, welded along that line. Mirror
    symmetric, so the two halves weigh the same about the held middle line: with halves that
    differ (a bias mesh cut at two different offsets of the lattice), the whole strip turned
    about that line by up to 40 deg, which no bending resists."""
    uv, faces, angle = strip_mesh(L, width, h, pattern, direction, seed, cuts=(0.0, L))
    n = len(uv)
    on_line = np.abs(uv[:, 0] - L) < 1e-12
    mirror = np.where(on_line, np.arange(n), n + np.cumsum(~on_line) - 1)
    uv2 = np.r_[uv, np.c_[2 * L - uv[~on_line, 0], uv[~on_line, 1]]]
    faces2 = np.r_[faces, mirror[faces][:, ::-1]]          # reversed: counter-clockwise again
    return uv2, faces2.astype(np.int32), angle


IRREGULAR = "irregular"      # a Delaunay triangulation of jittered points (no lattice)


def irregular_strip(length, width, h, seed=0, cuts=()):
    """[0, length] x [0, width] triangulated by Delaunay from points on a grid of spacing h
    jittered by up to 0.35 h (interior), plus evenly spaced points on the outline and on the
    lines u = c of ``cuts``: triangles of every shape and orientation, no mesh lines."""
    from scipy.spatial import Delaunay
    rng = np.random.default_rng(seed)
    nu, nv = max(int(round(length / h)), 1), max(int(round(width / h)), 1)
    du, dv = length / nu, width / nv
    U, V = np.meshgrid(np.arange(1, nu) * du, np.arange(1, nv) * dv, indexing="ij")
    inner = np.c_[U.ravel(), V.ravel()] + rng.uniform(-0.35, 0.35, (U.size, 2)) * [du, dv]
    us, vs = np.linspace(0.0, length, nu + 1), np.linspace(0.0, width, nv + 1)
    lines = [np.c_[us, np.zeros_like(us)], np.c_[us, np.full_like(us, width)],
             np.c_[np.zeros_like(vs), vs], np.c_[np.full_like(vs, length), vs]]
    lines += [np.c_[np.full_like(vs, c), vs] for c in cuts if 0.0 < c < length]
    if any(0.0 < c < length for c in cuts):      # interior cut: no jittered point across it
        for c in cuts:
            inner = inner[np.abs(inner[:, 0] - c) > 0.45 * du]
    uv = np.unique(np.round(np.r_[np.concatenate(lines), inner], 12), axis=0)
    faces = Delaunay(uv).simplices
    a, b, c = uv[faces[:, 0]], uv[faces[:, 1]], uv[faces[:, 2]]
    area = 0.5 * ((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])
    faces[area < 0] = faces[area < 0][:, ::-1]
    faces = faces[np.abs(area) > 1e-3 * h * h]
    return uv, faces.astype(np.int32), 0.0


def _bias_rows(width, h, cuts):
    """Half the number of vertex rows across a bias strip: the m >= 1 nearest to
    width sqrt(2) / (2 h) (the finer on a tie) for which every cut lies an even number of
    row spacings s = width / (2 m) from the last. The lattice's vertices on the edge rows then
    fall on every cut line, not only on the last, and each cut is straight to the corners:
    otherwise the tip is ragged (a 16 cm strip at 0.5 cm has L / s = 57.5 at the nearest m;
    the ledge strips lost up to 5 % of their area at the tip, and read too stiff)."""
    m0 = max(1, int(round(width * np.sqrt(2.0) / (2 * h))))
    for m in sorted(range(max(1, m0 // 2), 2 * m0 + 2), key=lambda m: (abs(m - m0), -m)):
        s = width / (2 * m)
        k = [(c - cuts[-1]) / s for c in cuts]
        if all(abs(x - 2 * round(x / 2)) < 1e-6 for x in k):
            return m
    return m0


def strip_mesh(length, width, h, pattern="regular", direction="warp", seed=0, cuts=()):
    """A strip [0, length] x [0, width] in material coordinates (u along the strip) meshed by
    ``make_sheet`` with legs of about ``h``, cut from a sheet meshed along its grain:

    warp   mesh lines along and across the strip (``make_sheet`` of the strip itself);
    weft   the same sheet turned by 90 degrees (the strip runs along the sheet's v lines);
    bias   mesh lines at 45 degrees to the strip: a larger sheet turned by +45 degrees
           (``bias-``: by -45 degrees), the faces whose
           centroid lies in the strip kept, and vertices snapped onto the strip's outline and
           onto the lines u = c for c in ``cuts`` (so a clamp edge is straight); faces that
           this flattens or turns over are dropped.

    Returns (uv, faces, grain angle): the angle of the warp (the sheet's u lines) from the
    strip's axis, for ``grain_from_angle``."""
    from cloth.sheet import make_sheet, quad_flips
    if pattern == IRREGULAR:
        return irregular_strip(length, width, h, seed, cuts)
    if direction == "warp":
        nu, nv = int(round(length / h)) + 1, max(int(round(width / h)) + 1, 2)
        uv, faces = make_sheet(length, width, nu, nv, pattern, seed=seed)
        return uv, faces, 0.0
    if direction == "weft":
        nu, nv = max(int(round(width / h)) + 1, 2), int(round(length / h)) + 1
        uv, faces = make_sheet(width, length, nu, nv, pattern, seed=seed)
        # (a, b) -> (b, width - a): a quarter turn, which keeps faces counter-clockwise.
        uv = np.c_[uv[:, 1], width - uv[:, 0]]
        return uv, faces, np.pi / 2
    if direction not in ("bias", "bias-"):
        raise ValueError(f"unknown direction '{direction}'")
    turn = np.pi / 4 if direction == "bias" else -np.pi / 4
    # The turned lattice's vertices lie on rows parallel to the strip, s = leg / sqrt(2)
    # apart: s is chosen so that rows lie on both long edges, and the quads that straddle an
    # edge are cut along their diagonal parallel to it, so the outline is straight (cut
    # through the turned pattern, it would be a saw-tooth of 45-degree edges whose loose teeth
    # carry weight but little stiffness: a bias strip 2 cm meshes wide read 25 % too soft).
    s = width / (2 * _bias_rows(width, h, cuts))                          # even rows
    leg = s * np.sqrt(2.0)
    n = int(np.ceil((length + width) / s)) + 4
    flip = quad_flips(n + 1, n + 1, pattern, seed)
    uv, faces = make_sheet(n * leg, n * leg, n + 1, n + 1, flip=flip)
    uv = _rotate(uv - n * leg / 2, turn) + np.array([length / 2, width / 2])
    # Rows on v = k s, and vertices of rows 0 and width / s (an even number of rows) on the
    # last cut (the clamp line of ``cantilever_mesh``): moving a row changes u by s, so the
    # lattice holds (c, 0) when c = u0 + k0 s (mod 2 s) for vertex 0 on row k0. Then the
    # quads at the clamp line's ends straddle only one line each.
    uv[:, 1] -= uv[0, 1] % s
    clamp = cuts[-1] if len(cuts) else 0.0
    uv[:, 0] -= (uv[0, 0] + round(uv[0, 1] / s) * s - clamp) % (2 * s)
    quad = np.arange(n * n)
    qi, qj = quad // n, quad % n
    corners = np.stack([qi * (n + 1) + qj, (qi + 1) * (n + 1) + qj,
                        (qi + 1) * (n + 1) + qj + 1, qi * (n + 1) + qj + 1], axis=1)
    mid_u, mid_v = uv[corners, 0].mean(axis=1), uv[corners, 1].mean(axis=1)
    # Quads that straddle a cut line u = c are cut along their diagonal parallel to it too
    # (a straight clamp line, and the mirrored halves of ``cantilever_mesh`` join along it;
    # the corners follow the cut, else the clamp line has a notch at each end).
    # The diagonal a-c (corners 0, 2) or b-d (1, 3) that runs along the strip's edge.
    ac_flat = np.abs(uv[corners[:, 2], 1] - uv[corners[:, 0], 1]) < 0.5 * s
    on_edge = (np.abs(mid_v) < 0.5 * s) | (np.abs(mid_v - width) < 0.5 * s)
    flip = np.where(on_edge, ~ac_flat, flip)
    on_cut = np.zeros(len(quad), bool)
    for c in cuts:
        on_cut |= np.abs(mid_u - c) < 0.5 * s
    flip = np.where(on_cut, ac_flat, flip)
    faces = make_sheet(n * leg, n * leg, n + 1, n + 1, flip=flip)[1]
    cen = uv[faces].mean(axis=1)
    tol = 1e-9 * width
    keep = (cen[:, 0] > 0) & (cen[:, 0] < length) & (cen[:, 1] > tol) & (cen[:, 1] < width - tol)
    uv, faces = _compact(uv, faces[keep])
    uv[:, 0] = np.clip(uv[:, 0], 0.0, length)
    uv[:, 1] = np.clip(uv[:, 1], 0.0, width)
    for c in cuts:
        near = np.abs(uv[:, 0] - c) < 0.3 * h
        uv[near, 0] = c
    a, b, cc = uv[faces[:, 0]], uv[faces[:, 1]], uv[faces[:, 2]]
    area = 0.5 * ((b - a)[:, 0] * (cc - a)[:, 1] - (b - a)[:, 1] * (cc - a)[:, 0])
    uv, faces = _compact(uv, faces[area > 0.05 * h * h])
    return uv, faces, turn


def _set(field, n, arr):
    full = field.to_numpy()
    full[:n] = arr
    field.from_numpy(full)


class Rig:
    """One ClothModel and one SparseImplicitEuler refilled for every experiment (one
    allocation and one sparse pattern set-up for a whole sweep). ``capacity``: vertices of
    the largest mesh to come."""

    def __init__(self, capacity=2500, bending="isotropic"):
        from cloth.dynamics import DynamicsSettings
        from cloth.dynamics_sparse import SparseImplicitEuler
        from cloth.model import ClothModel, MeshArrays
        from cloth.sheet import make_sheet
        n = int(np.ceil(np.sqrt(capacity)))
        uv, faces = make_sheet(1.0, 1.0, n, n)
        self.model = ClothModel(MeshArrays(uv=uv, x=np.c_[uv, np.zeros(len(uv))], faces=faces),
                                make_material(), capacity_factor=1.3, bending=bending)
        self.dyn = SparseImplicitEuler(self.model, DynamicsSettings(gravity=(0.0, -G_ACC, 0.0)))

    def load(self, uv, x, faces, pinned, grain_angle, material):
        from cloth.model import MeshArrays, grain_from_angle
        self.model.material = material
        self.model.load(MeshArrays(uv=uv, x=x, faces=faces, pinned=pinned,
                                   grain=grain_from_angle(grain_angle, len(faces))))
        self.dyn.on_mesh_changed()
        return self.model

    def settle(self, tol=1e-8, max_steps=500, h0=0.02):
        """Static equilibrium under gravity: backward-Euler steps from rest (velocities zeroed
        after each), a step kept only if it lowers elastic + gravitational energy; its size h
        doubles after a success and is quartered after a failure (h -> infinity is a Newton
        step with the simulator's positive semi-definite Jacobian, whose bending part leaves out
        the angle's curvature: convergence is linear at large deflections). Stops when a step
        moves no vertex more than ``tol`` m (a tip error of microns); after ``max_steps`` it
        accepts steps below 100 x ``tol``. Returns the number of steps."""
        model, dyn = self.model, self.dyn
        g = np.asarray(dyn.settings.gravity, float)
        mass, n = model.mass, model.n_verts

        def energy():
            return dyn.energy() - float(np.sum(mass * (model.positions() @ g)))

        h, zero, move = h0, np.zeros((n, 3)), np.inf
        e0 = energy()
        for it in range(max_steps):
            x0 = model.positions()
            _set(model.state.v, n, zero)
            dyn.step(h)
            e1 = energy()
            if not np.isfinite(e1) or e1 > e0 + 1e-13 * abs(e0):
                _set(model.state.x, n, x0)
                h *= 0.25
                if h < 1e-9:
                    raise RuntimeError("static solve stalled")
                continue
            move = np.abs(model.positions() - x0).max()
            e0, h = e1, min(h * 2.0, 1e3)
            if move < tol:
                _set(model.state.v, n, zero)
                return it + 1
        if move < 100 * tol:
            _set(model.state.v, n, zero)
            return max_steps
        raise RuntimeError(f"static solve did not converge in {max_steps} steps")


# Shear modulus of the calibration fabric, N/m: a woven's (KES-FB1 shear stiffness of cotton
# wovens is 0.5-2 gf/cm/deg, i.e. 30-110 N/m; the Material default). Stiffer shear locks a
# coarse bias mesh at large deflection (the LOCKING sweep).
CALIBRATION_SHEAR = 50.0


def make_material(**kw):
    """The calibration fabric: areal density 0.15 kg/m^2, a membrane stiff in stretch (the
    elastica is inextensible; 3e4 N/m along warp and weft, and ~200 N/m on the bias through
    the woven's shear, where the strip's own weight strains it by ~1e-3), no damping (the
    solve is static)."""
    from cloth.model import Material
    base = dict(density=0.15, k_warp=3e4, k_weft=3e4, k_shear=CALIBRATION_SHEAR, k_bend=1e-4,
                damp_mass=0.0, damp_stiff=0.0)
    base.update(kw)
    return Material(**base)


def cantilever(rig, G=1.0, h=0.01, pattern="regular", direction="warp", seed=0,
               material=None, L=CANT_L, width=CANT_WIDTH):
    """Two cantilevers back to back: a strip of length 2 L held only along its middle line
    of vertices (pinned), both halves overhanging L with q L^3 / B = G; B_eff / B is read back
    from the mean chord angle of the two halves through the elastica.

    Why not a ledge: with the vertices of a ledge pinned, the hinge line at the ledge's edge
    turns by the moment there times a full cell's compliance, where the continuum would give
    half a cell; the strip reads too soft by O(h / L) (10 % at h = 1 cm, L = 20 cm,
    measured). Held at its middle, that line's turn is shared by the two halves, so each
    gets half a cell, and the comparison with the clamped elastica is second-order in h."""
    mat = material or make_material()
    q = mat.density * G_ACC
    mat.k_bend = q * L ** 3 / G
    uv, faces, angle = cantilever_mesh(L, width, h, pattern, direction, seed)
    x = np.c_[uv[:, 0] - L, np.zeros(len(uv)), uv[:, 1]]
    mid = np.abs(uv[:, 0] - L) < 1e-12
    model = rig.load(uv, x, faces, mid, angle, mat)
    steps = rig.settle()
    xs = model.positions()
    root = xs[mid].mean(axis=0)
    chords = []
    for end_u, sign in ((0.0, -1.0), (2 * L, 1.0)):
        tip = xs[np.abs(uv[:, 0] - end_u) < 1e-12].mean(axis=0)
        chords.append(np.arctan2(root[1] - tip[1], sign * (tip[0] - root[0])))
    chord = float(np.mean(chords))
    G_eff = G_from_chord(chord)
    # Centre line of the right half: vertices averaged over the width at each u (a bias
    # mesh has no columns of vertices: bins of h / 2).
    right = uv[:, 0] >= L - 1e-12
    bins = np.round((uv[right, 0] - L) / (0.5 * h)).astype(int)
    shape = np.array([xs[right][bins == b][:, :2].mean(axis=0) for b in np.unique(bins)])
    return dict(kind="cantilever", G=G, h=h, pattern=pattern, direction=direction, seed=seed,
                chord_deg=float(np.degrees(chord)),
                chord_ref_deg=float(np.degrees(chord_angle(G))), ratio=G / G_eff,
                asymmetry_deg=float(np.degrees(chords[1] - chords[0])),
                steps=steps, faces=len(faces), shape=(shape - root[:2]) / L)


def hanging_strip(rig, h=0.01, pattern="regular", direction="warp", k=200.0, seed=0,
                  L=STRIP_L, width=STRIP_WIDTH):
    """A strip hanging from its top row (u = 0) with modulus k along it; k_eff / k from the
    strain of the top row of faces (mean over the faces of 0 <= u <= h, whose centres carry
    the tension rho g (L - h / 2) per unit width). Read back through the membrane law: the
    Green strain E = eps + eps^2 / 2 carries the second Piola-Kirchhoff stress k E, so the
    tension per unit reference width is (1 + eps) k E."""
    if direction.startswith("bias"):
        raise ValueError("the hanging strip is measured along the warp and the weft")
    other = 5.0 * k
    mat = make_material(k_bend=1e-7, k_shear=k / 4,
                        k_warp=k if direction == "warp" else other,
                        k_weft=k if direction == "weft" else other)
    uv, faces, angle = strip_mesh(L, width, h, pattern, direction, seed)
    x = np.c_[uv[:, 1], -uv[:, 0], np.zeros(len(uv))]
    model = rig.load(uv, x, faces, uv[:, 0] <= 1e-12, angle, mat)
    steps = rig.settle(tol=1e-10)
    xs = model.positions()
    f = faces[uv[faces].mean(axis=1)[:, 0] < h]
    a, b, c = uv[f[:, 0]], uv[f[:, 1]], uv[f[:, 2]]
    Dm = np.stack([b - a, c - a], axis=2)
    Ds = np.stack([xs[f[:, 1]] - xs[f[:, 0]], xs[f[:, 2]] - xs[f[:, 0]]], axis=2)
    F = Ds @ np.linalg.inv(Dm)
    eps = float(np.mean(np.linalg.norm(F[:, :, 0], axis=1)) - 1.0)
    T = mat.density * G_ACC * (L - h / 2)
    k_eff = T / ((1.0 + eps) * (eps + eps * eps / 2))
    bottom = np.abs(uv[:, 0] - L) < 1e-12
    elongation = float(-xs[bottom, 1].mean() - L)
    return dict(kind="strip", h=h, pattern=pattern, direction=direction, k=k, strain=eps,
                elongation=elongation,
                strain_linear=T / k, ratio=k_eff / k, ratio_linear=T / eps / k, steps=steps,
                faces=len(faces))


# ---- the sweep and its report ---------------------------------------------------------------
SIZES = (0.005, 0.01, 0.02)
PATTERNS = ("regular", "alternating", "random")
DEFLECTIONS = (1.0, 8.0)        # G = q L^3 / B: chord 7 deg (small), 41.5 deg (ASTM D1388's)


LOCKING_SHEAR = (50.0, 1e3, 1e4)   # N/m


def plan(quick=False):
    """The sweep's runs in the page's order: (kind, keyword arguments) for ``case``."""
    sizes = (0.01, 0.02) if quick else SIZES
    out = [("cantilever", dict(G=G, h=h, pattern=p, direction=d))
           for p in PATTERNS for h in sizes for d in DIRECTIONS for G in DEFLECTIONS]
    # A triangulation without mesh lines: one direction says all.
    out += [("cantilever", dict(G=G, h=h, pattern=IRREGULAR, direction="warp"))
            for h in sizes for G in DEFLECTIONS]
    # Membrane locking: large deflection on the bias, against the shear modulus.
    out += [("locking", dict(G=DEFLECTIONS[-1], h=h, pattern=p, direction=d, k_shear=k))
            for p in PATTERNS for h in (0.01, 0.02) for d in ("bias", "bias-")
            for k in LOCKING_SHEAR]
    out += [("ledge", dict(G=G, h=h, pattern=p, direction=d))
            for p, h, d, G in ledge_cases(sizes)]
    out += [("strip", dict(h=h, pattern=p, direction=d))
            for p in PATTERNS for h in sizes for d in ("warp", "weft")]
    return out


_RIGS = {}


def _rig(capacity, bending="isotropic"):
    """This process's Rig of that size and bending (built at its first use)."""
    if (capacity, bending) not in _RIGS:
        _RIGS[capacity, bending] = Rig(capacity=capacity, bending=bending)
    return _RIGS[capacity, bending]


def case(kind, kw, source=None):
    """One run of the sweep (in a worker; ``source``: this module's hash, ``module_hash``,
    for the cache key only): {"rows": the rows it adds to the page}. A cantilever is solved
    with the isotropic energy and again with the hinge energy (``ratio_hinge``); a ledge at
    every width of ``WIDTHS``; ``orthotropic``: ``orthotropic_sweep``'s cases of one ratio,
    deflection and width."""
    from cloth import backend
    backend.init("cpu", "f64")
    kw = dict(kw)
    if kind == "orthotropic":
        rig = _rig(700)
        ratio, G, w = kw["ratio"], kw["G"], kw["width"]
        rows = [ledge_orthotropic(rig, ratio, G=G, h=kw["h"], pattern=p, direction=d, width=w)
                for p in PATTERNS for d in ("warp", "weft", "bias", "bias-")]
        for gdeg in (0.0, 90.0, 45.0, -45.0, 30.0):
            r = ledge_orthotropic(rig, ratio, G=G, h=kw["h"], pattern=IRREGULAR,
                                  direction="warp", width=w, grain=np.radians(gdeg))
            r["direction"] = f"{gdeg:g} deg"
            rows.append(r)
        return {"rows": rows}
    rig = _rig(3000)
    if kind == "cantilever":
        r = cantilever(rig, **kw)
        r["ratio_hinge"] = cantilever(_rig(3000, "hinge"), **kw)["ratio"]
        return {"rows": [r]}
    if kind == "locking":
        k_shear = kw.pop("k_shear")
        r = cantilever(rig, material=make_material(k_shear=k_shear), **kw)
        r.update(kind="locking", k_shear=k_shear)
        return {"rows": [r]}
    if kind == "ledge":
        return {"rows": [ledge(rig, width=w, **kw) for w in WIDTHS]}
    if kind == "strip":
        return {"rows": [hanging_strip(rig, **kw)]}
    raise ValueError(f"unknown calibration run {kind!r}")


def _label(kind, kw):
    return f"{kind} " + " ".join(f"{k}={v}" for k, v in kw.items())


def _sweep(jobs, name, out=None, scheduler=None, workers=None, fresh=False):
    """(the Runs, their results) of ``case`` over ``jobs`` [(kind, kw)], cached in
    ``out``/calibration_runs (default results/)."""
    from benchmarks.sweep import Run, module_hash, run_sweep
    source = module_hash("benchmarks.calibration")
    sweep = [Run("benchmarks.calibration:case", [kind, kw, source], _label(kind, kw))
             for kind, kw in jobs]
    folder = os.path.join(out or os.path.join(ROOT, "results"), "calibration_runs")
    return sweep, run_sweep(sweep, folder, scheduler, workers, fresh, name=name)


def run(quick=False, log=print, out=None, scheduler=None, workers=None, fresh=False):
    """Every case of ``plan`` as a sweep (``_sweep``); (the rows, the Runs, their results)."""
    sweep, results = _sweep(plan(quick), "calibration", out, scheduler, workers, fresh)
    rows = []
    for run_, res in zip(sweep, results):
        if "error" in res:
            log(f"{run_.label}: failed")
            continue
        for r in res["rows"]:
            if "shape" in r:
                r["shape"] = np.asarray(r["shape"])
            rows.append(r)
    return rows, sweep, results


# ---- the lab's cantilever on a ledge (ASTM D1388) ---------------------------------------
# A strip on a ledge, its vertices there pinned, overhanging the ledge's edge by L = 20 cm under
# its own weight; B_eff read back from the chord angle through the inextensible elastica whose
# clamp is the ledge's edge. Unlike the back-to-back strips, a ledge has a clamp (two rows of
# pins or more hold the slope) and the strip's free long edges matter at every width: 2 cm (two
# triangles across at 1 cm), 2.5 cm (ASTM D1388's strip), 4, 8 and 16 cm. Bending has no Poisson
# coupling, so the width must not matter.
LEDGE = 0.10                       # m: the length of strip held on the ledge
WIDTHS = (0.02, 0.025, 0.04, 0.08, 0.16)
LEDGE_TARGET = {0.005: 0.03, 0.01: 0.05, 0.02: 0.05}      # |B_eff / B - 1| by triangle size


def ledge_mesh(width, h, pattern="regular", direction="warp", seed=0, L=CANT_L,
               ledge=LEDGE):
    """The strip [-ledge, L] x [0, width] (``calibration.strip_mesh``, shifted so that the
    ledge's edge is u = 0). The ledge's edge and the tip are mesh lines (cuts), so the clamp
    and the tip are straight on every pattern and direction."""
    uv, faces, angle = strip_mesh(ledge + L, width, h, pattern, direction, seed,
                                      cuts=(ledge + L, ledge))
    return uv - np.array([ledge, 0.0]), faces, angle


def ledge(rig, G=1.0, h=0.01, pattern="regular", direction="warp", seed=0, material=None,
          width=CANT_WIDTH, L=CANT_L, grain=None):
    """One ledge cantilever with q L^3 / B = G (B = ``material.k_bend``); returns the chord
    (root: the middle of the ledge's edge, tip: the middle of the free end) and
    ratio = B_eff / B. ``grain``: the warp's angle from the strip's axis (rad), instead of
    the mesh's (an orthotropic fabric cut at any angle from any mesh)."""
    mat = material or make_material()
    q = mat.density * G_ACC
    mat.k_bend = q * L ** 3 / G
    uv, faces, angle = ledge_mesh(width, h, pattern, direction, seed, L=L)
    angle = angle if grain is None else grain
    x = np.c_[uv[:, 0], np.zeros(len(uv)), uv[:, 1]]
    model = rig.load(uv, x, faces, uv[:, 0] <= 1e-12, angle, mat)
    try:
        steps = rig.settle()
    except RuntimeError:
        # No step lowers the energy beyond round-off: the reading is kept and flagged (the
        # old energy stalled so on a random bias strip at 0.5 cm).
        steps = -1
    xs = model.positions()
    root = xs[np.abs(uv[:, 0]) < 1e-12].mean(axis=0)
    tip = xs[np.abs(uv[:, 0] - L) < 1e-12].mean(axis=0)
    chord = float(np.arctan2(root[1] - tip[1], tip[0] - root[0]))
    return dict(kind="ledge", G=G, h=h, pattern=pattern, direction=direction, seed=seed,
                width=width, chord_deg=float(np.degrees(chord)),
                chord_ref_deg=float(np.degrees(chord_angle(G))),
                ratio=G / G_from_chord(chord), steps=steps, faces=len(faces))


# ---- orthotropic bending: B_warp != B_weft ---------------------------------------------------
def strip_rigidity(b_warp, b_weft, angle):
    """The B a narrow strip cut at ``angle`` (rad) from the warp reads, for Loom's orthotropic
    plate (cloth/bending.py: B_warp, B_weft, no Poisson coupling, twisting rigidity
    H = sqrt(B_warp B_weft)): its transverse curvature and twist are free, so B is 1 / S_ss of
    the plate's compliance, 1 / B = cos^4 / B_warp + sin^4 / B_weft + 2 cos^2 sin^2 / H, i.e.
    1 / sqrt(B) = cos^2 / sqrt(B_warp) + sin^2 / sqrt(B_weft). On the bias: the square of the
    harmonic mean of sqrt(B_warp) and sqrt(B_weft)."""
    from cloth.bending import strip_rigidity as closed_form
    return closed_form(b_warp, b_weft, angle)


def cylindrical_rigidity(b_warp, b_weft, angle):
    """The B of a wide plate bent into a cylinder across ``angle`` (its transverse curvature
    and twist held at zero): sqrt(B) = cos^2 sqrt(B_warp) + sin^2 sqrt(B_weft), the
    square of the arithmetic mean on the bias: the upper bound a wide strip's clamp tends to."""
    c2, s2 = np.cos(angle) ** 2, np.sin(angle) ** 2
    return (c2 * np.sqrt(b_warp) + s2 * np.sqrt(b_weft)) ** 2


DIRECTION_ANGLE = {"warp": 0.0, "weft": np.pi / 2, "bias": np.pi / 4, "bias-": -np.pi / 4}


def ledge_orthotropic(rig, ratio, G=1.0, h=0.01, pattern="regular", direction="warp",
                      width=0.04, grain=None, L=CANT_L):
    """A ledge cantilever of an orthotropic fabric with B_warp / B_weft = ``ratio``, scaled so
    that the strip's expected rigidity (``strip_rigidity`` at the strip's grain angle) is
    q L^3 / G; ``ratio`` in the result is B_eff / that. ``grain``: the warp's angle from the
    strip (default: the direction's, with the mesh cut along it)."""
    angle = DIRECTION_ANGLE[direction] if grain is None else grain
    q = 0.15 * G_ACC
    scale = q * L ** 3 / G / strip_rigidity(ratio, 1.0, angle)
    mat = make_material(k_bend_warp=ratio * scale, k_bend_weft=scale)
    r = ledge(rig, G=G, h=h, pattern=pattern, direction=direction, material=mat, width=width,
              L=L, grain=grain)
    r.update(bend_ratio=ratio, grain_deg=float(np.degrees(angle)),
             cylindrical=float(cylindrical_rigidity(ratio, 1.0, angle)
                               / strip_rigidity(ratio, 1.0, angle)))
    return r


ORTHO_RATIOS = (3.0, 4.0, 10.0)


def orthotropic_sweep(ratios=ORTHO_RATIOS, widths=(0.025, 0.04), h=0.01, log=print,
                      scheduler=None, workers=None, fresh=False, out=None):
    """``ledge_orthotropic`` over B_warp / B_weft, widths, both deflections, the three grid
    patterns cut along warp, weft and bias, and one Delaunay mesh with the grain turned by
    0, 90, 45, -45 and 30 deg (``--orthotropic``; docs/fabrics.md): a run per ratio,
    deflection and width (``case``)."""
    jobs = [dict(ratio=ratio, G=G, width=w, h=h) for ratio in ratios for G in DEFLECTIONS
            for w in widths]
    _, results = _sweep([("orthotropic", kw) for kw in jobs], "orthotropic", out, scheduler,
                        workers, fresh)
    rows = []
    for kw, res in zip(jobs, results):
        if "error" in res:
            log(f"orthotropic ratio {kw['ratio']:g} G {kw['G']:g} width {100 * kw['width']:g} "
                f"cm: failed: {res['error'].strip().splitlines()[-1]}")
            continue
        rows += res["rows"]
        log(f"orthotropic ratio {kw['ratio']:g} G {kw['G']:g} width {100 * kw['width']:g} cm: "
            + " ".join(f"{r['ratio']:.3f}" for r in res["rows"]))
    return rows


def orthotropic_lines(rows):
    """The table of B_eff / strip_rigidity by case (docs/fabrics.md)."""
    L = ["| B_warp / B_weft | G | width (cm) | pattern | warp | weft | bias | bias- | "
         "bias: cylindrical / strip |", "|" + " --- |" * 9]
    irr = ["| B_warp / B_weft | G | width (cm) | 0 deg | 90 deg | 45 deg | -45 deg | 30 deg |",
           "|" + " --- |" * 8]
    key = lambda r: (r["bend_ratio"], r["G"], r["width"])
    for k in sorted({key(r) for r in rows}):
        rs = [r for r in rows if key(r) == k]
        for p in PATTERNS:
            by = {r["direction"]: r for r in rs if r["pattern"] == p}
            L.append(f"| {k[0]:g} | {k[1]:g} | {100 * k[2]:g} | {p} | " + " | ".join(
                f"{by[d]['ratio']:.3f}" for d in ("warp", "weft", "bias", "bias-")) +
                f" | {by['bias']['cylindrical']:.3f} |")
        by = {r["direction"]: r for r in rs if r["pattern"] == IRREGULAR}
        irr.append(f"| {k[0]:g} | {k[1]:g} | {100 * k[2]:g} | " + " | ".join(
            f"{by[d]['ratio']:.3f}" for d in ("0 deg", "90 deg", "45 deg", "-45 deg",
                                              "30 deg")) + " |")
    return L + ["", "Delaunay strips (no mesh lines), the grain turned by the angle given:", ""] \
        + irr


def ledge_counts(r):
    """Whether the ledge targets cover a case: at least two triangles across."""
    return r["width"] >= 2 * r["h"] - 1e-9


def ledge_cases(sizes):
    for pattern in PATTERNS + (IRREGULAR,):
        for h in sizes:
            for direction in (("warp",) if pattern == IRREGULAR else DIRECTIONS):
                for G in DEFLECTIONS:
                    yield pattern, h, direction, G


def _ledge_group(rows):
    out = {}
    for r in rows:
        out.setdefault((r["pattern"], r["direction"], r["h"], r["G"]), {})[r["width"]] = r
    return out


def ledge_report_lines(rows):
    """The ledge section of calibration.md."""
    if not rows:
        return []
    L = ["## Ledge cantilever (ASTM D1388)\n",
         f"A strip on a ledge {100 * LEDGE:g} cm long (its vertices there pinned: the clamp) "
         f"overhangs it by L = {100 * CANT_L:g} cm, widths " +
         ", ".join(f"{100 * w:g}" for w in WIDTHS) + " cm (2.5 cm: ASTM D1388's strip); the "
         "same fabric, deflections, patterns and directions as the back-to-back strips. The "
         "chord from the middle of the ledge's edge to the middle of the tip is read back "
         "through the clamped elastica. Targets, for every width with at least two "
         "triangles across (width >= 2 h): within 5 % at 1 and 2 cm, within 3 % at 0.5 cm.\n"]
    used = [r for r in rows if ledge_counts(r)]
    for h in sorted({r["h"] for r in used}):
        rs = [r for r in used if r["h"] == h]
        v = np.array([r["ratio"] for r in rs])
        off = sorted((r for r in rs if abs(r["ratio"] - 1.0) > LEDGE_TARGET[h]),
                     key=lambda r: -abs(r["ratio"] - 1.0))
        L.append(f"- **h = {100 * h:g} cm: B_eff / B {v.min():.3f} ... {v.max():.3f}** over "
                 f"{len(rs)} cases; outside {100 * LEDGE_TARGET[h]:g} %: {len(off)}" + (
                     (": " if len(off) <= 8 else ", the worst: ") + "; ".join(
                         f"{r['pattern']} {r['direction']} G = {r['G']:g} {100 * r['width']:g} "
                         f"cm ({r['ratio']:.3f})" for r in off[:8]) if off else "") + ".")
    stalled = [r for r in rows if r["steps"] < 0]
    L.append(f"- Static solves that stalled (no step lowered the energy beyond round-off; the "
             f"reading kept): {len(stalled)}" + "".join(
                 f"; {r['pattern']} {r['direction']} h = {100 * r['h']:g} cm G = {r['G']:g} "
                 f"{100 * r['width']:g} cm" for r in stalled) + ".")
    spread = []
    for key, by_w in _ledge_group(used).items():
        v = [by_w[w]["ratio"] for w in (0.02, 0.04, 0.08, 0.16) if w in by_w]
        if len(v) > 1:
            spread.append((max(v) / min(v) - 1.0, key))
    if spread:
        worst = max(spread)
        L.append(f"- Widths 2, 4, 8 and 16 cm read the same B within **{100 * worst[0]:.1f} %** "
                 f"of each other (the largest spread, {worst[1][0]} {worst[1][1]} h = "
                 f"{100 * worst[1][2]:g} cm G = {worst[1][3]:g}; no Poisson coupling, so width "
                 "must not matter).")
    narrow = [r for r in used if r["width"] == 0.025 and r["h"] == 0.01]
    if narrow:
        v = [r["ratio"] for r in narrow]
        L.append(f"- ASTM's strip, 2.5 cm wide at 1 cm (two rows of 1.25 cm across): "
                 f"{min(v):.3f} ... {max(v):.3f}.")
    L.append("")
    L.append("B_eff / B by width (cm); a dash where the strip is narrower than two triangles "
             "(one row of quads):\n")
    L.append("| pattern | direction | h (cm) | G | " + " | ".join(f"{100 * w:g}" for w in WIDTHS)
             + " | chord at 2.5 cm (deg) | elastica (deg) |")
    L.append("|" + " --- |" * (6 + len(WIDTHS)))
    for (p, d, h, G), by_w in _ledge_group(rows).items():
        cells = ["" if w not in by_w else f"{by_w[w]['ratio']:.3f}" if ledge_counts(by_w[w])
                 else "-" for w in WIDTHS]
        r = by_w.get(0.025, next(iter(by_w.values())))
        L.append(f"| {p} | {d} | {100 * h:g} | {G:g} | " + " | ".join(cells) +
                 f" | {r['chord_deg']:.2f} | {r['chord_ref_deg']:.2f} |")
    L.append("")
    L.append("![ledge B_eff / B against width](ledge.png)\n")
    return L


def ledge_plot(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    marks = {"regular": "o", "alternating": "s", "random": "^", IRREGULAR: "D"}
    cols = {0.005: "C2", 0.01: "C0", 0.02: "C3"}
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.4), sharey=True)
    for a, G in zip(ax, DEFLECTIONS):
        for r in rows:
            if r["G"] != G or not ledge_counts(r):
                continue
            jitter = {"warp": -0.03, "weft": -0.01, "bias": 0.01, "bias-": 0.03}[r["direction"]]
            a.plot(np.log2(100 * r["width"]) + jitter, r["ratio"], marks[r["pattern"]],
                   color=cols[r["h"]], mfc="none", ms=5)
        a.axhspan(0.95, 1.05, color="0.92", zorder=0)
        a.axhspan(0.97, 1.03, color="0.85", zorder=0)
        a.axhline(1.0, color="k", lw=0.8)
        a.set_xticks(np.log2([100 * w for w in WIDTHS]), [f"{100 * w:g}" for w in WIDTHS])
        a.set_xlabel("strip width (cm)")
        a.set_title(f"ledge cantilever, G = {G:g} (chord {chord_angle(G) * 180 / np.pi:.1f}"
                    " deg)")
    ax[0].set_ylabel("B_eff / B")
    from matplotlib.lines import Line2D
    ax[1].legend(handles=[Line2D([], [], marker=m, ls="", color="k", mfc="none", label=p)
                          for p, m in marks.items()] +
                 [Line2D([], [], marker="o", ls="", color=c, label=f"h = {100 * h:g} cm")
                  for h, c in cols.items()], fontsize=8, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def report(rows, out, seconds, command, failed=()):
    """calibration.md, calibration.json, calibration.png and ledge.png in ``out`` (``failed``:
    the lines listing failed runs, ``sweep.failed_lines``)."""
    from benchmarks.harness import header, write_json
    os.makedirs(out, exist_ok=True)
    write_json(out, "calibration", {"rows": [{k: v for k, v in r.items() if k != "shape"}
                                             for r in rows]}, command, seconds)
    cant = [r for r in rows if r["kind"] == "cantilever"]
    strip = [r for r in rows if r["kind"] == "strip"]
    rows_all = rows
    L = []
    L.append("# Material calibration: bending rigidity and tensile modulus\n")
    L.append(header(command, seconds) + "\n")
    L.append("Cantilever: two cantilevers back to back, a strip 8 cm wide held along its "
             "middle line, each half overhanging L = 20 cm under its own weight (0.15 kg/m^2; "
             f"membrane 3e4 N/m, shear {CALIBRATION_SHEAR:g} N/m, a woven's, so it barely "
             "stretches); `material.k_bend` = B = q L^3 / G. Its static shape (the simulator's "
             "own forces, minimised) gives the chord angle from the root to the tips, read back "
             "through the inextensible elastica (B theta' = M, solved by shooting) as B_eff. "
             "G = 1: small deflection (chord 7.1 deg); G = 8: large (41.5 deg, the angle of the "
             "ASTM D1388 cantilever test, overhang = 2 x bending length). Directions: the strip "
             "along the mesh's warp lines, along its weft lines, or on the bias (cut at +45 or "
             "-45 deg from a sheet meshed along its grain, so no grid lines run across the "
             "strip; the regular pattern's diagonals run across it in `bias`, along it in "
             "`bias-`). A bias strip has straight edges (the lattice quads on its outline are "
             "cut along it) and mirror-symmetric halves (`cantilever_mesh`). `irregular`: a "
             "Delaunay triangulation of grid points jittered by up to 0.35 h, with no mesh "
             "lines and triangles of every shape (one direction: the mesh has none).\n")
    L.append("Bending energies: **isotropic** (the default, cloth/bending.py: the plate's "
             "|II|^2, its trace by finite volumes over the vertices' cells and its deviator "
             "from a per-face quadratic fit, consistent at free edges and clamps) and, for "
             "comparison, the **hinge** energy (discrete shells, weight "
             f"{_bend_constant():g} |e|^2 / (A1 + A2); `sim.bending = \"hinge\"`).\n")

    def span(rs, key="ratio"):
        v = np.array([r[key] for r in rs])
        return f"{v.min():.3f} ... {v.max():.3f}" if len(v) else "-"

    def outside(rs, key="ratio"):
        off = [r for r in rs if abs(r[key] - 1.0) > 0.05]
        return f"{len(off)} of {len(rs)}" + (": " + "; ".join(
            f"{r['pattern']} h = {100 * r['h']:g} cm {r['direction']} G = {r['G']:g} "
            f"({r[key]:.3f})" for r in off) if off else "")

    along = [r for r in cant if not r["direction"].startswith("bias")]
    bias = [r for r in cant if r["direction"].startswith("bias")]
    L.append(f"**B_eff / B, isotropic bending, all {len(cant)} cases: {span(cant)}** "
             f"(hinge: {span(cant, 'ratio_hinge')}). Outside 5 %: {outside(cant)}; hinge: "
             f"{sum(abs(r['ratio_hinge'] - 1.0) > 0.05 for r in cant)} of {len(cant)}.\n")
    L.append("| pattern | directions | G | isotropic | hinge |")
    L.append("| --- | --- | --- | --- | --- |")
    for p in PATTERNS + (IRREGULAR,):
        groups = (("any", along),) if p == IRREGULAR else \
            (("warp, weft", along), ("bias, bias-", bias))
        for name, group in groups:
            for G in DEFLECTIONS:
                rs = [r for r in group if r["pattern"] == p and r["G"] == G]
                if rs:
                    L.append(f"| {p} | {name} | {G:g} | {span(rs)} | "
                             f"{span(rs, 'ratio_hinge')} |")
    L.append("")
    L.append("The hinge energy bends a strip cheaply only about lines of edges: the regular "
             "mesh's diagonals are such lines across the strip in `bias`; along it (`bias-`) "
             "there are none and the strip reads 2.2-2.7 times too stiff (a smooth bend with "
             "its curvature along the diagonals turns the edges of all three families). No "
             "per-edge weight can cure that (docs/history/bending_models.md); the "
             "isotropic energy has no preferred direction.\n")
    lock = [r for r in rows_all if r["kind"] == "locking"]
    if lock:
        L.append("**Membrane locking** (isotropic bending, G = 8, on the bias, against the "
                 "shear modulus): a triangle mesh bends without stretching only by folding "
                 "along its edges, and a coarse bias mesh has few fold lines across the strip, "
                 "so at large deflection a stiff membrane stiffens the bend. The small "
                 "deflection (G = 1) is unaffected: there the membrane strain is second order. "
                 + "; ".join(f"k_shear {k:g} N/m: {span([r for r in lock if r['k_shear'] == k])}"
                             for k in LOCKING_SHEAR)
                 + ". Finer meshes lock less.\n")
        L.append("| pattern | h (cm) | direction | " + " | ".join(
            f"k_shear {k:g} N/m" for k in LOCKING_SHEAR) + " |")
        L.append("|" + " --- |" * (3 + len(LOCKING_SHEAR)))
        for p in PATTERNS:
            for h in (0.01, 0.02):
                for d in ("bias", "bias-"):
                    rs = {r["k_shear"]: r["ratio"] for r in lock
                          if r["pattern"] == p and r["h"] == h and r["direction"] == d}
                    L.append(f"| {p} | {100 * h:g} | {d} | " + " | ".join(
                        f"{rs[k]:.3f}" for k in LOCKING_SHEAR) + " |")
        L.append("")
    L.append("| pattern | h (cm) | direction | G | chord (deg) | elastica (deg) | B_eff / B | "
             "hinge B_eff / B | faces |")
    L.append("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in cant:
        L.append(f"| {r['pattern']} | {100 * r['h']:g} | {r['direction']} | {r['G']:g} | "
                 f"{r['chord_deg']:.2f} | {r['chord_ref_deg']:.2f} | {r['ratio']:.3f} | "
                 f"{r['ratio_hinge']:.3f} | {r['faces']} |")
    L.append("")
    ledge_rows = [r for r in rows if r["kind"] == "ledge"]
    L += ledge_report_lines(ledge_rows)
    L.append("Hanging strip: 1 m x 4 cm from its top row, modulus k = 200 N/m along the strip "
             "(the other direction 5 x stiffer, shear k / 4). k_eff from the top row of faces "
             "through the membrane law; the linear reading rho g (L - h/2) / strain in the last "
             "column.\n")
    L.append(f"**k_eff / k: {span(strip)}** (linear reading: "
             f"{min(r['ratio_linear'] for r in strip):.4f} ... "
             f"{max(r['ratio_linear'] for r in strip):.4f}).\n")
    L.append("| pattern | h (cm) | direction | top strain | rho g (L - h/2) / k | k_eff / k | linear reading / k |")
    L.append("| --- | --- | --- | --- | --- | --- | --- |")
    for r in strip:
        L.append(f"| {r['pattern']} | {100 * r['h']:g} | {r['direction']} | {r['strain']:.5f} | "
                 f"{r['strain_linear']:.5f} | {r['ratio']:.4f} | {r['ratio_linear']:.4f} |")
    L.append("")
    L.append("![B_eff / B and k_eff / k](calibration.png)\n")
    L += list(failed)
    with open(os.path.join(out, "calibration.md"), "w") as fh:
        fh.write("\n".join(L))
    plot(cant, strip, os.path.join(out, "calibration.png"))
    if ledge_rows:
        ledge_plot(ledge_rows, os.path.join(out, "ledge.png"))


def plot(cant, strip, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.6))
    marks = {"regular": "o", "alternating": "s", "random": "^", IRREGULAR: "D"}
    cols = {"warp": "C0", "weft": "C1", "bias": "C2", "bias-": "C3"}
    for r in cant:
        off = {"warp": -0.09, "weft": -0.03, "bias": 0.03, "bias-": 0.09}[r["direction"]] + \
            (0.02 if r["G"] > 2 else -0.02)
        ax[0].plot(np.log2(100 * r["h"]) + off, r["ratio_hinge"], marks[r["pattern"]],
                   color="0.75", ms=4, mfc="none" if r["G"] > 2 else "0.75", zorder=1)
        ax[0].plot(np.log2(100 * r["h"]) + off, r["ratio"], marks[r["pattern"]],
                   color=cols[r["direction"]], mfc="none" if r["G"] > 2 else cols[r["direction"]],
                   zorder=2)
    ax[0].axhspan(0.95, 1.05, color="0.9", zorder=0)
    ax[0].axhline(1.0, color="k", lw=0.8)
    ax[0].set_yscale("log")
    ax[0].set_yticks([0.75, 1.0, 1.5, 2.0, 3.0], ["0.75", "1", "1.5", "2", "3"])
    ax[0].minorticks_off()
    ax[0].set_xticks(np.log2([0.5, 1, 2]), ["0.5", "1", "2"])
    ax[0].set_xlabel("triangle legs h (cm)")
    ax[0].set_ylabel("B_eff / B")
    ax[0].set_title("cantilever, isotropic bending (grey: hinge)\nfilled: G = 1, open: G = 8")
    from matplotlib.lines import Line2D
    hand = [Line2D([], [], marker=m, ls="", color="k", label=p) for p, m in marks.items()] + \
        [Line2D([], [], marker="o", ls="", color=c, label=d) for d, c in cols.items()]
    ax[0].legend(handles=hand, fontsize=8, ncol=2)
    for G, ls in zip(DEFLECTIONS, ("-", "--")):
        _, _, x, y = elastica(G)
        ax[1].plot(x[:, 0], -y[:, 0], "k", ls=ls, lw=2.5, alpha=0.35,
                   label=f"elastica G = {G:g}")
        for r in cant:
            if r["G"] == G and r["h"] == 0.01 and r["direction"] == "warp":
                ax[1].plot(r["shape"][:, 0], r["shape"][:, 1], marks[r["pattern"]], ms=4,
                           mfc="none", color=cols["warp"])
    ax[1].set_aspect("equal")
    ax[1].set_xlabel("x / L")
    ax[1].set_ylabel("y / L")
    ax[1].set_title("centre lines, h = 1 cm, warp, against the elastica")
    ax[1].legend(fontsize=8)
    for r in strip:
        off = {"regular": -0.08, "alternating": 0.0, "random": 0.08}[r["pattern"]]
        ax[2].plot(np.log2(100 * r["h"]) + off + (-0.02 if r["direction"] == "warp" else 0.02),
                   r["ratio"], marks[r["pattern"]], color=cols[r["direction"]], mfc="none")
    ax[2].axhspan(0.98, 1.02, color="0.9", zorder=0)
    ax[2].axhline(1.0, color="k", lw=0.8)
    ax[2].set_xticks(np.log2([0.5, 1, 2]), ["0.5", "1", "2"])
    ax[2].set_xlabel("triangle legs h (cm)")
    ax[2].set_ylabel("k_eff / k")
    ax[2].set_title("hanging strip (warp, weft)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="h = 1 and 2 cm only")
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "calibration"))
    ap.add_argument("--orthotropic", action="store_true",
                    help="only the orthotropic ledge sweep: print its tables "
                         "(docs/fabrics.md; ~3 min)")
    from benchmarks.sweep import add_arguments, failed_lines
    add_arguments(ap)
    a = ap.parse_args()
    t0 = time.perf_counter()
    if a.orthotropic:
        import sys
        rows = orthotropic_sweep(log=lambda m: print(m, file=sys.stderr), scheduler=a.scheduler,
                                 workers=a.workers, fresh=a.fresh, out=a.out)
        print("\n".join(orthotropic_lines(rows)))
        print(f"\n({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
        return
    rows, sweep, results = run(quick=a.quick, out=a.out, scheduler=a.scheduler,
                               workers=a.workers, fresh=a.fresh)
    from benchmarks.harness import command
    cmd = command("benchmarks.calibration")
    report(rows, a.out, time.perf_counter() - t0, cmd, failed_lines(sweep, results))
    print(f"wrote {os.path.join(a.out, 'calibration.md')}")


if __name__ == "__main__":
    main()
