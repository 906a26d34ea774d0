"""Loom's settings: every section's keys with their defaults, units and allowed values, in
one place, and ``Settings``, the checked, typed view of a run's configuration that the
Simulator and its solvers read.

    settings = Settings(cfg)             # cfg: the merged nested dict (scenes.common.resolve)
    settings.strain.method               # 'mapping'; each section is a frozen dataclass
    settings = settings.replace("strain", rounds=20)   # a checked copy with one change

Unknown keys and wrong types are refused when layers are merged (``cloth.config.merge``);
ranges and choices are checked here (``validate``). Each failure is one ``ConfigError`` line
that names the key and the fix. The presentation of the same schema (``--show-config``, the
commented ``config.toml``, docs/scenes.md) lives in ``scenes/schema.py``.
"""
import copy
import dataclasses
import math
from dataclasses import asdict, dataclass
from typing import Optional

from .config import ConfigError, NUMBER_OR_WORD, merge
from .materials import MATERIAL_PRESETS  # noqa: F401 (re-exported)
from .remesh_params import RemeshParams
from .strain.families import STRAIN_METHODS
from .strain.defaults import AL_ROUNDS, MAPPING_ISO, SOLVES


# Fabric presets (cloth/materials.py, where their numbers and sources live).

COMMON_DEFAULTS = {
    "sim": {
        "frames": 120,            # frames to run headless
        "fps": 30.0,              # frames per simulated second
        "substeps": 1,            # time steps per frame (h = 1 / (fps * substeps))
        "gravity": [0.0, -9.81, 0.0],
        "stitch_stiffness": 0.0,  # N/m of seam springs (garments)
        # Relative residual (preconditioned norm) that ends the implicit solve's CG. 1e-4 moves
        # the settled hanging cotton sheet by 0.06 mm against a 1e-9 solve at a fifth of the
        # iterations (measured).
        "cg_tol": 1e-4,
        "cg_iters": 500,          # CG iteration budget per time step
        "linear_solver": "cg",    # cg (matrix-free PCG) | direct (sparse Cholesky)
        "bending": "isotropic",   # isotropic (B in every direction) | hinge (discrete shells)
        # A start moved by about 1 nm (seeded; 0: the scene's own start): another run of a
        # chaotic scene, as another CPU's last bits would give (Simulator.nudged_start).
        "nudge": 0,
    },
    "material": dict(preset="soft", **MATERIAL_PRESETS["soft"]),
    "strain": {
        "method": "none",         # svd | warp-weft | mapping | none
        "warp": [-0.01, 0.01],    # strain band along the warp (material u; vertical in hanging)
        "weft": [-0.05, 0.05],    # strain band along the weft
        "bias": [],               # bias-strain band; [] = automatic (docs/method.md §3.2)
        # How hard each projection is solved (cloth/strain/solver.py): "fast" stops once the
        # limits hold; "exact" solves to the projection's minimiser (about 2x the time on small
        # meshes, 20-500x on large ones and garments: docs/speed/projection_error.md).
        "solve": "fast",
        "rounds": AL_ROUNDS,      # AL round budget per projection (why 100: strain/defaults.py)
        "tol": 1e-4,              # largest violation accepted, in strain
        # mapping only: width (in eta1^2 - eta2^2) of the closure of its feasible set at
        # isotropy; 0 = the paper's constraint exactly (why 0.01: cloth/strain/defaults.py).
        "isotropy": MAPPING_ISO,
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
        "color": "warp-strain",   # shading | warp-strain | weft-strain | bias-strain | principal-strain | violation | size | binding
    },
}


@dataclass(frozen=True)
class Key:
    unit: str = ""
    doc: str = ""
    choices: Optional[tuple] = None
    lo: Optional[float] = None          # smallest allowed value
    hi: Optional[float] = None          # largest allowed value
    lo_open: bool = False               # value must be > lo (not >=)
    band: bool = False                  # a [min, max] strain band with min <= 0 <= max


