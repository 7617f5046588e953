"""The source studies' bank as a tracker: ``Tracker(scenario, method="bank")``.

The studies start many filters per passage from its first sample with a field value (the multiple-initial-value
bank, :func:`~shipsense.trackers.bank.seeding.seed_hypotheses`: moment levels times bearings) and select the
maximum-likelihood hypothesis; there is no detection window, no refit and no consistency test, and the reported
covariance is the selected hypothesis's own.  :class:`StudyBankTracker` runs the project tracker's loop
(:class:`~shipsense.trackers.tracker.tracker.Tracker`: streaming and batch forms, gaps, statuses) with that start;
the filter, its process noise and the bank come from the scenario (``[tracker]``, ``[tracker.process_noise]``,
``[tracker.bank]``).
"""

from __future__ import annotations

import numpy as np

from shipsense.trackers.bank.seeding import seed_hypotheses
from shipsense.trackers.tracker.passages import RUNNING
from shipsense.trackers.tracker.tracker import Tracker


class StudyBankTracker(Tracker, method="bank"):
    """The studies' bank over a batch of passages (see the module docstring); built by ``Tracker(...,
    method="bank")`` or from settings whose ``method`` is ``"bank"``."""

    MIXTURE = False
    TESTS_CONSISTENCY = False

    def _history(self):
        return 1                      # (no refits: the bank needs no history)

    @property
    def H(self):
        """Hypotheses of a passage's bank: the moment (or ``p``) levels times the bearings."""
        return len(self.bank_config.levels) * len(self.bank_config.bearings_deg)

    @staticmethod
    def _bank_model(model):
        return model                  # (the scenario's process noise)

    def _start_and_restart(self, starting, running, snr, yi, out, defer_fits):
        """Seed the passages ``starting`` from this sample (their first with a field value) and update their
        banks with it."""
        if starting.size == 0:
            return
        y = yi * self.model.y_scale
        seeds, P0 = seed_hypotheses(self.model, y[starting], self.bank_config)
        self.bank.reset_runs(starting, seeds, P0)
        self.bank.step(np.nan_to_num(y), mask=np.isfinite(y), predict=False, runs=starting)
        self.state.phase[starting] = RUNNING
        self.report_runs(starting, out)
