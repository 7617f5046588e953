"""Judging a layout by the tracker on held-out passages."""

import pytest

from shipsense.design.evaluate import evaluate_layout


def test_a_layout_is_judged_by_the_projects_tracker_and_the_bank_stays_an_option():
    """On the triangle P2 the project's tracker converges on every held-out passage and, where it reports a
    track (most of the second half: before its first fit it reports the prior, and says so), is far more
    accurate than the studies' bank on the same passages (kept only to reproduce earlier figures); a bad
    method is refused."""
    tracker = evaluate_layout("S1-P2", passages=6, check_passages=1)
    bank = evaluate_layout("S1-P2", passages=6, check_passages=1, method="bank")
    assert tracker.verdict == bank.verdict == "observable"
    assert tracker.convergence_rate == 1.0 and tracker.tracked_share > 0.9 and bank.tracked_share == 1.0
    assert tracker.rmse_tracked_m < 0.1 * bank.rmse_tracked_m
    assert tracker.ratio_to_bound < 0.1 * bank.ratio_to_bound
    with pytest.raises(ValueError, match="method"):
        evaluate_layout("S1-P2", passages=2, method="ekf")
