"""Scenes described entirely by a TOML file: ``python main.py path/to/scene.toml``.

    description = "a sheet on a sphere"
    [cloth]
    mesh = "sheet.obj"              # OBJ; vt are material coordinates (cloth/garment.py)
    uv_scale = 1.0                  # metres per vt unit, or "auto" (per UV island: area = 3-D area)
    warp = "u"                      # "u", "v", or degrees from material u
    pins = [[0.0, 0.0, 0.01, 1.0]]  # material-space boxes [u0, v0, u1, v1] (m), held in place
    [[pins]]                        # pins that move: a box and a motion
    box = [0.99, 0.0, 1.0, 0.01]
    motion = {translate = [0.0, 0.1, 0.4], duration = 2.0}
    [[obstacles]]
    kind = "sphere"                 # sphere | plane | capsule | box | mesh | union
    center = [0.0, 0.5, 0.0]
    radius = 0.3
    motion = {velocity = [0.0, 0.0, 0.1]}
    [collision]
    thickness = 0.005
    [camera]                        # optional: without it the view frames cloth and obstacles
    position = [0.0, 1.5, 3.0]
    [strain]
    method = "mapping"

Every section of ``--show-config`` (sim, material, strain, remesh, output) is allowed with the
same keys. Paths are relative to the scene file. Everything that can be wrong with the input
is found by ``check(cfg)``, before Taichi starts: one line naming the fix (exit code 2).

Motions (``motion`` of a moving pin group or an obstacle), all optional and added together:
    translate = [dx, dy, dz], duration = s, start = s, ease = "smooth" | "linear"
                                    moved by translate between start and start + duration, then held
    velocity = [vx, vy, vz]         constant velocity (m/s) from t = 0
    amplitude = [ax, ay, az], period = s
                                    oscillation amplitude * sin(2 pi t / period)
    spin = deg/s, axis = [x, y, z], pivot = [x, y, z]
                                    rotation about axis through pivot (default: the obstacle's
                                    centre, or the centroid of the pin group)

"""
import copy
import json
import os

import numpy as np

from cloth.collision import THICKNESS
from cloth.config import ConfigError, load_toml

from .common import material_from, resolve, scene_defaults

FILE_SECTIONS = {
    "description": "",
    "cloth": {
        "mesh": "",               # OBJ file; vt = material coordinates
        "uv_scale": 1.0,          # metres per vt unit, or "auto"
        "warp": "u",              # warp direction: "u", "v", or degrees from material u
        "pins": [],               # static material-space boxes [u0, v0, u1, v1] (m)
        "stitches": "",           # optional text file of 1-based OBJ vertex pairs to sew
        "offset": [0.0, 0.0, 0.0],  # m, added to the file's positions
        "max_faces": 200000,      # refuse larger meshes (about 20 kB of memory per triangle)
    },
    "pins": [],                   # moving pin groups: {box = [...], motion = {...}}
    "obstacles": [],              # [[obstacles]] tables, see OBSTACLE_KEYS
    "collision": {"thickness": THICKNESS, "self_collision": False},
    # [] (the default): placed so that the cloth and the obstacles fill the view (``framing``).
    "camera": {"position": [], "lookat": [], "fov": 40.0},
    # What the scene is for, tested by the final check on top of the checks every scene file
    # gets (finite, pins on their targets, outside the obstacles, seams closed, limits held).
    "check": {
        "rest_after": 0.0,        # s: from then on the cloth must be at rest (0: not checked)
        "limits_after": 0.0,      # s: from then on every frame must end within the limits
        "drape_over": "",         # name of a sphere obstacle the cloth must hang draped over
        "touching": [],           # names of obstacles the cloth must touch at the end
    },
}

