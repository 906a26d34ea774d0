"""Fabrics from the lab (docs/fabrics.md): measured fabric records (``fabrics/*.toml``) and the
rule that turns them into Loom's material and strain bands.

    from cloth import fabrics
    fabrics.names()                          # ['11oz-black-denim', 'camel-ponte-roma', ...]
    cfg = fabrics.apply_fabric(cfg, "denim") # material and bands of a config (dict or Settings)
    fabrics.provenance("denim")              # {"material.k_warp": "where it came from", ...}
    python -m cloth.fabrics                  # the table of docs/fabrics.md

A record holds what a KES-FB lab reports (Kawabata 1980), per direction where the test is
directional: tensile EMT (strain at Fm = 500 gf/cm, %), LT (linearity) or WT (tensile energy,
gf cm/cm^2; KES defines LT = WT / (Fm EMT / 2), so either gives the other), bending B
(gf cm^2/cm) along warp and weft; shear G (gf/(cm deg)) and 2HG (gf/cm); weight W (mg/cm^2).
``load`` checks a record: a missing direction or value, or one out of range, is one
``FabricError`` line naming the file and the field.

**The rule** (``derive``), every step a stated formula:

1. *The tensile curve.* KES gives two numbers per direction, EMT and LT. The curve through
   them is taken as ``F(e) = A (exp(e / e0) - 1)``: its tangent stiffness ``F'(e) = (A / e0)
   exp(e / e0)`` starts at the crimp modulus ``A / e0`` and rises as the crimp is pulled out,
   the convex shape of a woven's curve (LT < 1). ``F(EMT) = Fm`` and the area ``WT = LT Fm EMT
   / 2`` fix A and e0 (LT = 2 (1/x - 1/(e^x - 1)) with x = EMT / e0, solved for x). LT >= 1
   (a straight or concave curve) is taken as straight, ``F = Fm e / EMT``.
2. *What the limit means.* A band's upper end is the strain this curve reaches at the limit
   load ``LIMIT_LOAD`` = 20 gf/cm (19.6 N/m): about ten times the largest tension gravity puts
   in a hanging garment (rho g H: 2.0 N/m for 200 g/m^2 hanging 1 m), i.e. the most a fabric
   stretches under the loads of wear, and 4 % of KES's 500 gf/cm, inside the low-stress
   range KES characterises. Strain limiting then holds the cloth where the real fabric, under
   any load it meets in use, would be. The lower end is the mirror image (``-e_max``): in-plane
   compression is not measured by KES, and a fabric buckles before it shortens; a symmetric
   band is the paper's convention.
3. *The membrane moduli* (N/m): along warp and weft the secant of the measured curve at the
   limit load, ``k = LIMIT_LOAD / e_max``, so the linear membrane reaches the band exactly at
   the limit load (below it the convex curve is softer: the crimp modulus, 0.8-0.95 k on the
   woven records here, 0.2-0.4 k on the jersey, ``derive(...)['crimp_modulus']``). Shear:
   ``k_shear`` = G per radian, ``G * 0.980665 * 180 / pi`` N/m (Loom's membrane: the shear
   force per width per radian of shear angle). The shear hysteresis is not modelled (Loom's
   membrane is elastic).
4. *The bias band* (warp-weft's third band): a bias strip under the limit load T =
   ``LIMIT_LOAD`` along it. In thread axes that load is a tension T/2 in each thread and a
   shear force T/2 per width; the shear angle is the KES loading branch solved for it,
   ``gamma = (T/2 - 2HG/2) / G`` degrees (0 if the load does not overcome the hysteresis),
   capped at ``JAMMING_DEG`` = 30 deg (an estimate of a plain weave's jamming angle: KES shears
   only to 8 deg and does not measure where yarns jam). With the threads stretched to
   ``a = 1 + e_warp(T/2)`` and ``b = 1 + e_weft(T/2)``, the bias strain is
   ``sqrt(a^2 + b^2 + 2 a b sin(gamma)) / sqrt(2) - 1`` (and the other diagonal's, with
   ``-sin``, for the lower end). The band is widened where needed to contain the automatic band
   of docs/method.md §3.2, so every unsheared state the warp and weft bands accept stays
   feasible.
5. *Each method's bands:* warp-weft uses all three; mapping maps the warp and weft bands onto
   the principal directions; svd gives the warp band to the larger principal stretch and the
   weft band to the smaller (the paper's convention, docs/method.md §3.1): the same two
   bands serve all three methods.
6. *Density and bending:* ``density = W * 0.01`` kg/m^2; ``k_bend_warp``, ``k_bend_weft`` =
   B * 9.80665e-5 N m (1 gf cm^2/cm = 1 gf cm); ``k_bend`` = sqrt(B_warp B_weft), the twisting
   rigidity of the orthotropic plate (cloth/bending.py) and the value isotropic bending uses.

Damping is not measured by KES: ``apply_fabric`` keeps the configuration's damping.

**Measured-moduli records** (``format = "wang2011"``): the ten fabrics that H. Wang, J. F.
O'Brien and R. Ramamoorthi measured ("Data-Driven Elastic Models for Cloth: Modeling and
Measurement", ACM TOG 30(4) 71, SIGGRAPH 2011), as ARCSim ships them (``materials/*.json``),
transcribed digit for digit: ``density`` (kg/m^2); ``[stretching]``, six rows of [c11, c12,
c22, c33] (N/m): ``zero_strain``, then ``stretch0``, ``stretch22_5``, ``stretch45``,
``stretch67_5``, ``stretch90``, the moduli at a principal strain of 1/6 with the principal
stretch at that angle (deg) from the material's u axis; ``[bending]``, three rows of five
samples (N m) at rising curvature: ``hinge0``, ``hinge45``, ``hinge90``, the stiffness of a
hinge (fold line) at that angle from u. That is how ARCSim reads the files (src/conf.cpp: the
first JSON row fills every angle at zero strain, the next five the angles at 1/6; src/dde.cpp:
linear in the largest principal strain from 0 to 1/6, constant beyond, linear in the angle,
negative entries clamped at 0; a hinge's row by the angle of its edge in material space).
Neither the files nor ARCSim says which of u and v is the fabric's warp: Loom's warp is u.
``load`` checks a record: a missing row, a row of the wrong length, a c11, c22, bending sample
or density not > 0, is one line naming the file and the field; c12 and c33 may be negative
(published so in places) and the rule clamps them at 0, as ARCSim does.

The rule W (``derive`` on such a record), each step a stated formula:

W1. *The membrane the numbers describe* is ARCSim's (physics.cpp ``stretching_force``): energy
    per area ``c11 E11^2 + 2 c12 E11 E22 + c22 E22^2 + 2 c33 E12^2`` on the Green strain E
    (ARCSim doubles the four entries into k = 2c and applies the force of ``k0 E11^2 / 2 +
    k1 E11 E22 + k2 E22^2 / 2 + k3 E12^2``), the c's at the current strain (``wang_moduli``). In Loom's terms (energy ``k_warp E11^2 / 2 + k_weft E22^2 / 2 + 2
    k_shear E12^2``): k_warp = 2 c11, k_weft = 2 c22, k_shear = c33, and a Poisson coupling 2
    c12 that Loom's membrane does not have.
W2. *The strip curves* (what a strip test reads of that membrane): a strip cut along u (warp),
    v (weft) or the bias, free across its width, has the modulus ``1 / (n . S . n)``, S the
    compliance of the moduli at its strain (``strip_modulus``; c12 enters here), and the
    nominal tension ``T(e) = (1 + e)(e + e^2 / 2) * modulus`` (``strip_tension``), the
    moduli from ``stretch0``, ``stretch90`` and ``stretch45`` respectively.
W3. *What the limit means*: as in rule 2, the strain at which the strip's curve reaches the
    limit load ``LIMIT_LOAD`` = 20 gf/cm (19.6 N/m); the band is ``[-e, e]``. The bias band is
    the bias strip's ``[-e, e]``, widened where needed to contain the automatic band.
W4. *Moduli*: k_warp, k_weft the strips' secants at the limit load (as rule 3; the
    ``crimp_modulus`` entry is the strip's modulus at zero strain); k_shear = c33 of
    ``zero_strain``. The shear reported at the limit load is the bias strip's, ``T / (2
    c33)`` at its strain, capped at ``JAMMING_DEG``.
W5. *Bending*: per direction the median of the row's five samples (its curvature dependence
    is not modelled: Loom's plate is linear), times ``HINGE_TO_PLATE`` = 1/4:
    ``k_bend_warp`` from ``hinge90`` (hinges along v bend the cloth along u),
    ``k_bend_weft`` from ``hinge0``; ``k_bend`` = sqrt(B_warp B_weft). The factor: ARCSim's
    hinge energy ``ke l^2 theta^2 / (8 (A0 + A1))`` stores ``(ke / 4) kappa^2 / 2`` per area
    on a cylinder of curvature kappa meshed with near-equilateral triangles (and along the
    legs of a grid of right triangles), so the cloth ARCSim simulates from these files has the
    plate rigidity ke / 4 (tests/test_fabrics.py checks it on ARCSim's formula).
W6. *Density*: ``density`` as it is (kg/m^2; ``weight`` = 100 x it in mg/cm^2).

W1 and W5 take the numbers as ARCSim uses them. ARCSim's own comments in its aluminium and
paper files call the stretching entry "E h" and the bending entry "E h^3 / 12", i.e. half the
membrane stiffness and four times the plate rigidity that its code then simulates; docs/
fabrics.md says which reading the units check supports and by how much the two differ.
"""
import copy
import math
import os
import sys
import tomllib
from dataclasses import dataclass, field

