"""The classic draping test: a square sheet falls onto a sphere and the ground."""
import numpy as np

from cloth.collision import THICKNESS
from cloth.model import MeshArrays
from cloth.sheet import make_sheet
from cloth.simulator import SceneSetup

from . import checks
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


def drape_by(cfg):
    """When the sheet must hang draped (s): ``checks.drape_time``, 0.76 s by default.
    Measured with exact Newton steps (resolution 25): the sheet hangs below the equator on
    every side from frame 9 (0.30 s) to the end (frame 45, lowest point 0.31 m). A solve that
    damps the landing leaves it flat on the sphere's top (lowest point 0.62 m at frame 45, the
    equator at 0.55 m), and this check fails there."""
    s = cfg["sphere"]
    return checks.drape_time(cfg["cloth"]["drop"], s["center"], s["radius"],
                             cfg["sim"]["gravity"])


def check_final(sim, cfg):
    """Finite, outside the sphere and above the ground, the limits held, and from
    ``drape_by`` on draped over the sphere: on it, and below its equator on the sides it
    overhangs (``checks.draped_over_sphere``), not a flat sheet on its top."""
    s = cfg["sphere"]
    tol = cfg["collision"]["thickness"]
    x = sim.model.positions()
    center = np.asarray(s["center"], float)

    def draped():
        t = drape_by(cfg)
        if checks.before(sim, t):
            return True, f"drape not checked before {t:.2f} s"
        return checks.draped_over_sphere(x, center, s["radius"], margin=4 * tol)

    return checks.combine(
        lambda: checks.finite(sim),
        lambda: checks.outside(np.linalg.norm(x - center, axis=1) - s["radius"], tol,
                               "the sphere"),
        lambda: checks.outside(x[:, 1], tol, "the ground"),
        draped,
        lambda: checks.limits_held(sim, after=drape_by(cfg)))