VEC3 = "a list of 3 numbers"
OBSTACLE_KEYS = {   # kind -> {key: (default or None when required, what it takes)}
    "sphere": {"center": (None, VEC3), "radius": (None, "a number > 0 (m)")},
    "plane": {"point": ([0.0, 0.0, 0.0], VEC3), "normal": ([0.0, 1.0, 0.0], VEC3),
              "draw_size": (4.0, "a number (m)")},
    "capsule": {"a": (None, VEC3), "b": (None, VEC3), "radius": (None, "a number > 0 (m)")},
    "box": {"center": (None, VEC3), "extents": (None, VEC3 + " > 0 (full side lengths, m)"),
            "axis": ([0.0, 1.0, 0.0], VEC3), "angle": (0.0, "degrees")},
    "mesh": {"path": (None, "an OBJ/PLY/STL file"), "scale": (1.0, "a number"),
             "offset": ([0.0, 0.0, 0.0], VEC3), "resolution": (64, "grid cells, a whole number")},
    "union": {"path": (None, "a JSON list of spheres and capsules (assets/mannequin.json)")},
}
COMMON_OBSTACLE_KEYS = {"kind": None, "mu": (0.3, "a number >= 0"), "motion": ({}, "a table"),
                        "name": ("", "text")}
MOTION_KEYS = {"translate": VEC3, "duration": "seconds > 0", "start": "seconds",
               "ease": '"smooth" or "linear"', "velocity": VEC3, "amplitude": VEC3,
               "period": "seconds > 0", "spin": "degrees per second", "axis": VEC3,
               "pivot": VEC3}


# -- motions ------------------------------------------------------------------------------------
def _vec3(value, where):
    try:
        arr = np.asarray(value, dtype=np.float64).reshape(3)
    except (TypeError, ValueError):
        raise ConfigError(f"{where} takes {VEC3}, e.g. [0.0, 1.0, 0.0] (got {value!r})") from None
    if not np.all(np.isfinite(arr)):
        raise ConfigError(f"{where} must be finite (got {value!r})")
    return arr


def _number(value, where, positive=False, minimum=None):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise ConfigError(f"{where} takes a number (got {value!r})")
    if positive and not value > 0:
        raise ConfigError(f"{where} must be > 0 (got {value!r})")
    if minimum is not None and value < minimum:
        raise ConfigError(f"{where} must be >= {minimum} (got {value!r})")
    return float(value)


def _ramp(t, start, duration, ease):
    s = np.clip((t - start) / duration, 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s) if ease == "smooth" else s


class Motion:
    """A scripted rigid motion: ``apply(t, points)`` and ``pose(t) -> (offset, R, pivot)``."""

    def __init__(self, spec, where, default_pivot):
        if not isinstance(spec, dict):
            raise ConfigError(f"{where} takes a table like {{translate = [0, 0.1, 0], "
                              f"duration = 2.0}} (got {spec!r})")
        for k in spec:
            if k not in MOTION_KEYS:
                raise ConfigError(f"unknown key '{where}.{k}': a motion takes "
                                  + ", ".join(MOTION_KEYS))
        self.translate = _vec3(spec["translate"], f"{where}.translate") \
            if "translate" in spec else np.zeros(3)
        self.duration = _number(spec.get("duration", 1.0), f"{where}.duration", positive=True)
        self.start = _number(spec.get("start", 0.0), f"{where}.start")
        self.ease = spec.get("ease", "smooth")
        if self.ease not in ("smooth", "linear"):
            raise ConfigError(f"{where}.ease takes \"smooth\" or \"linear\" (got {self.ease!r})")
        self.velocity = _vec3(spec["velocity"], f"{where}.velocity") \
            if "velocity" in spec else np.zeros(3)
        self.amplitude = _vec3(spec["amplitude"], f"{where}.amplitude") \
            if "amplitude" in spec else np.zeros(3)
        self.period = _number(spec.get("period", 1.0), f"{where}.period", positive=True)
        self.spin = np.radians(_number(spec.get("spin", 0.0), f"{where}.spin"))
        axis = _vec3(spec.get("axis", [0.0, 1.0, 0.0]), f"{where}.axis")
        if not np.linalg.norm(axis) > 0:
            raise ConfigError(f"{where}.axis must be non-zero")
        self.axis = axis / np.linalg.norm(axis)
        self.pivot = _vec3(spec["pivot"], f"{where}.pivot") if "pivot" in spec \
            else np.asarray(default_pivot, np.float64)

    def pose(self, t):
        offset = (self.translate * _ramp(t, self.start, self.duration, self.ease)
                  + self.velocity * t + self.amplitude * np.sin(2 * np.pi * t / self.period))
        if self.spin:
            from cloth.collision import rotation_about
            R = rotation_about(self.axis, self.spin * t)
        else:
            R = np.eye(3)
        return offset, R, self.pivot

    def apply(self, t, points):
        offset, R, pivot = self.pose(t)
        if not self.spin:
            return np.asarray(points) + offset
        return (np.asarray(points) - pivot) @ R.T + pivot + offset


