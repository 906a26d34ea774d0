"""Every registered scene runs headless for a few frames and passes its check_final(). (That
each check can fail, and what it tests later in a run: tests/test_final_checks.py.)"""
import csv

import numpy as np
import pytest

import scenes
from tests.test_scenes import make_sim

SMALL = {"hanging": {"cloth": {"resolution": 9}}, "pull": {"cloth": {"resolution": 9}},
         "drape": {"cloth": {"resolution": 11}}, "tshirt": {}}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(scenes.SCENES))
def test_scene_runs_and_passes_its_check(name, tmp_path):
    from ui.headless import HeadlessRun
    sim, cfg = make_sim(name, **SMALL.get(name, {}))
    run = HeadlessRun(sim, cfg, str(tmp_path), images=False, quiet=True)
    assert run.run(4)
    ok, message = sim.setup.check_final(sim)
    assert ok, message
    row = sim.metrics_row()
    assert row["nan"] == 0
    if sim.strain is not None and sim.stage("strain_limit").enabled:
        # Every frame's limits, from the run's own metrics.csv. On tshirt (mapping) the
        # projection failed to converge at frame 3 before the isotropy closure
        # (constraints.MAPPING_ISO): violation 6.5e-3 after 50 rounds.
        with open(tmp_path / "metrics.csv") as fh:
            rows = list(csv.DictReader(fh))
        assert len(rows) == 5                 # the start and 4 frames
        assert max(float(r["own_violation_max"]) for r in rows) < 2 * sim.strain.tol
    if name == "tshirt":
        # Contacts and seams are in the projection: sewn (seams closed to mm), no kick (the
        # 0.2 kg shirt stays far below 1 J).
        st = np.asarray(sim.dynamics.stitches_np)
        x = sim.model.positions()
        assert np.linalg.norm(x[st[:, 0]] - x[st[:, 1]], axis=1).max() < 0.01
        assert row["kinetic_energy"] < 0.5
    if sim.collider is not None:
        assert sim.collider.max_penetration() < 1e-6
    # Obstacles are dumped with the meshes.
    if sim.setup.obstacles:
        assert any(p.name.startswith("obstacles") for p in (tmp_path / "meshes").iterdir())


def test_scenes_enable_only_what_they_need():
    stages, self_coll = {}, set()
    for name in scenes.SCENES:
        sim, cfg = make_sim(name, **SMALL.get(name, {}))
        stages[name] = {s.name for s in sim.stages if s.enabled}
        assert (sim.collider is not None) == bool(sim.setup.obstacles or sim.setup.self_collision)
        if sim.setup.self_collision:
            self_coll.add(name)
    # hanging runs the paper's experiment (mapping) by default.
    assert stages["hanging"] == {"dynamics", "strain_limit", "limits_watch", "snapshot"}
    assert "collision" in stages["drape"] and "collision" in stages["tshirt"]
    assert {"collision_final", "contact_reproject"} <= stages["drape"]
    assert "collision" not in stages["pull"] and "pins" in stages["pull"]
    assert {"self_collision" in stages[n] for n in stages} == {True, False}
    assert {n for n in stages if "self_collision" in stages[n]} == self_coll == {"tshirt"}


@pytest.mark.slow
@pytest.mark.parametrize("name,frames", [("drape", 20)])
def test_obstacle_contacts_keep_the_strain_limits(name, frames):
    """Contacts are constraints of the projection: landing on the sphere and the ground must
    not undo the limits (before, the own violation reached O(0.1-1) there)."""
    sim, cfg = make_sim(name, **SMALL.get(name, {}))
    worst, touched = 0.0, 0
    for _ in range(frames):
        sim.step_frame()
        worst = max(worst, sim.metrics_row()["own_violation_max"])
        touched = max(touched, sim.collider.last_contacts)
        assert sim.collider.max_penetration() < 1e-6
    # The cloth did land (test_the_drape_lands_without_stopping_dead: how far it wraps).
    assert touched > 5
    assert worst < 2 * sim.strain.tol