STRAIN_BAND = dict(unit="strain", band=True)

SCHEMA = {
    "sim": {
        "frames": Key("frames", "frames to run headless", lo=1),
        "fps": Key("1/s", "frames per simulated second", lo=0, lo_open=True),
        "substeps": Key("", "time steps per frame (h = 1 / (fps * substeps))", lo=1),
        "gravity": Key("m/s^2", "gravitational acceleration (x, y, z); y is up"),
        "stitch_stiffness": Key("N/m", "stiffness of the zero-length seam springs", lo=0),
        "cg_tol": Key("", "relative residual that ends the implicit step's CG", lo=0,
                      lo_open=True),
        "cg_iters": Key("", "CG iteration budget per time step", lo=1),
        "nudge": Key("seed", "start the free vertices ~1 nm away at random, seeded (0: the "
                     "scene's own start): another run of a chaotic scene", lo=0),
        "linear_solver": Key("", "implicit step's linear solver: matrix-free PCG or sparse "
                             "Cholesky", choices=("cg", "direct")),
        "bending": Key("", "bending energy: isotropic (k_bend is the plate's B in every "
                       "direction, docs/calibration/) or the hinge energy (discrete shells, "
                       "0.9-3 B depending on the direction)", choices=("isotropic", "hinge")),
    },
    "material": {
        "preset": Key("", "fabric preset (MATERIAL_PRESETS in cloth/materials.py) loaded first; "
                      "the other keys override it"),
        "density": Key("kg/m^2", "areal density", lo=0, lo_open=True),
        "k_warp": Key("N/m", "membrane stretch stiffness along the warp", lo=0),
        "k_weft": Key("N/m", "membrane stretch stiffness along the weft", lo=0),
        "k_shear": Key("N/m", "in-plane shear stiffness", lo=0),
        "k_bend": Key("N m", "flexural rigidity B of the plate, per unit width (bending energy density B kappa^2 / 2)", lo=0),
        "k_bend_warp": Key("N m", "B for bending along the warp (0 = k_bend); with k_bend_weft "
                           "different the plate is orthotropic (docs/method.md §9.11; read "
                           "when the cloth is built)", lo=0),
        "k_bend_weft": Key("N m", "B for bending along the weft (0 = k_bend)", lo=0),
        "damp_mass": Key("1/s", "mass-proportional damping", lo=0),
        "damp_stiff": Key("s", "stiffness-proportional damping", lo=0),
    },
    "strain": {
        "method": Key("", "strain-limiting method", choices=STRAIN_METHODS),
        "warp": Key(**STRAIN_BAND, doc="strain band [min, max] along the warp (material u "
                    "unless the mesh says otherwise)"),
        "weft": Key(**STRAIN_BAND, doc="strain band [min, max] along the weft"),
        "bias": Key(**STRAIN_BAND, doc="bias-strain band; [] = automatic (docs/method.md §3.2)"),
        "solve": Key("", "how hard each projection is solved: fast (stops once the limits "
                     "hold, a few mm short of the exact projection) or exact (to the "
                     "projection's minimiser; slower)", choices=SOLVES),
        "rounds": Key("", "augmented-Lagrangian round budget per projection", lo=1),
        "tol": Key("strain", "largest constraint violation accepted", lo=0, lo_open=True),
        "isotropy": Key("", "mapping only: width of the closure of its feasible set at "
                        "isotropy; 0 = the paper's constraint exactly", lo=0),
    },
    "remesh": {
        "enabled": Key("", "remesh once per frame in material space (Narain et al. 2012)"),
        "size_min": Key("m", "smallest edge length", lo=0, lo_open=True),
        "size_max": Key("m", "largest edge length", lo=0, lo_open=True),
        "aspect_min": Key("", "smallest short/long axis ratio of the sizing ellipse", lo=0,
                          hi=1, lo_open=True),
        "refine_angle": Key("rad", "largest turning of the normal across one edge", lo=0,
                            lo_open=True),
        "refine_velocity": Key("m/s", "largest velocity difference across one edge", lo=0,
                               lo_open=True),
        "refine_compression": Key("strain", "compression refined to size_min", lo=0,
                                  lo_open=True),
        "refine_obstacle": Key("", "largest change of obstacle distance across an edge, per "
                               "distance plus size_min", lo=0, lo_open=True),
        "obstacle_reach": Key("m", "distance from an obstacle within which refine_obstacle "
                              "applies", lo=0, lo_open=True),
        "curvature_smoothing": Key("", "rounds of averaging of the shape operator", lo=0),
        "collapse_margin": Key("", "hysteresis of edge collapses", lo=0, hi=0.999999),
        "collapse_rounds": Key("", "collapse passes per remesh", lo=0),
        "warm_multipliers": Key("", "carry the strain multipliers to the new faces"),
        "defer_ops": Key("per face", "a remesh with at most this many operations per face "
                         "is deferred (the mesh kept; counted before the remesh is made as "
                         "the edges to split and flip, and after it as its operations); 0 "
                         "applies every remesh", lo=0),
        "defer_frames": Key("frames", "most frames in a row a remesh is deferred", lo=0),
    },
    "output": {
        "images": Key("", "write frames/frame_NNNN.png"),
        "meshes": Key("", "write meshes/frame_NNNN.obj"),
        "video": Key("", "write video.mp4"),
        "every": Key("frames", "write every N-th frame", lo=1),
        "width": Key("px", "image width", lo=16),
        "height": Key("px", "image height", lo=16),
        "color": Key("", "colour mode of frames and the window (with its legend)",
                     choices=("shading", "warp-strain", "weft-strain", "bias-strain",
                              "principal-strain", "violation", "size", "binding")),
    },
    # Built-in sheet scenes (hanging, pull, drape) and scene files share this section's name.
    "cloth": {
        "width": Key("m", "sheet size along the weft (hanging, pull) or warp (drape)", lo=0,
                     lo_open=True),
        "height": Key("m", "the other side of the sheet", lo=0, lo_open=True),
        "resolution": Key("", "vertices along each side of the sheet", lo=2),
        "pattern": Key("", "triangulation", choices=("regular", "alternating", "random")),
        "top": Key("m", "height of the pins above the ground"),
        "bulge": Key("m", "initial out-of-plane bulge that lets the sheet buckle"),
        "drop": Key("m", "initial height of the horizontal sheet"),
        "mesh": Key("path", "scene files: OBJ whose vt are the material coordinates"),
        "uv_scale": Key("m per vt unit", "scene files: a number, or \"auto\" (each UV island "
                        "scaled so its material area equals its 3-D area)", lo=0,
                        lo_open=True),
        "warp": Key("", "scene files: warp direction: \"u\", \"v\" or degrees from material u"),
        "pins": Key("m", "scene files: material-space boxes [u0, v0, u1, v1] held in place"),
        "stitches": Key("path", "scene files: text file of 1-based OBJ vertex pairs to sew "
                        "(UV seams are sewn without it)"),
        "offset": Key("m", "scene files: added to the mesh's positions"),
        "max_faces": Key("", "scene files: refuse larger meshes (about 20 kB per triangle)",
                         lo=1),
    },
    "collision": {
        "thickness": Key("m", "distance the cloth keeps from obstacles", lo=0, lo_open=True),
        "self_collision": Key("", "cloth-cloth repulsion (spatial hash)"),
    },
    "check": {
        "rest_after": Key("s", "scene files: from then on the final check wants the cloth at "
                          "rest (RMS speed under 4 mm/s); 0 = not checked", lo=0),
        "limits_after": Key("s", "scene files: from then on every frame must end within "
                            "the limits (2 x strain.tol; before it a landing may pass them)",
                            lo=0),
        "drape_over": Key("", "scene files: name of a sphere obstacle the cloth must hang "
                          "draped over (below its equator on the sides it overhangs; "
                          "folds may rest above it on 2 of 8)"),
        "touching": Key("", "scene files: names of obstacles the cloth must touch at the end"),
    },
    "camera": {
        "position": Key("m", "camera position; scene files: [] (the default) frames the cloth "
                             "and the obstacles, seen from the front and 22 deg above"),
        "lookat": Key("m", "point the camera looks at; scene files: [] (the default) the "
                           "centre of the cloth and the obstacles"),
        "fov": Key("deg", "vertical field of view", lo=1, hi=170),
    },
    "pull": {
        "displacement": Key("m", "where the dragged corner ends up relative to rest"),
        "duration": Key("s", "time to get there (smoothstep), then held", lo=0, lo_open=True),
    },
    "sphere": {
        "center": Key("m", "sphere centre"),
        "radius": Key("m", "sphere radius", lo=0, lo_open=True),
        "mu": Key("", "Coulomb friction against the cloth", lo=0),
    },
    "ground": {"mu": Key("", "Coulomb friction of the ground", lo=0)},
    "garment": {"friction": Key("", "mannequin-cloth Coulomb friction", lo=0),
                "edge": Key("m", "the shirt's material edge length: 0.03 is the shipped mesh "
                            "(2,385 triangles), others are built at the start (1.5 cm: "
                            "9,548 triangles, 7 s)", lo=0.01, hi=0.06)},
}
TOP_LEVEL = {
    "description": Key("", "scene files: one line shown by --list-like tools"),
    "pins": Key("", "scene files: moving pin groups, [[pins]] with box and motion"),
    "obstacles": Key("", "scene files: [[obstacles]] tables (see below)"),
}


