"""The several-ship figure: every track drawn where it exists, the counts and GOSPA over time as the metric
gives them (a missed ship adds c / sqrt(2), a false one likewise)."""

import matplotlib.pyplot as plt
import numpy as np

from shipsense import load_scenario
from shipsense.plotting import plot_ships
from shipsense.trackers.metrics import GOSPA_CUTOFF_M
from shipsense.trackers.ships import ShipsResult


def crossing_result(K=12, n=7):
    """Two true ships on straight lines; track 1 follows ship 0 3 m off from sample 2, track 2 follows ship 1
    exactly from sample 6; ship 1 counts from sample 4 (so it is missed at samples 4 and 5)."""
    t = np.arange(K) * 0.5
    truth = np.full((2, K, n), np.nan)
    truth[0, :, :2] = np.stack([80 - 5 * t, 50 - 5 * t], axis=1)
    truth[1, :, :2] = np.stack([-30 + 5 * t, 60 - 5 * t], axis=1)
    est = np.full((1, K, 2, n), np.nan)
    est[0, 2:, 0, :2] = truth[0, 2:, :2] + [3.0, 0.0]
    est[0, 6:, 1, :2] = truth[1, 6:, :2]
    cov = np.where(np.isfinite(est[..., :1, None]), np.eye(n), np.nan) * np.ones((1, K, 2, n, n))
    status = np.zeros((1, K, 2), dtype=np.int8)
    result = ShipsResult(tuple("x y vx vy mx my mz".split()), t[None], est, cov, status,
                         np.array([[2, 6]]), np.array([[-1, -1]]))
    present = np.ones((2, K), dtype=bool)
    present[0, :2] = present[1, :4] = False
    return result, truth, present


def test_the_figure_draws_the_counts_and_gospa_of_the_metric(tmp_path):
    result, truth, present = crossing_result()
    array = load_scenario("S2-crossing").array()
    fig = plot_ships(result, array, truth=truth, present=present)
    count, gospa = fig.axes[1], fig.axes[2]
    np.testing.assert_array_equal(count.lines[0].get_ydata(), [0, 0] + [1] * 4 + [2] * 6)   # tracked
    np.testing.assert_array_equal(count.lines[1].get_ydata(), [0, 0] + [1] * 2 + [2] * 8)   # true, counted
    half = GOSPA_CUTOFF_M ** 2 / 2
    expected = np.sqrt([0, 0, 9, 9, 9 + half, 9 + half] + [9] * 6)
    np.testing.assert_allclose(gospa.lines[-1].get_ydata()[:12], expected)
    assert plot_ships(result, array, tmp_path / "f.png", truth=truth) == tmp_path / "f.png"
    assert (tmp_path / "f.png").stat().st_size > 10_000
    assert len(plot_ships(result, array).axes) == 2                  # no truth: tracks and count only
    plt.close("all")
