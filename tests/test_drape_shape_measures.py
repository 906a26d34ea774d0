"""The measures behind ``benchmarks.drape_shape`` (is the resting drape the same for the default
solve and exact steps?): the hem of a sheet, its folds, and the permutation test on fold counts.
Pure numpy, no simulation."""
import numpy as np
import pytest

from benchmarks.drape_shape import fold_count, hem_loop, permutation_p
from cloth.sheet import make_sheet


@pytest.mark.parametrize("pattern", ["alternating", "regular"])
def test_hem_loop_walks_the_whole_boundary_of_a_sheet_in_order(pattern):
    n = 7
    uv, faces = make_sheet(1.0, 1.0, n, n, pattern)
    loop = hem_loop(faces)
    assert len(loop) == 4 * (n - 1) == len(set(loop))
    on_edge = np.isclose(uv[loop], 0.0) | np.isclose(uv[loop], 1.0)
    assert on_edge.any(axis=1).all()
    # Consecutive hem vertices are one grid step apart (the loop does not jump).
    steps = np.linalg.norm(np.diff(uv[loop + loop[:1]], axis=0), axis=1)
    assert np.allclose(steps, 1.0 / (n - 1))


def test_hem_loop_refuses_a_mesh_with_two_boundaries():
    two = np.array([[0, 1, 2], [3, 4, 5]])
    with pytest.raises(ValueError):
        hem_loop(two)


@pytest.mark.parametrize("lobes", [3, 6, 9])
def test_fold_count_counts_the_lobes_of_a_wavy_hem_wherever_the_loop_starts(lobes):
    t = np.linspace(0.0, 2.0 * np.pi, 96, endpoint=False)
    r = 0.35 + 0.05 * np.cos(lobes * t + 0.3)
    x = np.stack([r * np.cos(t), 0.3 * np.ones_like(t), r * np.sin(t)], axis=1)
    loop = list(range(len(t)))
    assert fold_count(x, loop, (0.0, 0.0)) == lobes
    assert fold_count(x, loop[17:] + loop[:17], (0.0, 0.0)) == lobes
    # Bumps shallower than the prominence are not folds.
    assert fold_count(x, loop, (0.0, 0.0), prominence=0.2) == 0


def test_permutation_p_tells_a_real_difference_from_noise():
    assert permutation_p([5, 6, 5, 6, 5, 6], [9, 10, 9, 10, 9, 10]) < 0.01
    assert permutation_p([6, 7, 6, 7, 6, 7], [7, 6, 7, 6, 7, 6]) == 1.0
