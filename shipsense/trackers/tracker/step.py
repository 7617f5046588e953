"""The tracker's handling of a sample as two compiled calls: the sample's preparation (:func:`prepare_sample`:
the checks, the histories, the SNR, the passages' phases) and the step of its running passages.

:meth:`Tracker._step <shipsense.trackers.tracker.tracker.Tracker._step>` predicts and updates the banks of the
running passages (:meth:`BankState.step <shipsense.trackers.bank.bank.BankState.step>`: the filter's compiled
predict and update, :func:`~shipsense.trackers.filters.fused.predict` and
:func:`~shipsense.trackers.filters.fused.update`), moves their NIS windows, runs the
windowed innovation test (:func:`~shipsense.trackers.tracker.consistency.window_test`) and writes their output
(:func:`~shipsense.trackers.bank.selection.report`).  Each of those is compiled already; between them, about
thirty numpy calls a sample cost more than the arithmetic for one passage.  :class:`TrackerStep` is the
same sequence in one call, with the same kernels in the same order, so the numbers are the same bit for
bit (tests/trackers/tracker/test_step.py; tracked passages compared with the step by step path), with
the bank's own transition or, for irregular sampling, one per passage (the model's ``stepped``).

A repeat that fills a bank (a cumulative log-likelihood of -inf: fewer distinct fits than hypotheses) is
neither predicted nor updated while its passage has another hypothesis: it stays -inf until the bank
restarts and nothing reported reads it, so its mean and factor are kept as they are (the step by step path
steps it; the outputs are the same).  The passages are stepped in chunks of about :data:`THREAD_ROWS` rows,
shared among the CPUs (a passage's numbers do not depend on its chunk); a chunk in which an element fails
writes nothing, and its passages take the step by step path.

Which form is which.  For a model with a compiled measurement kernel, :class:`TrackerStep` is the tracker's
step, for every filter unit (the SR-CDKF with its square-root time update) and for regular or irregular
sampling; the step by step path (:meth:`Tracker._step <shipsense.trackers.tracker.tracker.Tracker._step>`
composing the bank's compiled filter steps, the window test and the report) is the generic path, for a model
without a compiled kernel (a user's own ``h``), and takes the passages of a chunk in which an element fails
numerically (nothing of the chunk is written before both kernels succeed; the filter's numpy steps flag and
repair such an element) and a pruned bank's.  The tests compare the two paths bit for bit.  What stays in
numpy here: the hypotheses' covariances ``L L^T`` the time update starts from (numpy's matmul, whose sums a
compiled loop does not reproduce to the last bit).  At every batch size this is the faster path (docs:
Results).

The step takes its arrays in a few bundles named by meaning (:class:`StepSample`, :class:`BankArrays`,
:class:`Motion`, :class:`StepModel`, :class:`PassageRows`, :class:`Consistency`, :class:`Selection`).  Python
calls its entry (:data:`STEP_KERNELS`) with the bundles' fields flat, which bundles them for the step: numba's
dispatcher types a flat argument in its compiled fast path and a tuple's fields one by one, which at a batch of
one costs a share of the step (benchmarks/run.py measures the step).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from shipsense import numba_cache
from shipsense.models.measurement import kernel_of
from shipsense.parallel import in_chunks
from shipsense.trackers.bank.selection import first_max, report
from shipsense.trackers.filters.fused import filter_constants, no_sqrt, noise_root, noise_variances, per_element
from shipsense.trackers.filters.kernels import CDKF, EKF, HUBER, PUEKF, SRCDKF, UKF, UPDATE_BUNDLED
from shipsense.trackers.filters.time_update import predict_kernel
from shipsense.trackers.init.detection import DOUBLE_MAX, strongest_kernel
from shipsense.trackers.tracker.consistency import window_test


class StepSample(NamedTuple):
    """A sample as :class:`TrackerStep`'s kernel reads it: ``y`` (P, m) in the tracker's internal units
    (NaN = missing), whose scales are ``scale`` (m,), and the bank's model's scales ``bank_scale`` (m,)."""

    y: np.ndarray
    scale: np.ndarray
    bank_scale: np.ndarray


class BankArrays(NamedTuple):
    """The bank's hypotheses, a row per (passage, hypothesis): means (P*H, n), lower Cholesky factors
    (P*H, n, n) and the cumulative log-likelihoods (P, H), all read and written."""

    mean: np.ndarray
    chol: np.ndarray
    cum: np.ndarray


class Motion(NamedTuple):
    """The time update of a chunk's rows (len(runs)*H): what it predicts from, ``prior`` (len(runs)*H, n, n)
    (the covariances ``L L^T`` of the live rows; the SR-CDKF's: their factors), the transitions ``A`` and
    process noise ``Q`` (1 or len(runs)*H, n, n) and the SR-CDKF's noise root ``sqQ`` (1 or len(runs)*H, n, k)
    (the covariance form's: (1, n, 0))."""

    prior: np.ndarray
    A: np.ndarray
    Q: np.ndarray
    sqQ: np.ndarray


class StepModel(NamedTuple):
    """The bank's filter on its model, the same for every sample: the update's
    :class:`~shipsense.trackers.filters.kernels.UpdateSpec` (a plain tuple of its fields) and the state
    bounds ``lo``, ``hi`` (n,) (empty: none)."""

    update: tuple
    lo: np.ndarray
    hi: np.ndarray


class PassageRows(NamedTuple):
    """The per-passage state the step reads and writes, indexed by passage (fields of
    :class:`~shipsense.trackers.tracker.passages.PassageArrays`): the NIS window ``nis`` (P, N), whether the
    bank's fits are ``trusted`` (P,), the sample's ``status`` (P,) (written) and its codes ``tracking`` and
    ``inconsistent``."""

    nis: np.ndarray
    trusted: np.ndarray
    status: np.ndarray
    tracking: int
    inconsistent: int


class Consistency(NamedTuple):
    """The windowed innovation test's arguments (:func:`~shipsense.trackers.tracker.consistency.window_test`):
    whether it runs (``test``), the noise variances on ``S`` (``R_used``, 1 or P*H, m) and the model's
    (``R_declared``), the Huber options (``gamma``, ``outliers``, ``scale``), the quantile ``table`` and the
    passages' windows and counters (written)."""

    test: bool
    R_used: np.ndarray
    R_declared: np.ndarray
    gamma: float
    outliers: float
    scale: float
    table: np.ndarray
    window: np.ndarray
    count: np.ndarray
    tests: np.ndarray
    fails: np.ndarray
    now: np.ndarray


class Selection(NamedTuple):
    """The output's arguments (:func:`~shipsense.trackers.bank.selection.report`): the state scales, whether
    the covariance is the mixture's, the report's thresholds, the per-passage inflation ``excess`` and own
    covariance ``own``, and the sample's outputs (written)."""

    x_scale: np.ndarray
    mixture: bool
    report_nats: float
    far_m: float
    excess: np.ndarray
    estimate: np.ndarray
    cov: np.ndarray
    own: np.ndarray
    gap: np.ndarray
    ambiguous: np.ndarray
    hypotheses: np.ndarray
    selected: np.ndarray


def _step_kernel_for(code):
    """The compiled step of filter ``code`` and its entry: the update kernel a global of the step's own copy,
    the step a global of the entry's (as fused's kernels find their loops), so that each filter's step is
    compiled and cached apart."""
    filt_code = code

    def kernel(runs, H, sample, bank, motion, model, passages, consistency, selection):
        """One sample of passages ``runs`` (see the module): the bundles :class:`StepSample`,
        :class:`BankArrays`, :class:`Motion`, :class:`StepModel`, :class:`PassageRows`, :class:`Consistency`
        and :class:`Selection`.  Returns False, having written nothing, when an element's time or measurement
        update failed."""
        square_root = filt_code == SRCDKF
        yi, cum, A, Q, lo, hi = sample.y, bank.cum, motion.A, motion.Q, model.lo, model.hi
        R = runs.shape[0]
        n = bank.mean.shape[1]
        m = yi.shape[1]
        B = R * H
        live = live_rows(cum, runs, H)             # (only these are predicted and updated)
        where = np.empty(B, np.int64)               # a row's place among the live ones, -1 for a repeat
        row = np.empty(B, np.int64)                 # its row of the bank
        nl = 0
        for b in range(B):
            row[b] = runs[b // H] * H + b % H
            if live[b]:
                where[b] = nl
                nl += 1
            else:
                where[b] = -1
        X = np.empty((nl, n))
        Y = np.empty((nl, m))
        src_l = np.empty((nl, n, n))
        A_l = np.empty((nl if A.shape[0] > 1 else 1, n, n))
        Q_l = np.empty((nl if Q.shape[0] > 1 else 1, n, n))
        sq = motion.sqQ
        sq_l = np.empty((nl if sq.shape[0] > 1 else 1, n, sq.shape[2]))
        if A.shape[0] == 1:
            A_l[0] = A[0]
        if Q.shape[0] == 1:
            Q_l[0] = Q[0]
        if sq.shape[0] == 1:
            sq_l[0] = sq[0]
        for b in range(B):
            i = where[b]
            if i < 0:
                continue
            r = runs[b // H]
            for a in range(n):
                X[i, a] = bank.mean[row[b], a]
            for j in range(m):
                Y[i, j] = (yi[r, j] * sample.scale[j]) / sample.bank_scale[j]
            src_l[i] = motion.prior[b]
            if A.shape[0] > 1:
                A_l[i] = A[b]
            if Q.shape[0] > 1:
                Q_l[i] = Q[b]
            if sq.shape[0] > 1:
                sq_l[i] = sq[b]
        x, P, L = np.empty((nl, n)), np.empty((nl, n, n)), np.zeros((nl, n, n))
        ok = np.empty(nl, np.bool_)
        if not _PREDICT(X, src_l, A_l, Q_l, sq_l, square_root, x, P, L, ok):  # noqa: F821 - the copy's global
            return False
        mean_l, P_l = np.empty((nl, n)), np.empty((nl, n, n))
        L_l = np.zeros((1, 1, 1)) if square_root else np.zeros((nl, n, n))
        eps_l, S_l = np.empty((nl, m)), np.empty((nl, m, m))
        loglik_l, nis_l, cnt_l = np.empty(nl), np.empty(nl), np.empty(nl, np.int64)
        mask = np.ones((1, m), np.bool_)
        if not _UPDATE((x, L, np.zeros((1, 1, 1)) if square_root else P), (Y, mask), model.update,  # noqa: F821
                       (mean_l, P_l, L_l, eps_l, S_l, loglik_l, nis_l, cnt_l, ok)):
            return False
        factor_l = P_l if square_root else L_l     # (the SR-CDKF's update writes its factor as the covariance)
        # every row again: a repeat gains no log-likelihood, and its mean and factor are not written (kept)
        mean_out, L_out = np.empty((B, n)), np.empty((B, n, n))
        eps, S = np.full((B, m), np.nan), np.full((B, m, m), np.nan)
        loglik, nis, cnt = np.zeros(B), np.full(B, np.nan), np.zeros(B, np.int64)
        for b in range(B):
            i = where[b]
            if i < 0:
                continue
            mean_out[b], L_out[b], eps[b], S[b] = mean_l[i], factor_l[i], eps_l[i], S_l[i]
            loglik[b], nis[b], cnt[b] = loglik_l[i], nis_l[i], cnt_l[i]
        if lo.size > 0:     # the means into the state bounds, as np.clip (kept as they are when none moves)
            clipped = np.empty((B, n))
            same = True
            for b in range(B):
                if where[b] < 0:                         # (a repeat is not written)
                    continue
                for a in range(n):
                    v = mean_out[b, a]
                    t = lo[a] if v < lo[a] else v        # (np.clip's order: a NaN, or a -0.0 at 0, kept)
                    t = hi[a] if t > hi[a] else t
                    clipped[b, a] = t
                    same = same and t == v
            if not same:
                mean_out = clipped
        sel = np.empty(R, np.int64)
        cum_runs = np.empty((R, H))
        nis_hist = passages.nis
        for p in range(R):
            r = runs[p]
            for k in range(H):
                b = p * H + k
                if where[b] >= 0:
                    for a in range(n):
                        bank.mean[row[b], a] = mean_out[b, a]
                        for c in range(n):
                            bank.chol[row[b], a, c] = L_out[b, a, c]
                cum[r, k] += loglik[b]
                cum_runs[p, k] = cum[r, k]
            sel[p] = first_max(cum_runs[p])
            pick = p * H + sel[p]
            N = nis_hist.shape[1]
            for i in range(N - 1):
                nis_hist[r, i] = nis_hist[r, i + 1]
            nis_hist[r, N - 1] = nis[pick] / max(cnt[pick], 1) if cnt[pick] > 0 else np.nan
        failed = np.zeros(R, np.bool_)
        if consistency.test:
            present = np.empty((R, m), np.bool_)
            for p in range(R):
                for j in range(m):
                    present[p, j] = math.isfinite(yi[runs[p], j])
            c = consistency
            window_test(runs, sel, H, eps, S, c.R_used, c.R_declared, present, c.gamma, c.outliers, c.scale, c.table,
                        c.window, c.count, c.tests, c.fails, c.now, failed)
        s = selection
        report(bank.mean, bank.chol, runs, H, s.x_scale, cum_runs, s.mixture, s.report_nats, s.far_m, s.excess,
               s.estimate, s.cov, s.own, s.gap, s.ambiguous, s.hypotheses, s.selected)
        status = passages.status
        for p in range(R):
            status[runs[p]] = passages.tracking if passages.trusted[runs[p]] else passages.inconsistent
        for p in range(R):
            if failed[p]:
                status[runs[p]] = passages.inconsistent
        return True

    def entry(runs, H, y, scale, bank_scale, mean, chol, cum, prior, A, Q, sqQ, R, measurement, spread, center, Wm,
              Wc, h, gamma, iterations, n_pu, lo, hi, nis, trusted, status, tracking, inconsistent, test, R_used,
              R_declared, c_gamma, outliers, c_scale, table, window, count, tests, fails, now, x_scale, mixture,
              report_nats, far_m, excess, estimate, cov, own, gap, ambiguous, hypotheses, selected):
        """The step's entry: the bundles' fields in their order, flat (numba's dispatch types a flat argument in
        its fast path, an array in a tuple field by field: at a batch of one, a share of the step), bundled
        for the step ``_STEP``."""
        return _STEP(runs, H, StepSample(y, scale, bank_scale), BankArrays(mean, chol, cum),  # noqa: F821
                     Motion(prior, A, Q, sqQ),
                     StepModel((R, measurement, spread, center, Wm, Wc, h, gamma, iterations, n_pu), lo, hi),
                     PassageRows(nis, trusted, status, tracking, inconsistent),
                     Consistency(test, R_used, R_declared, c_gamma, outliers, c_scale, table, window, count, tests,
                                 fails, now),
                     Selection(x_scale, mixture, report_nats, far_m, excess, estimate, cov, own, gap, ambiguous,
                               hypotheses, selected))

    step = numba_cache.specialised(kernel, f"_tracker_step_{code}", njit(cache=True, error_model="numpy",
                                                                          inline="always"),
                                   _PREDICT=predict_kernel, _UPDATE=UPDATE_BUNDLED[code])
    return numba_cache.specialised(entry, f"_tracker_step_entry_{code}",
                                   njit(cache=True, error_model="numpy", nogil=True), _STEP=step), step


@njit(cache=True, nogil=True)
def live_rows(cum, runs, H):
    """The hypothesis rows of passages ``runs`` (int64) that the compiled step predicts and updates (len(runs) * H,)
    bool, from the banks' cumulative log-likelihoods ``cum`` (P, H): a -inf (a repeat that fills a bank: no
    weight) stays -inf until the bank restarts, and nothing reported reads such a hypothesis while its passage
    has another (:func:`~shipsense.trackers.bank.selection.report` selects the first maximum), so only the others
    are stepped; a passage whose every hypothesis is -inf (an absurd sample) steps them all, as the step by
    step path does."""
    out = np.empty(runs.shape[0] * H, np.bool_)
    for p in range(runs.shape[0]):
        any_live = False
        for k in range(H):
            any_live = any_live or cum[runs[p], k] != -np.inf
        for k in range(H):
            out[p * H + k] = not (any_live and cum[runs[p], k] == -np.inf)
    return out


@njit(cache=True, error_model="numpy", nogil=True)
def prepare_sample(act, t, y, ys, phase, last_t, n, y_hist, t_hist, cons_now, field, std, gap_limit, phases):
    """:meth:`Tracker.update`'s handling of a sample before the passages' steps, in one pass.  First the checks:
    a code and the index ``i`` into ``act`` it is about (1: passage ``act[i]`` pending, 2: a time not finite,
    3: passage ``act[i]``'s time not later than its last, 4: ``act[i]`` not a passage, 5: ``act[i]`` given
    before in ``act``), nothing written then;
    else (0) the sample in internal units ``yi`` (P, m), the time steps ``dt`` (P,) (NaN for the passages not
    in ``act``), the histories written, the strongest field channel's SNR (P,) (as
    :func:`~shipsense.trackers.init.detection.strongest_snr`), the passages with a field value started, the
    passages of ``act`` starting and running, and whether a time step exceeds ``gap_limit``.  ``phases``: the
    codes ``(waiting, starting, running, pending)``."""
    waiting, starting, running, pending = phases
    P, m = phase.shape[0], y.shape[1]
    A = act.shape[0]
    code, at = 0, 0
    given = np.zeros(P, np.bool_)
    for i in range(A):
        if act[i] < -P or act[i] >= P:
            code, at = 4, i
            break
        r = act[i] % P
        if given[r]:
            code, at = 5, i
            break
        given[r] = True
    for i in range(A if code == 0 else 0):
        if phase[act[i]] == pending:
            code, at = 1, i
            break
    for i in range(A if code == 0 else 0):
        if not math.isfinite(t[i]):
            code, at = 2, i
            break
    for i in range(A if code == 0 else 0):
        last = last_t[act[i]]
        if math.isfinite(last) and not t[i] > last:
            code, at = 3, i
            break
    if code != 0:
        return code, at, np.empty((0, m)), np.empty(0), np.empty(0), np.empty(0, np.int64), np.empty(0, np.int64), False
    yi = np.full((P, m), np.nan)
    dt = np.full(P, np.nan)
    gap = False
    ya = np.empty((A, m))
    for i in range(A):
        r = act[i]
        for j in range(m):
            ya[i, j] = y[i, j] / ys[j]
            yi[r, j] = ya[i, j]
        step = t[i] - last_t[r]
        dt[r] = step
        gap = gap or step > gap_limit
    K = y_hist.shape[1]
    for i in range(A):
        r = act[i]
        slot = n[r] % K
        for j in range(m):
            y_hist[r, slot, j] = ya[i, j]
        t_hist[r, slot] = t[i]
    strongest = np.empty(A)
    strongest_kernel(ya, field, std, DOUBLE_MAX, strongest)
    snr = np.zeros(P)
    for i in range(A):
        snr[act[i]] = strongest[i]
        cons_now[act[i]] = False
    seen = np.zeros(P, np.bool_)
    for i in range(A):
        for j in range(m):
            if field[j] and math.isfinite(ya[i, j]):
                seen[act[i]] = True
    for r in range(P):
        if phase[r] == waiting and seen[r]:
            phase[r] = starting
    count_s, count_r = 0, 0
    for i in range(A):
        count_s += phase[act[i]] == starting
        count_r += phase[act[i]] == running
    starts, runs = np.empty(count_s, np.int64), np.empty(count_r, np.int64)
    count_s, count_r = 0, 0
    for i in range(A):
        if phase[act[i]] == starting:
            starts[count_s] = act[i]
            count_s += 1
        elif phase[act[i]] == running:
            runs[count_r] = act[i]
            count_r += 1
    return 0, 0, yi, dt, snr, starts, runs, gap


THREAD_ROWS = 96
"""Hypothesis rows in a chunk of :class:`TrackerStep`'s passages; the chunks are shared among the CPUs."""

_STEP_PAIRS = {code: _step_kernel_for(code) for code in (UKF, CDKF, HUBER, EKF, PUEKF, SRCDKF)}
STEP_KERNELS = {code: entry for code, (entry, _) in _STEP_PAIRS.items()}
STEPS = {code: step for code, (_, step) in _STEP_PAIRS.items()}
"""Each filter's compiled step (``STEPS``, on the bundles) and its entry (``STEP_KERNELS``, on their fields), by
the filter's code (compiled at the entry's first call; the steps are here so that
:func:`shipsense.numba_cache.key_on_sources` stamps them too)."""


class TrackerStep:
    """The compiled step of a tracker's bank (``unit`` on ``model``, ``H`` hypotheses a passage), or None
    from :meth:`TrackerStep.of` where it does not apply; its arguments that do not change between samples kept."""

    @classmethod
    def of(cls, unit, model, H):
        """The step of ``unit`` on ``model`` with ``H`` hypotheses a passage, or None where the model has no
        compiled measurement kernel or a transition that changes between samples."""
        spec = kernel_of(model)
        if spec is None or np.ndim(model.A) != 2 or np.ndim(model.Q) != 2:
            return None
        return cls(unit, model, H, spec)

    def __init__(self, unit, model, H, spec):
        n = model.n
        consts = filter_constants(unit.name, n, unit.options)
        self.kernel = STEP_KERNELS[consts[0]]
        self.square_root = consts[0] == SRCDKF
        self.H = H
        bounds = getattr(model, "state_bounds", None)
        lo, hi = (np.empty(0), np.empty(0)) if bounds is None else (np.asarray(b, dtype=float) for b in bounds)
        self.motion = (per_element(model.A, (1,), n), per_element(model.Q, (1,), n),
                       noise_root(model.Q, (1,), n) if self.square_root else no_sqrt(n))
        # StepModel's fields, its UpdateSpec's flat (the entry's arguments)
        self.model = (noise_variances(model), spec, *consts[1:], np.ascontiguousarray(lo), np.ascontiguousarray(hi))
        self.ys_bank = np.ascontiguousarray(model.y_scale, dtype=float)

    def __call__(self, runs, yi, ys_in, bank, passages, consistency, selection, stepped=None):
        """Step passages ``runs`` (int64) with samples ``yi`` (P, m) (internal units of the tracker's model,
        whose scales are ``ys_in``) and the bank's transition, or ``stepped``'s (a model with one per hypothesis,
        irregular sampling); ``passages``, ``consistency`` and ``selection`` the kernel's bundles
        (:class:`PassageRows`, :class:`Consistency`, :class:`Selection`).  Returns the passages not stepped, for
        the step by step path (nothing of theirs written): none when done, all of them for a pruned bank.

        The passages are stepped in contiguous chunks of about :data:`THREAD_ROWS` hypothesis rows, the chunks
        shared among the CPUs (:func:`~shipsense.parallel.in_chunks`): a passage's step reads and writes only its
        own rows and entries, so the chunks change no number; a chunk in which an element failed writes nothing
        and its passages are returned.  The chunks do not depend on the number of threads, so neither do the
        passages a failure sends to the step by step path (whose batch is then theirs)."""
        H = self.H
        if len(bank.idx) != bank.R * H:
            return runs                     # (a pruned bank: BankState.step says why)
        rows = (runs[:, None] * H + np.arange(H)).ravel()
        # what the kernel predicts from, of the rows it steps only (it reads no repeat's, most of the rows in
        # the environments): the factors (SR-CDKF), or the covariances, each the product it would be in a full
        # batch (numpy multiplies a stack matrix by matrix)
        live = live_rows(bank.cum, runs, H)
        C = bank.belief.chol[rows[live]]
        src = np.zeros((rows.size,) + C.shape[1:])
        src[live] = C if self.square_root else C @ np.swapaxes(C, -1, -2)
        if stepped is None:
            A, Q, sqQ = self.motion
        else:
            n = bank.model.n
            A, Q = (per_element(a, (rows.size,), n) for a in (stepped.A, stepped.Q))
            sqQ = noise_root(stepped.Q, (rows.size,), n) if self.square_root else self.motion[2]
        mean, chol, cum = bank.belief.mean, bank.belief.chol, bank.cum

        def per_row(a, part):
            return a[part] if a.shape[0] > 1 else a

        def chunk(lo, hi):    # (the entry takes the bundles' fields, flat)
            part = slice(lo * H, hi * H)
            return self.kernel(runs[lo:hi], H, yi, ys_in, self.ys_bank, mean, chol, cum, src[part], per_row(A, part),
                               per_row(Q, part), per_row(sqQ, part), *self.model, *passages, *consistency, *selection)

        size = max(1, -(-THREAD_ROWS // H))            # passages a chunk
        count = -(-runs.size // size)
        parts = in_chunks(lambda c0, c1: [(c * size, min(runs.size, (c + 1) * size)) for c in range(c0, c1)
                                          if not chunk(c * size, min(runs.size, (c + 1) * size))], count, split_min=2)
        left = [runs[lo:hi] for failed in parts for lo, hi in failed]
        return np.concatenate(left) if left else runs[:0]


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
