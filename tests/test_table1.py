"""Paper Table 1 at low resolution: the hanging cloth near rest for the three methods x the two
band settings, asserting the findings recorded in docs/table1.

The cloth does not come fully to rest with strain limiting (kinetic energy stays ~1e-4 J: a
jitter of a few vertices), so the strain maxima of single frames jitter too (mapping's warp
max between 1.0 and 1.24 % from frame to frame in V1H5). Each run is therefore summarised
over a window of its last frames: the largest strain reached in the window, the mean wrinkle
measure. Margins quoted below are from resolution 9, 90 frames (3 s), window of 30 frames.
"""
import numpy as np
import pytest

import scenes
from benchmarks.reproduce_paper import BANDS, METHODS, measure
from cloth.simulator import Simulator
from scenes.common import resolve

# Whole module: simulation sweeps (make test-quick leaves them out).
pytestmark = pytest.mark.slow

RES = 9            # vertices per side (128 triangles)
FRAMES = 90        # 3 s at 30 fps; the strain maxima and wrinkle measures plateau from ~40
WINDOW = 30        # frames summarised at the end of each run
TOL = 1e-4         # the strain solver's tolerance (strain.tol): violations below it are met
LOOSE, TIGHT = 0.05, 0.01


def _tight_loose(bands):
    """(tight direction, loose direction) of a band setting: V1H5 holds the warp to 1 %."""
    return ("warp", "weft") if bands == "V1H5" else ("weft", "warp")


def _setting(bands, method):
    module = scenes.get("hanging")
    cfg = resolve(module.DEFAULTS, [{"cloth": {"resolution": RES},
                                     "strain": dict(method=method, **BANDS[bands])}])
    return module.build(cfg), cfg


def _run(sim):
    out = {"viol": 0.0, "converged": True, "warp_max": -1.0, "weft_max": -1.0,
           "principal_max": -1.0, "curvature": [], "height": []}
    for frame in range(1, FRAMES + 1):
        sim.step_frame()
        own = sim.strain.constraint_values()
        out["viol"] = max(out["viol"], float(own.max()))
        out["converged"] &= bool(sim.strain.last_converged)
        if frame > FRAMES - WINDOW:
            r = measure(sim)
            for key in ("warp_max", "weft_max"):
                out[key] = max(out[key], r[key])
            out["principal_max"] = max(out["principal_max"],
                                       float(sim.face_strains()["principal_max"].max()))
            out["curvature"].append(r["curvature_energy"])
            out["height"].append(r["height"])
    out["curvature"] = float(np.mean(out["curvature"]))
    out["height_range"] = float(np.ptp(out["height"]))
    return out


@pytest.fixture(scope="module")
def table():
    rows = {}
    for bands in BANDS:
        for method in METHODS:
            setup, cfg = _setting(bands, method)
            sim = Simulator(setup, cfg)
            rows[bands, method] = _run(sim)
    return rows


@pytest.mark.xdist_group("table1")     # one worker: the table's runs happen once
@pytest.mark.parametrize("bands", list(BANDS))
@pytest.mark.parametrize("method", METHODS)
def test_every_run_meets_its_own_constraints_and_settles(table, bands, method):
    r = table[bands, method]
    # The projection ends every substep within its tolerance (strain units), or reports that
    # it did not converge. (The margin is small by construction: the solver stops as soon as
    # the violation drops below tol; measured up to 0.99e-4.)
    assert r["converged"]
    assert r["viol"] < TOL
    # Near rest: the cloth's hanging height changes by millimetres over the window (measured
    # 0.7-4.6 mm; it fell 10 cm in its first frames), so the window's strains describe the
    # hanging shape, not the fall.
    assert r["height_range"] < 1e-2


@pytest.mark.xdist_group("table1")     # one worker: the table's runs happen once
@pytest.mark.parametrize("bands", list(BANDS))
def test_svd_is_isotropic_within_each_setting(table, bands):
    r = table[bands, "svd"]
    # The paper gives the first band to eta1 (docs/method.md §3.1).
    first = BANDS[bands]["warp"][1]
    # Every directional stretch is at most the largest principal stretch eta1 <= 1 + first
    # band, so both warp and weft stay within the FIRST band, whichever direction it names.
    assert r["warp_max"] < first + TOL
    assert r["weft_max"] < first + TOL
    # The soft cloth would stretch tens of percent: the eta1 limit binds.
    assert r["principal_max"] > first - TOL
    # ... and both material directions come close to it: svd ignores which direction the
    # band was meant for. V5H1 is the telling case: the weft band is 1 %, yet svd's weft
    # reaches ~4.9 % (the tight direction of warp-weft stays at 1 %). Measured: within 0.25 %
    # of the first band (V1H5 both 1.00 %; V5H1 warp 4.76 %, weft 4.86 %).
    assert r["warp_max"] > 0.8 * first
    assert r["weft_max"] > 0.8 * first
    assert abs(r["warp_max"] - r["weft_max"]) < 0.1 * first


