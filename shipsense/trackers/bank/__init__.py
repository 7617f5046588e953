"""The bank of hypotheses: many filters of one passage run side by side as one batch.

:mod:`~shipsense.trackers.bank.seeding` (the source studies' hypotheses from the first sample),
:mod:`~shipsense.trackers.bank.bank` (the hypotheses' beliefs stepped as one batch, their cumulative
log-likelihoods, pruning) and :mod:`~shipsense.trackers.bank.selection` (the maximum-likelihood hypothesis and
the mixture's mean-square error).
"""

from shipsense.trackers.bank.bank import BankRun, BankState, default_bank, run_bank
from shipsense.trackers.bank.seeding import seed_hypotheses, seed_ranges

__all__ = ["BankRun", "BankState", "default_bank", "run_bank", "seed_hypotheses", "seed_ranges"]