from .config import ConfigError

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FABRIC_DIR = os.path.join(ROOT, "fabrics")

# Units (KES-FB reports in gram-force and centimetres).
GF = 9.80665e-3                  # N per gram-force
GF_PER_CM = GF * 100.0           # 0.980665 N/m per gf/cm (tension per width)
GF_CM2_PER_CM = GF * 0.01        # 9.80665e-5 N m per gf cm^2/cm (flexural rigidity)
MG_PER_CM2 = 0.01                # kg/m^2 per mg/cm^2
PER_DEG = 180.0 / math.pi        # a stiffness per degree -> per radian

KES_FM = 500.0                   # gf/cm: the KES-FB1 tensile test's maximum load
LIMIT_LOAD = 20.0                # gf/cm: the load that defines a band (the module's rule, 2)
JAMMING_DEG = 30.0               # deg: the largest shear angle a bias band allows (rule, 4)

DIRECTIONS = ("warp", "weft")
# field -> (unit, what it is); every direction needs EMT, B and one of LT or WT.
TENSILE = {"EMT": ("%", "strain at 500 gf/cm (KES-FB1)"),
           "LT": ("", "linearity of the load-extension curve (KES-FB1)"),
           "WT": ("gf cm/cm^2", "tensile energy (KES-FB1)"),
           "B": ("gf cm^2/cm", "bending rigidity (KES-FB2)")}
