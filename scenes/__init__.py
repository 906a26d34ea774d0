"""Scene registry: name -> module with ``DEFAULTS`` (every settable key) and ``build(cfg)``."""
import importlib

SCENES = {
    "hanging": "scenes.hanging",
    "pull": "scenes.pull",
    "drape": "scenes.drape",
    "tshirt": "scenes.tshirt",
}
DESCRIPTIONS = {
    "hanging": "paper Table 1: a cloth hanging from its two top corners, settling to rest "
               "(mapping, warp +-1 %, weft +-5 %)",
    "pull": "a sheet pinned along its top edge with a corner dragged away (the user stretches it)",
    "drape": "a square sheet falling onto a sphere and the ground",
    "tshirt": "paper Table 2: a mannequin wearing a T-shirt, settling at rest",
}
DEFAULT_SCENE = "hanging"


def get(name):
    """A built-in scene's module, or for a path (``*.toml``) a ``SceneFile`` that behaves like
    one (``DEFAULTS``, ``build``; plus ``NAME`` and ``check``)."""
    from .scene_file import SceneFile, is_scene_file
    if name not in SCENES and is_scene_file(name):
        import os
        from cloth.config import load_toml
        data = load_toml(name) if os.path.isfile(name) else {}
        base = data.get("scene")
        if base in SCENES and not (data.get("cloth") or {}).get("mesh"):
            # A config.toml written by a run of a built-in scene: that scene with these values.
            import types
            from .common import resolve
            module = importlib.import_module(SCENES[base])
            data = {k: v for k, v in data.items() if k != "scene"}
            return types.SimpleNamespace(
                DEFAULTS=resolve(module.DEFAULTS, [data]), build=module.build,
                NAME=os.path.splitext(os.path.basename(name))[0], __name__=module.__name__,
                path=base)
        return SceneFile(name)
    if name not in SCENES:
        import difflib
        hint = difflib.get_close_matches(name, list(SCENES), n=1)
        raise KeyError(f"unknown scene '{name}'" + (f" (did you mean '{hint[0]}'?)" if hint else "")
                       + f": choose one of {', '.join(SCENES)} (python main.py --list)")
    return importlib.import_module(SCENES[name])
