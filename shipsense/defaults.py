"""Numerical defaults shared by the settings (:mod:`shipsense.config`) and the code that runs them (the filter
units, the robust fits): one home for each, imported by both."""

HUBER_GAMMA = 1.345
"""Huber's threshold on a whitened residual (95 % efficiency under Gaussian noise; Huber, "Robust estimation of
a location parameter", Ann. Math. Statist. 35, 1964): the Huber UKF's reweighting and the robust fits' cost."""

N_PU = 5
"""Sub-updates of the progressive-update EKF, each with noise ``R N_PU`` (``N_PU = 1`` is the EKF)."""
