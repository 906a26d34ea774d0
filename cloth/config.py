"""Scene configuration: nested dicts of sections, merged strictly (an unknown key is an error
that names the known ones), read from TOML and ``--set key=value``, written back as TOML."""
import copy
import difflib
import tomllib


class ConfigError(ValueError):
    """Bad configuration input; the message names the fix."""


# List keys whose empty list is a value of its own ("automatic"), settable at any time.
EMPTY_MEANS_AUTOMATIC = ("strain.bias",)

# Keys that take a number or one of a few words (key path -> the words).
NUMBER_OR_WORD = {
    "cloth.uv_scale": ("auto",),      # metres per vt unit, or per-island area matching
    "cloth.warp": ("u", "v"),         # the warp direction: material u, v, or degrees from u
}


def merge(base, override, where=""):
    """A copy of ``base`` with ``override`` applied. Keys must already exist in ``base`` (the
    defaults declare every settable key); values keep their type where it is clear."""
    out = copy.deepcopy(base)
    for key, value in override.items():
        path = f"{where}{key}"
        if key not in out:
            hint = difflib.get_close_matches(key, list(out), n=1)
            known = ", ".join(f"{where}{k}" for k in out)
            raise ConfigError(f"unknown setting '{path}'"
                              + (f" (did you mean '{where}{hint[0]}'?)" if hint else "")
                              + f"; known keys here: {known}. See --show-config.")
        if isinstance(out[key], dict):
            if not isinstance(value, dict):
                raise ConfigError(f"'{path}' is a section; set one of its keys, e.g. "
                                  f"{path}.{next(iter(out[key]), 'key')}=...")
            out[key] = merge(out[key], value, path + ".")
        else:
            out[key] = _coerce(out[key], value, path)
    return out


def _coerce(old, value, path):
    if path in NUMBER_OR_WORD:
        words = NUMBER_OR_WORD[path]
        if isinstance(value, str) and value in words:
            return value
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        raise ConfigError(f"'{path}' takes a number or " + " or ".join(f'"{w}"' for w in words)
                          + f" (got {value!r})")
    if isinstance(old, bool) or old is None:
        if old is not None and not isinstance(value, bool):
            raise ConfigError(f"'{path}' takes true or false (got {value!r})")
        return value
    if isinstance(old, (int, float)) and not isinstance(value, bool):
        if isinstance(value, (int, float)):
            return float(value) if isinstance(old, float) else _as_int(value, path)
        raise ConfigError(f"'{path}' takes a number (got {value!r})")
    if isinstance(old, (list, tuple)):
        if path in EMPTY_MEANS_AUTOMATIC and isinstance(value, (list, tuple)) and not value:
            return []
        # An empty default list means "any length" (e.g. an optional band: [] = automatic).
        if not isinstance(value, (list, tuple)) or (old and len(value) != len(old)):
            raise ConfigError(f"'{path}' takes a list of {len(old)} values like {list(old)} "
                              f"(got {value!r})")
        if not old:
            return list(value)
        return [float(v) if isinstance(o, float) else v for o, v in zip(old, value)]
    if isinstance(old, str) and not isinstance(value, str):
        raise ConfigError(f"'{path}' takes a text value (got {value!r})")
    return value


def _as_int(value, path):
    if float(value) != int(value):
        raise ConfigError(f"'{path}' takes a whole number (got {value!r})")
    return int(value)


def parse_assignment(text):
    """'a.b.c=value' -> nested dict. The value is read as TOML (numbers, true/false, [lists],
    "strings"); anything else is taken as a plain string."""
    if "=" not in text:
        raise ConfigError(f"--set takes key=value (got '{text}'), e.g. --set cloth.width=1.5")
    key, raw = text.split("=", 1)
    key, raw = key.strip(), raw.strip()
    if not key:
        raise ConfigError(f"--set '{text}' has no key before '='")
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    out = node = {}
    parts = key.split(".")
    for p in parts[:-1]:
        node = node.setdefault(p, {})
    node[parts[-1]] = value
    return out


def load_toml(path):
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"config file '{path}' not found: give an existing .toml file "
                          "(see --show-config for the keys)") from None
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"config file '{path}' is not valid TOML ({err}); fix that line "
                          "(strings need quotes, sections look like [material])") from None


def toml_value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {toml_value(x)}" for k, x in v.items()
                               if x is not None) + "}"
    raise ConfigError(f"cannot write {v!r} to TOML")


def to_toml(cfg, prefix=""):
    """Nested dict -> TOML text (top-level scalars first, then one table per section)."""
    lines, tables, arrays = [], [], []
    for k, v in cfg.items():
        if isinstance(v, dict):
            tables.append((k, v))
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            arrays.append((k, v))            # an array of tables: [[obstacles]]
        elif v is not None:
            lines.append(f"{k} = {toml_value(v)}")
    for k, v in tables:
        name = f"{prefix}{k}"
        body = to_toml(v, name + ".")
        lines.append(f"\n[{name}]\n{body}" if body.strip() else f"\n[{name}]")
    for k, v in arrays:
        for item in v:
            body = "\n".join(f"{ik} = {toml_value(iv)}" for ik, iv in item.items()
                             if iv is not None)
            lines.append(f"\n[[{prefix}{k}]]\n{body}")
    return "\n".join(lines).strip("\n") + "\n" if not prefix else "\n".join(lines)


def flatten(cfg, prefix=""):
    """Nested dict -> list of ('a.b', value) for --show-config."""
    out = []
    for k, v in cfg.items():
        if isinstance(v, dict):
            out.extend(flatten(v, f"{prefix}{k}."))
        else:
            out.append((f"{prefix}{k}", v))
    return out