@pytest.mark.slow
def test_the_drape_lands_without_stopping_dead():
    """The sheet that lands on the sphere keeps falling around it: the part on the sphere
    stops, the rest does not. Measured at resolution 11 (the default drop) over six starts
    1 nm apart: kinetic energy at frame 8 = 0.61-0.76 of the largest before it, 41-50
    vertices in contact at frame 16 (29-34 at frame 12: the wrap is under way). Its PCG steps
    start from where each vertex was going (strain.solver.SETTLE_SPEED); from the substep's
    start they kept 0.20 of the energy and touched 9 vertices at frame 12 (exact Newton steps:
    0.22 and 37, at frame 8 already stopped around the sphere; docs/speed/motion_error.md)."""
    from cloth import metrics
    sim, cfg = make_sim("drape", cloth={"resolution": 11})
    ke = []
    for _ in range(16):
        sim.step_frame()
        ke.append(metrics.kinetic_energy(sim.model.velocities(), sim.model.mass))
    assert ke[7] >= 0.5 * max(ke[:8])
    assert sim.collider.last_contacts > 30


@pytest.mark.slow
def test_the_default_drape_drapes():
    """The drape scene as a user runs it (`python main.py drape`, 25 x 25 vertices) hangs down
    around the sphere by 1.5 s. With the PCG steps started from the substep's start it lay flat
    on the sphere's top in 4 of 7 drop heights (docs/speed/motion_error.md): then it stays
    above the sphere's equator on every side.

    A landing is chaotic, so this asserts what every start 1 nm apart does (LOOM_JITTER_SEED),
    as the scene's final check does (every side but one below the equator). Over ten such
    starts, at 1.5 s: the cloth rests on the top and hangs 0.23-0.24 m below the equator in
    all; below it on all 8 sides in 8, on 7 of 8 in 2 (a fold up to 3.2 cm above it, once
    still at 3 s); the limits held at the last frame in all (largest 0.93 tol)."""
    from scenes import checks
    sim, cfg = make_sim("drape")
    for _ in range(45):
        sim.step_frame()
    s = cfg["sphere"]
    margin = 4 * cfg["collision"]["thickness"]
    x = sim.model.positions()
    rel = x - np.asarray(s["center"], float)
    assert checks.finite(sim)[0]
    assert checks.outside(np.linalg.norm(rel, axis=1) - s["radius"], margin / 4, "the sphere")[0]
    assert checks.outside(x[:, 1], margin / 4, "the ground")[0]
    on_top = (np.linalg.norm(rel, axis=1) - s["radius"] < margin) & \
        (rel[:, 1] > s["radius"] * np.cos(np.radians(30.0)))
    assert on_top.any()                                   # it landed on the sphere
    assert rel[:, 1].min() < -0.15                        # and hangs well below its equator
    # The lowest point in each of 8 sectors round the vertical axis, beyond the outline.
    rho = np.hypot(rel[:, 0], rel[:, 2])
    beyond = rho > s["radius"] + margin
    side = np.minimum((8 * (np.arctan2(rel[beyond, 2], rel[beyond, 0]) + np.pi)
                       / (2 * np.pi)).astype(int), 7)
    lowest = np.full(8, np.inf)
    np.minimum.at(lowest, side, rel[beyond, 1])
    assert np.isfinite(lowest).sum() >= 6                 # it overhangs on (nearly) every side
    assert (lowest >= 0.0).sum() <= 1, lowest             # and hangs below the equator there
    assert sim.own_violation().max() <= checks.LIMIT_FACTOR * sim.settings.strain.tol


def test_the_pull_target_is_within_every_methods_bands():
    """The dragged corner's target asks no pinned pair to stretch past svd's bound (svd, the
    strictest method, holds every direction to the warp band's upper end): each pin's distance
    to the corner grows, by less than that. The earlier target asked 3.3 % along the diagonal
    from the top-right pin; no state met svd's limits, and its runs failed their check."""
    from scenes import pull
    from scenes.common import resolve
    cfg = resolve(scenes.get("pull").DEFAULTS, [])
    most, least = pull.pin_stretch(cfg)
    assert 0.0 < least <= most < cfg["strain"]["warp"][1]
    old = resolve(scenes.get("pull").DEFAULTS, [{"pull": {"displacement": [-0.1, 0.15, 0.45]}}])
    assert pull.pin_stretch(old)[0] > 0.03
