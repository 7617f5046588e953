"""The project's passage tracker: one public tracker behind ``shipsense track``, ``demo``, the environments and
the Python API.

:class:`Tracker` is built from a scenario and runs, for every passage of a
batch, the pipeline of this package one sample at a time:

1. **no data** until the passage's first sample with a field value;
2. **initialising**: detection (the strongest field channel above
   ``snr_start`` noise standard deviations), then a window of ``window_s``
   seconds (or less, once the signal has passed its peak: a late detection
   still gets a fit across the closest approach), then the global
   initialiser's fits of that window
   (:func:`~shipsense.trackers.init.window_fits.window_fits`: grid search with the
   moment eliminated, Levenberg-Marquardt refinement, a chi-square test).
   Before the window is complete the initialiser already tries the samples
   since the detection, every ``window // 15`` samples from the fourth
   (:func:`~shipsense.trackers.tracker.bank_starts.early_attempt`), and starts
   the bank from such an early fit once it passes its test, locates the ship
   within 10 m (one standard deviation) and explains the samples better than
   the passage mirrored across the array by ``2 ambiguity_nats``
   (:func:`~shipsense.trackers.tracker.bank_starts.accepted`): the tracker
   starts about when the data locate the ship rather than a whole window
   later (``experiments/first_track.py``).  Until then the reported belief is
   the prior's (the array centroid with the passage prior's spread: honest,
   not informative); a bank starts from a fit's information plus that
   prior's, so never wider than the prior;
3. **tracking**: a bank of the distinct fits (filter unit ``ukf``, or the
   Huber UKF when ``robust``), without process noise -- the passages are
   straight and constant-velocity -- restarted from batch refits of its
   recent samples (:func:`~shipsense.trackers.tracker.restarts.refit_window`): every
   ``refit_every`` samples until the closest approach, once when the signal
   has fallen to ``through_peak`` of its peak, when the selection becomes
   ambiguous (a near tie between hypotheses far apart has just arisen: the
   filters' running likelihoods can drift near the closest approach, a refit
   weighs the hypotheses by their fits to every sample), when the selected hypothesis's
   innovations say it has diverged, when its covariance collapses (see
   :mod:`~shipsense.trackers.tracker.restarts`), and when the windowed innovation
   consistency test fails (:mod:`~shipsense.trackers.tracker.consistency`: the
   innovations of the last ``consistency_window`` samples have a mean the
   filter's covariance does not allow, at level ``consistency_level``; that
   sample is **inconsistent**, with the refit's covariance).  At a refit the status is
   **restarted**; a fit that fails its goodness-of-fit test makes the status
   **inconsistent** and its covariance is inflated by the ratio of its
   chi-square to the expected (never NaN), and it is re-fitted every
   ``nis_window`` samples until one passes; while a passage is inconsistent
   its reported covariance also holds the passage prior's spread (the model
   does not explain its data, so its estimate may be anywhere the prior
   allows).  A refit after an alarm (divergence
   or a failed fit) also starts from the global initialiser's fits of every
   sample since the detection, so it can leave a wrong track that a local
   refit would stay near (``experiments/tracker_consistency.py`` measures it
   with outliers; docs: Results).
   With ``rescan`` (one magnetometer's default) the global initialiser also
   runs every ``refit_every`` samples until the closest approach, counted
   from the last such rescan rather than from the last restart (the collapse
   alarm restarts one magnetometer's bank every few samples early in a
   passage): far out, one magnetometer's samples fit a wrong track hundreds
   of metres off as well as the true one, and refits started from the bank's
   hypotheses stayed on it after the data had told the two apart
   (docs: Results).

The reported estimate is the maximum-likelihood hypothesis, the reported
covariance its mean-square-error matrix under the mixture of the bank's
hypotheses (when a passage 20 m away explains the data almost as well, the
covariance says so).  Everything is causal: the output at sample ``k`` uses
samples ``<= k`` only.  Time comes from the timestamps (irregular sampling
works: each prediction and each fit uses the samples' times); a gap longer
than ``gap_limit_s`` is predicted through and reported once.  A refit uses
at most the last ``history`` samples, so the cost per sample is bounded.

``method="bank"`` gives the source studies' multiple-initial-value bank
instead (:class:`~shipsense.trackers.tracker.study_bank.StudyBankTracker`: the scenario's filter, process noise
and ``[tracker.bank]``, seeded per passage from its own first sample with a field value), kept to reproduce
the studies; it runs this class's loop with its own start, no restarts and no consistency test.

The streaming form, :meth:`Tracker.update`, takes one sample of every passage;
the batch form, :meth:`Tracker.track`, is the same loop over samples, so the
two agree exactly.
"""

