r"""A tracker that counts and labels up to two ships: the one-ship tracker, births on its residual, a joint filter.

:class:`ShipsTracker` runs, over a batch of passages:

1. **Ship 1**: the project's one-ship :class:`~shipsense.trackers.Tracker` over every sample (its detection,
   global initialiser, bank and restarts, unchanged); while a passage has one ship, track 1 is its output.
2. **Births** (every ``every_s`` seconds while a passage has one ship and ship 1 is tracked): ship 1's line is
   taken back over the last ``window_s`` seconds from its current estimate (constant velocity); the project's
   global initialiser searches the residual of that one-ship model, :math:`r_k = y_k - h(\hat x_{1,k})`, for
   a second source, and every pair is refined jointly on the window with the summed model
   :math:`y = h(x_1) + h(x_2) + v` (:mod:`~shipsense.trackers.ships.window`,
   :class:`~shipsense.trackers.ships.joint_model.JointModel`).  The one-ship model's best fit of the same
   window is the comparison: with the fits' chi-squares :math:`\chi^2_S` (maximised window log-likelihoods
   :math:`\ell_S = -\chi^2_S / 2` up to a common constant) the second ship is born when

   .. math::  \ell_2 - \ell_1 > \tfrac12\, \lambda\, n_1 \ln N ,

   the BIC penalty of the second ship's :math:`n_1` state components, ``N`` the measurements in the window
   and :math:`\lambda` the ``penalty`` setting (1: BIC), and the two fitted ships are at least
   ``min_separation_m`` apart (else the "second ship" is ship 1's own model error).  The likelihoods are the
   window's batch fits (the filters' predictive likelihoods over the window, which the spec suggests, are not
   used: the fits already carry the window's evidence and need no starting covariance).
3. **Two ships**: from the birth on, the joint filter (the UKF's numpy steps on the joint model, batched over
   the passages that have two ships, with :math:`\kappa = n_1 - n` so that its sigma points spread each ship
   as the one-ship UKF does) carries both from the joint fit (its covariance: the inverse of the fit's
   information plus the passage prior's, times ``inflate``).  Every ``every_s`` seconds, while both ships'
   own fields locate them (``refit_sd_m``), the joint state is refitted on the last window (starts: the
   current ships, the one-ship tracker's estimate, and the global searches on their residuals) and the model
   order tested again: when one ship explains the window (the test of the birth fails), track 2 dies and
   track 1 is the one-ship tracker's again.  Track 1 and track 2 are the two blocks of the joint state, and a
   refit's ships are matched to the current tracks (the nearer pairing at the window's middle), so the labels
   persist.
4. **Deaths** by reach: a ship whose information contribution -- the position standard deviation
   :math:`\sqrt{\mathrm{tr}(I_s^{-1})/2}` that one sample of its own field gives, :math:`I_s = H_{s,xy}^T
   R^{-1} H_{s,xy}` at its estimate -- has stayed above ``death_sd_m`` for ``death_samples`` samples, after
   having been below it, has left the array's reach and is no longer reported (in the joint state it stays,
   its small field still predicted).  A dead track is not reborn, and a passage has at most one birth.

Seismic bearings: in the joint model each bearing channel reads the ship nearest to its node (the louder one;
the simulator's rule); they are left out of the residuals searched for a second ship.

Not done: more than two ships; a second birth after a death; a ship 2 that arrives after ship 1 has left;
manoeuvre models per ship; irregular sampling in the joint filter (it steps with the scenario's period); a
compiled joint step (the joint filter runs the numpy UKF).  Everything is causal: the output at sample ``k``
uses samples ``<= k``.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import block_diag

from shipsense.models.transitions import shared_powers
from shipsense.trackers.filters import Belief, get_filter
from shipsense.trackers.ships.joint_model import JointModel
from shipsense.trackers.ships.results import ShipsResult
from shipsense.trackers.ships.settings import ShipsSettings
from shipsense.trackers.ships.window import one_ship_fit, two_ship_fits
from shipsense.trackers.tracker.results import NO_DATA, TRACKING
from shipsense.trackers.tracker.tracker import Tracker

MAX_TRACKS = 2
"""Track slots of a result (ships tracked at once, at most)."""


class ShipsTracker:
    """Counts and labels up to two ships (see the module docstring).

    Parameters
    ----------
    scenario : Scenario or str
    passages : int
        Passages tracked side by side.
    sensors : list of str, optional
        Sensor ids to use (default: all).
    settings : ShipsSettings, optional
        The birth and death settings (default: :class:`ShipsSettings`'s).
    **options
        Options of the one-ship :class:`~shipsense.trackers.Tracker` (fields of ``[tracker]``).

    Examples
    --------
    >>> import shipsense
    >>> from shipsense.trackers.ships import ShipsTracker
    >>> sim = shipsense.simulate("S2-crossing", runs=1, seed=1)
    >>> result = ShipsTracker("S2-crossing", sensors=["M1", "M2"]).track(sim.times, sim.measurements[..., :6])
    >>> result.estimates.shape
    (1, 80, 2, 7)
    """

    def __init__(self, scenario, *, passages=1, sensors=None, settings=None, **options):
        from shipsense.models.field_model import model_from_scenario

        self.settings = ShipsSettings() if settings is None else settings
        if not isinstance(self.settings, ShipsSettings):
            raise TypeError(f"settings must be ShipsSettings, got {type(self.settings).__name__}")
        self.one = Tracker(scenario, passages=passages, sensors=sensors, **options)
        sc = self.one.scenario
        self.scenario = sc
        self.base = model_from_scenario(sc, sensors=sensors, process_noise=self.one.settings.process_noise)
        self.joint = JointModel(self.base, 2)
        self.joint_fit = JointModel(self.one.model, 2)     # (without process noise: the window fits' lines)
        self.unit = get_filter("ukf", kappa=-float(self.base.n))    # the one-ship spread (JointModel)
        T = sc.period
        self.window = max(4, int(round(self.settings.window_s / T)))
        self.every = max(1, int(round(self.settings.every_s / T)))
        self.labels = self.base.labels

    # -- the pieces ---------------------------------------------------------------------------------------------
    def reach_sd(self, x):
        """Position standard deviation (m) one sample of a ship's own field gives, of ship states ``x`` (..., n)
        SI: :math:`\\sqrt{\\mathrm{tr}(I^{-1})/2}` with :math:`I = H_{xy}^T R^{-1} H_{xy}` over the field
        channels (inf where singular)."""
        b = self.base
        H = b.H(b.to_internal(x))[..., ~b.axial, :2]                     # (..., f, 2): d(reading)/d(x, y), per m
        Hw = H / b.R[~b.axial, None]
        info = np.swapaxes(H, -1, -2) @ Hw                                # (..., 2, 2)
        det = info[..., 0, 0] * info[..., 1, 1] - info[..., 0, 1] ** 2
        tr_inv = np.where(det > 0, (info[..., 0, 0] + info[..., 1, 1]) / np.where(det > 0, det, 1.0), np.inf)
        return np.sqrt(0.5 * tr_inv)

    def _window(self, y, k):
        """The last :attr:`window` samples up to ``k`` of ``y`` (C, K, m) SI, internal units (C, W, m)."""
        return y[:, k - self.window + 1:k + 1] / self.base.y_scale

    def _back(self, x):
        """Internal states at the window's first sample of SI states ``x`` (C, n) at its last."""
        b, W = self.base, self.window
        return np.linalg.solve(shared_powers(b.A, W)[W - 1], b.to_internal(x).T).T

    def _at_end(self, th, info):
        """A joint fit (C, 2n), information (C, 2n, 2n) at the window's first sample as the joint filter's state
        and covariance at its last (SI): propagated, the covariance the inverse of the information plus the
        passage prior's on each ship, times ``inflate``."""
        W = self.window
        A = shared_powers(self.base.A, W)[W - 1]
        F = block_diag(A, A)
        cov = np.linalg.inv(info + np.kron(np.eye(2), self.one.prior_info))
        scale = self.joint.x_scale
        return (th @ F.T) * scale, self.settings.inflate * (F @ cov @ F.T) * np.outer(scale, scale)

    def _labelled(self, th, ref1, ref2=None):
        """Joint fits ``th`` (C, 2n) with the two ships' blocks swapped where that puts them nearer (at the
        window's middle) to the tracks ``ref1`` and ``ref2`` (C, n) internal, at the window's first sample:
        labels persist through refits.  Returns the labelled fits (C, 2n) and the distance (C,) between their
        two ships at the window's middle, m (the same positions give both)."""
        n, W = self.base.n, self.window
        mid = shared_powers(self.base.A, W)[W // 2][:2]
        p1, p2, r1 = th[:, :n] @ mid.T, th[:, n:] @ mid.T, ref1 @ mid.T
        same, swap = np.sum((p1 - r1) ** 2, axis=1), np.sum((p2 - r1) ** 2, axis=1)
        if ref2 is not None:
            r2 = ref2 @ mid.T
            same, swap = same + np.sum((p2 - r2) ** 2, axis=1), swap + np.sum((p1 - r2) ** 2, axis=1)
        flip = swap < same
        labelled = np.where(flip[:, None], np.concatenate([th[:, n:], th[:, :n]], axis=1), th)
        return labelled, np.hypot(*(p1 - p2).T)

    def birth_test(self, y, x1, k):
        """The birth test of passages with ship 1 at ``x1`` (C, n) SI at sample ``k``, on their measurements
        ``y`` (C, K, m) SI (see the module docstring).  Returns ``(born, mean, cov, gain, penalty)``: born (C,)
        bool, the joint fit's state (C, 2n) and covariance (C, 2n, 2n) SI at ``k``, the log-likelihood gain
        :math:`\\ell_2 - \\ell_1` (C,) and the penalty (C,)."""
        o = self.settings
        yw = self._window(y, k)
        x1 = self._back(x1)
        _, chi2_1 = one_ship_fit(self.one, yw, x1)
        th, chi2_2, info = two_ship_fits(self.one, self.joint_fit, yw, x1)
        th, separation = self._labelled(th, x1)
        gain = 0.5 * (chi2_1 - chi2_2)
        penalty = self._penalty(yw)
        apart = separation >= o.min_separation_m
        mean, cov = self._at_end(th, info)
        ok = np.isfinite(gain) & np.isfinite(mean).all(axis=1) & np.isfinite(cov).all(axis=(1, 2))
        return ok & apart & (gain > penalty), mean, cov, gain, penalty

    def refit(self, y, mean, k, x1_alone=None):
        """Joint refits of passages with two ships at ``mean`` (C, 2n) SI at sample ``k``, on the last window of
        their measurements ``y`` (C, K, m) SI, labels kept, and the model order tested again.  Returns
        ``(keep, mean, cov)``: whether two ships still beat one (the birth test's penalty and separation), the
        state (C, 2n) and covariance (C, 2n, 2n) SI at ``k``.  ``x1_alone`` (C, n) SI, optional: the one-ship
        tracker's estimate at ``k``, tried as a ship-1 start too (as are both current ships)."""
        o, n = self.settings, self.base.n
        yw = self._window(y, k)
        x1, x2 = self._back(mean[:, :n]), self._back(mean[:, n:])
        starts = [x1, x2] + ([] if x1_alone is None else [self._back(x1_alone)])
        th, chi2_2, info = two_ship_fits(self.one, self.joint_fit, yw, np.stack(starts, axis=1), x2)
        th, separation = self._labelled(th, x1, x2)
        _, chi2_1 = one_ship_fit(self.one, yw, x1)
        keep = (0.5 * (chi2_1 - chi2_2) > self._penalty(yw)) & (separation >= o.min_separation_m)
        return keep, *self._at_end(th, info)

    def _penalty(self, yw):
        r"""The model-order penalty (C,) of windows ``yw`` (C, W, m): ``penalty`` times BIC's
        :math:`\tfrac12 n \ln N`, ``n`` one ship's state size, ``N`` the window's measurements."""
        return self.settings.penalty * 0.5 * self.base.n * np.log(np.maximum(np.isfinite(yw).sum(axis=(1, 2)), 2))

    # -- a batch ------------------------------------------------------------------------------------------------
    def track(self, times, measurements, progress=False) -> ShipsResult:
        """Track a batch: ``times`` (K,) or (P, K) s, ``measurements`` (P, K, m) SI (NaN = missing)."""
        y = np.asarray(measurements, dtype=float)
        if y.ndim != 3 or y.shape[2] != self.base.m:
            raise ValueError(f"measurements must be (passages, samples, {self.base.m}), got {y.shape}")
        P, K, _ = y.shape
        times = np.broadcast_to(np.asarray(times, dtype=float), (P, K))
        first = self.one.track(times, y, progress=progress)
        o, b, n, I = self.settings, self.base, self.base.n, MAX_TRACKS
        est = np.full((P, K, I, n), np.nan)
        cov = np.full((P, K, I, n, n), np.nan)
        status = np.full((P, K, I), NO_DATA, dtype=np.int8)
        born, died = np.full((P, I), -1), np.full((P, I), -1)
        two = np.zeros(P, dtype=bool)                  # passages with the joint filter running
        mean = np.zeros((P, 2 * n))                    # its belief (internal units)
        jcov = np.tile(np.eye(2 * n), (P, 1, 1))
        seen = np.zeros((P, I), dtype=bool)            # within reach at some sample
        out = np.zeros((P, I), dtype=int)              # consecutive samples out of reach
        dead = np.zeros((P, I), dtype=bool)
        tracked_since = np.full(P, -1)
        yi = y / b.y_scale
        for k in range(K):
            st = first.status[:, k]
            tracked_since = np.where(st >= TRACKING, np.where(tracked_since < 0, k, tracked_since), -1)
            run = np.flatnonzero(two & (born[:, 1] < k))
            if run.size:
                belief = Belief.from_cov(mean[run], jcov[run])
                belief, _ = self.unit.step(belief, yi[run, k], self.joint)
                mean[run], jcov[run] = belief.mean, belief.cov
            due = k % self.every == 0 and k >= self.window
            again = np.flatnonzero(two & (born[:, 1] < k)) if due else run[:0]
            if again.size:                              # (while both ships' own fields locate them)
                sd = self.reach_sd(self.joint.split(mean[again]) * b.x_scale)
                again = again[np.all(sd <= o.refit_sd_m, axis=1)]
            if again.size:                              # joint refits of the recent window (labels kept)
                still, m2, c2 = self.refit(y[again], self.joint.to_si(mean[again]), k, first.estimates[again, k])
                fine = np.isfinite(m2).all(axis=1)
                mean[again[fine]] = self.joint.to_internal(m2[fine])
                jcov[again[fine]] = self.joint.cov_to_internal(c2[fine])
                merged = again[~still & ~dead[again, 1]]  # one ship explains the window: track 2 dies
                died[merged, 1], dead[merged, 1], two[merged] = k, True, False
            one_ship = ~two                             # (after the refits: a track 2 that died leaves one)
            s1 = one_ship & (st >= TRACKING)
            est[s1, k, 0], cov[s1, k, 0], status[s1, k, 0] = first.estimates[s1, k], first.covs[s1, k], st[s1]
            if o.max_ships > 1 and due:
                cand = np.flatnonzero(one_ship & (tracked_since >= 0)
                                      & ~dead[:, 0] & (born[:, 1] < 0))
                if cand.size:
                    ok, m2, c2, _, _ = self.birth_test(y[cand], first.estimates[cand, k], k)
                    new = cand[ok]
                    if new.size:
                        mean[new] = self.joint.to_internal(m2[ok])
                        jcov[new] = self.joint.cov_to_internal(c2[ok])
                        two[new], born[new, 1] = True, k
            live = np.flatnonzero(two)
            if live.size:
                xs = self.joint.split(mean[live]) * b.x_scale
                cs = self.joint.cov_to_si(jcov[live])
                for s in range(I):
                    est[live, k, s] = xs[:, s]
                    cov[live, k, s] = cs[:, s * n:(s + 1) * n, s * n:(s + 1) * n]
                    status[live, k, s] = TRACKING
            # deaths: a ship whose own field no longer locates it (after it did) has left the array's reach
            has = np.isfinite(est[:, k, :, 0]) & ~dead
            sd = np.full((P, I), np.inf)
            if has.any():
                sd[has] = self.reach_sd(est[:, k][has])
            inside = has & (sd <= o.death_sd_m)
            seen |= inside
            out = np.where(has & ~inside, out + 1, 0)
            gone = seen & (out >= o.death_samples) & ~dead
            died[gone] = k
            dead |= gone
            est[:, k][dead], cov[:, k][dead], status[:, k][dead] = np.nan, np.nan, NO_DATA
        born[:, 0] = np.where(np.isfinite(est[:, :, 0, 0]).any(axis=1), np.argmax(np.isfinite(est[:, :, 0, 0]), axis=1),
                              -1)
        return ShipsResult(tuple(self.labels), np.array(times), est, cov, status, born, died)