SHEAR = {"G": ("gf/(cm deg)", "shear stiffness (KES-FB1)"),
         "2HG": ("gf/cm", "shear hysteresis at 0.5 deg (KES-FB1)")}

# Measured-moduli records (format "wang2011"): an ARCSim material file's tables, row by row
# (Wang, O'Brien and Ramamoorthi 2011; the layout as ARCSim's conf.cpp and dde.cpp read it).
FORMATS = ("kes", "wang2011")
WANG_STRAIN = 1.0 / 6.0          # the principal strain of the stretching rows after the first
STRETCH_ROWS = {                 # row -> (the principal stretch's angle from u, deg; what it is)
    "zero_strain": (None, "the moduli at zero strain, every direction"),
    "stretch0": (0.0, "the moduli at 1/6 strain, principal stretch along u (Loom's warp)"),
    "stretch22_5": (22.5, "the moduli at 1/6 strain, principal stretch at 22.5 deg from u"),
    "stretch45": (45.0, "the moduli at 1/6 strain, principal stretch on the bias"),
    "stretch67_5": (67.5, "the moduli at 1/6 strain, principal stretch at 67.5 deg from u"),
    "stretch90": (90.0, "the moduli at 1/6 strain, principal stretch along v (Loom's weft)")}
MODULI = ("c11", "c12", "c22", "c33")
BEND_ROWS = {                    # row -> what it is (five samples, curvature 0 to 0.4 1/cm)
    "hinge0": "bending stiffness of hinges along u (curvature along v: Loom's weft)",
    "hinge45": "bending stiffness of hinges on the bias",
    "hinge90": "bending stiffness of hinges along v (curvature along u: Loom's warp)"}
BEND_SAMPLES = 5
HINGE_TO_PLATE = 0.25            # the plate rigidity of ARCSim's hinge energy per its ke (rule, W5)


class FabricError(ConfigError):
    """A fabric record that cannot be used; the message is one line naming file and field."""


@dataclass(frozen=True)
class Fabric:
    """One checked record. A KES-FB record (``format`` "kes"): ``warp`` / ``weft`` {EMT, LT,
    WT?, B}, ``shear`` {G, 2HG}. A measured-moduli record (``format`` "wang2011"):
    ``stretching`` {row: [c11, c12, c22, c33] N/m} and ``bending`` {row: five N m}, the
    tables of an ARCSim material file; its ``warp``, ``weft``, ``shear`` are empty."""
    name: str
    path: str
    kind: str
    weight: float                               # mg/cm^2
    warp: dict
    weft: dict
    shear: dict
    source: dict = field(default_factory=dict)
    format: str = "kes"
    stretching: dict = field(default_factory=dict)
    bending: dict = field(default_factory=dict)


def _where(path):
    return os.path.relpath(path, ROOT) if path.startswith(ROOT) else path


def _number(value, path, key, unit, what, lo=0.0, hi=None):
    """A positive finite number, or one FabricError line."""
    u = f" {unit}" if unit else ""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise FabricError(f"{_where(path)}: {key} = {value!r} must be a number ({what}{u})")
    if not math.isfinite(value) or value <= lo:
        raise FabricError(f"{_where(path)}: {key} = {value!r} must be > {lo:g}{u} ({what})")
    if hi is not None and value > hi:
        raise FabricError(f"{_where(path)}: {key} = {value!r} must be <= {hi:g}{u} ({what})")
    return float(value)


