"""Taichi starts once per test process: CPU, f64 (the project default), compiling fast."""
import os
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

# Compile fast (cloth/backend.py: 12 s instead of 158 s for the AL solve on an empty cache);
# inherited by the subprocesses the tests start (CLI runs, the window under Xvfb).
os.environ.setdefault("LOOM_FAST_COMPILE", "1")

from cloth import backend  # noqa: E402

backend.init("cpu", "f64")


@pytest.fixture
def rng():
    import numpy as np
    return np.random.default_rng(1234)
