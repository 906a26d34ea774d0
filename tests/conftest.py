"""Taichi starts once per test process: CPU, f64 (the project default)."""
import os
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

from cloth import backend  # noqa: E402

backend.init("cpu", "f64")


@pytest.fixture
def rng():
    import numpy as np
    return np.random.default_rng(1234)
