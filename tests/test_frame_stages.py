"""A flat frame: every piece of work a frame does is a named, timed stage of
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


def _adds_up(sim, gaps):
    """The frame's row; appends to ``gaps`` the frame time the stages do not account for
    (ms). The stages time only themselves, so a gap is what runs between them: the loop's
    own overhead, or the process waiting for a core on a busy machine (hence the callers
    look at the median over frames)."""
    row = sim.metrics_row()
    total = sum(s.ms for s in sim.stages)
    assert row["ms_total"] == sim.frame_ms
    assert total <= sim.frame_ms
    gaps.append((sim.frame_ms - total) / (0.1 + 0.01 * sim.frame_ms))
    for s in sim.stages:
        assert row[f"ms_{s.name}"] == s.ms
        assert s.enabled or s.ms == 0.0
    return row


def test_the_stages_add_up_to_the_frame_time_and_the_csv_has_one_column_each():
    sim = _sim("hanging", {"cloth": {"resolution": 7}, "strain": {"method": "mapping"},
                           "sim": {"substeps": 2}})
    assert {s.name for s in sim.stages if s.enabled} == {"dynamics", "strain_limit",
                                                          "limits_watch", "metrics", "snapshot"}
    gaps = []
    for _ in range(7):
        sim.step_frame()
        row = _adds_up(sim, gaps)
        assert row["frame"] == sim.frame and sim.stage("metrics").ms > 0
    # Within 0.1 ms + 1 % of the frame (measured: 0.01-0.05 ms).
    assert np.median(gaps) <= 1.0, gaps
    # Columns per stage, every stage, on or off (fixed columns).
    assert [k for k in row if k.startswith("ms_")] == \
        ["ms_total"] + [f"ms_{s.name}" for s in sim.stages]


def test_the_contact_reprojection_is_timed_in_its_own_column():
    """drape with mapping: the final obstacle pass is made to report a push beyond the strain
    tolerance once per substep, so each substep re-projects once. Every re-projection runs
    inside the stage ``contact_reproject`` (none inside strain_limit or collision_final), whose
    time holds them all, and the frame still adds up."""
    sim = _sim("drape", {"cloth": {"resolution": 6}, "strain": {"method": "mapping"}})
    assert sim.stage("collision_final").enabled and sim.stage("contact_reproject").enabled
    running = []                       # the stage whose run is on
    for s in sim.stages:
        def run(run=s.run, name=s.name):
            running.append(name)
            try:
                return run()
            finally:
                running.pop()
        s.run = run
    calls, project = [], sim.strain.project

    def timed(h, contacts=False, warm=True, friction=True):
        t0 = time.perf_counter()
        project(h, contacts=contacts, warm=warm, friction=friction)
        calls.append((running[-1], warm, 1e3 * (time.perf_counter() - t0)))
    sim.strain.project = timed
    resolve, passes = sim.collider.resolve_obstacles, []

    def far(h, t):
        moved = resolve(h, t)
        passes.append(running[-1])
        if running[-1] == "collision_final":   # the first pass after the substep's projection
            return max(moved, 1.0)
        return moved
    sim.collider.resolve_obstacles = far
    gaps = []
    for _ in range(3):
        calls.clear()
        passes.clear()
        sim.step_frame()
        _adds_up(sim, gaps)
        assert [c[:2] for c in calls if c[1]] == [("strain_limit", True)] * sim.substeps
        cold = [c for c in calls if not c[1]]
        assert len(cold) >= sim.substeps
        assert {c[0] for c in cold} == {"contact_reproject"}
        assert sim.stage("contact_reproject").ms >= sum(c[2] for c in cold)
        assert passes.count("collision_final") == sim.substeps
    assert np.median(gaps) <= 1.0, gaps


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
    assert sum(r["stage_ms"].values()) <= r["sim_ms"]
    assert sum(r["stage_ms"].values()) == sum(s.ms for s in st.sim.stages)