def _finite(value, path, key, unit, what):
    """A finite number of either sign (a published modulus ARCSim clamps at 0), or one line."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise FabricError(f"{_where(path)}: {key} = {value!r} must be a number ({what}, {unit})")
    return float(value)


def _parse_wang(data, path, name):
    """A measured-moduli record (``format = "wang2011"``): the ARCSim material file's density,
    stretching and bending tables, each row under its name (module docstring, W)."""
    density = data.get("density")
    if density is None:
        raise FabricError(f"{_where(path)}: density is missing (areal density, kg/m^2)")
    density = _number(density, path, "density", "kg/m^2", "areal density")
    tables = {}
    for table, rows, width, unit in (("stretching", STRETCH_ROWS, len(MODULI), "N/m"),
                                     ("bending", BEND_ROWS, BEND_SAMPLES, "N m")):
        t = data.get(table)
        if not isinstance(t, dict):
            raise FabricError(f"{_where(path)}: [{table}] is missing (the {table} table of the "
                              "material file, one row per direction)")
        unknown = sorted(set(t) - set(rows))
        if unknown:
            raise FabricError(f"{_where(path)}: {table}.{unknown[0]} is not a row (use "
                              + ", ".join(rows) + ")")
        out = {}
        for r in rows:
            what = rows[r][1] if table == "stretching" else rows[r]
            if r not in t:
                raise FabricError(f"{_where(path)}: {table}.{r} is missing ({what})")
            row = t[r]
            if not isinstance(row, list) or len(row) != width:
                raise FabricError(f"{_where(path)}: {table}.{r} must be a list of {width} numbers"
                                  f" ({what}, {unit})")
            vals = []
            for i, v in enumerate(row):
                if table == "stretching":
                    key = f"{table}.{r}[{i}]"
                    label = f"{MODULI[i]}, {what}"
                    # c11 and c22 (the direct moduli) must be positive; c12 and c33 are
                    # published negative in places and clamped at 0 by the rule, as by ARCSim.
                    vals.append(_number(v, path, key, unit, label) if i in (0, 2)
                                else _finite(v, path, key, unit, label))
                else:
                    vals.append(_number(v, path, f"{table}.{r}[{i}]", unit,
                                        f"curvature sample {i}, {what}"))
            out[r] = vals
        tables[table] = out
    return Fabric(name=name, path=path, kind=str(data.get("kind", "")), weight=density * 100.0,
                  warp={}, weft={}, shear={}, source=dict(data.get("source", {})),
                  format="wang2011", stretching=tables["stretching"], bending=tables["bending"])


def parse(data, path="<record>"):
    """A ``Fabric`` from a record's parsed TOML (``load`` reads the file)."""
    def need(table, key, where):
        if key not in table:
            unit, what = TENSILE.get(key) or SHEAR.get(key) or ("", "")
            raise FabricError(f"{_where(path)}: {where}{key} is missing ({what}"
                              + (f", {unit})" if unit else ")"))
        return table[key]

    name = data.get("name", os.path.splitext(os.path.basename(path))[0])
    if not isinstance(name, str) or not name:
        raise FabricError(f"{_where(path)}: name must be a word")
    fmt = data.get("format", "kes")
    if fmt not in FORMATS:
        raise FabricError(f"{_where(path)}: format = {fmt!r} is not a record kind (use "
                          + " or ".join(repr(f) for f in FORMATS) + ")")
    if fmt == "wang2011":
        return _parse_wang(data, path, name)
    weight = _number(need(data, "weight", ""), path, "weight", "mg/cm^2", "areal density W")
    dirs = {}
    for d in DIRECTIONS:
        if not isinstance(data.get(d), dict):
            raise FabricError(f"{_where(path)}: [{d}] is missing (the {d} direction's EMT, "
                              "LT or WT, and B)")
        t = data[d]
        unknown = sorted(set(t) - set(TENSILE))
        if unknown:
            raise FabricError(f"{_where(path)}: {d}.{unknown[0]} is not a fabric field (use "
                              + ", ".join(TENSILE) + ")")
        emt = _number(need(t, "EMT", d + "."), path, d + ".EMT", *TENSILE["EMT"], hi=500.0)
        b = _number(need(t, "B", d + "."), path, d + ".B", *TENSILE["B"])
        if "LT" not in t and "WT" not in t:
            raise FabricError(f"{_where(path)}: {d}.LT is missing (linearity of the "
                              "load-extension curve; or give WT, the tensile energy)")
        rec = dict(EMT=emt, B=b)
        if "WT" in t:
            rec["WT"] = _number(t["WT"], path, d + ".WT", *TENSILE["WT"])
        if "LT" in t:
            rec["LT"] = _number(t["LT"], path, d + ".LT", *TENSILE["LT"], hi=2.0)
        else:
            rec["LT"] = rec["WT"] / (KES_FM * emt / 100.0 / 2.0)
        if "WT" in rec:
            wt = rec["LT"] * KES_FM * emt / 100.0 / 2.0
            if abs(wt - rec["WT"]) > 0.05 * rec["WT"]:
                raise FabricError(f"{_where(path)}: {d}.WT = {rec['WT']:g} disagrees with LT "
                                  f"and EMT (LT * 500 * EMT / 200 = {wt:.3g} gf cm/cm^2): fix "
                                  "one of them or leave WT out")
        dirs[d] = rec
    if not isinstance(data.get("shear"), dict):
        raise FabricError(f"{_where(path)}: [shear] is missing (G and 2HG, KES-FB1)")
    shear = {k: _number(need(data["shear"], k, "shear."), path, "shear." + k, *SHEAR[k])
             for k in SHEAR}
    return Fabric(name=name, path=path, kind=str(data.get("kind", "")), weight=weight,
                  warp=dirs["warp"], weft=dirs["weft"], shear=shear,
                  source=dict(data.get("source", {})))


def load(path):
    """Read and check one record (``FabricError`` on any problem, one line)."""
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except tomllib.TOMLDecodeError as e:
        raise FabricError(f"{_where(path)}: not valid TOML ({e})") from None
    except OSError as e:
        raise FabricError(f"{_where(path)}: cannot read it ({e.strerror})") from None
    return parse(data, path)


def paths(directory=None):
    d = directory or FABRIC_DIR
    return sorted(os.path.join(d, f) for f in os.listdir(d) if f.endswith(".toml")) \
        if os.path.isdir(d) else []


def names(directory=None):
    """The fabrics' names (their files' stems), sorted: for ``--list`` and a picker."""
    return [os.path.splitext(os.path.basename(p))[0] for p in paths(directory)]


def get(name, directory=None):
    """The record ``name`` (a name from ``names()`` or a path to a .toml file)."""
    if name.endswith(".toml") or os.sep in name:
        return load(name)
    p = os.path.join(directory or FABRIC_DIR, name + ".toml")
    if not os.path.exists(p):
        raise FabricError(f"unknown fabric '{name}': use one of {', '.join(names(directory))} "
                          f"(files in {_where(directory or FABRIC_DIR)}/), or a path to a .toml")
    return load(p)


