r"""Window fits of one and two ships: the global initialiser on residuals, then joint Levenberg-Marquardt.

The field is linear in each ship's moment given the ships' lines, so the global initialiser's separable least
squares (:func:`~shipsense.trackers.init.window_fits.window_fits`) finds one ship's line on the residual of
the others.  :func:`two_ship_fits` alternates it: ship 2 on the residual of ship 1's line, then ship 1 again
on the residual of each ship-2 candidate, and refines every pair jointly on the window with the summed model
(:func:`~shipsense.trackers.fit.least_squares.fit_passages` on the
:class:`~shipsense.trackers.ships.joint_model.JointModel`: its numpy path); the best pair is kept.
:func:`one_ship_fit` is the one-ship model's best fit of the same window, the comparison for a birth.
All states are internal units at the window's first sample; bearing channels are left out of the residual
searches (bearings do not add) but kept in the joint refinement (the nearest ship's).
"""

from __future__ import annotations

import numpy as np

from shipsense.models.transitions import shared_powers
from shipsense.trackers.fit.least_squares import fit_passages
from shipsense.trackers.init.window_fits import depth_prior, window_fits


def line(model, x0, W):
    """States (C, W, n) of constant-velocity lines from ``x0`` (C, n) over ``W`` samples."""
    return np.einsum("kij,cj->cki", shared_powers(model.A, W), x0)


def residual_fits(tracker, yw, others, keep):
    """The global initialiser's ``keep`` best fits (C, keep, n) of ``yw`` (C, W, m) minus the readings of the
    lines ``others`` (C, n) (bearings left out); ``tracker``: the one-ship :class:`~shipsense.trackers.Tracker`
    (its model without process noise, grid and settings)."""
    model, g = tracker.model, tracker.settings
    r = yw - model.h(line(model, others, yw.shape[1]))
    r[..., model.axial] = np.nan
    fits = window_fits(model, r, **tracker.grid, keep=keep, grid_samples=g.grid_samples, distinct_m=g.distinct_m,
                       z_std=g.z_std, refine=g.refine, gof=g.gof)
    return fits.theta


def one_ship_fit(tracker, yw, x1):
    """The better of the one-ship Levenberg-Marquardt fit of ``yw`` (C, W, m) from ``x1`` (C, n) and the global
    initialiser's best: states (C, n) and chi-squares (C,)."""
    model = tracker.model
    C, W, _ = yw.shape
    g = residual_fits(tracker, yw, np.zeros_like(x1), 1)[:, 0]
    starts = np.stack([x1, g], axis=1).reshape(2 * C, -1)
    starts = np.where(np.isfinite(starts), starts, 0.0)
    th, chi2 = fit_passages(model, np.repeat(yw, 2, axis=0), starts, W,
                            prior=depth_prior(model, tracker.settings.z_std))
    chi2 = np.where(np.isfinite(chi2), chi2, np.inf).reshape(C, 2)
    best = np.argmin(chi2, axis=1)
    return th.reshape(C, 2, -1)[np.arange(C), best], chi2[np.arange(C), best]


def two_ship_fits(tracker, joint, yw, x1, x2=None, keep=3):
    """The best joint fit of two ships to ``yw`` (C, W, m): states (C, 2n), chi-squares (C,) and Gauss-Newton
    information (C, 2n, 2n).

    Starts: each ship-1 start of ``x1`` (C, n) or (C, A, n) with each of the ``keep`` global fits of ship 2 on
    its residual, each of those with ship 1 found again on ship 2's residual, and ``(x1[:, 0], x2)`` when
    ``x2`` (C, n) is given (the current estimate); every start is refined jointly on the summed model ``joint``
    (:class:`~shipsense.trackers.ships.joint_model.JointModel`, without process noise)."""
    C, W, _ = yw.shape
    x1 = x1[:, None] if x1.ndim == 2 else x1
    A, n = x1.shape[1:]
    x1 = np.where(np.isfinite(x1), x1, 0.0)
    flat1 = x1.reshape(C * A, n)
    cand2 = residual_fits(tracker, np.repeat(yw, A, axis=0), flat1, keep)                    # (C A, keep, n)
    again1 = residual_fits(tracker, np.repeat(yw, A * keep, axis=0), cand2.reshape(-1, n), 1)[:, 0]
    again1 = again1.reshape(C * A, keep, n)
    pairs = [np.concatenate([np.repeat(flat1[:, None], keep, axis=1), cand2], axis=2).reshape(C, A * keep, 2 * n),
             np.concatenate([again1, cand2], axis=2).reshape(C, A * keep, 2 * n)]
    if x2 is not None:
        pairs.append(np.concatenate([x1[:, 0], x2], axis=1)[:, None])
    starts = np.concatenate(pairs, axis=1)                                                    # (C, S, 2n)
    S = starts.shape[1]
    starts = np.where(np.isfinite(starts), starts, 0.0).reshape(C * S, 2 * n)
    prior = depth_prior(tracker.model, tracker.settings.z_std)
    prior = None if prior is None else tuple(np.tile(a, 2) for a in prior)
    th, chi2, info = fit_passages(joint, np.repeat(yw, S, axis=0), starts, W, return_information=True, prior=prior)
    chi2 = np.where(np.isfinite(chi2), chi2, np.inf).reshape(C, S)
    best = np.argmin(chi2, axis=1)
    pick = np.arange(C) * S + best
    return th[pick], chi2[np.arange(C), best], info[pick]
