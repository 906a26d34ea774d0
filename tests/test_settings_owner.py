"""One owner per setting: ``Simulator.settings`` is the truth. Every live control the window
exposes is changed here through the path the window uses (``ui.state.AppState``), and every
copy of the setting kept elsewhere (the strain limiter's attributes, its kernels' ``params``,
the model's material, the stages switched on, the collider) must have followed, or not
exist."""
import dataclasses
import os

import numpy as np
import pytest

from cloth import metrics
from cloth.strain import buffers

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# Every strain setting the limiter keeps a copy of, as (setting, limiter attribute).
LIMITER_COPIES = (("method", "method"), ("solve", "solve"), ("tol", "tol"),
                  ("rounds", "max_rounds"), ("isotropy", "isotropy"))


def check_copies(st):
    """Every derived copy of every simulator of the app equals what its settings say."""
    for sim in st.sims:
        s = sim.settings
        lim = sim.strain
        limited = s.strain.method != "none"
        assert sim.method == s.strain.method
        assert sim.stage("strain_limit").enabled == limited
        assert sim.stage("remesh").enabled == s.remesh.enabled
        assert (sim.remesher is not None) or not s.remesh.enabled
        assert sim.substeps == s.sim.substeps
        assert sim.h == pytest.approx(1.0 / (s.sim.fps * s.sim.substeps))
        for f in dataclasses.fields(sim.model.material):
            assert getattr(sim.model.material, f.name) == getattr(s.material, f.name), f.name
        warp, weft = tuple(s.strain.warp), tuple(s.strain.weft)
        bias = tuple(s.strain.bias) if s.strain.bias else metrics.default_bias_band(warp, weft)
        assert sim.bands() == {"warp": warp, "weft": weft, "bias": bias}
        if lim is None:
            assert not limited       # no limiter, no copy: only method "none" may have none
            continue
        for key, attr in LIMITER_COPIES:
            assert getattr(lim, attr) == getattr(s.strain, key), key
        assert lim.warp == warp and lim.weft == weft and np.allclose(lim.bias, bias)
        p = lim._ws.params.to_numpy()
        assert np.allclose(p[buffers.P_WARP:buffers.P_WARP + 2], warp)
        assert np.allclose(p[buffers.P_WEFT:buffers.P_WEFT + 2], weft)
        assert np.allclose(p[buffers.P_SHEAR:buffers.P_SHEAR + 2],
                           np.sqrt(2.0) * (1.0 + np.asarray(bias)))
        assert p[buffers.P_ISO] == s.strain.isotropy
        exact = s.strain.solve == "exact"
        kernel_pdas = exact and not lim.uses_host_loop()
        assert p[buffers.P_PDAS] == float(kernel_pdas)
        assert p[buffers.P_MARGIN] == (0.0 if exact else lim.newton_margin())
        assert p[buffers.P_INNER_RTOL] == (0.0 if kernel_pdas else lim.inner_rtol)
    # The window keeps no copy: it reads the simulator's settings.
    assert not hasattr(st, "cfg")
    assert st.bands() == st.sim.bands()
    assert st.auto_bias == (not st.sim.settings.strain.bias)
    assert st.exact_solve == (st.sim.settings.strain.solve == "exact")
    assert st.remesh_on == st.sim.settings.remesh.enabled


def test_every_live_control_of_the_window_reaches_every_copy():
    from ui.state import MATERIAL_KEYS, AppState
    st = AppState.from_scene("hanging", [{"cloth": {"resolution": 5}}])
    check_copies(st)
    for method in ("svd", "warp-weft", "none", "mapping"):
        assert st.switch_method(method), st.message
        check_copies(st)
    # One check of a method's name, the schema's: the window shows its one line.
    assert not st.switch_method("isotropic") and "strain.method" in st.message
    assert st.sim.method == "mapping"
    for which in ("warp", "weft", "bias"):
        assert st.set_band(which, lo=-0.02, hi=0.03), st.message
        check_copies(st)
        assert st.bands()[which] == (-0.02, 0.03)
    assert not st.auto_bias
    assert st.set_auto_bias(True) and st.auto_bias
    check_copies(st)
    assert st.set_band("warp", hi=0.05)        # the automatic bias band follows the warp's
    check_copies(st)
    assert st.set_auto_bias(False) and not st.auto_bias
    frozen = st.bands()["bias"]
    assert st.set_band("warp", hi=0.02) and st.bands()["bias"] == frozen
    check_copies(st)
    assert st.set_rounds(7) and st.sim.strain.max_rounds == 7
    check_copies(st)
    assert st.set_exact_solve(True) and st.sim.strain.solve == "exact"
    check_copies(st)
    assert st.set_exact_solve(False)
    assert st.set_substeps(3)
    check_copies(st)
    for i, key in enumerate(MATERIAL_KEYS):
        assert st.set_material(key, 0.5 + i), st.message
        check_copies(st)
    assert st.sim.model.material.k_warp == 0.5
    assert st.set_remesh(True) and st.sim.stage("remesh").enabled
    check_copies(st)
    assert st.set_remesh(False)
    check_copies(st)
    # A refused change leaves the settings and every copy as they were.
    before = st.sim.settings.to_dict()
    assert not st.set_material("k_warp", -1.0) and "k_warp" in st.message
    with pytest.raises(ValueError, match="warp band min"):     # the limiter's own check
        st.sim.set_bands(warp=(-1.5, 0.1), weft=(-0.1, 0.1))
    assert st.sim.settings.to_dict() == before
    check_copies(st)
    # The same settings survive the comparison view and back (rebuilt from the settings).
    assert st.set_compare(True)
    check_copies(st)
    assert [s.method for s in st.sims] == ["svd", "warp-weft", "mapping"]
    assert all(s.settings.strain.rounds == 7 and s.settings.sim.substeps == 3 for s in st.sims)
    assert st.set_compare(False) and st.sim.method == "mapping"
    assert st.sim.settings.strain.warp == [-0.02, 0.02]
    check_copies(st)
    st.tick()
    check_copies(st)