# -- the scene ------------------------------------------------------------------------------------
def _inside(uv, box, tol):
    u0, v0, u1, v1 = box
    return ((uv[:, 0] >= u0 - tol) & (uv[:, 0] <= u1 + tol)
            & (uv[:, 1] >= v0 - tol) & (uv[:, 1] <= v1 + tol))


def _box(value, where):
    try:
        b = [float(x) for x in value]
    except (TypeError, ValueError):
        b = []
    if len(b) != 4 or not np.all(np.isfinite(b)):
        raise ConfigError(f"{where} takes a material-space box [u0, v0, u1, v1] in metres "
                          f"(got {value!r})")
    if b[0] > b[2] or b[1] > b[3]:
        raise ConfigError(f"{where} = {value!r} is empty: give [u0, v0, u1, v1] with u0 <= u1 "
                          "and v0 <= v1")
    return b


class SceneFile:
    """A scene file as a scene module: ``DEFAULTS`` (every key, the file's values in them),
    ``check(cfg)`` (every input check, no Taichi) and ``build(cfg)``."""

    def __init__(self, path):
        self.path = os.path.abspath(path)
        self.dir = os.path.dirname(self.path)
        self.NAME = os.path.splitext(os.path.basename(path))[0]
        self.__name__ = f"scene file {path}"
        if not os.path.isfile(path):
            raise ConfigError(f"scene file '{path}' not found: give an existing .toml file "
                              "(python main.py path/to/scene.toml) or a scene name (--list)")
        data = load_toml(path)
        data.pop("scene", None)        # the name a written config.toml carries
        self._resolve_paths(data)
        base = scene_defaults(copy.deepcopy(FILE_SECTIONS))
        self.DEFAULTS = resolve(base, [data])
        if not self.DEFAULTS["cloth"]["mesh"]:
            raise ConfigError(f"scene file '{path}' has no cloth mesh: add [cloth] mesh = "
                              "\"panel.obj\" (an OBJ whose vt are the material coordinates)")
        self._cache = {}

    def _resolve_paths(self, data):
        """Paths relative to the scene file become absolute."""
        def fix(table, key):
            if isinstance(table, dict) and isinstance(table.get(key), str) and table[key]:
                table[key] = os.path.normpath(os.path.join(self.dir, table[key]))
        fix(data.get("cloth"), "mesh")
        fix(data.get("cloth"), "stitches")
        for o in data.get("obstacles", []) if isinstance(data.get("obstacles"), list) else []:
            fix(o, "path")

    # -- checks (no Taichi) -------------------------------------------------------------------
    def garment(self, cfg):
        from cloth.garment import load_garment
        c = cfg["cloth"]
        key = (c["mesh"], c["uv_scale"], c["warp"], int(c["max_faces"]))
        if key not in self._cache:
            self._cache = {key: load_garment(c["mesh"], uv_scale=c["uv_scale"], warp=c["warp"],
                                             max_faces=int(c["max_faces"]))}
        return copy.deepcopy(self._cache[key])

    def check(self, cfg):
        """Everything build() needs, checked and prepared without Taichi: (garment, pinned,
        pin groups, stitches, obstacle specs)."""
        c = cfg["cloth"]
        g = self.garment(cfg)
        mesh = g.mesh
        mesh.x = mesh.x + _vec3(c["offset"], "cloth.offset")
        uv = mesh.uv
        span = np.ptp(uv, axis=0)
        tol = 1e-9 * max(float(span.max()), 1e-9)
        extent = (f"the material coordinates span u {uv[:, 0].min():.4g}..{uv[:, 0].max():.4g}, "
                  f"v {uv[:, 1].min():.4g}..{uv[:, 1].max():.4g} m")
        pinned = np.zeros(len(uv), bool)
        for k, b in enumerate(c["pins"]):
            sel = _inside(uv, _box(b, f"cloth.pins[{k}]"), tol)
            if not sel.any():
                raise ConfigError(f"cloth.pins[{k}] = {b} holds no vertex ({extent} after "
                                  "uv_scale): move or enlarge the box")
            pinned |= sel
        groups = []
        if not isinstance(cfg["pins"], list):
            raise ConfigError("pins takes [[pins]] tables with a box and a motion")
        for k, p in enumerate(cfg["pins"]):
            where = f"pins[{k}]"
            if not isinstance(p, dict) or "box" not in p:
                raise ConfigError(f"{where} needs box = [u0, v0, u1, v1] (and a motion table)")
            for key in p:
                if key not in ("box", "motion"):
                    raise ConfigError(f"unknown key '{where}.{key}': a moving pin group takes "
                                      "box and motion")
            sel = _inside(uv, _box(p["box"], f"{where}.box"), tol)
            if not sel.any():
                raise ConfigError(f"{where}.box = {p['box']} holds no vertex ({extent} after "
                                  "uv_scale): move or enlarge the box")
            motion = Motion(p.get("motion", {}), f"{where}.motion", mesh.x[sel].mean(axis=0))
            groups.append((list(_box(p["box"], where)), motion))
            pinned |= sel
        mesh.pinned = pinned
        mesh.pin_target = mesh.x.copy()
        stitches = g.stitches
        if c["stitches"]:
            stitches = np.concatenate([stitches, self._stitch_file(c["stitches"], g)])
        specs = [self._obstacle_spec(o, k) for k, o in enumerate(cfg["obstacles"])]
        _number(cfg["collision"]["thickness"], "collision.thickness", positive=True)
        _check_targets(cfg["check"], specs)
        cam = cfg["camera"]
        for key in ("position", "lookat"):
            if len(cam[key]):
                _vec3(cam[key], f"camera.{key}")
        if len(cam["position"]) and len(cam["lookat"]) and \
                np.allclose(cam["position"], cam["lookat"]):
            raise ConfigError("camera.position and camera.lookat are the same point: move the "
                              "camera back, or leave both out to frame the scene")
        return g, mesh, groups, stitches, specs, tol

    def _stitch_file(self, path, g):
        if not os.path.isfile(path):
            raise ConfigError(f"cloth.stitches file '{path}' not found (paths are relative to "
                              "the scene file)")
        try:
            pairs = np.loadtxt(path, dtype=np.int64, ndmin=2, comments="#")
        except ValueError:
            raise ConfigError(f"cloth.stitches file '{path}' must hold two whole numbers per "
                              "line (1-based OBJ vertex indices)") from None
        if pairs.size == 0:
            return np.zeros((0, 2), np.int32)
        n_file = int(g.source_vertex.max()) + 1
        if pairs.shape[1] != 2 or pairs.min() < 1 or pairs.max() > n_file:
            raise ConfigError(f"cloth.stitches file '{path}': every line needs two OBJ vertex "
                              f"indices from 1 to {n_file}")
        first_copy = np.full(n_file, -1, np.int64)
        for i in range(len(g.source_vertex) - 1, -1, -1):
            first_copy[g.source_vertex[i]] = i
        out = first_copy[pairs - 1]
        if (out < 0).any():
            raise ConfigError(f"cloth.stitches file '{path}' names a vertex no face uses")
        return out.astype(np.int32)

    def _obstacle_spec(self, o, k):
        where = f"obstacles[{k}]"
        if not isinstance(o, dict) or "kind" not in o:
            raise ConfigError(f"{where} needs kind = one of {', '.join(OBSTACLE_KEYS)}")
        kind = o["kind"]
        if kind not in OBSTACLE_KEYS:
            raise ConfigError(f"{where}.kind = {kind!r} is not a kind of obstacle: use one of "
                              f"{', '.join(OBSTACLE_KEYS)}")
        keys = OBSTACLE_KEYS[kind]
        spec = {"kind": kind, "name": str(o.get("name", ""))}
        for key in o:
            if key not in keys and key not in COMMON_OBSTACLE_KEYS:
                raise ConfigError(f"unknown key '{where}.{key}' for a {kind}: it takes "
                                  + ", ".join(list(keys) + ["mu", "motion", "name"]))
        for key, (default, what) in keys.items():
            if key not in o and default is None:
                raise ConfigError(f"{where} (a {kind}) needs {key} = {what}")
            value = o.get(key, default)
            if what.startswith(VEC3):
                value = _vec3(value, f"{where}.{key}")
            elif key == "path":
                if not isinstance(value, str) or not os.path.isfile(value):
                    raise ConfigError(f"{where}.path '{value}' not found: give an existing file "
                                      "(paths are relative to the scene file)")
            elif key == "resolution":
                if isinstance(value, bool) or not isinstance(value, int) or value < 8:
                    raise ConfigError(f"{where}.resolution takes a whole number >= 8 "
                                      f"(got {value!r})")
            else:
                value = _number(value, f"{where}.{key}", positive=key in ("radius",))
            spec[key] = value
        spec["mu"] = _number(o.get("mu", 0.3), f"{where}.mu", minimum=0.0)
        if kind == "box" and not np.all(spec["extents"] > 0):
            raise ConfigError(f"{where}.extents must all be > 0 (got {o['extents']})")
        if kind in ("plane",) and not np.linalg.norm(spec["normal"]) > 0:
            raise ConfigError(f"{where}.normal must be non-zero")
        if kind == "mesh":
            spec["trimesh"] = self._closed_mesh(spec["path"], where)
        if kind == "union":
            spec["prims"] = self._union(spec["path"], where)
        centre = {"sphere": spec.get("center"), "plane": spec.get("point"),
                  "box": spec.get("center")}.get(kind)
        if kind == "capsule":
            centre = 0.5 * (spec["a"] + spec["b"])
        if centre is None:
            centre = np.zeros(3)
        spec["motion"] = Motion(o["motion"], f"{where}.motion", centre) if o.get("motion") \
            else None
        return spec

    @staticmethod
    def _closed_mesh(path, where):
        import trimesh
        try:
            m = trimesh.load(path, force="mesh")
        except Exception as err:       # trimesh raises many kinds on a bad file
            raise ConfigError(f"{where}.path '{path}' could not be read as a mesh ({err}): use "
                              "an OBJ, PLY or STL with triangles") from None
        if not isinstance(m, trimesh.Trimesh) or len(m.faces) == 0:
            raise ConfigError(f"{where}.path '{path}' holds no triangles: use an OBJ, PLY or "
                              "STL with faces")
        if not np.all(np.isfinite(m.vertices)):
            raise ConfigError(f"{where}.path '{path}' has NaN or infinite coordinates")
        if not m.is_watertight:
            edges = trimesh.grouping.group_rows(m.edges_sorted, require_count=1)
            raise ConfigError(f"{where}.path '{path}' is not a closed surface ({len(edges)} "
                              "boundary edges): a mesh obstacle needs an inside; close its holes "
                              "(e.g. trimesh's fill_holes) or use a primitive")
        return m

    @staticmethod
    def _union(path, where):
        try:
            with open(path) as fh:
                prims = json.load(fh)
            for p in prims:
                if p["kind"] not in ("sphere", "capsule") or not p["radius"] > 0:
                    raise ValueError
        except (OSError, ValueError, KeyError, TypeError):
            raise ConfigError(f"{where}.path '{path}' must be a JSON list of "
                              "{\"kind\": \"sphere\", \"center\", \"radius\"} and "
                              "{\"kind\": \"capsule\", \"a\", \"b\", \"radius\"}") from None
        return prims

    # -- build (Taichi) ----------------------------------------------------------------------
    def build(self, cfg):
        from cloth import collision as col
        from cloth.simulator import SceneSetup
        g, mesh, groups, stitches, specs, tol = self.check(cfg)
        for note in g.notes:
            import sys
            print(f"loom: note: {cfg['cloth']['mesh']}: {note}", file=sys.stderr)
        obstacles = [self._make_obstacle(s) for s in specs]
        def moved_pins(t, uv_pinned, rest):
            out = rest.copy()
            for box, motion in groups:
                sel = _inside(uv_pinned, box, tol)
                out[sel] = motion.apply(t, rest[sel])
            return out
        pin_motion = moved_pins if groups else None
        framed = [mesh.x] + [o.mesh_at(0.0)[0] for o in obstacles
                             if not isinstance(o, col.Plane)]
        return SceneSetup(mesh=mesh, material=material_from(cfg), pin_motion=pin_motion,
                          obstacles=obstacles, stitches=stitches if len(stitches) else None,
                          self_collision=bool(cfg["collision"]["self_collision"]),
                          camera=framing(np.concatenate(framed), **cfg["camera"]),
                          check_final=lambda sim: check_final(sim, cfg))

    @staticmethod
    def _make_obstacle(s):
        from cloth import collision as col
        from cloth.collision import CapsuleUnion
        kind, mu = s["kind"], s["mu"]
        R0 = np.eye(3)
        if kind == "sphere":
            o = col.Sphere(center=tuple(s["center"]), radius=s["radius"], mu=mu)
        elif kind == "plane":
            o = col.Plane(point=tuple(s["point"]), normal=tuple(s["normal"]), mu=mu,
                          draw_size=s["draw_size"])
        elif kind == "capsule":
            d = s["b"] - s["a"]
            length = float(np.linalg.norm(d))
            rot = col.rotation_between([0, 0, 1], d) if length > 0 else np.eye(3)
            o = col.Capsule(center=tuple(0.5 * (s["a"] + s["b"])), length=length,
                            radius=s["radius"], rotation=rot, mu=mu)
        elif kind == "box":
            rot = col.rotation_about(s["axis"], np.radians(s["angle"])) if s["angle"] else None
            o = col.Box(center=tuple(s["center"]), extents=tuple(s["extents"]), rotation=rot,
                        mu=mu)
        elif kind == "mesh":
            o = col.MeshObstacle(s["trimesh"], resolution=s["resolution"], mu=mu,
                                 scale=s["scale"], offset=tuple(s["offset"]))
        else:
            o = CapsuleUnion(s["prims"], mu=mu)
        R0 = o.rotation.copy()
        c0 = o.position.copy()
        motion = s["motion"]
        if motion is not None:
            def path(t, motion=motion, c0=c0, R0=R0):
                offset, R, pivot = motion.pose(t)
                return R @ (c0 - pivot) + pivot + offset, R @ R0
            o.path = path
        return o


