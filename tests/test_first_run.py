"""The first run's compile choice (cloth/backend.py choose_compile_mode, cloth/warm.py): fast
while the cache has no optimised kernels of this code, one line saying so, and the background
warmer never started under pytest unless a test asks."""
import json
import os
import subprocess
import sys

from cloth import backend, warm

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _mode(monkeypatch, cache, env_value, first_run_fast=True):
    monkeypatch.setenv("TI_OFFLINE_CACHE_FILE_PATH", str(cache))
    if env_value is None:
        monkeypatch.delenv(backend.FAST_COMPILE_ENV, raising=False)
    else:
        monkeypatch.setenv(backend.FAST_COMPILE_ENV, env_value)
    return backend.choose_compile_mode("cpu", "f64", first_run_fast)


def test_first_run_compiles_fast_until_the_marker_is_written(tmp_path, monkeypatch):
    assert _mode(monkeypatch, tmp_path, None) == (True, "first run")
    assert _mode(monkeypatch, tmp_path, None, first_run_fast=False) == (False, "library")
    (tmp_path / warm.MARKER_NAME).write_text(json.dumps({"0123456789abcdef": {}}))
    assert _mode(monkeypatch, tmp_path, None) == (True, "code changed")
    fp = warm.optimised_fingerprint("cpu", "f64")
    (tmp_path / warm.MARKER_NAME).write_text(json.dumps({fp: {}}))
    assert _mode(monkeypatch, tmp_path, None) == (False, "warmed")
    assert warm.marker_state(str(tmp_path), "cpu", "f32") == "other code"


def test_the_environment_forces_either_way(tmp_path, monkeypatch):
    assert _mode(monkeypatch, tmp_path, "1") == (True, "forced")
    assert _mode(monkeypatch, tmp_path, "0") == (False, "forced")
    fp = warm.optimised_fingerprint("cpu", "f64")
    (tmp_path / warm.MARKER_NAME).write_text(json.dumps({fp: {}}))
    assert _mode(monkeypatch, tmp_path, "1") == (True, "forced")


def test_the_first_run_line():
    line = warm.first_run_line("first run", "started", "/c/loom_warm.log")
    assert line == ("loom: first run on this machine: kernels compiled quickly (up to 1.4x "
                    "slower); optimised ones are being built in the background for the next "
                    "run (log: /c/loom_warm.log)")
    assert "the code changed" in warm.first_run_line("code changed", "running", "x")
    assert "by another Loom process" in warm.first_run_line("first run", "running", "x")
    assert "LOOM_BACKGROUND_COMPILE=0" in warm.first_run_line("first run", "off", "x")


def test_no_warmer_under_pytest_unless_asked():
    assert "PYTEST_CURRENT_TEST" in os.environ
    assert not warm.allowed()
    assert warm.allowed({"LOOM_BACKGROUND_COMPILE": "1", "PYTEST_CURRENT_TEST": "x"})
    assert not warm.allowed({"LOOM_BACKGROUND_COMPILE": "0"})
    assert warm.allowed({})


def test_a_cli_run_under_pytest_starts_no_warmer(tmp_path):
    """The suite forces fast compiles (conftest); even unforced, a run under pytest says
    that it builds nothing in the background, and no lock or log appears."""
    env = dict(os.environ, TI_OFFLINE_CACHE_FILE_PATH=str(tmp_path))
    env.pop(backend.FAST_COMPILE_ENV, None)
    r = subprocess.run([sys.executable, "main.py", "hanging", "--headless", "--frames", "1",
                        "--resolution", "5", "--method", "none", "--no-images",
                        "--out", str(tmp_path / "out")], cwd=ROOT, env=env,
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert "optimised ones are not built in the background" in r.stderr
    assert not (tmp_path / warm.LOCK_NAME).exists() and not (tmp_path / warm.LOG_NAME).exists()


def test_the_warmer_command_runs_and_writes_its_marker(tmp_path):
    """The warmer's own command line with a tiny plan (no strain solve), compiling fast:
    it takes the lock, writes the marker for what it compiled and releases the lock."""
    env = dict(os.environ, TI_OFFLINE_CACHE_FILE_PATH=str(tmp_path), LOOM_FAST_COMPILE="1")
    cmd = warm.command("cpu", "f64", plan=[("hanging", "none")], resolution=3)
    r = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert "hanging none" in r.stdout and "done in" in r.stdout
    marker = json.loads((tmp_path / warm.MARKER_NAME).read_text())
    from cloth import compile_notice
    assert list(marker) == [compile_notice.fingerprint("cpu", "f64", fast=True)]
    assert marker[list(marker)[0]]["plan"] == ["hanging:none"]
    assert not (tmp_path / warm.LOCK_NAME).exists()


def test_one_warmer_at_a_time(tmp_path):
    (tmp_path / warm.LOCK_NAME).write_text(f"{os.getpid()}\n")
    assert warm.running(str(tmp_path)) == os.getpid()
    assert warm.start(str(tmp_path), "cpu", "f64") == "running"
    (tmp_path / warm.LOCK_NAME).write_text("999999999\n")     # its process is gone: stale
    assert warm.running(str(tmp_path)) is None
