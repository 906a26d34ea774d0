"""The statistics that decide the paper's Table 2 claim from many runs (benchmarks/table2.py):
an exact rank test, a bootstrap interval for the median, the runs a test would need, and the
verdict's three outcomes on runs made up to have each."""
from math import comb

import numpy as np

from benchmarks.table2 import decide, median_interval, rank_test, runs_needed


def test_rank_test_is_exact_on_separated_and_on_mixed_runs():
    a, b = np.arange(8.0), np.arange(8.0) + 100.0
    # Fully separated: only the split itself and its mirror are as extreme.
    assert np.isclose(rank_test(a, b), 2 / comb(16, 8))
    assert np.isclose(rank_test(b, a), rank_test(a, b))
    # Interleaved runs: the rank sums are equal, every split is as extreme.
    assert rank_test(np.arange(0.0, 16.0, 2), np.arange(1.0, 17.0, 2)) > 0.7
    # One outlier does not make a difference significant (ranks, not values).
    rng = np.random.default_rng(1)
    x, y = rng.normal(size=8), rng.normal(size=8)
    y[0] = 1e6
    assert rank_test(x, y) > 0.05


def test_median_interval_brackets_the_median_and_narrows_with_runs():
    rng = np.random.default_rng(2)
    few, many = rng.normal(10, 1, 8), rng.normal(10, 1, 200)
    m, lo, hi = median_interval(few)
    assert lo <= m <= hi
    M, LO, HI = median_interval(many)
    assert LO <= M <= HI and HI - LO < hi - lo and LO < 10 < HI


def test_runs_needed_grows_as_the_difference_shrinks():
    rng = np.random.default_rng(3)
    base = rng.normal(0, 1, 8)
    assert runs_needed(base, base + 0.5) > runs_needed(base, base + 2.0) >= 2
    assert runs_needed(base, base) is None


def test_the_verdict_confirms_refutes_or_asks_for_runs():
    rng = np.random.default_rng(4)
    noise = lambda: rng.normal(0, 1, 8)  # noqa: E731
    verdict, _ = decide(m5=30 + noise(), w5=50 + noise(), w3=30 + noise())
    assert verdict == "confirmed"
    verdict, lines = decide(m5=30 + noise(), w5=50 + noise(), w3=70 + noise())
    assert verdict == "refuted" and "other way" in lines[-1]
    verdict, lines = decide(m5=50 + noise(), w5=50 + noise(), w3=50 + noise())
    assert verdict == "not resolved" and "about" in lines[-1]