# ---- the rule ----------------------------------------------------------------------------------
def curve(emt, lt):
    """(A gf/cm, e0): the tensile curve F(e) = A (exp(e / e0) - 1) through F(EMT) = 500 gf/cm
    with linearity LT (``emt`` in %); e0 = inf (a straight line, A / e0 = Fm / EMT) for
    LT >= 1."""
    E = emt / 100.0
    if lt >= 1.0 - 1e-9:
        return KES_FM / E, math.inf
    # LT(x) = 2 (1/x - 1/(e^x - 1)), x = E / e0, falls from 1 (x -> 0) to 0: bisection on x.
    def lin(x):
        return 2.0 * (1.0 / x - 1.0 / math.expm1(x))
    lo, hi = 1e-6, 1.0
    while lin(hi) > lt:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if lin(mid) > lt else (lo, mid)
    x = 0.5 * (lo + hi)
    return KES_FM / math.expm1(x), E / x


def strain_at(load, emt, lt):
    """The strain (fraction) of the fitted curve at ``load`` gf/cm."""
    A, e0 = curve(emt, lt)
    return load / A if math.isinf(e0) else e0 * math.log1p(load / A)


def crimp_modulus(emt, lt):
    """The curve's initial tangent stiffness A / e0, N/m."""
    A, e0 = curve(emt, lt)
    return (A if math.isinf(e0) else A / e0) * GF_PER_CM


def bias_stretch(eps_warp, eps_weft, gamma):
    """(lower, upper) bias strain of threads stretched by eps_warp, eps_weft and sheared by
    gamma (rad): the two diagonals of the sheared cell, ||w_u +- ...|| / sqrt(2) - 1."""
    a, b = 1.0 + eps_warp, 1.0 + eps_weft
    s = math.sin(gamma)
    return (math.sqrt(a * a + b * b - 2 * a * b * s) / math.sqrt(2.0) - 1.0,
            math.sqrt(a * a + b * b + 2 * a * b * s) / math.sqrt(2.0) - 1.0)


def automatic_bias(warp, weft):
    """docs/method.md §3.2's automatic bias band of the warp and weft bands."""
    lo = math.sqrt((1 + warp[0]) ** 2 + (1 + weft[0]) ** 2) / math.sqrt(2.0) - 1.0
    hi = math.sqrt((1 + warp[1]) ** 2 + (1 + weft[1]) ** 2) / math.sqrt(2.0) - 1.0
    return lo, hi


def shear_limits(strain):
    """{method: the largest shear angle (deg) of the threads' cell that the method's bands
    ``strain`` (warp, weft, bias) admit either way}: the threads unstretched and turned
    towards (or away from) each other by gamma/2 each (w_u . w_v = +-sin gamma), so the
    principal stretches are sqrt(1 +- sin gamma) along the bias. warp-weft bounds the
    diagonal w_u + w_v by its bias band (the upper end one way, the lower end the other); svd
    bounds eta1 by the warp band's upper end and eta2 by the weft band's lower end; mapping,
    whose factors are 1/sqrt 2 at 45 deg, bounds both by sqrt 2 x the tighter thread band
    (docs/method.md §3). The fabric's own shear at the limit load is
    ``derive(...)['shear_deg']``."""
    w, f = strain["warp"], strain["weft"]
    b = strain.get("bias") or automatic_bias(w, f)
    r2 = math.sqrt(2.0)
    ends = {"warp-weft": (b[1], b[0]),
            "svd": (w[1], f[0]),
            "mapping": (r2 * min(w[1], f[1]), r2 * max(w[0], f[0]))}
    out = {}
    for m, (hi, lo) in ends.items():
        s = min((1.0 + hi) ** 2 - 1.0, 1.0 - (1.0 + max(lo, -1.0)) ** 2, 1.0)
        out[m] = math.degrees(math.asin(max(s, 0.0)))
    return out


