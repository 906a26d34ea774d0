"""The stability suite's ``--fast`` cases (``benchmarks.stability``), small enough for CI, and
the report they write.

Everything runs in this process (each run builds its Simulator: the kernels compile once per
process).
"""
import json
import os

import numpy as np
import pytest

from benchmarks import stability

# Whole module: simulation runs (make test-quick leaves them out).
pytestmark = pytest.mark.slow


# ---- stability: the --fast cases ------------------------------------------------------------
FAST = [c for c in stability.cases() if c.fast]
KNOWN = {}      # case name -> reason, for a known failure (strict xfail)


@pytest.fixture(scope="module")
def stability_results(tmp_path_factory):
    out = str(tmp_path_factory.mktemp("stability"))
    results = stability.run_cases(FAST, log=lambda *a: None)
    stability.write_report(results, out, "tests/test_benchmarks.py", 0.0)
    return out, {r["case"]: r for r in results}


def test_stability_report_lists_every_fast_case(stability_results):
    out, by_name = stability_results
    md = open(os.path.join(out, "stability.md")).read()
    data = json.load(open(os.path.join(out, "stability.json")))
    assert [r["case"] for r in data["results"]] == [c.name for c in FAST]
    for c in FAST:
        assert f"| {c.name} | " in md
    assert len(FAST) >= 7
    # The protocol's header: the command, the commit, the date and the CPU model.
    head = md.splitlines()[2:4]
    assert head[0].startswith("Command: `tests/test_benchmarks.py`"), head
    assert head[1].startswith("Commit ") and ", run 20" in head[1] and "CPU (" in head[1], head
    assert {"command", "commit", "date", "machine"} <= set(data)


@pytest.mark.parametrize("name", [
    pytest.param(c.name, marks=pytest.mark.xfail(strict=True, reason=KNOWN[c.name]))
    if c.name in KNOWN else c.name for c in FAST])
def test_stability_case_passes(stability_results, name):
    r = stability_results[1][name]
    assert r["finite"], r.get("error")
    for key in ("ke_peak", "violation_peak", "violation_end"):
        assert np.isfinite(r[key])
    assert r["passed"], r["why"]
