"""Assets for the T-shirt experiment: a mannequin made of spheres and capsules, and a two-panel
T-shirt pattern placed around it. ``python -m assets.make_assets`` regenerates every file here.

Units are SI (metres); y is up, the mannequin stands on y = 0 and faces +z.

Loaders (numpy only; Taichi is imported only by ``load_tshirt_mesh``):
  load_mannequin()        list of primitives, each {"kind", "name", "radius", and "center" for a
                          sphere or "a", "b" (segment end points) for a capsule}
  mannequin_sdf(points)   signed distance (N,) to the union of the primitives (< 0 inside)
  load_tshirt()           dict of arrays: uv, x, faces, grain, panel, region, stitches, ...
  load_tshirt_mesh()      the shirt as ``cloth.model.MeshArrays`` (stitches in ``extras``)
  tshirt_at(edge)         the shirt's arrays at another material edge length (built)
"""
import json
import os

import numpy as np

ASSET_DIR = os.path.dirname(os.path.abspath(__file__))
MANNEQUIN_JSON = os.path.join(ASSET_DIR, "mannequin.json")
TSHIRT_NPZ = os.path.join(ASSET_DIR, "tshirt.npz")


def load_mannequin(path=MANNEQUIN_JSON):
    """The mannequin's primitives (list of dicts, coordinates as lists of floats)."""
    with open(path) as f:
        return json.load(f)


def primitive_arrays(prims):
    """Primitives as arrays: segment starts a (P,3), ends b (P,3), radii (P,). A sphere is a
    capsule whose segment has zero length."""
    a, b, r = [], [], []
    for p in prims:
        if p["kind"] == "sphere":
            a.append(p["center"])
            b.append(p["center"])
        elif p["kind"] == "capsule":
            a.append(p["a"])
            b.append(p["b"])
        else:
            raise ValueError(f"unknown primitive kind '{p['kind']}': use sphere or capsule")
        r.append(p["radius"])
    return np.array(a, float), np.array(b, float), np.array(r, float)


def _closest_on_segments(points, a, b):
    """Closest point on every segment to every point: (N, P, 3)."""
    ab = b - a                                                   # (P, 3)
    len2 = np.maximum(np.einsum("pk,pk->p", ab, ab), 1e-300)
    t = np.einsum("npk,pk->np", points[:, None, :] - a[None], ab) / len2
    t = np.clip(t, 0.0, 1.0)
    return a[None] + t[..., None] * ab[None]


def primitives_sdf(points, prims, return_grad=False):
    """Signed distance from ``points`` (N,3) to the union of ``prims`` (min over primitives).
    With ``return_grad`` also the unit gradient (N,3) of the nearest primitive."""
    points = np.atleast_2d(np.asarray(points, float))
    a, b, r = primitive_arrays(prims)
    c = _closest_on_segments(points, a, b)
    diff = points[:, None, :] - c
    dist = np.linalg.norm(diff, axis=2) - r[None]                # (N, P)
    k = np.argmin(dist, axis=1)
    rows = np.arange(len(points))
    sdf = dist[rows, k]
    if not return_grad:
        return sdf
    g = diff[rows, k]
    n = np.linalg.norm(g, axis=1, keepdims=True)
    g = np.where(n > 1e-12, g / np.maximum(n, 1e-12), np.array([0.0, 1.0, 0.0]))
    return sdf, g


_MANNEQUIN_CACHE = {}


def mannequin_sdf(points, prims=None):
    """Signed distance (N,) from ``points`` (N,3) to the mannequin (negative inside)."""
    if prims is None:
        if "prims" not in _MANNEQUIN_CACHE:
            _MANNEQUIN_CACHE["prims"] = load_mannequin()
        prims = _MANNEQUIN_CACHE["prims"]
    return primitives_sdf(points, prims)


def load_tshirt(path=TSHIRT_NPZ):
    """The T-shirt as a dict of numpy arrays:
      uv (V,2) material coordinates (m), flat rest shape of each panel
      x (V,3) initial world positions (m), panels wrapped around the mannequin
      faces (F,3) counter-clockwise in uv; grain (F,2,2) columns warp, weft (warp = vertical)
      panel (F,) 0 front, 1 back; region (F,) 0 body, 1 sleeve
      vert_panel (V,) panel of every vertex
      stitches (K,2) (front vertex, back vertex) pairs to sew; stitch_seam (K,) index into
      seam_names; resolution () target edge length used (m); thickness () clearance target (m)
    """
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


SHIPPED_EDGE = 0.03        # m: the material edge length of tshirt.npz


_built = {}


def tshirt_at(edge):
    """The T-shirt arrays (as ``load_tshirt``) with material edges about ``edge`` metres long:
    the shipped file at ``SHIPPED_EDGE``, else built by ``make_assets.build_tshirt`` (1.6 s
    at 3 cm, 6.5 s at 1.5 cm; kept for the process's later runs)."""
    if abs(edge - SHIPPED_EDGE) < 1e-12:
        return load_tshirt()
    if edge not in _built:
        from .make_assets import build_tshirt
        _built[edge] = build_tshirt(resolution=edge)
    return dict(_built[edge])


def load_tshirt_mesh(path=TSHIRT_NPZ, edge=None):
    """The T-shirt as a ``cloth.model.MeshArrays``; stitches, panel and region in ``extras``.
    ``edge`` (m): the shirt built at that material edge length instead (``tshirt_at``)."""
    from cloth.model import MeshArrays
    d = load_tshirt(path) if edge is None else tshirt_at(edge)
    extras = {k: d[k] for k in ("stitches", "panel", "region", "vert_panel", "stitch_seam")}
    return MeshArrays(uv=d["uv"], x=d["x"], faces=d["faces"], grain=d["grain"], extras=extras)
