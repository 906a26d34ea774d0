"""The paper's motivating case: a user stretches the garment. A sheet hangs pinned along its
top edge and its bottom-left corner is dragged out towards the viewer and up, then held; the
sheet is pulled taut and strain limiting decides how far it gives."""
import numpy as np

from cloth.model import MeshArrays
from cloth.sheet import make_sheet
from cloth.simulator import SceneSetup

from . import checks
from .common import scene_defaults

DEFAULTS = scene_defaults({
    "cloth": {
        "width": 1.0,             # m, horizontal (weft, material v)
        "height": 1.0,            # m, vertical (warp, material u)
        "resolution": 25,         # vertices along each side
        "pattern": "alternating",
        "top": 2.0,               # m, height of the pinned edge
    },
    "pull": {
        # m, where the corner ends up relative to rest. Every method can meet it: each pin's
        # distance to the corner grows by 0.3-0.6 % (``pin_stretch``), inside svd's 1 % in
        # every direction (a target past it leaves no state within the limits).
        "displacement": [0.0, 0.1, 0.45],
        "duration": 2.0,                     # s to get there (smooth ramp), then held
    },
    "strain": {"method": "mapping"},
    "sim": {"frames": 120},
})


def ramp(t, duration):
    """Smoothstep from 0 to 1 over ``duration`` seconds (no velocity jump at either end)."""
    s = np.clip(t / duration, 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


def rest_positions(uv, c):
    """Where material points ``uv`` hang at rest: the sheet upright, its top edge (u = 0) at
    height ``c["top"]``, centred on x = 0 (``c``: the cloth settings)."""
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    return np.stack([uv[:, 1] - 0.5 * c["width"], c["top"] - uv[:, 0], np.zeros(len(uv))],
                    axis=1)


def build(cfg):
    from .common import material_from
    c, p = cfg["cloth"], cfg["pull"]
    if not p["duration"] > 0:
        raise ValueError(f"pull.duration must be > 0 (got {p['duration']})")
    n = int(c["resolution"])
    uv, faces = make_sheet(c["height"], c["width"], n, n, c["pattern"])
    x = rest_positions(uv, c)
    top = np.isclose(uv[:, 0], 0.0)
    corner = np.isclose(uv[:, 0], c["height"]) & np.isclose(uv[:, 1], 0.0)
    mesh = MeshArrays(uv=uv, x=x, faces=faces, pinned=top | corner)
    disp = np.asarray(p["displacement"], dtype=np.float64)
    height = c["height"]

    def pin_motion(t, uv_pinned, rest):
        moving = np.isclose(uv_pinned[:, 0], height)
        return rest + np.outer(moving, disp) * ramp(t, p["duration"])

    return SceneSetup(
        mesh=mesh, material=material_from(cfg), pin_motion=pin_motion,
        camera={"position": [1.6, c["top"] - 0.3, 2.2], "lookat": [0.0, c["top"] - 0.55, 0.2]},
        check_final=lambda sim: check_final(sim, cfg))


def pin_stretch(cfg):
    """The largest and smallest ratio, minus 1, of a pinned pair's distance at the end of the
    drag to its distance in the material (the top edge's pins against the dragged corner):
    no state meets the limits where this exceeds what a method lets any direction stretch."""
    c, p = cfg["cloth"], cfg["pull"]
    uv = np.c_[np.zeros(201), np.linspace(0.0, c["width"], 201)]
    corner_uv = np.array([c["height"], 0.0])
    corner = rest_positions(corner_uv, c)[0] + np.asarray(p["displacement"], dtype=np.float64)
    ratio = np.linalg.norm(rest_positions(uv, c) - corner, axis=1) / \
        np.linalg.norm(uv - corner_uv, axis=1)
    return float(ratio.max() - 1.0), float(ratio.min() - 1.0)


def check_final(sim, cfg):
    """Finite, the dragged corner on its target, and the limits held while the sheet is
    stretched (the scene is the user stretching the garment against its limits)."""
    def on_target():
        uv = sim.model.uv
        c = cfg["cloth"]
        corner = np.isclose(uv[:, 0], c["height"]) & np.isclose(uv[:, 1], 0.0)
        rest = rest_positions([c["height"], 0.0], c)[0]
        want = rest + np.asarray(cfg["pull"]["displacement"]) * ramp(sim.time,
                                                                     cfg["pull"]["duration"])
        err = np.abs(sim.model.positions()[corner][0] - want).max()
        if err > 1e-9:
            return False, f"the dragged corner is {err:.3g} m off its target"
        return True, "corner dragged and held"

    return checks.combine(lambda: checks.finite(sim), on_target,
                          lambda: checks.limits_held(sim))