def _type_of(value):
    if isinstance(value, bool):
        return bool
    if isinstance(value, int):
        return int
    if isinstance(value, float):
        return float
    if isinstance(value, str):
        return str
    return list


def section_class(name, defaults):
    """A dataclass for section ``name`` with the fields and defaults of ``defaults`` and each
    field's Key as its metadata."""
    fields = []
    for key, value in defaults.items():
        meta = {"key": SCHEMA.get(name, {}).get(key, Key())}
        if isinstance(value, (list, dict)):
            f = dataclasses.field(default_factory=lambda v=value: type(v)(v), metadata=meta)
        else:
            f = dataclasses.field(default=value, metadata=meta)
        fields.append((key, _type_of(value), f))
    cls_name = "".join(p.capitalize() for p in name.split("_")) + "Settings"
    return dataclasses.make_dataclass(cls_name, fields, frozen=True)


def _fail(path, value, meta, why, unit=False):
    unit = f" {meta.unit}" if unit and meta.unit and meta.unit != "path" else ""
    raise ConfigError(f"{path} = {value!r} {why}{unit}: fix it with --set {path}=... or in "
                      "the TOML file (see --show-config, docs/scenes.md)")


def check_value(path, value, meta):
    """Range and choice checks of one value (types were checked by the merge)."""
    if meta.choices is not None and isinstance(value, str):
        if value not in meta.choices:
            _fail(path, value, meta, "is not one of " + ", ".join(meta.choices))
        return
    if path in NUMBER_OR_WORD and isinstance(value, str):
        return
    if meta.band:
        if value in ([], ()):
            return
        if len(value) != 2 or not value[0] <= 0 <= value[1]:
            _fail(path, value, meta, "must be a band [min, max] with min <= 0 <= max")
        return
    nums = value if isinstance(value, (list, tuple)) else [value]
    for v in nums:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            continue
        if not math.isfinite(v):
            _fail(path, value, meta, "must be finite")
        if meta.lo is not None and (v <= meta.lo if meta.lo_open else v < meta.lo):
            _fail(path, value, meta, f"must be {'>' if meta.lo_open else '>='} {meta.lo:g}",
                  unit=True)
        if meta.hi is not None and v > meta.hi:
            _fail(path, value, meta, f"must be <= {meta.hi:g}", unit=True)


