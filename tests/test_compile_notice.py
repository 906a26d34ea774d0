"""Compiles are announced: one line before a kernel variant's first cold compile, with the
time the last one took on this machine; nothing when the record says it is cached."""
import io

import numpy as np

import pytest

from cloth import compile_notice as cn


@pytest.fixture
def record(tmp_path, monkeypatch):
    path = tmp_path / cn.RECORD_NAME
    monkeypatch.setattr(cn, "_record_path", lambda: str(path))
    monkeypatch.setattr(cn, "_used", set())
    return path


def _use(key, what="the strain solver for svd", seconds=(120, 12)):
    out = io.StringIO()
    with cn.first_use(what, key, seconds, stream=out):
        pass
    return out.getvalue()


def test_first_compile_is_announced_with_an_estimate_then_recorded(record, monkeypatch):
    monkeypatch.setattr(cn, "COMPILED_ABOVE_S", 0.0)      # the empty body counts as a compile
    line = _use("k")
    assert line.startswith("loom: compiling the strain solver for svd (first use on this machine")
    from cloth import backend
    assert ("about 12 s" if backend.fast_compile() else "about 2.0 min") in line
    assert _use("k") == ""                          # used in this process: silent
    monkeypatch.setattr(cn, "_used", set())         # a new process with the same code
    assert _use("k") == ""
    # The code changes: announced again, with the time measured last time.
    monkeypatch.setattr(cn, "_fingerprint", "other")
    monkeypatch.setattr(cn, "_used", set())
    line = _use("k")
    assert "the code changed since the last compile; last time 0 s" in line


def test_a_cache_load_keeps_the_last_compile_time(record, monkeypatch):
    monkeypatch.setattr(cn, "COMPILED_ABOVE_S", 0.0)
    _use("k")
    seconds = __import__("json").loads(record.read_text())["k"]["seconds"]
    monkeypatch.setattr(cn, "COMPILED_ABOVE_S", 1e9)   # the next first use is a quick load
    monkeypatch.setattr(cn, "_used", set())
    monkeypatch.setattr(cn, "_fingerprint", "other")
    assert _use("k") != ""
    entry = __import__("json").loads(record.read_text())["k"]
    assert entry["fingerprint"] == "other" and entry["seconds"] == seconds


def test_progress_bar_starts_at_once_and_a_notice_ends_its_line():
    from ui.progress import Progress

    class Tty(io.StringIO):
        def isatty(self):
            return True
    out = Tty()
    bar = Progress(10, stream=out)
    bar.update(0, "first frame")
    assert "0/10 frames" in out.getvalue() and "eta     ?" in out.getvalue()
    for hook in cn.before_print:
        hook()
    assert out.getvalue().endswith("\n")
    bar.close()
    assert bar.end_line not in cn.before_print


def test_window_shows_the_notice_before_the_step_that_compiles(monkeypatch):
    """A method switch whose solver is not compiled on this machine: the next tick only
    shows the notice; the one after it steps. (The switch is to "none" with the pending
    compile faked, so that the test compiles nothing.)"""
    from ui.state import AppState
    st = AppState.from_scene("hanging", [{"cloth": {"resolution": 5}}])
    monkeypatch.setattr(type(st.sim), "compile_pending",
                        lambda self: "loom: compiling the strain solver for svd (first use)")
    assert st.switch_method("none")
    assert st.message.startswith("compiling the strain solver for svd")
    frame = st.sim.frame
    st.tick()
    assert st.sim.frame == frame and st.message.startswith("compiling")
    st.tick()
    assert st.sim.frame == frame + 1 and st.message == ""


def test_window_prepares_the_other_methods_without_touching_the_simulation(monkeypatch):
    """After the first step the window compiles the other methods' strain solvers, one per
    two window frames (the panel names each before it waits), on a throwaway sheet: the
    simulation is bit for bit what it was, and a switch afterwards has nothing to compile."""
    from ui.state import AppState
    monkeypatch.delenv("LOOM_PREPARE_METHODS", raising=False)
    monkeypatch.setattr(cn, "_used", set())     # as in a new process (xdist workers share one)
    st = AppState.from_scene("hanging", [{"cloth": {"resolution": 5}}])
    st.tick()
    x, frame = st.sim.model.positions().copy(), st.sim.frame
    announced, calls = [], 0
    while st.prepare_step():
        calls += 1
        name = st.message.split()[1].strip(",") if st.message.startswith("preparing") else None
        if name and announced[-1:] != [name]:
            announced.append(name)
        assert calls < 10
    assert announced == ["svd", "warp-weft"] and calls == 4
    assert st.message == "" and st.methods_to_prepare() == []
    assert st.sim.frame == frame and np.array_equal(st.sim.model.positions(), x)
    for m in ("svd", "warp-weft"):
        assert cn.used(st.sim.strain_solver_key(m))
        assert st.switch_method(m) and st.sim.compile_pending() is None
    st.tick()
    assert st.sim.frame == frame + 1 and st.sim.method == "warp-weft"


def test_preparing_can_be_turned_off(monkeypatch):
    from ui.state import AppState
    monkeypatch.setenv("LOOM_PREPARE_METHODS", "0")
    st = AppState.from_scene("hanging", [{"cloth": {"resolution": 5}}])
    assert st.methods_to_prepare() == [] and not st.prepare_step()
