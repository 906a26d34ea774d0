"""What every scene shares: the settable keys with their defaults, material presets, and
the resolution of a scene's configuration (defaults < preset < TOML file < --set flags)."""
import copy
from dataclasses import asdict

from cloth.config import ConfigError, merge
from cloth.model import Material
from cloth.remesh import RemeshParams

# Fabric presets in lab units (SI): areal density kg/m^2; stretch and shear stiffnesses are
# membrane moduli per unit width (N/m, as a KES-FB1 tensile/shear test or a strip test gives
# them); k_bend is the flexural rigidity B (N m, per unit width, as a KES-FB2 bending test or
# an ASTM D1388 cantilever gives it: B = w c^3, w = density * g, c the bending length).
# benchmarks/calibration.py checks that the simulated cloth has these values
# (docs/calibration/calibration.md).
MATERIAL_PRESETS = {
    # The paper's stretchy test cloth, soft on purpose: under its own weight it stretches well
    # past 5 % near the pins, so the paper's 1 % / 5 % strain limits bind, as in its experiment
    # (Table 1); not a real fabric. Its bending is the one it always had (k_bend was 2e-6 with
    # the discrete-shells weight 3 |e|^2 / (A1 + A2); 2e-6 x 3 / 1.17, the calibrated weight,
    # keeps every edge's stiffness), now stated as what it is: B = 5.13e-6 N m, bending
    # length (B / w)^(1/3) = 1.52 cm, a light shirting's.
    "soft": dict(density=0.15, k_warp=20.0, k_weft=20.0, k_shear=4.0, k_bend=5.13e-6,
                 damp_mass=0.2, damp_stiff=0.002),
    # Woven cotton shirting, about 150 g/m^2. Tensile moduli: woven cotton's initial modulus is
    # roughly 2-8 kN/m per unit width, warp stiffer than weft. Shear: 50 N/m (per radian) is
    # 0.9 gf/cm/deg, inside KES-FB1's usual 0.5-2 gf/cm/deg for cotton wovens. Bending: KES-FB2
    # bending rigidities of cotton shirtings are around 0.05-0.2 gf cm^2/cm (1 gf cm^2/cm =
    # 9.81e-5 N m), i.e. 5-20 uN m; B = 1.5e-5 N m (0.15 gf cm^2/cm) gives a bending length of
    # 2.2 cm, a typical cantilever reading for a shirting. Isotropic bending (one B for warp
    # and weft; see the README).
    "cotton": dict(density=0.15, k_warp=3000.0, k_weft=2000.0, k_shear=50.0, k_bend=1.5e-5,
                   damp_mass=0.1, damp_stiff=0.002),
}

COMMON_DEFAULTS = {
    "sim": {
        "frames": 120,            # frames to run headless
        "fps": 30.0,              # frames per simulated second
        "substeps": 1,            # time steps per frame (h = 1 / (fps * substeps))
        "gravity": [0.0, -9.81, 0.0],
        "stitch_stiffness": 0.0,  # N/m of seam springs (garments)
        "cg_tol": 1e-4,           # relative residual that ends the implicit solve's CG
        "cg_iters": 500,          # CG iteration budget per time step
        "linear_solver": "cg",    # cg (matrix-free PCG) | direct (sparse Cholesky)
    },
    "material": dict(preset="soft", **MATERIAL_PRESETS["soft"]),
    "strain": {
        "method": "none",         # svd | warp-weft | mapping | none
        "warp": [-0.01, 0.01],    # strain band along the warp (material u; vertical in hanging)
        "weft": [-0.05, 0.05],    # strain band along the weft
        "bias": [],               # bias-strain band; [] = automatic (METHOD.md 3.2)
        "solver": "al",           # al (augmented Lagrangian) | jacobi (baseline)
        # How the limits meet the dynamics: "implicit" projects in the implicit step's metric
        # (one linearised backward-Euler step with the limits as constraints: a cloth at rest
        # is an exact fixed point); "projection" is the paper's split step (eq. 6: the
        # mass-weighted projection of the unconstrained x_hat), which never comes to rest.
        "coupling": "implicit",
        # Newton steps of the AL: "cholesky" (sparse direct, CHOLMOD) or "pcg" (block-Jacobi
        # PCG in one kernel, the earlier solver).
        "linear_solver": "pcg",
        # Outer-iteration budget per projection: a cap for solves that stall, since converged
        # solves stop at `tol` (2-8 AL rounds on hanging). 50 was too tight: svd on hanging with
        # remeshing ran out once in 300 frames (violation 1.3e-3); that solve, continued,
        # converged 84 rounds later, and with 100 all 300 frames pass
        # (docs/remesh/remesh_limits.md).
        "iters": 100,
        "tol": 1e-4,              # largest violation accepted, in strain
        # mapping only: width (in eta1^2 - eta2^2) of the closure of its feasible set at
        # isotropy, where the paper's constraint depends on an arbitrary principal frame;
        # 0 = the paper's constraint exactly (see constraints.MAPPING_ISO).
        "isotropy": 0.01,
    },
    # Adaptive remeshing in material space, once per frame (Narain et al. 2012); lengths in m.
    "remesh": dict(enabled=False, **asdict(RemeshParams())),
    "output": {
        "images": True,           # frames/frame_NNNN.png
        "meshes": True,           # meshes/frame_NNNN.obj
        "video": False,           # video.mp4
        "every": 1,               # write every N-th frame
        "width": 640,             # image size in pixels
        "height": 480,
        # Frames (and the window) start coloured by warp strain with its band on the legend,
        # so the output shows what strain limiting does.
        "color": "warp-strain",   # shading | warp-strain | weft-strain | bias-strain | principal-strain | violation | size
    },
}


def material_from(cfg):
    m = cfg["material"]
    return Material(**{k: float(v) for k, v in m.items() if k != "preset"})


def resolve(defaults, overrides_list):
    """Apply each override dict in order. A ``material.preset`` override first loads that
    preset's values, then the remaining material keys of the same override apply on top."""
    cfg = copy.deepcopy(defaults)
    for ov in overrides_list:
        ov = copy.deepcopy(ov)
        preset = ov.get("material", {}).get("preset")
        if preset is not None:
            if preset not in MATERIAL_PRESETS:
                raise ConfigError(f"unknown material preset '{preset}': use one of "
                                  f"{', '.join(MATERIAL_PRESETS)}")
            cfg["material"].update(MATERIAL_PRESETS[preset], preset=preset)
            del ov["material"]["preset"]
        cfg = merge(cfg, ov)
    return cfg


def scene_defaults(specific):
    """COMMON_DEFAULTS with a scene's own sections and changed values merged in (a scene may
    add sections; it changes common keys only through existing names)."""
    cfg = copy.deepcopy(COMMON_DEFAULTS)
    for key, value in specific.items():
        if key in cfg and isinstance(value, dict):
            cfg[key] = merge(cfg[key], value, key + ".")
        else:
            cfg[key] = copy.deepcopy(value)
    return cfg