def derive(fabric, limit_load=LIMIT_LOAD):
    """The rule of the module docstring applied to a ``Fabric`` (or a name): a dict with
    ``material`` (Loom's material keys, SI), ``strain`` (warp, weft, bias bands), ``shear_deg``
    (the bias band's shear angle), ``crimp_modulus`` (per direction, N/m) and ``provenance``
    (setting key -> one line saying where its number came from)."""
    f = get(fabric) if isinstance(fabric, str) else fabric
    if f.format == "wang2011":
        return _derive_wang(f, limit_load)
    src = _where(f.path)
    mat, bands, prov, crimp = {}, {}, {}, {}
    for d in DIRECTIONS:
        r = getattr(f, d)
        e = strain_at(limit_load, r["EMT"], r["LT"])
        bands[d] = [-e, e]
        mat["k_" + d] = limit_load * GF_PER_CM / e
        crimp[d] = crimp_modulus(r["EMT"], r["LT"])
        mat["k_bend_" + d] = r["B"] * GF_CM2_PER_CM
        prov[f"strain.{d}"] = (f"{src}: strain at {limit_load:g} gf/cm of the curve through "
                               f"{d} EMT {r['EMT']:g} % and LT {r['LT']:.3g} (cloth/fabrics.py)")
        prov[f"material.k_{d}"] = (f"{src}: secant of the {d} curve at {limit_load:g} gf/cm "
                                   f"({limit_load:g} x 0.980665 N/m / {e:.4g})")
        prov[f"material.k_bend_{d}"] = f"{src}: {d} B {r['B']:g} gf cm^2/cm x 9.80665e-5"
    G, HG = f.shear["G"], f.shear["2HG"] / 2.0
    gamma_deg = min(max(0.0, (limit_load / 2.0 - HG) / G), JAMMING_DEG)
    lo, hi = bias_stretch(strain_at(limit_load / 2, f.warp["EMT"], f.warp["LT"]),
                          strain_at(limit_load / 2, f.weft["EMT"], f.weft["LT"]),
                          math.radians(gamma_deg))
    alo, ahi = automatic_bias(bands["warp"], bands["weft"])
    bands["bias"] = [min(lo, alo), max(hi, ahi)]
    prov["strain.bias"] = (f"{src}: a bias strip under {limit_load:g} gf/cm: shear "
                           f"{gamma_deg:.3g} deg from G {G:g} and 2HG {f.shear['2HG']:g}"
                           + (f" (capped at {JAMMING_DEG:g})" if gamma_deg >= JAMMING_DEG
                              else "") + ", threads at half the load (cloth/fabrics.py)")
    mat["k_shear"] = G * GF_PER_CM * PER_DEG
    prov["material.k_shear"] = f"{src}: G {G:g} gf/(cm deg) x 0.980665 x 180/pi"
    prov["material.density"] = f"{src}: W {f.weight:g} mg/cm^2 x 0.01"
    return _derived(f, src, mat, bands, gamma_deg, crimp, prov)


# ---- the rule for measured-moduli records (format "wang2011") ------------------------------------
def wang_moduli(fabric, row, strain):
    """[c11, c12, c22, c33] (N/m, the file's numbers) at principal strain ``strain`` of
    stretching row ``row``: linear from ``zero_strain`` to ``row`` over 0 ... 1/6, constant
    beyond, each clamped at 0 (ARCSim's dde.cpp does both)."""
    w = min(max(strain / WANG_STRAIN, 0.0), 1.0)
    a, b = fabric.stretching["zero_strain"], fabric.stretching[row]
    return [max((1.0 - w) * x + w * y, 0.0) for x, y in zip(a, b)]


def strip_modulus(c, angle):
    """The modulus (N/m, second Piola-Kirchhoff tension per Green strain) of a strip cut at
    ``angle`` (rad) from u, free across its width, of a membrane with energy density
    ``c11 E11^2 + 2 c12 E11 E22 + c22 E22^2 + 2 c33 E12^2`` (ARCSim's, rule W1): 1 / (n.S.n),
    S the compliance (engineering shear). 0 where the membrane is not stable."""
    a, b, d, g = 2.0 * c[0], 2.0 * c[1], 2.0 * c[2], c[3]
    det = a * d - b * b
    cs, sn = math.cos(angle) ** 2, math.sin(angle) ** 2
    if det <= 0.0 or (g <= 0.0 and cs * sn > 1e-12):
        return 0.0
    comp = (d * cs * cs - 2.0 * b * cs * sn + a * sn * sn) / det
    if cs * sn > 1e-12:
        comp += cs * sn / g
    return 1.0 / comp


def strip_tension(fabric, row, angle, strain):
    """The nominal tension (N/m) of a strip at ``strain`` (the tension a strip test reads):
    ``(1 + e) (e + e^2 / 2) * strip_modulus`` at that strain."""
    e = strain
    return (1.0 + e) * (e + 0.5 * e * e) * strip_modulus(wang_moduli(fabric, row, e), angle)


def strip_strain(fabric, row, angle, load):
    """The strain (fraction) at which the strip reaches ``load`` N/m: the first crossing,
    found on a 1e-4 grid and bisected; inf if not reached by 300 %."""
    step, e = 1e-4, 0.0
    while e < 3.0:
        if strip_tension(fabric, row, angle, e + step) >= load:
            lo, hi = e, e + step
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if strip_tension(fabric, row, angle, mid) < load else (lo, mid)
            return 0.5 * (lo + hi)
        e += step
    return math.inf


WANG_STRIPS = {"warp": ("stretch0", 0.0), "weft": ("stretch90", 0.5 * math.pi),
               "bias": ("stretch45", 0.25 * math.pi)}
WANG_BENDS = {"warp": "hinge90", "weft": "hinge0", "bias": "hinge45"}


