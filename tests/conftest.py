"""Taichi starts once per test process: CPU, f64 (the project default), compiling fast.

Jitter mode: ``LOOM_JITTER_SEED=N pytest ...`` moves every simulation's start by about 1 nm
(``JITTER_M``: a random offset per free vertex, normal, seeded by N and the test's node id),
so a run with a few seeds shows that no test's verdict hangs on one run's last bits. The hook
is here: every in-process run starts in ``Simulator.__init__``, which this file wraps for
the session to move its start with the product's ``nudged_start`` (what settings
``sim.nudge`` does; the scene builders and the set-ups they return stay untouched). Within
one test every Simulator of the same mesh size gets the same offsets, so
tests that compare two runs bit for bit compare two equally moved runs. Runs in a child
process (the command line, the window under Xvfb) are not moved; a test comparing such a run
bit for bit with an in-process one is marked ``no_jitter``.
"""
import os
import sys
import zlib

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

from cloth import backend  # noqa: E402

backend.init("cpu", "f64")

JITTER_ENV = "LOOM_JITTER_SEED"
JITTER_M = 1e-9
_jitter = {"seed": None, "key": 0}


def jitter_seed():
    """The jitter mode's seed (``LOOM_JITTER_SEED``), None when off."""
    value = os.environ.get(JITTER_ENV, "").strip()
    return int(value) if value else None


def pytest_configure(config):
    config.addinivalue_line(
        "markers", "no_jitter: compares an in-process run bit for bit with one in a child "
        "process, which the jitter mode (LOOM_JITTER_SEED) does not move")
    _jitter["seed"] = jitter_seed()
    if _jitter["seed"] is None:
        return
    from cloth.simulator import Simulator, nudged_start
    original = Simulator.__init__

    def moved_start(self, setup, settings):
        # The product's own nudge (settings sim.nudge), seeded by the test and the mesh size:
        # the same offsets for every call within a test; none at pinned vertices.
        if _jitter["seed"] is not None and _jitter["key"] is not None:
            setup = nudged_start(setup, [_jitter["seed"], _jitter["key"], *setup.mesh.x.shape],
                                 JITTER_M)
        original(self, setup, settings)
    moved_start.__wrapped__ = original
    Simulator.__init__ = moved_start


def pytest_report_header(config):
    if _jitter["seed"] is not None:
        return (f"jitter mode: every simulation starts {JITTER_M:g} m from its scene's start "
                f"({JITTER_ENV}={_jitter['seed']})")


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item):
    """The test's jitter key, set before its fixtures (a module-scoped fixture's runs take the
    key of the test that first asks for them); None for ``no_jitter`` tests."""
    no = item.get_closest_marker("no_jitter") is not None
    _jitter["key"] = None if no else zlib.crc32(item.nodeid.encode())


@pytest.fixture
def rng():
    import numpy as np
    return np.random.default_rng(1234)