def _check_targets(check, specs):
    """The obstacles ``[check]`` names exist (and ``drape_over`` is a sphere)."""
    names = {s["name"]: s for s in specs if s["name"]}
    known = ", ".join(f"'{n}'" for n in names) or "none has a name"
    wanted = ([("check.drape_over", check["drape_over"])] if check["drape_over"] else []) + \
        [(f"check.touching[{k}]", n) for k, n in enumerate(check["touching"])]
    for where, name in wanted:
        if name not in names:
            raise ConfigError(f"{where} = '{name}' names no obstacle (obstacles: {known}): give "
                              "the obstacle name = \"...\" or fix the name")
    if check["drape_over"] and names[check["drape_over"]]["kind"] != "sphere":
        raise ConfigError(f"check.drape_over = '{check['drape_over']}' is a "
                          f"{names[check['drape_over']]['kind']}: draping is checked over a "
                          "sphere")


# The view a framed camera looks along (from the front, 22 degrees above: a sheet lying on an
# obstacle shows its top), and the screen box it fills: the window's middle, between its two columns, is about
# 0.8 as wide as it is high; a headless frame (4:3) then has room to spare at the sides.
FRAMING_DIRECTION = np.array([0.0, 1.0, 2.5]) / np.linalg.norm([0.0, 1.0, 2.5])
FRAMING_ASPECT, FRAMING_FILL = 0.8, 0.85


