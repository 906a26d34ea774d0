"""The classic draping test: a square sheet falls onto a sphere and the ground."""
import numpy as np

from cloth.collision import THICKNESS
from cloth.model import MeshArrays
from cloth.sheet import make_sheet
from cloth.simulator import SceneSetup

from .common import material_from, scene_defaults

DEFAULTS = scene_defaults({
    "cloth": {
        "width": 1.0,             # m, along the warp (material u, world x)
        "height": 1.0,            # m, along the weft (material v, world z)
        "resolution": 25,         # vertices along each side
        "pattern": "alternating",
        "drop": 0.95,             # m, initial height of the horizontal sheet
    },
    "sphere": {"center": [0.0, 0.55, 0.0], "radius": 0.3, "mu": 0.4},
    "ground": {"mu": 0.6},
    "collision": {"thickness": THICKNESS},
    "strain": {"method": "mapping"},
    "sim": {"frames": 120},
})


def build(cfg):
    from cloth.collision import Plane, Sphere
    c, s = cfg["cloth"], cfg["sphere"]
    n = int(c["resolution"])
    uv, faces = make_sheet(c["width"], c["height"], n, n, c["pattern"])
    x = np.stack([uv[:, 0] - 0.5 * c["width"], np.full(len(uv), c["drop"]),
                  uv[:, 1] - 0.5 * c["height"]], axis=1)
    obstacles = [Sphere(center=tuple(s["center"]), radius=s["radius"], mu=s["mu"]),
                 Plane(point=(0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0), mu=cfg["ground"]["mu"])]
    return SceneSetup(mesh=MeshArrays(uv=uv, x=x, faces=faces), material=material_from(cfg),
                      obstacles=obstacles,
                      camera={"position": [1.3, 1.3, 1.9], "lookat": [0.0, 0.45, 0.0]},
                      check_final=lambda sim: check_final(sim, cfg))


def check_final(sim, cfg):
    x = sim.model.positions()
    if not np.all(np.isfinite(x)):
        return False, "non-finite state"
    s = cfg["sphere"]
    d = np.linalg.norm(x - np.asarray(s["center"]), axis=1) - s["radius"]
    tol = cfg["collision"]["thickness"]
    if d.min() < -tol:
        return False, f"a vertex is {-d.min():.4f} m inside the sphere"
    if x[:, 1].min() < -tol:
        return False, "a vertex is below the ground"
    top = np.asarray(s["center"])[1] + s["radius"]
    if sim.time >= 2.0 and not x[:, 1].max() < top + 0.05:
        return False, "the sheet has not come down onto the sphere"
    # Still on it: some vertex within a few thicknesses of the sphere's surface near its top.
    # (Measured with mapping at resolution 17 before the projection had friction: the sheet
    # drifted sideways and slid off at about 2.5 s; with it, its centre stays within 1 cm
    # for 4 s.)
    near_top = (d < 4 * tol) & (x[:, 1] > top - 0.1)
    if sim.time >= 2.0 and not near_top.any():
        return False, "the sheet slid off the sphere"
    return True, "draped over the sphere"