def _median(xs):
    ys = sorted(xs)
    n = len(ys)
    return ys[n // 2] if n % 2 else 0.5 * (ys[n // 2 - 1] + ys[n // 2])


def _derive_wang(f, limit_load):
    """The rule W of the module docstring on a measured-moduli record."""
    src = _where(f.path)
    load = limit_load * GF_PER_CM                          # N/m
    mat, bands, prov, crimp = {}, {}, {}, {}
    strains = {}
    for d, (row, angle) in WANG_STRIPS.items():
        e = strip_strain(f, row, angle, load)
        if not math.isfinite(e):
            raise FabricError(f"{src}: the {d} strip ({row}) does not reach {limit_load:g} "
                              "gf/cm by 300 % strain")
        strains[d] = e
    for d in DIRECTIONS:
        row, angle = WANG_STRIPS[d]
        e = strains[d]
        bands[d] = [-e, e]
        mat["k_" + d] = load / e
        crimp[d] = strip_modulus(wang_moduli(f, row, 0.0), angle)
        prov[f"strain.{d}"] = (f"{src}: strain at {limit_load:g} gf/cm of the {d} strip "
                               f"(stretching.zero_strain to .{row}; cloth/fabrics.py, rule W)")
        prov[f"material.k_{d}"] = (f"{src}: secant of the {d} strip at {limit_load:g} gf/cm "
                                   f"({load:.4g} N/m / {e:.4g})")
        b = _median(f.bending[WANG_BENDS[d]])
        mat["k_bend_" + d] = HINGE_TO_PLATE * b
        prov[f"material.k_bend_{d}"] = (f"{src}: {HINGE_TO_PLATE:g} x the median of "
                                        f"bending.{WANG_BENDS[d]} ({1e6 * b:.4g} uN m)")
    e_b = strains["bias"]
    alo, ahi = automatic_bias(bands["warp"], bands["weft"])
    bands["bias"] = [min(-e_b, alo), max(e_b, ahi)]
    g = wang_moduli(f, "stretch45", e_b)[3]
    gamma_deg = JAMMING_DEG if g <= 0 else min(math.degrees(load / (2.0 * g)), JAMMING_DEG)
    prov["strain.bias"] = (f"{src}: strain at {limit_load:g} gf/cm of the bias strip "
                           f"(stretching.zero_strain to .stretch45), mirrored; shear "
                           f"{gamma_deg:.3g} deg" + (f" (capped at {JAMMING_DEG:g})"
                                                     if gamma_deg >= JAMMING_DEG else "")
                           + " (cloth/fabrics.py, rule W)")
    c33 = max(f.stretching["zero_strain"][3], 0.0)
    mat["k_shear"] = c33
    prov["material.k_shear"] = f"{src}: c33 of stretching.zero_strain ({c33:.4g} N/m)"
    prov["material.density"] = f"{src}: density {f.weight * MG_PER_CM2:g} kg/m^2"
    return _derived(f, src, mat, bands, gamma_deg, crimp, prov)


def _derived(f, src, mat, bands, gamma_deg, crimp, prov):
    """The steps both rules end with: density from the weight, the twisting rigidity from
    the two bending rigidities, the record's status on every provenance line; the result
    ``derive`` returns."""
    mat["density"] = f.weight * MG_PER_CM2
    mat["k_bend"] = math.sqrt(mat["k_bend_warp"] * mat["k_bend_weft"])
    prov["material.k_bend"] = f"{src}: sqrt(B_warp B_weft), the plate's twisting rigidity"
    status = f.source.get("status", "")
    if status:
        for k in prov:
            prov[k] += f" [{status}]"
    return dict(name=f.name, material=mat, strain=bands, shear_deg=gamma_deg,
                crimp_modulus=crimp, provenance=prov)


# ---- applying a fabric to a configuration --------------------------------------------------------
def _material_keys(cfg):
    """The material keys a configuration has (a fabric sets only these)."""
    return set(cfg.get("material", {}))


def fabric_changes(name, cfg=None):
    """{section: {key: value}}: what ``apply_fabric`` sets. Keys the configuration does not
    have (k_bend_warp / k_bend_weft before anisotropic bending) are left out, their geometric
    mean being k_bend."""
    d = derive(name)
    mat = dict(d["material"], preset=d["name"])
    if cfg is not None:
        have = _material_keys(cfg)
        mat = {k: v for k, v in mat.items() if k in have}
    return {"material": mat, "strain": {k: list(v) for k, v in d["strain"].items()}}


def apply_fabric(config, name):
    """``config`` with fabric ``name``'s material and bands (rule: the module docstring):
    a nested dict gives a new nested dict, a ``Settings`` a new checked ``Settings``. The
    damping, the method and every other key are kept; ``material.preset`` becomes the
    fabric's name."""
    from .settings import Settings
    if isinstance(config, Settings):
        changes = fabric_changes(name, config.to_dict())
        out = config
        for section, values in changes.items():
            out = out.replace(section, **values)
        return out
    out = copy.deepcopy(config)
    for section, values in fabric_changes(name, config).items():
        out.setdefault(section, {}).update(copy.deepcopy(values))
    return out


def provenance(name):
    """{setting key: where its number came from} for ``--show-config`` to print as comments."""
    return dict(derive(name)["provenance"])


def material_preset(name):
    """The material keys of fabric ``name`` (for ``material.preset = "denim"``)."""
    return dict(derive(name)["material"])


# ---- for main.py and the window --------------------------------------------------------------
def list_lines(directory=None):
    """``--list``'s fabric section: one line per fabric (name, kind, the record's status)."""
    out = ["fabrics (--fabric NAME; fabrics/*.toml, docs/fabrics.md):"]
    for p in paths(directory):
        f = load(p)
        out.append(f"  {f.name:18s} {f.kind}" + (f" [{f.source['status']}]"
                                                  if f.source.get("status") else ""))
    return out


def annotate(lines, cfg):
    """``--show-config``'s lines with, under each key whose value a fabric gave, a comment
    saying where it came from. The fabric is ``cfg["material"]["preset"]`` when that names
    one; a key another layer changed since (``--set``, a TOML file) gets no comment."""
    name = cfg.get("material", {}).get("preset")
    if name not in names():
        return list(lines)
    d = derive(name)
    given = {f"material.{k}": v for k, v in d["material"].items()}
    given.update({f"strain.{k}": v for k, v in d["strain"].items()})
    out = []
    for line in lines:
        out.append(line)
        key = line.split(" = ", 1)[0].strip()
        if key in d["provenance"]:
            section, k = key.split(".", 1)
            value = cfg.get(section, {}).get(k)
            if value is not None and _close(value, given[key]):
                out.append(f"#   ^ from {d['provenance'][key]}")
    return out


def _close(a, b):
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_close(x, y) for x, y in zip(a, b))
    return math.isclose(float(a), float(b), rel_tol=1e-9, abs_tol=1e-15)