from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np

from shipsense.models.measurement import FIELD, kernel_of
from shipsense.trackers.bank.bank import BankState
from shipsense.trackers.bank.selection import report
from shipsense.trackers.filters.core import UNROLL_MIN_BATCH, Belief
from shipsense.trackers.tracker import bank_starts
from shipsense.trackers.tracker.consistency import quantile_table, window_test
from shipsense.trackers.tracker.passages import (
    PENDING,
    PHASES,
    RUNNING,
    PassageArrays,
    passage_states,
    set_passage_states,
)
from shipsense.trackers.tracker.results import (
    INCONSISTENT,
    INITIALISING,
    MANOEUVRING,
    NO_DATA,
    TRACKING,
    Gap,
    Sample,
    TrackResult,
)
from shipsense.trackers.tracker.settings import TrackerSettings, initial_grid, prior_belief, resolve_settings
from shipsense.trackers.tracker.step import TrackerStep, prepare_sample


class Tracker:
    """The project's passage tracker (see the module docstring), built from a scenario.

    Parameters
    ----------
    scenario : Scenario or str
        The array, medium, noise, passage prior and ``[tracker]`` options.
    passages : int
        Passages tracked side by side (the batch).
    sensors : list of str, optional
        The sensor ids to use (default: all).
    settings : TrackerSettings, optional
        Resolved settings (:func:`~shipsense.trackers.tracker.settings.resolve_settings`); by default resolved
        here from the scenario and ``options``.
    **options
        Fields of :class:`~shipsense.config.TrackerConfig` that override the scenario's ``[tracker]`` table.

    Examples
    --------
    >>> import shipsense
    >>> from shipsense.trackers import Tracker
    >>> sim = shipsense.simulate("S2", runs=2, seed=1, random=True)
    >>> result = Tracker("S2", passages=2, sensors=["M1", "M2"]).track(sim.times, sim.measurements[..., :6])
    >>> result.estimates.shape, result.covs.shape, result.status.shape
    ((2, 80, 7), (2, 80, 7, 7), (2, 80))
    """

    MIXTURE = True
    """The reported covariance is the mixture's mean-square error about the selected estimate (the studies'
    bank: the selected hypothesis's own)."""

    def __new__(cls, scenario=None, *, settings=None, **options):
        # ``Tracker(..., method="bank")`` (or a scenario or settings that say so) is the studies' variant
        # (:data:`VARIANTS`), as ``pathlib.Path`` is its system's path; a scenario read here to tell is kept for
        # __init__ (read once)
        loaded = None
        if cls is Tracker and scenario is not None:
            method = settings.method if settings is not None else options.get("method")
            if method is None:
                from shipsense.config import load_scenario

                loaded = load_scenario(scenario)
                method = loaded.tracker.method if loaded.tracker is not None else "tracker"
            if method != "tracker":
                cls = Tracker.VARIANTS[method]
        tracker = super().__new__(cls)
        tracker._loaded = (scenario, loaded)
        return tracker

    VARIANTS: dict = {}
    """Tracker classes by ``method`` other than ``"tracker"``: a variant registers itself by its class statement,
    ``class StudyBankTracker(Tracker, method="bank")``."""

    def __init_subclass__(cls, method=None, **kwargs):
        super().__init_subclass__(**kwargs)
        if method is not None:
            Tracker.VARIANTS[method] = cls

    def __init__(self, scenario, *, passages=1, sensors=None, settings=None, **options):
        from shipsense.config import load_scenario
        from shipsense.models.field_model import model_from_scenario

        given, loaded = self.__dict__.pop("_loaded", (None, None))
        self.scenario = sc = loaded if loaded is not None and given is scenario else load_scenario(scenario)
        if settings is None:
            settings = resolve_settings(sc, sensors, **options)
        elif options:
            raise TypeError(f"give settings or options, not both (got {', '.join(options)})")
        elif not isinstance(settings, TrackerSettings):
            raise TypeError(f"settings must be TrackerSettings (resolve_settings), got {type(settings).__name__}")
        self.settings = opts = settings
        model = model_from_scenario(sc, sensors=sensors, process_noise=opts.process_noise)
        self.bank_config = opts.bank
        self.unit = opts.filter_unit()
        # the project's tracker: a bank without process noise (the passages are straight); the studies' bank
        # keeps the scenario's
        self.model = self._bank_model(model)
        self.huber = opts.huber(sc.noise)
        # the bank's noise: with Huber updates the estimate's variance is kappa times the nominal one
        kappa = self.huber.variance_factor if self.huber is not None else 1.0
        self.filter_model = replace(self.model, R=self.model.R * kappa)
        self.kappa = kappa
        self.window = max(4, int(round(opts.window_s / sc.period)))
        self._snr_field = np.ascontiguousarray(~self.model.axial)                  # (update's SNR: strongest_snr)
        self._snr_std = np.ascontiguousarray(np.sqrt(self.model.R), dtype=float)
        self.grid = initial_grid(sc)                       # (the window fits' grid: bank_starts)
        self._prior = prior_belief(self.model, sc, self.bank_config)
        self.prior_info = np.diag(self.model.x_scale ** 2 / np.diag(self._prior[1]))   # internal units
        # the motion modes of an IMM (None: constant velocity alone, and the compiled step of the bank)
        self.modes = opts.motion_modes(self.filter_model)
        self._compiled = TrackerStep.of(self.unit, self.filter_model, self.H) if self.modes is None else None
        spec = kernel_of(self.model)
        self.pads_exactly = self.huber is None and spec is not None and spec[0] == FIELD   # (bank_starts.refit)
        self._R_used = np.ascontiguousarray(self.filter_model.R[None], dtype=float)
        self._testing = bool(opts.consistency_window) and self.TESTS_CONSISTENCY
        self.layout = PassageArrays.layout(self.model.m, self.model.n, self.settings, self._history())
        self.reset(passages)

    labels = property(lambda self: self.model.labels, doc="State component names.")

    # -- state ------------------------------------------------------------------------------------------------
    def reset(self, passages=None):
        """Start over with ``passages`` passages (default: as many as before)."""
        P = int(passages if passages is not None else self.P)
        if P < 1:
            raise ValueError(f"passages must be at least 1, got {passages}")
        n, H = self.model.n, self.H
        self.P = P
        self.state = PassageArrays.fresh(P, self.layout)
        self.gaps = []
        self.seconds = {"initialiser": 0.0, "refits": 0.0}   # time spent in window fits and in refits
        self._blank = None                                    # the prior Sample of P passages (prior_sample)
        self.bank = BankState(self.unit, self.filter_model, np.broadcast_to(self._prior[0], (P, H, n)),
                              self._prior[1], modes=self.modes)
        return self

    @property
    def mode_names(self):
        """The motion modes' names (:data:`~shipsense.models.motion_modes.MODES`), () without them."""
        return () if self.modes is None else tuple(self.modes.names)

    def reset_passages(self, passages):
        """Start passages ``passages`` (indices) over, leaving the others as they are."""
        idx = np.asarray(passages, dtype=int)
        self.state.reset(idx, self.layout)
        H, n = self.H, self.model.n
        self.bank.reset_runs(idx, np.broadcast_to(self._prior[0], (idx.size, H, n)), self._prior[1])
        return self

    def sibling(self, passages):
        """A tracker of this one's model and options over ``passages`` passages of its own, sharing this one's
        compiled kernels and caches: passages run side by side there and are carried on here
        (:meth:`passage_states`, :meth:`set_passage_states`), e.g. the run-ins of an environment's next
        passages in one batch."""
        return copy.copy(self).reset(passages)

    @property
    def independent_batch(self):
        """The most passages whose banks may start in one call with the numbers each would have alone: a
        bank's start factorises its hypotheses' covariances (``safe_cholesky``), which from 512 matrices on
        takes an unrolled form equal to LAPACK's only to rounding (e.g. run-ins side by side,
        :meth:`sibling`)."""
        return max(1, (UNROLL_MIN_BATCH - 1) // self.H)

    def passage_states(self, passages):
        """The :class:`PassageState` of each of ``passages`` (indices): copies, for :meth:`set_passage_states`
        of this tracker or a sibling (:meth:`sibling`)."""
        return passage_states(self, passages)

    def set_passage_states(self, passages, states):
        """Carry on ``states`` (:meth:`passage_states` of this tracker or a sibling) as passages ``passages``
        (indices, distinct): everything of theirs is replaced, as if they had run here (their gaps in
        ``gaps`` too)."""
        set_passage_states(self, passages, states)
        return self

    # -- what the studies' variant changes (StudyBankTracker) ----------------------------------------------------
    TESTS_CONSISTENCY = True
    """Whether the windowed innovation consistency test runs (with ``consistency_window``)."""

    def _history(self):
        """Samples of history a passage keeps (its refits' window)."""
        return self.settings.history

    @property
    def H(self):
        """Hypotheses of a passage's bank."""
        return self.settings.keep_init

    @staticmethod
    def _bank_model(model):
        """The bank's model: without process noise (the passages are straight; the refits restart it)."""
        return model.without_process_noise()

    def _start_and_restart(self, starting, running, snr, yi, out, defer_fits):
        """After the step: detection and window fits of the passages ``starting``, restarts of those
        ``running`` that are due."""
        bank_starts.initialise(self, starting, snr, out, defer_fits)
        if running.size:
            bank_starts.restart(self, running, snr, out)

    # -- one sample ---------------------------------------------------------------------------------------------
    def update(self, t, y, passages=None, defer_fits=False) -> Sample:
        """Process one sample: times ``t`` (P,) s and measurements ``y`` (P, m) SI of every passage (NaN =
        missing: a dropout, or a sensor not read), or of the passages ``passages`` (distinct indices) only, the
        others left as they are.  Returns the :class:`Sample` of those passages at this time.

        With ``defer_fits``, a passage whose initialisation window completes at this sample is not fitted
        yet: it is left pending (:meth:`pending`, still initialising here) and takes no further samples
        until :meth:`fit_pending` fits every pending passage in one batch, as this call would have."""
        act = np.arange(self.P) if passages is None else np.asarray(passages, dtype=np.int64)
        if act.ndim != 1:
            raise ValueError(f"passages must be a sequence of passage indices, got an array of shape {act.shape}")
        t = np.asarray(t, dtype=float)
        if t.shape != act.shape:
            t = np.broadcast_to(t, act.shape)
        y = np.asarray(y, dtype=float)
        if y.shape != (act.size, self.model.m):
            raise ValueError(f"y must be (passages, channels) = ({act.size}, {self.model.m}), got {y.shape}")
        s = self.state
        code, i, yi, dt, snr, starting, running, gap = prepare_sample(
            act, np.ascontiguousarray(t), np.ascontiguousarray(y), self.model.y_scale, s.phase, s.last_t, s.n,
            s.y_hist, s.t_hist, s.cons_now, self._snr_field, self._snr_std, float(self.settings.gap_limit_s), PHASES)
        if code == 4:
            raise IndexError(f"index {int(act[i])} is out of bounds for {self.P} passages")
        if code == 5:
            raise ValueError(f"passage {int(act[i])} is given twice: one sample per passage")
        if code == 1:
            raise ValueError(f"passage {int(act[i])} has its window fits deferred: call fit_pending() before "
                             f"giving it another sample")
        if code == 2:
            raise ValueError("times must be finite numbers")
        if code == 3:
            p = int(act[i])
            raise ValueError(f"time must increase: passage {p} goes from {self.state.last_t[p]:.9g} s to {t[i]:.9g} s")
        if gap:
            step = dt[act]
            for p in act[step > self.settings.gap_limit_s]:
                self.gaps.append(Gap(int(p), float(self.state.last_t[p]), float(t[act == p][0])))
        if self.settings.robust:
            snr = bank_starts.robust_snr(self.state, snr, yi, act)
        out = self.prior_sample()
        out.status[starting] = INITIALISING
        if running.size:
            self._step(running, yi, dt, out)
        self._start_and_restart(starting, running, snr, yi, out, defer_fits)
        if self.modes is not None:            # the selected hypotheses' modes, after any (re)start
            live = act[self.state.phase[act] == RUNNING]
            out.modes[live] = self.bank.modal.prob[live * self.H + np.argmax(self.bank.cum[live], axis=1)]
        self.widen_inconsistent(act, out)
        self.state.last_t[act] = t
        self.state.n[act] += 1
        if passages is None or (act.size == self.P and (act[0] == 0 if self.P == 1 else
                                                        np.array_equal(act, np.arange(self.P)))):
            return out                                              # (a fresh Sample: no copy needed)
        return out.take(act)

    def widen_inconsistent(self, act, out):
        """A failed fit or a diverged bank among passages ``act``: the model does not explain the data, so the
        estimate is located no better than the passage prior says (its spread is added to ``out.cov``: an
        inconsistent track's own covariance was centimetres to metres while it was 20-150 m off,
        docs: Results); not a failed consistency test whose refit passed its own (that sample has the
        refit's covariance)."""
        bad = act[(out.status[act] == INCONSISTENT) & ~self.state.cons_now[act]]
        if bad.size:
            out.cov[bad] += self._prior[1]

    def track(self, times, measurements, progress=False) -> TrackResult:
        """Track a batch: ``times`` (K,) or (P, K) s, ``measurements`` (P, K, m) SI (NaN = missing).

        The tracker is reset to the batch; the result is what :meth:`update` gives sample by sample.
        """
        y = np.asarray(measurements, dtype=float)
        if y.ndim != 3 or y.shape[2] != self.model.m:
            raise ValueError(f"measurements must be (passages, samples, {self.model.m}), got {y.shape}")
        P, K, _ = y.shape
        times = np.broadcast_to(np.asarray(times, dtype=float), (P, K))
        self.reset(P)
        n = self.model.n
        est, cov = np.empty((P, K, n)), np.empty((P, K, n, n))
        status, gap_nats = np.empty((P, K), dtype=np.int8), np.empty((P, K))
        amb, hyps = np.empty((P, K), dtype=bool), np.empty((P, K), dtype=np.int16)
        steps = range(K)
        if progress:
            from tqdm import tqdm

            steps = tqdm(steps, desc=f"tracking {P} passage(s)", unit="sample", leave=False, disable=None)
        modes = np.empty((P, K, len(self.mode_names)))
        for k in steps:
            s = self.update(times[:, k], y[:, k])
            est[:, k], cov[:, k], status[:, k] = s.estimate, s.cov, s.status
            gap_nats[:, k], amb[:, k], hyps[:, k], modes[:, k] = s.gap_nats, s.ambiguous, s.hypotheses, s.modes
        return TrackResult(tuple(self.labels), np.array(times), est, cov, status, gap_nats, amb, hyps,
                           list(self.gaps), modes, self.mode_names)

    # -- parts --------------------------------------------------------------------------------------------------
    def prior_sample(self):
        """A fresh :class:`Sample` of every passage at the prior (copies of one kept until the next reset)."""
        P = self.P
        if self._blank is None:
            mean, cov = self._prior
            self._blank = Sample(np.repeat(mean[None], P, axis=0), np.repeat(cov[None], P, axis=0),
                                 np.full(P, NO_DATA, dtype=np.int8), np.full(P, np.inf), np.zeros(P, dtype=bool),
                                 np.zeros(P, dtype=np.int16), np.full(P, -1, dtype=np.int16),
                                 np.full((P, len(self.mode_names)), np.nan))
        b = self._blank
        return Sample(b.estimate.copy(), b.cov.copy(), b.status.copy(), b.gap_nats.copy(), b.ambiguous.copy(),
                      b.hypotheses.copy(), b.selected.copy(), b.modes.copy())

    def _step(self, runs, yi, dt, out):
        """Predict (time steps ``dt``) and update the banks of passages ``runs``; write their output (one
        compiled call where the model has a compiled step, :mod:`~shipsense.trackers.tracker.step`: the same
        numbers)."""
        H = self.H
        d, T = dt[runs], self.model.period
        regular = all(abs(step - T) <= 1e-9 * T for step in d.tolist())
        model = None if regular else self.filter_model.stepped(np.repeat(d, H))
        if self._compiled is not None:
            runs = self._compiled_step(runs, yi, out, model)          # (those it did not step)
            if runs.size == 0:
                return
            if model is not None:
                model = self.filter_model.stepped(np.repeat(dt[runs], H))
        ysi = yi * self.model.y_scale
        inn = self.bank.step(ysi, predict=True, runs=runs, model=model)
        sel = np.argmax(self.bank.cum[runs], axis=1)              # (the bank's selected(), of these runs)
        pick = np.arange(runs.size) * H + sel                     # the selected hypotheses' rows of inn
        m_sel = inn.m.reshape(-1)[pick]
        self.state.nis[runs, :-1] = self.state.nis[runs, 1:]                  # the window moves on by one sample
        self.state.nis[runs, -1] = np.where(m_sel > 0, inn.nis.reshape(-1)[pick] / np.maximum(m_sel, 1), np.nan)
        failed = self._consistency(runs, yi, inn, sel) if self._testing else runs[:0]
        self.report_runs(runs, out)
        out.status[failed] = INCONSISTENT
        if self.modes is not None:
            self._manoeuvres(runs, sel, out)

    def _manoeuvres(self, runs, sel, out):
        """The motion modes' probabilities of the selected hypotheses ``sel`` of passages ``runs`` into ``out``;
        a passage whose manoeuvre modes hold more than ``[tracker.motion] threshold`` is ``manoeuvring`` (unless
        inconsistent), and, if its bank's fit passed, its later refits start after this sample (the samples of a
        manoeuvre lie about the line after it; a bank whose fit failed explains its misfit by the manoeuvre modes,
        which says nothing of when a manoeuvre ended: :func:`~shipsense.trackers.tracker.bank_starts.settled`)."""
        prob = self.bank.modal.prob[runs * self.H + sel]
        man = runs[1.0 - prob[:, 0] > self.settings.motion.threshold]
        man_trusted = man[self.state.trusted[man]]
        self.state.since[man_trusted] = self.state.n[man_trusted]
        out.status[man] = np.where(out.status[man] == INCONSISTENT, INCONSISTENT, MANOEUVRING)

    def _compiled_step(self, runs, yi, out, stepped=None):
        """:meth:`_step` of passages ``runs`` in compiled calls (``stepped``: the filter model with their
        transitions, irregular sampling); returns the passages it did not step (an element's update failed:
        nothing of theirs written)."""
        o, h, s = self.settings, self.huber, self.state
        runs = np.asarray(runs, dtype=np.int64)
        # the fields of the step's bundles step.PassageRows, Consistency and Selection, in their order
        passages = (s.nis, s.trusted, out.status, TRACKING, INCONSISTENT)
        consistency = (self._testing, self._R_used, self.model.R,
                       *((float(h.gamma), float(h.eps), float(h.scale)) if h is not None else (np.inf, 0.0, 1.0)),
                       quantile_table(o.consistency_level, self.model.m), s.cons, s.cons_n, s.cons_tests, s.cons_fails,
                       s.cons_now)
        selection = (self.model.x_scale, self.MIXTURE, float(o.report_nats), float(o.report_distance_m),
                     s.excess, out.estimate, out.cov, s.own, out.gap_nats, out.ambiguous, out.hypotheses, out.selected)
        left = self._compiled(runs, yi, self.model.y_scale, self.bank, passages, consistency, selection, stepped)
        if left.size < runs.size:
            self.bank.belief = Belief(*self.bank.belief)   # (as BankState.step leaves it)
        if left.size == 0:
            self.bank.steps += 1                           # (else the step by step path counts the sample)
        return left

    def _consistency(self, runs, yi, inn, sel):
        """The windowed innovation test (:mod:`~shipsense.trackers.tracker.consistency`) of passages ``runs`` with the
        innovations ``inn`` of this sample (selected hypotheses ``sel``).  Returns the passages it failed on
        (their window starts over; :func:`~shipsense.trackers.tracker.bank_starts.restart` refits them)."""
        h = self.huber
        R_used = self.filter_model.R[None] if inn.R is None else inn.R
        failed = np.empty(runs.size, dtype=bool)
        window_test(np.asarray(runs, dtype=np.int64), np.asarray(sel, dtype=np.int64), self.H, inn.eps, inn.S,
                    np.asarray(R_used, dtype=float), self.model.R, np.isfinite(yi[runs]),
                    *((float(h.gamma), float(h.eps), float(h.scale)) if h is not None else (np.inf, 0.0, 1.0)),
                    quantile_table(self.settings.consistency_level, self.model.m), self.state.cons, self.state.cons_n,
                    self.state.cons_tests, self.state.cons_fails, self.state.cons_now, failed)
        return runs[failed]

    def report_runs(self, runs, out):
        """Selected estimate, its mixture mean-square error (:attr:`MIXTURE`) or own covariance, and the
        selection figures of passages ``runs`` (:func:`~shipsense.trackers.bank.selection.report`)."""
        o, belief = self.settings, self.bank.belief
        report(belief.mean, belief.chol, np.asarray(runs, dtype=np.int64), self.H, self.model.x_scale,
               self.bank.cum[runs], self.MIXTURE, float(o.report_nats), float(o.report_distance_m),
               self.state.excess, out.estimate, out.cov, self.state.own, out.gap_nats, out.ambiguous, out.hypotheses,
               out.selected)
        out.status[runs] = np.where(self.state.trusted[runs], TRACKING, INCONSISTENT)

    def pending(self, passages=None):
        """Whether the passages (indices; default all) have window fits deferred by ``update(...,
        defer_fits=True)``."""
        return self.state.phase[slice(None) if passages is None else np.asarray(passages, dtype=int)] == PENDING

    def fit_pending(self):
        """Fit the deferred windows of every pending passage in one batch (a passage's fits do not depend on
        the passages beside it in a batch) and start their banks as :meth:`update` would have at the sample
        their windows completed.  Returns the passages (indices) and their :class:`Sample` at that sample."""
        return bank_starts.fit_pending(self)