def validate(cfg):
    """Check every value of a resolved configuration; return {section: settings object}."""
    out = {}
    for name, section in cfg.items():
        if not isinstance(section, dict):
            continue
        for key, value in section.items():
            check_value(f"{name}.{key}", value, SCHEMA.get(name, {}).get(key, Key()))
        out[name] = section_class(name, section)(**section)
    _check_across(out)
    return out


def _check_across(sections):
    """The rules that involve more than one value."""
    sim, rm = sections.get("sim"), sections.get("remesh")
    frames = getattr(sim, "frames", 1)
    if not float(frames) == int(frames):
        raise ConfigError("sim.frames takes a whole number")
    if rm is not None and getattr(rm, "size_max", 1) < getattr(rm, "size_min", 0):
        raise ConfigError(f"remesh.size_max = {rm.size_max} must be >= remesh.size_min "
                          f"({rm.size_min}) m: raise size_max or lower size_min")


def section(name, **changes):
    """One section's settings on their own: its defaults with ``changes``, checked as a scene's
    would be (for a part built without a whole configuration, e.g. ``StrainLimiter(model,
    section("strain", method="svd"))`` in a test or a script)."""
    merged = merge(copy.deepcopy(COMMON_DEFAULTS[name]), changes, name + ".")
    for key in changes:
        check_value(f"{name}.{key}", merged[key], SCHEMA.get(name, {}).get(key, Key()))
    return section_class(name, merged)(**merged)