def framing(points, position=(), lookat=(), fov=40.0):
    """The scene's camera (position, lookat, fov): what the file gives, the rest chosen so
    that ``points`` (the cloth and the bounded obstacles) fill FRAMING_FILL of a view
    FRAMING_ASPECT wide: the target at the points' bounding-box centre unless given, the eye
    along the given position's direction (else FRAMING_DIRECTION) at the nearest distance
    where every point projects inside."""
    pts = np.asarray(points, float)
    target = np.asarray(lookat, float) if len(lookat) else 0.5 * (pts.min(0) + pts.max(0))
    if len(position):
        return {"position": [float(v) for v in position],
                "lookat": [float(v) for v in target], "fov": float(fov)}
    d = FRAMING_DIRECTION
    right = np.cross(-d, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, -d)
    t = np.tan(np.radians(fov) / 2) * FRAMING_FILL
    rel = pts - target
    # A point at depth (dist - rel.d) is inside when |rel.right| <= depth t aspect and
    # |rel.up| <= depth t: the distance is the largest of those bounds.
    need = rel @ d + np.maximum(np.abs(rel @ right) / (t * FRAMING_ASPECT), np.abs(rel @ up) / t)
    dist = max(float(need.max()), 0.1)
    return {"position": [float(v) for v in target + dist * d],
            "lookat": [float(v) for v in target], "fov": float(fov)}


