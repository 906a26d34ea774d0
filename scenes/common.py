"""What every scene shares: the settable keys with their defaults, material presets, and
the resolution of a scene's configuration (defaults < preset < TOML file < --set flags)."""
import copy

from cloth.config import ConfigError, merge
from cloth.model import Material
# The common sections' defaults and the presets live with their units in cloth/settings.py.
from cloth.settings import COMMON_DEFAULTS, MATERIAL_PRESETS  # noqa: F401 (re-exported)


def material_from(cfg):
    m = cfg["material"]
    return Material(**{k: float(v) for k, v in m.items() if k != "preset"})


def preset_values(preset, material):
    """The material keys of preset ``preset``: a built-in one (MATERIAL_PRESETS) or a fabric
    record (fabrics/*.toml, cloth/fabrics.py: its material only; ``--fabric`` also sets its
    bands), restricted to the keys ``material`` has."""
    if preset in MATERIAL_PRESETS:
        return MATERIAL_PRESETS[preset]
    from cloth import fabrics
    if preset in fabrics.names():
        return {k: v for k, v in fabrics.material_preset(preset).items() if k in material}
    raise ConfigError(f"unknown material preset '{preset}': use one of "
                      f"{', '.join(MATERIAL_PRESETS)} or a fabric ({', '.join(fabrics.names())})")


def resolve(defaults, overrides_list):
    """Apply each override dict in order. A ``material.preset`` override first loads that
    preset's values (``preset_values``), then the remaining material keys of the same override
    apply on top."""
    cfg = copy.deepcopy(defaults)
    for ov in overrides_list:
        ov = copy.deepcopy(ov)
        preset = ov.get("material", {}).get("preset")
        if preset is not None:
            cfg["material"].update(preset_values(preset, cfg["material"]), preset=preset)
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
