"""The settings schema: every key documented with its unit, out-of-range values and unknown
choices refused with one line naming the key, --show-config and config.toml from the schema,
and docs/scenes.md generated from it."""
import os
import tomllib

import pytest

import main as loom_main
import scenes
from cloth.config import ConfigError
from scenes.common import COMMON_DEFAULTS, resolve
from scenes.schema import SCHEMA, commented_toml, markdown, show_config, validate

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_docs_scenes_md_is_generated_from_the_schema():
    with open(os.path.join(ROOT, "docs", "scenes.md")) as fh:
        assert fh.read() == markdown(), \
            "docs/scenes.md is out of date: python -m scenes.schema --markdown docs/scenes.md"


def test_every_key_of_every_scene_is_documented():
    for name in list(scenes.SCENES) + [os.path.join(ROOT, "scenes", "examples", "garment.toml")]:
        cfg = resolve(scenes.get(name).DEFAULTS, [])
        for section, values in cfg.items():
            if isinstance(values, dict):
                for key in values:
                    meta = SCHEMA.get(section, {}).get(key)
                    assert meta is not None and meta.doc, f"{name}: {section}.{key} undocumented"
    for section, values in COMMON_DEFAULTS.items():
        assert set(values) <= set(SCHEMA[section])


def test_validate_returns_typed_sections():
    cfg = resolve(scenes.get("hanging").DEFAULTS, [])
    s = validate(cfg)
    assert s["strain"].method == "mapping" and s["strain"].warp == [-0.01, 0.01]
    assert s["sim"].fps == 30.0 and s["cloth"].resolution == 25
    with pytest.raises(Exception):
        s["strain"].method = "svd"           # frozen: the dict stays the one source


@pytest.mark.parametrize("setting,words", [
    ("strain.method=\"svdd\"", ["strain.method", "is not one of svd, warp-weft"]),
    ("material.k_warp=-3", ["material.k_warp", "must be >= 0 N/m"]),
    ("strain.warp=[0.01,0.02]", ["strain.warp", "min <= 0 <= max"]),
    ("output.every=0", ["output.every", "must be >= 1"]),
    ("remesh.aspect_min=2", ["remesh.aspect_min", "must be <= 1"]),
    ("strain.tol=0", ["strain.tol", "must be > 0"]),
    ("sim.cg_tol=nan", ["sim.cg_tol", "must be finite"]),
])
def test_out_of_range_values_are_refused_with_one_line(capsys, setting, words):
    rc = loom_main.main(["hanging", "--set", setting, "--headless", "--show-config"])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("loom: error:")]
    assert rc == 2 and len(lines) == 1, err
    for w in words:
        assert w in lines[0], lines[0]
    assert "--set" in lines[0]


def test_wrong_type_is_refused_at_the_merge(capsys):
    rc = loom_main.main(["hanging", "--set", "sim.substeps=\"two\"", "--show-config"])
    assert rc == 2 and "'sim.substeps' takes a number" in capsys.readouterr().err


def test_show_config_and_config_toml_carry_units_and_read_back():
    cfg = resolve(scenes.get("drape").DEFAULTS, [])
    cfg["scene"] = "drape"
    lines = show_config(cfg)
    assert "sim.fps = 30.0  # [1/s] frames per simulated second" in lines
    text = commented_toml(cfg)
    assert "k_warp = 20.0  # [N/m]" in text or "k_warp = " in text
    assert tomllib.loads(text) == cfg


def test_scene_file_keys_are_validated(tmp_path, capsys):
    (tmp_path / "s.toml").write_text('[cloth]\nmesh = "x.obj"\nuv_scale = -2\n')
    rc = loom_main.main([str(tmp_path / "s.toml"), "--headless"])
    err = capsys.readouterr().err
    assert rc == 2 and "cloth.uv_scale = -2.0 must be > 0" in err, err


def test_validate_rejects_a_bad_value_directly():
    cfg = resolve(scenes.get("pull").DEFAULTS, [])
    cfg["pull"]["duration"] = 0.0
    with pytest.raises(ConfigError, match="pull.duration = 0.0 must be > 0 s"):
        validate(cfg)


def test_settings_are_the_typed_checked_view_the_simulator_reads():
    from cloth.settings import Settings
    cfg = resolve(scenes.get("hanging").DEFAULTS, [])
    cfg["scene"] = "hanging"
    s = Settings(cfg)
    assert s.strain.method == "mapping" and s.sim.substeps == 1 and "cloth" in s
    assert s.to_dict() == cfg                       # nothing lost or added on the way
    assert Settings.of(s) is s
    t = s.replace("strain", rounds=7, warp=[-0.02, 0.02])
    assert (t.strain.rounds, t.strain.warp) == (7, [-0.02, 0.02])
    assert s.strain.rounds == 100                    # the original is unchanged
    with pytest.raises(ConfigError, match="strain.rounds = 0 must be >= 1"):
        s.replace("strain", rounds=0)
    # An explicit bias band and back to automatic ([]), which other list keys do not allow.
    explicit = s.replace("strain", bias=[-0.04, 0.04])
    assert explicit.strain.bias == [-0.04, 0.04]
    assert explicit.replace("strain", bias=[]).strain.bias == []
    with pytest.raises(ConfigError, match="strain.warp"):
        s.replace("strain", warp=[])
    with pytest.raises(ConfigError, match="unknown setting 'strain.itres'"):
        s.replace("strain", itres=3)
    with pytest.raises(AttributeError, match="no settings section 'pul'"):
        s.pul