SHEET_OBJ = "".join(f"v {x} {1.0 - y} 0\n" for y in (0, 0.5, 1) for x in (0, 0.5, 1)) + \
    "".join(f"vt {x} {y}\n" for y in (0, 0.5, 1) for x in (0, 0.5, 1)) + \
    "".join(f"f {a}/{a} {b}/{b} {c}/{c}\n" for a, b, c in
            ((1, 2, 5), (1, 5, 4), (2, 3, 6), (2, 6, 5), (4, 5, 8), (4, 8, 7), (5, 6, 9),
             (5, 9, 8)))


def sheet_scene(tmp_path, section):
    """The app on a scene file: the 2 x 2 sheet pinned along one edge, plus ``section``."""
    from ui.state import AppState
    (tmp_path / "sheet.obj").write_text(SHEET_OBJ)
    (tmp_path / "s.toml").write_text('[cloth]\nmesh = "sheet.obj"\npins = [[-0.01, -0.01, '
                                     '1.01, 0.01]]\n' + section)
    return AppState.from_scene(str(tmp_path / "s.toml"))


def test_the_self_collision_box_is_a_setting_the_collider_follows(tmp_path):
    st = sheet_scene(tmp_path, '[collision]\nself_collision = true\n')
    sim = st.sim
    assert st.has_self_collision and st.self_collision_on
    assert sim.settings.collision.self_collision
    assert st.set_self_collision(False)
    assert not sim.settings.collision.self_collision and not sim.self_collision_on
    assert st.set_self_collision(True)
    assert sim.settings.collision.self_collision and sim.self_collision_on
    check_copies(st)


def test_the_strain_limiter_is_built_from_the_settings_alone():
    """The limiter takes the model, the strain settings and the seams, nothing else: built
    without settings it has the settings' defaults (cloth/settings.py), not numbers of its
    own; and no code outside cloth/strain/ sets an attribute on it."""
    import inspect
    import re

    from cloth.settings import COMMON_DEFAULTS
    from cloth.strain.solver import StrainLimiter
    from tests.helpers import sheet_model
    assert list(inspect.signature(StrainLimiter.__init__).parameters) == \
        ["self", "model", "strain", "stitches"]
    lim = StrainLimiter(sheet_model(n=3))
    d = COMMON_DEFAULTS["strain"]
    for key, attr in LIMITER_COPIES:
        assert getattr(lim, attr) == d[key], key
    setter = re.compile(r"\.strain\.[a-z_]+\s*=[^=]|\blim(iter)?\.[a-z_]+\s*=[^=]")
    for folder in ("cloth", "scenes", "ui"):
        for dirpath, _, files in os.walk(os.path.join(ROOT, folder)):
            if dirpath.endswith(os.path.join("cloth", "strain")):
                continue
            for name in files:
                if name.endswith(".py"):
                    with open(os.path.join(dirpath, name)) as fh:
                        hits = setter.findall(fh.read())
                    assert not hits, (name, hits)


def test_the_bending_ratio_is_read_when_the_cloth_is_built(tmp_path):
    # k_bend_warp / k_bend_weft's ratio lives in the bending matrix (built with the cloth); a
    # live change of it is refused with one line and changes nothing, scaling both together is
    # live (the kernels' factor, Material.bend_scale).
    from cloth.config import ConfigError
    st = sheet_scene(tmp_path, '[material]\npreset = "cotton-jersey"\n')
    sim = st.sim
    bw, bf = sim.settings.material.k_bend_warp, sim.settings.material.k_bend_weft
    assert bw == pytest.approx(2 * bf) and sim.model.bend_alpha == pytest.approx(2 ** 0.125)
    with pytest.raises(ConfigError, match="k_bend_weft: their ratio is read when the cloth"):
        sim.set_material(k_bend_warp=3 * bw)
    assert sim.settings.material.k_bend_warp == bw and sim.model.material.k_bend_warp == bw
    sim.set_material(k_bend_warp=2 * bw, k_bend_weft=2 * bf)
    assert sim.model.material.bend_scale() == pytest.approx(2 * np.sqrt(bw * bf))
    check_copies(st)