def check_final(sim, cfg):
    """Every scene file: finite, pins on their targets, no vertex inside an obstacle beyond
    the thickness, every seam closed to 1 mm after 2 s, the limits held (now, and at the end
    of every frame from ``limits_after`` on). Then what the file's ``[check]`` asks: at rest
    from ``rest_after`` on, draped over the sphere ``drape_over``
    (``checks.draped_over_sphere``, from ``checks.drape_time`` on), touching the obstacles
    named in ``touching``."""
    from . import checks
    x = sim.model.positions()
    tol = cfg["collision"]["thickness"]
    want = cfg["check"]
    named = {o["name"]: k for k, o in enumerate(cfg["obstacles"]) if o.get("name")}
    sdf = [o.distance(x, sim.time) for o in sim.setup.obstacles]

    def pins():
        m = sim.model
        pinned = np.asarray(m.pinned[: m.n_verts], bool)
        if not pinned.any():
            return True, ""
        target = m.vert_pin_target.to_numpy()[: m.n_verts][pinned]
        err = float(np.abs(x[pinned] - target).max())
        if err > 1e-6:
            return False, f"a pinned vertex is {err:.3g} m off its target"
        return True, "pins on their targets"

    def obstacles():
        for k, phi in enumerate(sdf):
            ok, text = checks.outside(phi, tol, f"obstacle {k} ({sim.setup.obstacles[k].kind})")
            if not ok:
                return ok, text
        return True, "outside the obstacles" if sdf else ""

    def draped():
        if not want["drape_over"]:
            return True, ""
        o = sim.setup.obstacles[named[want["drape_over"]]]
        center, radius = o.pose(sim.time)[0], o.radius
        t = checks.drape_time(sim.setup.mesh.x[:, 1].min(), center, radius,
                              sim.settings.sim.gravity)
        if checks.before(sim, t):
            return True, f"drape not checked before {t:.2f} s"
        return checks.draped_over_sphere(x, center, radius, margin=4 * tol)

    def touching():
        for name in want["touching"]:
            if not sdf[named[name]].min() < 3.0 * tol:
                return False, f"the cloth does not touch '{name}'"
        return True, ("touching " + ", ".join(want["touching"])) if want["touching"] else ""

    def rest():
        if not want["rest_after"] > 0:
            return True, ""
        return checks.at_rest(sim, after=want["rest_after"])

    return checks.combine(lambda: checks.finite(sim), pins, obstacles,
                          lambda: checks.seams_closed(sim, 1e-3, after=2.0),
                          lambda: checks.limits_held(sim, after=want["limits_after"]),
                          draped, touching, rest)


def is_scene_file(name):
    return name.endswith(".toml") or os.sep in name or os.path.isfile(name)