class Settings:
    """The checked settings of one run: one frozen dataclass per section (``settings.sim``,
    ``settings.strain``, ...), plus the file-level entries that are not sections (``scene``,
    ``obstacles``, ``pins``). Immutable: ``replace`` returns a checked copy, so a live change
    that is out of range is refused with the same one-line error as a bad scene file."""

    def __init__(self, cfg):
        cfg = copy.deepcopy(cfg)
        self._sections = validate(cfg)
        self._extras = {k: v for k, v in cfg.items() if not isinstance(v, dict)}

    @classmethod
    def of(cls, cfg):
        """``cfg`` as Settings: a Settings is returned as it is, a nested dict is checked."""
        return cfg if isinstance(cfg, Settings) else cls(cfg)

    def __getattr__(self, name):
        if name.startswith("_"):
            raise AttributeError(name)
        try:
            return self._sections[name]
        except KeyError:
            raise AttributeError(f"no settings section '{name}' (sections: "
                                 f"{', '.join(self._sections)})") from None

    def __contains__(self, name):
        return name in self._sections

    def section(self, name, default=None):
        return self._sections.get(name, default)

    def replace(self, section, **changes):
        """A copy with ``changes`` applied to ``section`` (types and ranges checked). Only
        the changed values are checked again; the other sections are shared (a live control
        calls this on every change)."""
        old = self._sections.get(section)
        if old is None:
            raise ConfigError(f"no settings section '{section}'")
        current = {f.name: getattr(old, f.name) for f in dataclasses.fields(old)}
        merged = merge(current, changes, section + ".")
        for key in changes:
            check_value(f"{section}.{key}", merged[key], SCHEMA.get(section, {}).get(key, Key()))
        new = object.__new__(Settings)
        new._extras = self._extras
        new._sections = dict(self._sections)
        new._sections[section] = dataclasses.replace(old, **{k: merged[k] for k in changes})
        _check_across(new._sections)
        return new

    def to_dict(self):
        """The nested dict this was built from (with every change since): what config.toml
        and ``--show-config`` print, and what a rebuild starts from."""
        out = copy.deepcopy(self._extras)
        for name, sec in self._sections.items():
            out[name] = {f.name: copy.deepcopy(getattr(sec, f.name))
                         for f in dataclasses.fields(sec)}
        return out

    def material_model(self):
        """The ``material`` section as the model's ``Material``."""
        from .model import Material
        return Material(**{k: float(v) for k, v in self.to_dict()["material"].items()
                           if k != "preset"})
