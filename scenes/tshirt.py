"""Paper Table 2: a standing mannequin wearing a T-shirt, settling at rest. The shirt's front
and back panels (warp vertical) start wrapped around the body with their seams a centimetre
apart; stitch springs sew them while gravity and contact settle the garment."""
import numpy as np

from cloth.simulator import SceneSetup

from . import checks

from .common import scene_defaults

DEFAULTS = scene_defaults({
    # mannequin-cloth Coulomb friction; the shirt's material edge length (0.03: the shipped
    # mesh, 2,385 triangles; a finer one is built at the start: 1.5 cm, 9,548 triangles)
    "garment": {"friction": 0.5, "edge": 0.03},
    "collision": {"thickness": 0.004, "self_collision": True},
    "strain": {"method": "mapping", "warp": [-0.05, 0.05], "weft": [-0.05, 0.05]},
    "sim": {"frames": 120, "stitch_stiffness": 300.0, "substeps": 2},
})


def build(cfg):
    from assets import load_mannequin, load_tshirt_mesh
    from cloth.collision import Plane
    from cloth.collision import CapsuleUnion
    from .common import material_from
    mesh = load_tshirt_mesh(edge=cfg["garment"]["edge"])
    stitches = np.asarray(mesh.extras["stitches"], np.int32)
    body = CapsuleUnion(load_mannequin(), mu=cfg["garment"]["friction"])
    ground = Plane(point=(0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0), mu=0.6)
    return SceneSetup(mesh=mesh, material=material_from(cfg), obstacles=[body, ground],
                      stitches=stitches, self_collision=cfg["collision"]["self_collision"],
                      camera={"position": [0.0, 1.3, 2.2], "lookat": [0.0, 1.2, 0.0]},
                      check_final=lambda sim: check_final(sim, cfg))


# The seams are sewn by then (stitch springs alone; with strain limiting they are equality
# constraints of the projection and close at the start: gaps under 1 um on the default run).
SEWN_BY = 2.0           # s
SEAM_GAP = 1e-3         # m


def shoulder_height():
    """Height of the mannequin's shoulder line (the axis of its "shoulders" capsule, m): a
    shirt that hangs on the body touches it above this line."""
    from assets import load_mannequin
    prims = [p for p in load_mannequin() if p.get("name") == "shoulders"]
    return min(p["a"][1] for p in prims) if prims else None


def check_final(sim, cfg):
    """Finite, outside the body, hanging on it (touching it above the shoulder line: a shirt
    that slid down or fell touches it lower or not at all), the seams closed (from SEWN_BY
    on) and the limits held."""
    from assets import mannequin_sdf
    x = sim.model.positions()
    tol = cfg["collision"]["thickness"]
    depth = mannequin_sdf(x)

    def on_body():
        touching = depth < 3.0 * tol
        line = shoulder_height()
        if not touching.any():
            return False, "the shirt does not touch the body (it fell off)"
        top = float(x[touching, 1].max())
        if line is not None and not top >= line:
            return False, (f"the shirt slid down: it touches the body only up to {top:.3f} m, "
                           f"below the shoulders ({line:.3f} m)")
        return True, f"hangs on the shoulders ({int(touching.sum())} vertices touch the body)"

    return checks.combine(lambda: checks.finite(sim),
                          lambda: checks.outside(depth, tol, "the mannequin"),
                          on_body,
                          lambda: checks.seams_closed(sim, SEAM_GAP, after=SEWN_BY),
                          lambda: checks.limits_held(sim))
