"""The settings schema: one dataclass per section, with every key's unit, meaning and allowed
values, built from the defaults (``scenes/common.py`` for the common sections, each scene's
``DEFAULTS`` for its own, ``scenes/scene_file.py`` for scene files).

    settings = validate(cfg)        # typed section objects; ConfigError names key and fix
    settings["strain"].method       # 'mapping'
    show_config(cfg)                # the --show-config listing, with units
    commented_toml(cfg)             # the config.toml written into every output folder
    python -m scenes.schema --markdown docs/scenes.md   # the reference (a test keeps it current)

The simulator still reads the nested dict ``cfg`` (``cfg["strain"]["method"]``); ``validate``
checks that dict and returns the typed view of it. Wrong types and unknown keys are refused
when the layers are merged (``cloth.config.merge``); ranges and choices are checked here.
"""
import argparse
import dataclasses
import math
from dataclasses import dataclass
from typing import Optional

from cloth.config import ConfigError, NUMBER_OR_WORD, to_toml
from cloth.simulator import STRAIN_METHODS


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
        "linear_solver": Key("", "implicit step's linear solver: matrix-free PCG or sparse "
                             "Cholesky", choices=("cg", "direct")),
    },
    "material": {
        "preset": Key("", "fabric preset (MATERIAL_PRESETS in scenes/common.py) loaded first; "
                      "the other keys override it"),
        "density": Key("kg/m^2", "areal density", lo=0, lo_open=True),
        "k_warp": Key("N/m", "membrane stretch stiffness along the warp", lo=0),
        "k_weft": Key("N/m", "membrane stretch stiffness along the weft", lo=0),
        "k_shear": Key("N/m", "in-plane shear stiffness", lo=0),
        "k_bend": Key("N m", "bending stiffness (dihedral-angle energy)", lo=0),
        "damp_mass": Key("1/s", "mass-proportional damping", lo=0),
        "damp_stiff": Key("s", "stiffness-proportional damping", lo=0),
    },
    "strain": {
        "method": Key("", "strain-limiting method", choices=STRAIN_METHODS),
        "warp": Key(**STRAIN_BAND, doc="strain band [min, max] along the warp (material u "
                    "unless the mesh says otherwise)"),
        "weft": Key(**STRAIN_BAND, doc="strain band [min, max] along the weft"),
        "bias": Key(**STRAIN_BAND, doc="bias-strain band; [] = automatic (METHOD.md 3.2)"),
        "solver": Key("", "al = augmented Lagrangian; jacobi = per-triangle projection "
                      "(baseline)", choices=("al", "jacobi")),
        "coupling": Key("", "how the limits meet the dynamics: the paper's split step "
                        "(projection: mass-weighted projection of x_hat) or one implicit step "
                        "with the limits as constraints (implicit: projection in the implicit "
                        "step's metric)", choices=("projection", "implicit")),
        "linear_solver": Key("", "the AL's Newton steps: block-Jacobi PCG or sparse Cholesky",
                             choices=("pcg", "cholesky")),
        "iters": Key("", "outer-iteration budget per projection", lo=1),
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
                               "edge length", lo=0, lo_open=True),
        "curvature_smoothing": Key("", "rounds of averaging of the shape operator", lo=0),
        "collapse_margin": Key("", "hysteresis of edge collapses", lo=0, hi=0.999999),
        "collapse_rounds": Key("", "collapse passes per remesh", lo=0),
        "warm_multipliers": Key("", "carry the strain multipliers to the new faces"),
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
                              "principal-strain", "violation", "size")),
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
    "camera": {
        "position": Key("m", "camera position"),
        "lookat": Key("m", "point the camera looks at"),
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
    "garment": {"friction": Key("", "mannequin-cloth Coulomb friction", lo=0)},
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
    sim = cfg.get("sim", {})
    if not float(sim.get("frames", 1)) == int(sim.get("frames", 1)):
        raise ConfigError("sim.frames takes a whole number")
    rm = cfg.get("remesh", {})
    if rm and rm.get("size_max", 1) < rm.get("size_min", 0):
        raise ConfigError(f"remesh.size_max = {rm['size_max']} must be >= remesh.size_min "
                          f"({rm['size_min']}) m: raise size_max or lower size_min")
    return out


def _comment(path, value):
    name, _, key = path.partition(".")
    meta = SCHEMA.get(name, {}).get(key) if key else TOP_LEVEL.get(name)
    if meta is None:
        return ""
    bits = [f"[{meta.unit}]" if meta.unit else "", meta.doc]
    if meta.choices:
        bits.append("(" + " | ".join(meta.choices) + ")")
    return "  # " + " ".join(b for b in bits if b)


def show_config(cfg):
    """The --show-config listing: every key, its value, unit and meaning."""
    from cloth.config import flatten
    lines = []
    for key, value in flatten(cfg):
        if key == "scene":
            continue
        lines.append(f"{key} = {value!r}" + _comment(key, value))
    return lines


def commented_toml(cfg):
    """``to_toml(cfg)`` with each key's unit and meaning as a trailing comment."""
    out, section = [], ""
    for line in to_toml(cfg).splitlines():
        s = line.strip()
        if s.startswith("[[") and s.endswith("]]"):
            section = ""
        elif s.startswith("[") and s.endswith("]"):
            section = s[1:-1]
        elif "=" in s and not s.startswith("#"):
            key = s.split("=", 1)[0].strip()
            path = f"{section}.{key}" if section else key
            line += _comment(path, None)
        out.append(line)
    return "\n".join(out) + "\n"


# -- the reference page ----------------------------------------------------------------------------
def _fmt(v):
    from cloth.config import _toml_value
    return "`" + _toml_value(v).replace("|", "\\|") + "`"


def _table(name, defaults):
    rows = [f"| key | default | unit | meaning |", "|---|---|---|---|"]
    for key, value in defaults.items():
        meta = SCHEMA.get(name, {}).get(key, Key())
        what = meta.doc + (" (" + " \\| ".join(meta.choices) + ")" if meta.choices else "")
        rng = []
        if meta.lo is not None:
            rng.append(f"{'>' if meta.lo_open else '>='} {meta.lo:g}")
        if meta.hi is not None:
            rng.append(f"<= {meta.hi:g}")
        if meta.band:
            rng.append("min <= 0 <= max")
        if rng:
            what += "; " + ", ".join(rng)
        rows.append(f"| `{name}.{key}` | {_fmt(value)} | {meta.unit} | {what} |")
    return rows


def markdown():
    """docs/scenes.md: every section's keys with defaults, units, meanings and ranges."""
    import scenes
    from scenes.common import COMMON_DEFAULTS, resolve
    from scenes.scene_file import FILE_SECTIONS, MOTION_KEYS, OBSTACLE_KEYS
    lines = ["# Scene settings", "",
             "Generated by `python -m scenes.schema --markdown docs/scenes.md` from the schema "
             "(`scenes/schema.py`) and the defaults (`scenes/common.py`, each scene's "
             "`DEFAULTS`, `scenes/scene_file.py`); `tests/test_schema.py` fails when this page "
             "is out of date.", "",
             "Settings are resolved in layers: the scene's defaults (a built-in scene or a scene "
             "file), then `--config FILE.toml`, then each `--set key=value`, then the flags "
             "(`--frames`, `--method`, ...). An unknown key, a value of the wrong type or out of "
             "range stops the run before anything is computed or written, with one line naming "
             "the key and the fix (exit code 2). `--show-config` lists every key of a scene with "
             "its value and unit; every output folder gets the same as `config.toml`.", "",
             "## Common sections", ""]
    for name in COMMON_DEFAULTS:
        lines += [f"### [{name}]", ""] + _table(name, COMMON_DEFAULTS[name]) + [""]
    lines += ["## Built-in scenes", "",
              "Each scene adds its own sections and changes some defaults:", ""]
    for sname in scenes.SCENES:
        d = resolve(scenes.get(sname).DEFAULTS, [])
        lines += [f"### {sname}", "", scenes.DESCRIPTIONS.get(sname, ""), ""]
        changed = [f"`{s}.{k}` = {_fmt(v)}" for s in COMMON_DEFAULTS for k, v in d[s].items()
                   if COMMON_DEFAULTS[s].get(k) != v]
        if changed:
            lines += ["Changed defaults: " + ", ".join(changed) + ".", ""]
        for sec, vals in d.items():
            if sec not in COMMON_DEFAULTS and isinstance(vals, dict):
                lines += _table(sec, vals) + [""]
    lines += ["## Scene files", "",
              "`python main.py path/to/scene.toml` runs a scene described by the file; paths in "
              "it are relative to the file. Every common section above is allowed with the same "
              "keys, plus these (examples: `scenes/examples/`):", ""]
    for sec in ("cloth", "collision", "camera"):
        lines += [f"### [{sec}]", ""] + _table(sec, FILE_SECTIONS[sec]) + [""]
    lines += ["### Top level", "", "| key | meaning |", "|---|---|"]
    lines += [f"| `{k}` | {m.doc} |" for k, m in TOP_LEVEL.items()] + [""]
    lines += ["### [[obstacles]]", "",
              "Every obstacle takes `kind`, `mu` (Coulomb friction, default 0.3), optionally "
              "`name` and a `motion` table; by kind (a `-` default means required):", "",
              "| kind | key | default | takes |", "|---|---|---|---|"]
    for kind, keys in OBSTACLE_KEYS.items():
        for k, (default, what) in keys.items():
            lines.append(f"| {kind} | `{k}` | {'-' if default is None else _fmt(default)} | "
                         f"{what} |")
    lines += ["", "### Motions", "",
              "`motion = {...}` of an obstacle or of a `[[pins]]` group (`box = [u0, v0, u1, "
              "v1]`, material space): the parts add up; rotation about `axis` through `pivot` "
              "(default: the obstacle's centre or the pin group's centroid).", "",
              "| key | takes |", "|---|---|"]
    lines += [f"| `{k}` | {v} |" for k, v in MOTION_KEYS.items()] + [""]
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description="Write the settings reference.")
    ap.add_argument("--markdown", metavar="PATH", required=True)
    args = ap.parse_args(argv)
    with open(args.markdown, "w") as fh:
        fh.write(markdown())
    print(f"wrote {args.markdown}")


if __name__ == "__main__":
    main()
