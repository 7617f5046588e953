r"""The multiple-initial-value (MIV) bank with maximum-likelihood selection (the source studies' method).

All hypotheses of all runs are one flat batch of (run, hypothesis) pairs.
Each step is one batched predict and update; the cumulative log-likelihood

.. math::  \ell_j(k) = \sum_{i \le k} \ln L_j(i)

ranks the hypotheses.  Outputs: maximum-likelihood selection
(``argmax_j ell_j``), static multiple-model fusion (weights
``softmax(ell)``), pruning (hypotheses more than ``prune_nats`` below the best
of their run are removed from the batch, so their compute is freed), a
divergence flag per hypothesis (mean NIS over a window above its 99.9 %
chi-square bound, or a lost covariance), and the **near-tie ambiguity
report**: hypotheses far apart in position whose normalised log-likelihoods
are within ``ambiguity_nats`` are reported, not silently resolved by the
argmax.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from shipsense.trackers.bank.selection import mixture_mse
from shipsense.trackers.filters import Belief, FilterUnit, get_filter
from shipsense.trackers.filters.imm import IMM, ModeBelief, combine


@dataclass(frozen=True)
class BankRun:
    """Output of :func:`run_bank` (SI units).  Axes: runs R, hypotheses H, steps K.

    Attributes
    ----------
    seeds : (R, H, n)              initial means
    means : (R, H, K, n)           posterior means (NaN after a hypothesis is pruned)
    pos_cov : (R, H, K, 2, 2)      posterior position covariances
    loglik : (R, H, K)             innovation log-likelihoods (NaN after pruning)
    nis : (R, H, K)                normalised innovation squared
    m : (R, H, K)                  measurement components used
    ok : (R, H, K)                 covariance still positive definite
    active : (R, H, K)             not yet pruned
    labels : tuple                 state component names
    positions : (R, H, K, 2)       posterior positions (the first two columns of ``means``)

    A record :func:`run_bank` was not asked to keep (``store``) is None; ``positions`` and
    ``selected_means`` are then kept as the bank ran (``"positions"``, ``"selected"``); with ``"selected"``
    kept, ``selected`` is the selection made as the bank ran (the maximum of :attr:`cum_loglik`, which sums
    in the bank's order), so ``selected_means`` and ``selected_pos_cov`` are one choice.
    """

    seeds: np.ndarray
    means: np.ndarray | None
    pos_cov: np.ndarray | None
    loglik: np.ndarray | None
    nis: np.ndarray | None
    m: np.ndarray | None
    ok: np.ndarray | None
    active: np.ndarray
    labels: tuple
    initial_loglik: np.ndarray = 0.0
    kept_positions: np.ndarray | None = None
    kept_selected: np.ndarray | None = None
    kept_selected_index: np.ndarray | None = None

    def _kept(self, name):
        """The record ``name``, or a clear error when :func:`run_bank` was not asked to keep it."""
        value = getattr(self, name)
        if value is None:
            raise ValueError(f"this bank run did not keep {name!r}: run_bank(..., store=) must include it")
        return value

    @property
    def positions(self) -> np.ndarray:
        """Posterior positions (R, H, K, 2), SI."""
        if self.means is None:
            return self._kept("kept_positions")
        return self.means[..., :2]

    @property
    def cum_loglik(self) -> np.ndarray:
        """Cumulative log-likelihood (R, H, K) (from ``initial_loglik``); -inf once pruned.

        Summed as the bank sums while it runs, ``((initial + l_0) + l_1) + ...``: the same numbers, so a
        selection kept as it ran (``store`` with ``"selected"``) is their maximum even at a near-tie."""
        c = self._running_sums()
        c[~self.active] = -np.inf
        return c

    @property
    def final_loglik(self) -> np.ndarray:
        """:attr:`cum_loglik` at the last step (R, H), with one (R, H, K) temporary instead of two."""
        return np.where(self.active[..., -1], self._running_sums()[..., -1], -np.inf)

    def _running_sums(self):
        """The log-likelihoods summed in the bank's order from ``initial_loglik`` (R, H, K), a pruned entry
        adding 0."""
        c = np.where(self.active, self._kept("loglik"), 0.0)
        c[..., 0] += np.asarray(self.initial_loglik)
        return np.cumsum(c, axis=-1, out=c)

    @property
    def normalised_loglik(self) -> np.ndarray:
        """``ell_j - max_j ell_j`` (R, H, K)."""
        c = self.cum_loglik
        return c - c.max(axis=1, keepdims=True)

    @property
    def selected(self) -> np.ndarray:
        """Index of the maximum-likelihood hypothesis at every step (R, K)."""
        if self.kept_selected_index is not None:
            return self.kept_selected_index
        return np.argmax(self.cum_loglik, axis=1)

    @property
    def selected_means(self) -> np.ndarray:
        """Estimate of the selected hypothesis at every step (R, K, n)."""
        if self.kept_selected is not None:
            return self.kept_selected
        idx = self.selected[:, None, :, None]
        return np.take_along_axis(self._kept("means"), idx, axis=1)[:, 0]

    @property
    def selected_pos_cov(self) -> np.ndarray:
        """Position covariance of the selected hypothesis at every step (R, K, 2, 2), SI."""
        idx = self.selected[:, None, :, None, None]
        return np.take_along_axis(self._kept("pos_cov"), idx, axis=1)[:, 0]

    @property
    def weights(self) -> np.ndarray:
        """Static multiple-model weights ``softmax_j(ell_j)`` (R, H, K)."""
        w = np.exp(self.normalised_loglik)
        return w / w.sum(axis=1, keepdims=True)

    @property
    def fused_means(self) -> np.ndarray:
        """Fused mean ``sum_j mu_j x_j`` (R, K, n)."""
        w = self.weights[..., None]
        return np.sum(w * np.nan_to_num(self._kept("means")), axis=1)

    @property
    def fused_pos_cov(self) -> np.ndarray:
        """Fused position covariance ``sum_j mu_j (P_j + d_j d_j^T)`` (R, K, 2, 2)."""
        w = self.weights[..., None, None]
        d = np.nan_to_num(self.positions) - self.fused_means[:, None, :, :2]
        spread = d[..., :, None] * d[..., None, :]
        return np.sum(w * (np.nan_to_num(self._kept("pos_cov")) + spread), axis=1)

    @property
    def selected_pos_mse(self) -> np.ndarray:
        """Position mean-square-error matrix of the selected estimate under the bank's mixture (R, K, 2, 2):
        ``sum_j mu_j (P_j + e_j e_j^T)`` with ``e_j`` the position of hypothesis ``j`` minus the selected
        one's.  Equal to :attr:`selected_pos_cov` when one hypothesis holds all the weight; when
        distant hypotheses explain the data almost as well, it says so."""
        return mixture_mse(self.weights, self.positions, self._kept("pos_cov"), self.selected_means[:, None, :, :2])

    def diverged(self, window: int = 10, confidence: float = 0.999) -> np.ndarray:
        """Divergence flag (R, H, K): lost covariance, or mean NIS over the last ``window`` steps
        above its ``confidence`` chi-square bound."""
        from scipy import special  # 2 gammaincinv(k / 2, p) = scipy.stats.chi2.ppf(p, k), without scipy.stats

        nis = np.where(self.active, self._kept("nis"), 0.0)
        m = np.where(self.active, self._kept("m"), 0)
        cs_n = np.cumsum(nis, axis=-1)
        cs_m = np.cumsum(m, axis=-1)
        lag = lambda a: np.concatenate([np.zeros_like(a[..., :window]), a[..., :-window]], axis=-1)  # noqa: E731
        win_n = cs_n - lag(cs_n)
        win_m = cs_m - lag(cs_m)
        bound = 2.0 * special.gammaincinv(np.maximum(win_m, 1) / 2.0, confidence)
        return (~self._kept("ok")) | ((win_n > bound) & (win_m > 0))

    def ambiguities(self, step: int = -1, nats: float = 3.0, distance: float = 20.0):
        """Near-ties at ``step``: per run, a list of ``(i, j, delta_nats, distance_m)``.

        Pairs of hypotheses within ``nats`` of the best likelihood (both) and
        more than ``distance`` metres apart in position.
        """
        norm = self.normalised_loglik[:, :, step]
        pos = self.positions[:, :, step]
        out = []
        for r in range(norm.shape[0]):  # reporting only, not a hot path
            near = np.flatnonzero(norm[r] > -nats)
            pairs = []
            for a_i, i in enumerate(near):
                for j in near[a_i + 1:]:
                    d = float(np.linalg.norm(pos[r, i] - pos[r, j]))
                    if d > distance:
                        pairs.append((int(i), int(j), float(abs(norm[r, i] - norm[r, j])), d))
            out.append(pairs)
        return out


def _project(belief, model):
    """Means clipped into the model's physical ``state_bounds`` (e.g. the source stays in the water).

    Projecting the estimate onto the constraint set is the simplest
    state-constrained Kalman filter (Simon 2010, IET Control Theory Appl. 4(8)).
    """
    bounds = getattr(model, "state_bounds", None)
    if bounds is None:
        return belief
    clipped = np.clip(belief.mean, *bounds)
    if np.array_equal(clipped, belief.mean):
        return belief
    if hasattr(belief, "with_mean"):   # keeps a filter's covariance cache (and a pending factor pending)
        return belief.with_mean(clipped)
    return Belief(clipped, belief.chol, belief.ok)


class BankState:
    """The running state of a bank over R passages x H hypotheses: one flat batch, stepped one sample at a time.

    This is the bank's only time step: :func:`run_bank` loops over it, and the
    gymnasium environments call it once per environment step.

    Parameters
    ----------
    unit : FilterUnit
    model : FieldModel
    seeds : ndarray, shape (R, H, n)
        Initial means (SI).
    P0 : ndarray, shape (n, n) or (R, H, n, n)
        Initial covariances (SI).
    modes : MotionModes, optional
        Motion modes of an interacting multiple model filter (:mod:`~shipsense.trackers.filters.imm`): each
        hypothesis then carries one belief per mode and the modes' probabilities (``modal``, a
        :class:`~shipsense.trackers.filters.imm.ModeBelief`), and ``belief`` is their moment-matched
        combination; None: the unit's own (constant-velocity) filter.
    """

    def __init__(self, unit, model, seeds, P0, initial_loglik=None, modes=None):
        self.unit, self.model = unit, model
        self.filter = unit.on(model)                 # (its compiled or numpy steps, chosen once)
        self.imm = None if modes is None else IMM(unit, modes)
        seeds = np.asarray(seeds, dtype=float)
        self.R, self.H, n = seeds.shape
        xs = model.x_scale
        P0 = np.broadcast_to(np.asarray(P0, dtype=float) / np.outer(xs, xs), (self.R, self.H, n, n))
        self.belief = Belief.from_cov(seeds.reshape(-1, n) / xs, P0.reshape(-1, n, n))
        self.modal = None if self.imm is None else self.imm.start(self.belief)
        self.cum = np.zeros((self.R, self.H)) if initial_loglik is None else np.array(initial_loglik, float)
        self.idx = np.arange(self.R * self.H)        # active (not pruned) flat elements
        self.steps = 0

    @property
    def idx(self):
        """Flat indices (run * H + hypothesis) of the active (not pruned) elements."""
        return self._idx

    @idx.setter
    def idx(self, value):
        self._idx = value
        self._run_of, self._hyp_of = value // self.H, value % self.H

    run_of = property(lambda self: self._run_of, doc="Run of every active element (read-only use).")
    hyp_of = property(lambda self: self._hyp_of, doc="Hypothesis of every active element (read-only use).")

    def reset_runs(self, runs, seeds, P0, loglik=None):
        """Re-seed the hypotheses of some runs (all elements must be active); ``loglik`` (len(runs), H): their
        prior log-likelihoods (default 0)."""
        if len(self.idx) != self.R * self.H:
            raise ValueError("reset_runs needs a bank without pruning")
        runs = np.asarray(runs, dtype=int)
        xs = self.model.x_scale
        n = xs.size
        P0 = np.broadcast_to(np.asarray(P0, float) / np.outer(xs, xs), (len(runs), self.H, n, n))
        fresh = Belief.from_cov(np.asarray(seeds, float).reshape(-1, n) / xs, P0.reshape(-1, n, n))
        self.set_rows((runs[:, None] * self.H + np.arange(self.H)).ravel(), fresh)
        self.cum[runs] = 0.0 if loglik is None else loglik

    def set_rows(self, rows, belief, modal=None):
        """Rows ``rows`` of the bank set to ``belief`` (and, with modes, to ``modal``, or every mode at
        ``belief`` with the modes' prior when None)."""
        for arr, new in zip(self.belief, belief):
            arr[rows] = new
        self.belief = Belief(*self.belief)   # written in place: drop a filter's covariance cache
        if self.imm is not None:
            for arr, new in zip(self.modal, self.imm.start(Belief(*belief)) if modal is None else modal):
                arr[rows] = new

    def step(self, y, mask=None, predict=True, runs=None, model=None):
        """Predict (unless ``predict`` is False) and update with the samples ``y`` (R, m) SI.

        ``mask`` (R, m) marks the components to use.  With ``runs`` (indices),
        only those runs' hypotheses step (their rows are gathered, stepped and
        written back); the others are untouched.  ``model`` replaces the
        bank's model for this step (e.g. one with a transition per element,
        :meth:`~shipsense.models.field_model.FieldModel.stepped`).  Returns the
        innovation of the stepped elements.
        """
        if runs is None:
            sub, rows = self.belief, None
            run, hyp = self.run_of, self.hyp_of
        else:
            if len(self.idx) != self.R * self.H:
                raise ValueError("stepping a subset of runs needs a bank without pruning")
            runs = np.asarray(runs, dtype=int)
            rows = (runs[:, None] * self.H + np.arange(self.H)).ravel()
            sub = Belief(*(a[rows] for a in self.belief))
            run, hyp = np.repeat(runs, self.H), None
        yy = np.asarray(y, dtype=float)[run] / self.model.y_scale
        mk = None if mask is None else np.asarray(mask)[run]
        if self.imm is not None:
            return self._step_modes(yy, mk, predict, rows, runs, run, hyp, model)
        if predict and model is None:
            new, inn = self.filter.step(sub, yy, self.model, mk)
        else:
            b = self.filter.predict(sub, model) if predict else sub
            new, inn = self.filter.update(b, yy, self.model, mk)
        new = _project(new, self.model)
        if rows is None:
            self.belief = new
        else:
            self.set_rows(rows, new)
        return self._accumulate(inn, rows, runs, run, hyp)

    def _accumulate(self, inn, rows, runs, run, hyp):
        """The stepped elements' log-likelihoods into the cumulative ones; the step counted; ``inn`` back."""
        if rows is not None:
            self.cum[runs] += inn.loglik.reshape(runs.size, self.H)
        elif len(self.idx) == self.R * self.H:
            self.cum += inn.loglik.reshape(self.R, self.H)
        else:
            self.cum[run, hyp] += inn.loglik
        self.steps += 1
        return inn

    def _step_modes(self, yy, mk, predict, rows, runs, run, hyp, model):
        """:meth:`step` of an IMM bank: one IMM cycle of the rows (all active ones when ``rows`` is None)."""
        sub = self.modal if rows is None else ModeBelief(*(a[rows] for a in self.modal))
        if predict:
            tau = None if model is None else getattr(model, "tau", None)
            predicted, c = self.imm.predict(sub, self.model, tau)
        else:
            predicted, c = Belief(sub.mean, sub.chol, sub.ok), sub.prob
        modal, inn = self.imm.update(predicted, c, yy, self.model, mk)
        bounds = getattr(self.model, "state_bounds", None)
        if bounds is not None:
            modal = modal._replace(mean=np.clip(modal.mean, *bounds))
        x, P = combine(modal)
        new = Belief.from_cov(x, P)
        if rows is None:
            self.belief, self.modal = new, modal
        else:
            self.set_rows(rows, new, modal)
        return self._accumulate(inn, rows, runs, run, hyp)

    def prune(self, nats):
        """Drop active elements more than ``nats`` below the best of their run."""
        run = self.run_of
        c = self.cum[run, self.hyp_of]
        best = np.full(self.R, -np.inf)
        np.maximum.at(best, run, c)
        keep = c >= best[run] - nats
        if not keep.all():
            self.idx = self.idx[keep]
            self.belief = Belief(*(a[keep] for a in self.belief))
            if self.modal is not None:
                self.modal = ModeBelief(*(a[keep] for a in self.modal))
            dropped = np.zeros(self.R * self.H, dtype=bool)
            dropped[:] = True
            dropped[self.idx] = False
            self.cum.reshape(-1)[dropped] = -np.inf
        return ~keep

    def means(self, rows=None):
        """Posterior means of the active elements (or of active rows ``rows``), SI (len(idx), n)."""
        mean = self.belief.mean if rows is None else self.belief.mean[rows]
        return mean * self.model.x_scale

    def position_cov(self, rows=None):
        """Posterior position covariances of the active elements (or rows ``rows``), SI (len(idx), 2, 2)."""
        xs = self.model.x_scale[:2]
        cached = getattr(self.belief, "_cov", None)   # a filter's covariance: no factor needed
        if cached is not None:
            P = cached[:, :2, :2] if rows is None else cached[rows, :2, :2]
            return P * (xs[:, None] * xs)
        chol = self.belief.chol if rows is None else self.belief.chol[rows]
        L = chol[:, :2, :] * xs[:, None]
        return L @ np.swapaxes(L, -1, -2)

    def selected(self):
        """Maximum-likelihood hypothesis of every run (R,)."""
        return np.argmax(self.cum, axis=1)


RECORDS = ("means", "pos_cov", "loglik", "nis", "m", "ok", "positions", "selected")
"""What :func:`run_bank` can keep per step (``store``): the per-hypothesis records of :class:`BankRun`, the
positions alone (two of the ``n`` state columns), and the selected hypothesis's mean (R, K, n)."""


def run_bank(unit, model, measurements, seeds, P0, *, prune_nats=None, progress=False,
             initial_loglik=None, store=("means", "pos_cov", "loglik", "nis", "m", "ok")) -> BankRun:
    """Run a bank of hypotheses over passages as one batch.

    Parameters
    ----------
    unit : FilterUnit or str
    model : FieldModel
    measurements : ndarray, shape (R, K, m)
        SI units, NaN = missing.
    seeds : ndarray, shape (R, H, n)
        Initial means (SI), e.g. from :func:`shipsense.trackers.bank.seeding.seed_hypotheses`.
    P0 : ndarray, shape (n, n) or (R, H, n, n)
        Initial covariances (SI).
    prune_nats : float, optional
        Remove hypotheses whose cumulative log-likelihood falls this far below
        the best of their run (checked every step); their compute is freed.
    progress : bool
        Progress bar over the steps.
    initial_loglik : ndarray, shape (R, H), optional
        Prior log-likelihoods of the hypotheses (e.g. from a batch fit); the
        cumulative log-likelihoods start there.
    store : sequence of str
        The records to keep (:data:`RECORDS`); the others are None.  All but
        ``positions`` and ``selected`` by default.  A study over many runs
        that reads only the hypotheses' positions, their likelihoods and the
        selected track keeps ``("positions", "loglik", "selected")``: a
        fraction of the memory.
        ``selected`` is the maximum-likelihood hypothesis's mean at each step,
        chosen as the bank runs (the cumulative log-likelihood at that step).
    """
    if isinstance(unit, str):
        unit = get_filter(unit)
    if not isinstance(unit, FilterUnit):
        raise TypeError(f"unit must be a FilterUnit or a filter name, got {type(unit).__name__}")
    y = np.asarray(measurements, dtype=float)
    seeds = np.asarray(seeds, dtype=float)
    if y.ndim != 3 or seeds.ndim != 3 or y.shape[0] != seeds.shape[0]:
        raise ValueError(f"measurements must be (R, K, m) and seeds (R, H, n) with the same R; "
                         f"got {y.shape} and {seeds.shape}")
    store = (store,) if isinstance(store, str) else tuple(store)
    unknown = [s for s in store if s not in RECORDS]
    if unknown:
        raise ValueError(f"store: unknown {unknown[0]!r}; choose from {', '.join(RECORDS)}")
    R, K, m = y.shape
    H, n = seeds.shape[1:]
    state = BankState(unit, model, seeds, P0, initial_loglik)
    blank = np.empty if prune_nats is None else partial(np.full, fill_value=np.nan)   # unpruned: every entry written

    def kept(name, shape, make=blank, **kw):
        return make(shape, **kw) if name in store else None

    means = kept("means", (R, H, K, n))
    positions = kept("positions", (R, H, K, 2)) if means is None else None
    pos_cov = kept("pos_cov", (R, H, K, 2, 2))
    loglik = kept("loglik", (R, H, K))
    nis = kept("nis", (R, H, K))
    used = kept("m", (R, H, K), np.zeros, dtype=int)
    ok = kept("ok", (R, H, K), np.zeros, dtype=bool)
    selected = kept("selected", (R, K, n), np.empty)
    chosen = None if selected is None else np.empty((R, K), dtype=np.intp)
    active = np.zeros((R, H, K), dtype=bool)
    steps = range(K)
    if progress:
        from tqdm import tqdm

        steps = tqdm(steps, desc=f"bank {unit.name} {R}x{H}", unit="step", leave=False, disable=None)
    for k in steps:
        inn = state.step(y[:, k], predict=k > 0)
        if len(state.idx) == R * H:     # every hypothesis active: plain slices (fancy indexing costs more)
            at, rows = (slice(None), slice(None), k), (R, H)
        else:
            at, rows = (state.run_of, state.hyp_of, k), (-1,)
        mean = state.means() if means is not None or positions is not None or selected is not None else None
        for record, value in ((means, mean), (positions, None if positions is None else mean[:, :2]),
                              (pos_cov, None if pos_cov is None else state.position_cov()), (loglik, inn.loglik),
                              (nis, inn.nis), (used, inn.m), (ok, state.belief.ok)):
            if record is not None:
                record[at] = value.reshape(rows + value.shape[1:])
        active[at] = True
        if selected is not None:       # the maximum-likelihood hypothesis now, among the active ones
            chosen[:, k] = state.selected()
            row = np.arange(R) * H + chosen[:, k]                     # its flat element
            if len(state.idx) != R * H:                               # pruned: its row among the active ones
                row = np.searchsorted(state.idx, row)
            selected[:, k] = mean[row]
        if prune_nats is not None:
            state.prune(prune_nats)
    init = np.zeros((R, H)) if initial_loglik is None else np.asarray(initial_loglik, float)
    return BankRun(seeds, means, pos_cov, loglik, nis, used, ok, active, tuple(model.labels), init, positions,
                   selected, chosen)


def default_bank():
    """The bank used when a scenario has no ``[tracker.bank]`` section."""
    from shipsense.config import BankConfig

    return BankConfig(levels=[1e5, 1e6, 1e7], bearings_deg=[45.0, 135.0, 225.0, 315.0],
                      initial_velocity=(5.0, 5.0), initial_course="towards_array")
