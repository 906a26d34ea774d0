"""Compiles are announced: one line before a kernel variant's first cold compile, with the
time the last one took on this machine; nothing when the record says it is cached."""
import io

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


def test_a_load_much_quicker_than_the_last_compile_keeps_its_time(record, monkeypatch):
    """The cloth package changed but not its kernels: the first use is announced (the
    fingerprint changed) and is a cache load; its time is not the next compile's estimate."""
    import json
    monkeypatch.setattr(cn, "COMPILED_ABOVE_S", 0.0)    # judged by the last compile's time alone
    record.write_text(json.dumps({"k": {"fingerprint": "old", "seconds": 20.0}}))
    assert "the code changed since the last compile; last time 20 s" in _use("k")
    entry = json.loads(record.read_text())["k"]
    assert entry["fingerprint"] == cn.fingerprint() and entry["seconds"] == 20.0


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


def test_a_method_switch_compiles_nothing_and_the_exact_solve_announces_its_own(monkeypatch):
    """The strain solver is one kernel for the three methods: once one method has run, a
    switch to another compiles no kernel variant and announces nothing, while the exact
    solve is a kernel of its own, announced before its first step."""
    from cloth.strain import al
    from ui.state import AppState
    monkeypatch.setattr(cn, "_used", set())     # as in a new process (xdist workers share one)
    st = AppState.from_scene("hanging", [{"cloth": {"resolution": 5}}])
    st.tick()
    fast = st.sim.compile_work("strain_limit")[1]
    assert cn.used(fast)
    variants = len(al.solve_al._primal.compiled_kernels)
    for m in ("svd", "warp-weft", "mapping"):
        assert st.switch_method(m) and st.sim.compile_pending() is None and st.message == ""
        frame = st.sim.frame
        st.tick()
        assert st.sim.frame == frame + 1 and st.sim.method == m
    assert len(al.solve_al._primal.compiled_kernels) == variants
    st.sim._change("strain", solve="exact")
    assert st.sim.compile_work("strain_limit")[1] != fast
