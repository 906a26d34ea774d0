"""The compile choice (cloth/backend.py): Taichi's fast compile unless LOOM_FAST_COMPILE=0 asks
for its full IR optimisation (minutes for the strain solve, no faster on a CPU:
docs/speed/first_run.md)."""
from cloth import backend


def test_kernels_compile_fast_unless_full_optimisation_is_asked_for(monkeypatch):
    for value in (None, "", "1", "yes"):
        if value is None:
            monkeypatch.delenv(backend.FAST_COMPILE_ENV, raising=False)
        else:
            monkeypatch.setenv(backend.FAST_COMPILE_ENV, value)
        assert backend.compile_mode() == "fast", value
    monkeypatch.setenv(backend.FAST_COMPILE_ENV, "0")
    assert backend.compile_mode() == "optimised"