@pytest.mark.xdist_group("table1")     # one worker: the table's runs happen once
@pytest.mark.parametrize("bands", list(BANDS))
def test_warp_weft_follows_the_material_bands(table, bands):
    r = table[bands, "warp-weft"]
    tight, loose = _tight_loose(bands)
    # Its constraints bound the directional stretches themselves (docs/method.md §3.2).
    assert r[f"{tight}_max"] < TIGHT + TOL
    assert r[f"{loose}_max"] < LOOSE + TOL
    # Both bands bind on this soft cloth (measured 1.00 % and 5.00 %).
    assert r[f"{tight}_max"] > TIGHT - TOL
    assert r[f"{loose}_max"] > LOOSE - 1e-3


@pytest.mark.xdist_group("table1")     # one worker: the table's runs happen once
@pytest.mark.parametrize("bands", list(BANDS))
def test_mapping_stretches_the_tight_direction_beyond_its_band(table, bands):
    r = table[bands, "mapping"]
    tight, loose = _tight_loose(bands)
    # Directional stretch along e_i is sqrt(sum_j eta_j^2 c_ij^2) with eta_j - 1 <= eps/c_ij,
    # hence at most 1 + sqrt(2) eps (equality: isotropic stretch, principal axes at 45
    # degrees; docs/method.md §3.3). The isotropy closure (strain.isotropy = 0.01) keeps it: a grid
    # search over (eta1, eta2, axis angle) finds no state it accepts beyond. Measured 1.24 %
    # (V1H5 warp) and 1.20 % (V5H1 weft) against 1.414 %.
    assert r[f"{tight}_max"] < np.sqrt(2.0) * TIGHT + TOL
    # The mapped band eps/|e.v| exceeds eps wherever the principal axes leave the material
    # axes, and the hanging cloth goes there: the tight direction stretches beyond its band,
    # the paper's "larger deformation" (warp-weft: 1.00 %). Measured 1.20-1.24 %, so a margin
    # of 0.1 % strain.
    assert r[f"{tight}_max"] > TIGHT + 1e-3
    assert r[f"{tight}_max"] > table[bands, "warp-weft"][f"{tight}_max"] + 1e-3
    # The loose band binds as with warp-weft. It is not exceeded by more than the closure's
    # slack: the paper's constraint allows at most the band itself along the loose direction
    # (an off-axis principal frame would stretch the tight direction too), the closed one up
    # to ~5.02 % (same grid search). Measured 5.01 %.
    assert LOOSE - 1e-3 < r[f"{loose}_max"] < LOOSE + 5e-4


@pytest.mark.xdist_group("table1")     # one worker: the table's runs happen once
@pytest.mark.parametrize("bands", list(BANDS))
def test_material_methods_swap_with_the_bands_svd_does_not(table, bands):
    tight, loose = _tight_loose(bands)
    # warp-weft and mapping: swapping the bands swaps which material direction is held. The
    # tight direction (1 % band, at most sqrt 2 x 1 %) ends well below the loose one (5 %
    # band, binding). Measured gap 3.8-4.0 % strain in both settings.
    for method in ("warp-weft", "mapping"):
        r = table[bands, method]
        assert r[f"{loose}_max"] - r[f"{tight}_max"] > 0.03
    # svd has no tight material direction in either setting (both get the eta1 band):
    # measured gap 0.01 % (V1H5) and 0.1 % (V5H1) strain.
    svd = table[bands, "svd"]
    assert abs(svd["warp_max"] - svd["weft_max"]) < 0.005


@pytest.mark.xdist_group("table1")     # one worker: the table's runs happen once
def test_wrinkle_measures_differ_between_methods(table):
    curv = {k: v["curvature"] for k, v in table.items()}
    # The folds follow how far the horizontal (weft) direction may stretch, whichever
    # method: the three runs that let it reach ~5 % (V1H5 warp-weft and mapping by their
    # weft band; V5H1 svd because its first band, 5 %, goes to eta1) all fold more than the
    # three that hold it to ~1 % (V5H1 warp-weft and mapping; V1H5 svd, capped at 1 % in
    # every direction). This is a measured pattern, not derived: curvature energy 19-43 vs
    # 2.7-4.6 here (res 9, three initial bulges; hinge bending), 67-249 vs 22-52 at
    # resolution 25 (docs/table1, isotropic bending; the margin there is 1.3x, not 2x). So
    # svd's wrinkles change with the band setting as much as the others'.
    # Margin 1.5: the svd rows moved when svd's gradients began to blend at near-ties
    # (constraints.SVD_ISO_GAP), to 13.8 against 7.1 here (a ratio of 1.96; it was over 2
    # before, and is 2.2 at resolution 25).
    stretchy = [curv["V1H5", "warp-weft"], curv["V1H5", "mapping"], curv["V5H1", "svd"]]
    held = [curv["V5H1", "warp-weft"], curv["V5H1", "mapping"], curv["V1H5", "svd"]]
    assert min(stretchy) > 1.5 * max(held)
    # The paper's "richer wrinkles" for mapping: in V1H5 its curvature energy exceeds
    # warp-weft's here. Measured ratios 1.12-1.57 (res 9, bulges 2-5 mm), 1.1 at res 11 (hinge
    # bending). At resolution 25 it does not hold (0.43: 106 vs 249 with isotropic bending,
    # 0.86 with the hinge; docs/table1), so this asserts the coarse sheet's order only. V5H1
    # shows no consistent difference; it is not asserted.
    assert curv["V1H5", "mapping"] > curv["V1H5", "warp-weft"]
