"""Paper Table 2: a standing mannequin wearing a T-shirt, settling at rest. The shirt's front
and back panels (warp vertical) start wrapped around the body with their seams a centimetre
apart; stitch springs sew them while gravity and contact settle the garment."""
import numpy as np

from cloth.simulator import SceneSetup

from .common import scene_defaults

DEFAULTS = scene_defaults({
    "garment": {"friction": 0.5},           # mannequin-cloth Coulomb friction
    "collision": {"thickness": 0.004, "self_collision": True},
    "strain": {"method": "mapping", "warp": [-0.05, 0.05], "weft": [-0.05, 0.05]},
    "sim": {"frames": 120, "stitch_stiffness": 300.0, "substeps": 2},
})


def build(cfg):
    from assets import load_mannequin, load_tshirt_mesh
    from cloth.collision import Plane
    from cloth.collision import CapsuleUnion
    from .common import material_from
    mesh = load_tshirt_mesh()
    stitches = np.asarray(mesh.extras["stitches"], np.int32)
    body = CapsuleUnion(load_mannequin(), mu=cfg["garment"]["friction"])
    ground = Plane(point=(0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0), mu=0.6)
    return SceneSetup(mesh=mesh, material=material_from(cfg), obstacles=[body, ground],
                      stitches=stitches, self_collision=cfg["collision"]["self_collision"],
                      camera={"position": [0.0, 1.3, 2.2], "lookat": [0.0, 1.2, 0.0]},
                      check_final=lambda sim: check_final(sim, cfg))


def check_final(sim, cfg):
    """Always: finite, outside the body, still on it. After 2 s: seams closed."""
    from assets import mannequin_sdf
    x = sim.model.positions()
    if not np.all(np.isfinite(x)):
        return False, "non-finite state"
    depth = -mannequin_sdf(x).min()
    if depth > cfg["collision"]["thickness"]:
        return False, f"a vertex is {depth:.4f} m inside the mannequin"
    st = np.asarray(sim.dynamics.stitches_np)
    gap = np.linalg.norm(x[st[:, 0]] - x[st[:, 1]], axis=1).max()
    if sim.time >= 2.0 and gap > 0.02:
        return False, f"a seam is still {gap:.3f} m open"
    if x[:, 1].min() < 0.5:
        return False, "the shirt slid off the body"
    return True, "shirt on the body, seams closed"
