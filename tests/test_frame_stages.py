"""A flat frame (issue #37): every piece of work a frame does is a named, timed stage of
``Simulator.stages``; the stages' times add up to the frame's wall time, metrics.csv has a
column per stage, and the re-projections (after contact, after a remesh) have their own."""
import time

import numpy as np
import pytest

from benchmarks.harness import configure
from cloth.simulator import Simulator


def _sim(scene, over):
    _, cfg, setup = configure(scene, [over])
    sim = Simulator(setup, cfg)
    sim.set_metrics_stage(True)
    return sim


def _timed_projections(sim):
    """Wrap the limiter's ``project``: a list of (warm, ms) per call."""
    calls, project = [], sim.strain.project

    def timed(h, contacts=False, warm=True):
        t0 = time.perf_counter()
        project(h, contacts=contacts, warm=warm)
        calls.append((warm, 1e3 * (time.perf_counter() - t0)))
    sim.strain.project = timed
    return calls


def _adds_up(sim):
    row = sim.metrics_row()
    total = sum(s.ms for s in sim.stages)
    assert row["ms_total"] == sim.frame_ms
    assert abs(sim.frame_ms - total) <= 0.1 + 0.01 * sim.frame_ms, (sim.frame_ms, total)
    for s in sim.stages:
        assert row[f"ms_{s.name}"] == s.ms
        assert s.enabled or s.ms == 0.0
    return row


def test_the_stages_add_up_to_the_frame_time_and_the_csv_has_one_column_each():
    sim = _sim("hanging", {"cloth": {"resolution": 7}, "strain": {"method": "mapping"},
                           "sim": {"substeps": 2}})
    assert {s.name for s in sim.stages if s.enabled} == {"dynamics", "strain_limit",
                                                          "metrics", "snapshot"}
    for _ in range(4):
        sim.step_frame()
        row = _adds_up(sim)
        assert row["frame"] == sim.frame and sim.stage("metrics").ms > 0
    # Columns per stage, every stage, on or off (fixed columns).
    assert [k for k in row if k.startswith("ms_")] == \
        ["ms_total"] + [f"ms_{s.name}" for s in sim.stages]


def test_the_contact_reprojection_is_timed_in_its_own_column():
    """drape with mapping: the final obstacle pass is made to report a push beyond the strain
    tolerance once per substep, so each substep re-projects once; that projection's time is
    in ``contact_reproject`` (not in strain_limit or collision_final), and the frame still
    adds up."""
    sim = _sim("drape", {"cloth": {"resolution": 6}, "strain": {"method": "mapping"}})
    assert sim.stage("collision_final").enabled and sim.stage("contact_reproject").enabled
    calls = _timed_projections(sim)
    resolve, pushed = sim.collider.resolve_obstacles, []

    def far(h, t):
        moved = resolve(h, t)
        if len(pushed) < len(calls):       # the first pass after each substep's projection
            pushed.append(1)
            return max(moved, 1.0)
        return moved
    sim.collider.resolve_obstacles = far
    for _ in range(3):
        calls.clear()
        pushed.clear()
        sim.step_frame()
        _adds_up(sim)
        warm = [ms for w, ms in calls if w]
        cold = [ms for w, ms in calls if not w]
        assert len(warm) == sim.substeps and len(cold) >= sim.substeps
        assert sim.stage("contact_reproject").ms >= sum(cold)
        assert sim.stage("strain_limit").ms >= sum(warm)
        assert sim.stage("strain_limit").ms < sum(warm) + min(cold) + 0.5
        assert sim.stage("collision_final").ms < min(cold)


def test_obstacles_and_self_collision_are_separate_stages(tmp_path):
    from tests.test_settings_owner import SHEET_OBJ
    import scenes
    (tmp_path / "sheet.obj").write_text(SHEET_OBJ)
    (tmp_path / "s.toml").write_text('[cloth]\nmesh = "sheet.obj"\npins = [[-0.01, -0.01, '
                                     '1.01, 0.01]]\n[collision]\nself_collision = true\n'
                                     '[[obstacles]]\nkind = "plane"\n')
    module = scenes.get(str(tmp_path / "s.toml"))
    sim = Simulator(module.build(module.DEFAULTS), module.DEFAULTS)
    assert sim.stage("self_collision").enabled and sim.stage("collision").enabled
    sim.step_frame()
    assert sim.stage("self_collision").ms > 0 and sim.stage("collision").ms > 0
    sim.set_self_collision(False)
    assert not sim.stage("self_collision").enabled and sim.stage("collision").enabled
    sim.step_frame()
    assert sim.stage("self_collision").ms == 0.0


@pytest.mark.parametrize("scene, on", [("pull", {"pins"}), ("hanging", set())])
def test_moving_pins_are_a_stage_of_the_scenes_that_have_them(scene, on):
    sim = _sim(scene, {"cloth": {"resolution": 5}, "strain": {"method": "none"}})
    assert {s.name for s in sim.stages if s.enabled} & {"pins"} == on
    sim.step_frame()
    assert (sim.stage("pins").ms > 0) == bool(on)
    assert np.all(np.isfinite(sim.last_good.x))


def test_the_window_read_out_shows_every_stage_and_they_add_up():
    from ui.state import AppState
    st = AppState.from_scene("drape", [{"cloth": {"resolution": 5}}])
    st.tick()
    st.tick()
    r = st.readouts()
    assert r["sim_ms"] == st.sim.frame_ms
    assert set(r["stage_ms"]) == {s.name for s in st.sim.stages if s.enabled}
    assert {"collision_final", "contact_reproject"} <= set(r["stage_ms"])
    assert abs(sum(r["stage_ms"].values()) - r["sim_ms"]) <= 0.1 + 0.01 * r["sim_ms"]