# ---- the table of docs/fabrics.md ----------------------------------------------------------------
def table_lines(directory=None):
    L = ["| fabric | kind | W (g/m^2) | EMT warp / weft (%) | LT warp / weft | B warp / weft "
         "(gf cm^2/cm) | G (gf/(cm deg)) | 2HG (gf/cm) | source |",
         "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for p in paths(directory):
        f = load(p)
        if f.format != "kes":
            continue
        L.append(f"| {f.name} | {f.kind} | {10 * f.weight:.0f} | {f.warp['EMT']:g} / "
                 f"{f.weft['EMT']:g} | {f.warp['LT']:.3g} / {f.weft['LT']:.3g} | "
                 f"{f.warp['B']:g} / {f.weft['B']:g} | {f.shear['G']:g} | {f.shear['2HG']:g} | "
                 f"{f.source.get('cite', '')} ({f.source.get('status', '')}) |")
    L += ["", "Measured-moduli records (`format = \"wang2011\"`: Wang, O'Brien and Ramamoorthi "
          "2011, the tables of ARCSim's material files; N/m and N m as in the files):", "",
          "| fabric | kind | density (g/m^2) | zero strain: c11 / c12 / c22 / c33 (N/m) | at 1/6 "
          "strain: c11 along u / c22 along v / c33 on the bias (N/m) | bending, median of 5: "
          "hinges along u / bias / along v (uN m, file values) | source |",
          "| --- | --- | --- | --- | --- | --- | --- |"]
    for p in paths(directory):
        f = load(p)
        if f.format != "wang2011":
            continue
        z, st, b = f.stretching["zero_strain"], f.stretching, f.bending
        L.append(f"| {f.name} | {f.kind} | {10 * f.weight:.0f} | "
                 + " / ".join(f"{v:.4g}" for v in z) + " | "
                 f"{st['stretch0'][0]:.4g} / {st['stretch90'][2]:.4g} / {st['stretch45'][3]:.4g} | "
                 + " / ".join(f"{1e6 * _median(b[r]):.3g}" for r in BEND_ROWS) + " | "
                 f"{f.source.get('cite', '')} ({f.source.get('status', '')}) |")
    L += ["", "Derived by the rule (cloth/fabrics.py; limit load "
          f"{LIMIT_LOAD:g} gf/cm, jamming cap {JAMMING_DEG:g} deg):", "",
          "| fabric | warp band (%) | weft band (%) | bias band (%) | shear at the limit (deg) "
          "| k_warp / k_weft (N/m) | crimp modulus warp / weft (N/m) | k_shear (N/m) | "
          "density (kg/m^2) | k_bend_warp / k_bend_weft (uN m) | bending length warp / weft / "
          "bias (cm) |",
          "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for p in paths(directory):
        d = derive(load(p))
        m, s = d["material"], d["strain"]
        L.append(f"| {d['name']} | ±{100 * s['warp'][1]:.3g} | ±{100 * s['weft'][1]:.3g} | "
                 f"{100 * s['bias'][0]:.3g} ... {100 * s['bias'][1]:.3g} | {d['shear_deg']:.3g} | "
                 f"{m['k_warp']:.4g} / {m['k_weft']:.4g} | {d['crimp_modulus']['warp']:.4g} / "
                 f"{d['crimp_modulus']['weft']:.4g} | {m['k_shear']:.4g} | {m['density']:.3g} | "
                 f"{1e6 * m['k_bend_warp']:.3g} / {1e6 * m['k_bend_weft']:.3g} | " +
                 " / ".join(f"{100 * c:.2f}" for c in bending_lengths(d)) + " |")
    L += ["", "The shear each method's derived bands admit (`cloth.fabrics.shear_limits`: the threads' "
          "cell sheared, the threads unstretched):", "",
          "| fabric | shear at the limit load (deg; rule 4 or W4) | largest shear admitted: "
          "warp-weft / svd / mapping (deg) |", "| --- | --- | --- |"]
    for p in paths(directory):
        d = derive(load(p))
        lim = shear_limits(d["strain"])
        L.append(f"| {d['name']} | {d['shear_deg']:.3g} | "
                 + " / ".join(f"{lim[m]:.3g}" for m in ("warp-weft", "svd", "mapping")) + " |")
    return L


def bending_lengths(derived):
    """ASTM D1388 bending lengths c = (B / (rho g))^(1/3), m, along warp, weft and bias, B the
    strip's closed form (``bending.strip_rigidity``): what a lab's cantilever would read."""
    from .bending import strip_rigidity
    m = derived["material"]
    w = m["density"] * 9.81
    return [float((strip_rigidity(m["k_bend_warp"], m["k_bend_weft"], t) / w) ** (1 / 3))
            for t in (0.0, math.pi / 2, math.pi / 4)]


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--names"]:
        print("\n".join(names()))
        return
    print("\n".join(table_lines()))


if __name__ == "__main__":
    main()
